//! Padding and windowing: mirror reflection of image coordinates, and cutting aligned windows out
//! of the mirror-padded prepared image or out of a planar per-pixel map.

use burn::tensor::{Device, Tensor};

use crate::preprocess::window::{cut_window, Offset};
use crate::preprocess::PreparedImage;

/// The `w × h` window whose top-left corner is at padded coordinates (x0, y0); padded
/// coordinate p is image coordinate p − pad, read from the mirror-extended image as training
/// patches are ([`cut_window`]: normals flipped and gradients recomputed in the pad).
/// Descriptors are cut only if `descriptors` (the tiled pass reads precomputed P-buffers).
pub(super) fn window(img: &PreparedImage, pad: usize, x0: usize, y0: usize, w: usize, h: usize, descriptors: bool) -> PreparedImage {
    let (mut win, pixels) = cut_window(img, &Offset { x0: x0 as isize - pad as isize, y0: y0 as isize - pad as isize }, w, h);
    if descriptors {
        win.descriptors = img.descriptor_columns(&pixels);
    }
    // Pass-through pixels are restored from the noisy image after inference, not per window.
    win.passthrough = Vec::new();
    win
}

pub(super) fn align_up(x: usize, a: usize) -> usize {
    x.div_ceil(a) * a
}

/// Where a window of `size` pixels goes so that it contains the block starting at padded
/// coordinate `p` plus `c` pixels of context, with its origin a multiple of `a` and the window
/// inside `0..padded` (shifted inward at the edge, never clipped).
pub(super) fn window_origin(p: usize, c: usize, a: usize, size: usize, padded: usize) -> usize {
    (p.saturating_sub(c) / a * a).min(padded - size)
}

/// Planar `[ch, h, w]` map → `[1, ch, wh, ww]` tensor of the window at (x0, y0), for each window.
pub(super) fn cut_map(map: &[f32], ch: usize, w: usize, h: usize, origins: &[(usize, usize)], ww: usize, wh: usize, device: &Device) -> Tensor<4> {
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
