//! The path-manifold stage: each branch's per-pixel P-buffers [f_P, v_P] on the whole padded
//! image, the per-sample stages run over chunks of pixels and the U-Net over aligned windows.

use burn::tensor::Device;

use super::path_mlp::PathMlp;
use super::to_vec;
use super::window::{cut_map, reflect, window_origin};
use crate::model::DenoiserConfig;
use crate::pathnet::PathNet;
use crate::preprocess::PreparedImage;

/// Receptive radius (pixels, per side) of the U-Net of the path-manifold module, a bound:
/// each same-padded k×k convolution at level l adds (k/2)·2^l, each 2×2 pooling into level l
/// adds 2^(l−1), each bilinear upsampling from level l+1 reads ±1 pixel there, 2^(l+1).
pub fn pathnet_radius(config: &DenoiserConfig) -> usize {
    let p = &config.pathnet;
    let r = p.convs_per_block * (p.unet_kernel / 2);
    let levels = p.unet_widths.len();
    let mut total = 0;
    for l in 0..levels {
        total += r << l;
        if l > 0 {
            total += 1 << (l - 1);
        }
        if l + 1 < levels {
            total += (2 << l) + (r << l);
        }
    }
    total
}

/// One branch's P-buffer [f_P, v_P] `[13, ph, pw]` (planar) on the padded grid: padded pixel
/// (x, y) is image pixel (reflect(x − m), reflect(y − m)), as in [`window`]. Same arithmetic as
/// [`PathNet::forward`] on the whole padded image, staged so that memory stays bounded: the
/// pointwise stages per pixel on the host ([`PathMlp`]), the U-Net over `tile` blocks with
/// `radius` pixels of context in windows of side `side` (see [`unet_window_side`]), aligned to `a`.
///
/// [`window`]: super::window::window
/// [`unet_window_side`]: super::unet_window_side
pub(super) fn path_buffer(
    net: &PathNet,
    image: &PreparedImage,
    (m, pw, ph): (usize, usize, usize),
    (tile, radius, a, side): (usize, usize, usize, usize),
    device: &Device,
) -> Vec<f32> {
    let (w, h) = (image.width, image.height);
    let n = w * h;
    let mlp = PathMlp::new(net);
    let ew = mlp.embed_width();
    // Per-pixel mean embedding of the image (pixel-major), then mirror-padded planar: the
    // embedding is pointwise, so the mean at a mirrored pixel is the mirrored mean.
    let all: Vec<usize> = (0..n).collect();
    let mean = mlp.mean_embedding(image, &all);
    let cols: Vec<usize> = (0..pw).map(|x| reflect(x as isize - m as isize, w)).collect();
    let rows: Vec<usize> = (0..ph).map(|y| reflect(y as isize - m as isize, h)).collect();
    let np = pw * ph;
    let mut padded = Vec::with_capacity(ew * np);
    for c in 0..ew {
        for &r in &rows {
            padded.extend(cols.iter().map(|&x| mean[(r * w + x) * ew + c]));
        }
    }
    drop(mean);

    // U-Net over aligned windows of the padded map; each keeps its block.
    let (uw, uh) = (side.min(pw), side.min(ph));
    let mut g_map: Vec<f32> = Vec::new();
    let mut gw = 0;
    // A window spanning a whole axis keeps all of it (the grid may exceed `tile` by the margin).
    let (tx, ty) = (if uw == pw { pw } else { tile }, if uh == ph { ph } else { tile });
    for by in (0..ph).step_by(ty) {
        for bx in (0..pw).step_by(tx) {
            let o = (window_origin(bx, radius, a, uw, pw), window_origin(by, radius, a, uh, ph));
            let g = to_vec(net.unet(cut_map(&padded, ew, pw, ph, &[o], uw, uh, device)));
            if g_map.is_empty() {
                gw = g.len() / (uw * uh);
                g_map = vec![0.0; gw * np];
            }
            for c in 0..gw {
                for y in by..(by + ty).min(ph) {
                    let (bw, ly) = (tx.min(pw - bx), y - o.1);
                    let src = (c * uh + ly) * uw + bx - o.0;
                    g_map[(c * ph + y) * pw + bx..][..bw].copy_from_slice(&g[src..src + bw]);
                }
            }
        }
    }
    drop(padded);

    // Head and pooling per padded pixel, re-embedding its samples (storing the embeddings would
    // cost spp × E floats per pixel).
    let source: Vec<usize> = (0..np).map(|p| rows[p / pw] * w + cols[p % pw]).collect();
    let v = mlp.pixel_buffer(image, &source, |p, g: &mut [f32]| {
        for (c, o) in g.iter_mut().enumerate() {
            *o = g_map[c * np + p];
        }
    });
    // Pixel-major → planar.
    let oc = v.len() / np.max(1);
    let mut out = vec![0.0; oc * np];
    for (p, px) in v.chunks_exact(oc).enumerate() {
        for (c, &x) in px.iter().enumerate() {
            out[c * np + p] = x;
        }
    }
    out
}
