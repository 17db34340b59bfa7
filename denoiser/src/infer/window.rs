//! Padding and windowing: mirror reflection of image coordinates, and cutting aligned windows out
//! of the mirror-padded prepared image or out of a planar per-pixel map.

use burn::tensor::{Device, Tensor};

use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::preprocess::PreparedImage;

/// Mirror index into 0..n for any integer (period 2n−2).
pub(super) fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let j = i.rem_euclid(period);
    (if j < n as isize { j } else { period - j }) as usize
}

pub(super) fn align_up(x: usize, a: usize) -> usize {
    x.div_ceil(a) * a
}

/// The `w × h` window whose top-left corner is at padded coordinates (x0, y0); padded
/// coordinate p maps to image coordinate reflect(p − pad).
/// Descriptors are cut only if `descriptors` (the tiled pass reads precomputed P-buffers).
pub(super) fn window(img: &PreparedImage, pad: usize, x0: usize, y0: usize, w: usize, h: usize, descriptors: bool) -> PreparedImage {
    let cols: Vec<usize> = (0..w).map(|x| reflect((x0 + x) as isize - pad as isize, img.width)).collect();
    let rows: Vec<usize> = (0..h).map(|y| reflect((y0 + y) as isize - pad as isize, img.height)).collect();
    let n = img.width * img.height;
    let cut = |src: &[f32], planes: usize| -> Vec<f32> {
        let mut out = Vec::with_capacity(planes * w * h);
        for p in 0..planes {
            let plane = &src[p * n..(p + 1) * n];
            for &r in &rows {
                let row = &plane[r * img.width..(r + 1) * img.width];
                out.extend(cols.iter().map(|&c| row[c]));
            }
        }
        out
    };
    PreparedImage {
        width: w,
        height: h,
        spp: img.spp,
        diffuse: cut(&img.diffuse, COLOUR_BLOCK),
        specular: cut(&img.specular, COLOUR_BLOCK),
        g_block: cut(&img.g_block, G_BLOCK),
        path_weight: cut(&img.path_weight, 1),
        descriptors: if descriptors {
            let pixels: Vec<usize> = rows.iter().flat_map(|&r| cols.iter().map(move |&c| r * img.width + c)).collect();
            img.descriptor_columns(&pixels)
        } else {
            None
        },
        records: None,
        passthrough: Vec::new(),
    }
}

/// Where a window of `size` pixels goes so that it contains the block starting at padded
/// coordinate `p` plus `c` pixels of context, with its origin a multiple of `a` and the window
/// inside `0..padded` (shifted inward at the edge, never clipped).
pub(super) fn window_origin(p: usize, c: usize, a: usize, size: usize, padded: usize) -> usize {
    (p.saturating_sub(c) / a * a).min(padded - size)
}

/// Planar `[ch, h, w]` map → `[1, ch, wh, ww]` tensor of the window at (x0, y0), for each window.
pub(super) fn cut_map(
    map: &[f32],
    ch: usize,
    w: usize,
    h: usize,
    origins: &[(usize, usize)],
    ww: usize,
    wh: usize,
    device: &Device,
) -> Tensor<4> {
    let mut data = Vec::with_capacity(origins.len() * ch * ww * wh);
    for &(x0, y0) in origins {
        for c in 0..ch {
            for y in y0..y0 + wh {
                let row = (c * h + y) * w + x0;
                data.extend_from_slice(&map[row..row + ww]);
            }
        }
    }
    Tensor::from_data(burn::tensor::TensorData::new(data, [origins.len(), ch, wh, ww]), device)
}
