//! The path-manifold stage: each branch's per-pixel P-buffers [f_P, v_P] on the whole padded
//! image, the per-sample stages run over chunks of pixels and the U-Net over aligned windows.

use burn::tensor::{Device, Tensor};

use super::to_vec;
use super::window::{cut_map, reflect, window_origin};
use crate::model::DenoiserConfig;
use crate::pathnet::PathNet;
use crate::preprocess::{PreparedImage, DESCRIPTOR_CHANNELS};

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

/// Samples × pixels per chunk of the per-sample stages of the path-manifold module. Each
/// sample-pixel holds ~36 + 3·E + 2·(E + G) + hidden + 12 floats of activations (≈ 1 KB for
/// the default preset), so a chunk is ~130 MB whatever the image size and spp; large enough
/// that the 1×1 convolutions run as big matrix products.
pub const CHUNK_SAMPLE_PIXELS: usize = 1 << 17;

/// One branch's P-buffer [f_P, v_P] `[13, ph, pw]` (planar) on the padded grid: padded pixel
/// (x, y) is image pixel (reflect(x − m), reflect(y − m)), as in [`window`]. Same arithmetic as
/// [`PathNet::forward`] on the whole padded image, staged so that memory stays bounded: the
/// pointwise stages over chunks of `chunk` sample-pixels, the U-Net over `tile` blocks with
/// `radius` pixels of context in windows of side `side` (see [`unet_window_side`]), aligned to `a`.
///
/// [`window`]: super::window::window
/// [`unet_window_side`]: super::unet_window_side
#[allow(clippy::too_many_arguments)]
pub(super) fn path_buffer(
    net: &PathNet,
    image: &PreparedImage,
    (m, pw, ph): (usize, usize, usize),
    (tile, radius, a, side): (usize, usize, usize, usize),
    chunk: usize,
    device: &Device,
) -> Vec<f32> {
    let (w, h, s) = (image.width, image.height, image.spp.max(1));
    let n = w * h;
    let per_chunk = (chunk / s).max(1);
    // Descriptors of the listed image pixels as `[1, S, 36, 1, len]`.
    let gather = |pixels: &mut dyn Iterator<Item = usize>| -> Tensor<5> {
        let idx: Vec<usize> = pixels.collect();
        let len = idx.len();
        let data = image.descriptor_columns(&idx).unwrap_or_else(|| vec![0.0; s * DESCRIPTOR_CHANNELS * len]);
        Tensor::from_data(burn::tensor::TensorData::new(data, [1, s, DESCRIPTOR_CHANNELS, 1, len]), device)
    };

    // Per-pixel mean embedding of the image, then mirror-padded: embedding is pointwise, so the
    // mean at a mirrored pixel is the mirrored mean.
    let mut mean: Vec<f32> = Vec::new();
    let mut ew = 0;
    for p0 in (0..n).step_by(per_chunk) {
        let p1 = (p0 + per_chunk).min(n);
        let e = net.embed(gather(&mut (p0..p1)));
        let v = to_vec(PathNet::pixel_mean(&e));
        if mean.is_empty() {
            ew = v.len() / (p1 - p0);
            mean = vec![0.0; ew * n];
        }
        for c in 0..ew {
            mean[c * n + p0..c * n + p1].copy_from_slice(&v[c * (p1 - p0)..(c + 1) * (p1 - p0)]);
        }
    }
    let cols: Vec<usize> = (0..pw).map(|x| reflect(x as isize - m as isize, w)).collect();
    let rows: Vec<usize> = (0..ph).map(|y| reflect(y as isize - m as isize, h)).collect();
    let np = pw * ph;
    let mut padded = Vec::with_capacity(ew * np);
    for c in 0..ew {
        for &r in &rows {
            padded.extend(cols.iter().map(|&x| mean[c * n + r * w + x]));
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

    // Head and pooling per chunk of padded pixels, re-embedding their samples.
    let mut out: Vec<f32> = Vec::new();
    let mut oc = 0;
    for p0 in (0..np).step_by(per_chunk) {
        let p1 = (p0 + per_chunk).min(np);
        let len = p1 - p0;
        let e = net.embed(gather(&mut (p0..p1).map(|p| rows[p / pw] * w + cols[p % pw])));
        let mut gd = Vec::with_capacity(gw * len);
        for c in 0..gw {
            gd.extend_from_slice(&g_map[c * np + p0..c * np + p1]);
        }
        let g = Tensor::from_data(burn::tensor::TensorData::new(gd, [1, gw, 1, len]), device);
        let v = to_vec(net.head_pool(e, g).pixel_buffer());
        if out.is_empty() {
            oc = v.len() / len;
            out = vec![0.0; oc * np];
        }
        for c in 0..oc {
            out[c * np + p0..c * np + p1].copy_from_slice(&v[c * len..(c + 1) * len]);
        }
    }
    out
}
