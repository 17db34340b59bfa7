//! Tile geometry (context, alignment, window sides, the default tile) and the tiled column/E pass
//! that turns the prepared image and its P-buffers into the denoised image.

use std::time::Instant;

use burn::tensor::{Device, Tensor};

use super::path_stage::{path_buffer, pathnet_radius};
use super::timing::{timed_forward, Timings};
use super::window::{align_up, cut_map, window, window_origin};
use super::{to_vec, BranchMaps, Denoised, InferError, InferOptions, MAX_RADIANCE};
use crate::method::{Method, MethodModel};
use crate::model::DenoiserConfig;
use crate::preprocess::PreparedImage;

/// Input context (pixels, per side) of the tiled column/E pass: the columns' receptive radius
/// (a KPCN's margin; a U-Net's reaches further) plus E's. The path-manifold module's U-Net is not
/// included: its output is computed for the whole image beforehand, with its own context
/// ([`pathnet_radius`]).
pub fn context(config: &DenoiserConfig, method: Method) -> usize {
    let e = if method == Method::Guided { config.ensemble.depth * (config.ensemble.conv_kernel / 2) } else { 0 };
    config.column_radius() + e
}

/// Alignment of the padded image and of window origins and sizes that keeps every U-Net's
/// pooling grid (the path-manifold module's, the columns') in phase with the whole image.
pub fn alignment(config: &DenoiserConfig, method: Method) -> usize {
    let path = if method.needs_descriptors() { 1 << (config.pathnet.unet_widths.len().max(1) - 1) } else { 1 };
    path.max(config.column_alignment())
}

/// Window side of the column/E pass for an output tile of side `tile`.
pub fn window_side(config: &DenoiserConfig, method: Method, tile: usize) -> usize {
    let a = config.column_alignment();
    align_up(tile + 2 * context(config, method) + a - 1, a)
}

/// Window side of the U-Net pass (path-manifold models) for a block of side `tile`.
pub fn unet_window_side(config: &DenoiserConfig, method: Method, tile: usize) -> usize {
    let a = alignment(config, method);
    align_up(tile + 2 * pathnet_radius(config) + a - 1, a)
}

/// Default output tile. KPCN columns: 256 (a 280² window of the default guided model, 1.2× its
/// output). U-Net columns need far more context (their receptive radius), so their tiles are
/// 1024: images up to that size run as one window, and larger ones waste ≤ 1.7× on context.
/// Windows hold per-pixel inputs only, so the sample count does not matter here; the per-sample
/// stages run per pixel ([`PathMlp`]).
///
/// [`PathMlp`]: super::PathMlp
pub fn auto_tile(config: &DenoiserConfig) -> usize {
    if config.mskp.is_some() {
        1024
    } else {
        256
    }
}

/// See [`denoise`].
///
/// [`denoise`]: super::denoise
pub(super) fn denoise_tiled(
    model: &MethodModel,
    config: &DenoiserConfig,
    image: &PreparedImage,
    noisy: &[f32],
    opts: &InferOptions,
    device: &Device,
) -> Result<Denoised, InferError> {
    let t0 = Instant::now();
    let method = model.method().ok_or(InferError::BadModel)?;
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return Err(InferError::Empty);
    }
    if noisy.len() != 3 * w * h {
        return Err(InferError::NoisySize { got: noisy.len(), expected: 3 * w * h });
    }
    if method.needs_descriptors() && !image.has_descriptors() {
        return Err(InferError::MissingDescriptors(method));
    }
    let m = config.margin();
    let c = context(config, method);
    let a = alignment(config, method);
    let ca = config.column_alignment();
    // Padded image: m on the left/top, m plus alignment slack (for the U-Net's pooling) on the
    // right/bottom.
    let (pw, ph) = (align_up(w + 2 * m, a), align_up(h + 2 * m, a));
    let tile = if opts.tile == 0 { auto_tile(config) } else { opts.tile };
    let win = window_side(config, method, tile);
    let (ww, wh) = (win.min(pw), win.min(ph));
    let mut timings = Timings { tile, ..Default::default() };

    let tp = Instant::now();
    let pbufs: Option<[Vec<f32>; 2]> = match (&model.diffuse.path, &model.specular.path) {
        (Some(pd), Some(ps)) => {
            let unet = (tile, pathnet_radius(config), a, unet_window_side(config, method, tile));
            Some([pd, ps].map(|net| path_buffer(net, image, (m, pw, ph), unet, device)))
        }
        _ => None,
    };
    if pbufs.is_some() {
        timings.path_s = tp.elapsed().as_secs_f64();
        timings.d_p_s += timings.path_s;
        timings.forward_s += timings.path_s;
    }

    let mut blocks = Vec::new();
    for ty in (0..h).step_by(tile) {
        for tx in (0..w).step_by(tile) {
            blocks.push((tx, ty, tile.min(w - tx), tile.min(h - ty)));
        }
    }
    let mut radiance = vec![0.0f32; 3 * w * h];
    let guided = method == Method::Guided;
    let mut wd = if guided { vec![0.0f32; w * h] } else { Vec::new() };
    let mut ws = wd.clone();
    timings.windows = blocks.len();
    timings.window = ww.max(wh);
    for chunk in blocks.chunks(opts.batch.max(1)) {
        let tg = Instant::now();
        // Block at output coordinate t starts at padded coordinate t + m.
        let origins: Vec<(usize, usize)> =
            chunk.iter().map(|&(tx, ty, _, _)| (window_origin(tx + m, c, ca, ww, pw), window_origin(ty + m, c, ca, wh, ph))).collect();
        let wins: Vec<PreparedImage> = origins.iter().map(|&(x0, y0)| window(image, m, x0, y0, ww, wh, false)).collect();
        let refs: Vec<&PreparedImage> = wins.iter().collect();
        let input = PreparedImage::to_tensors(&refs, device);
        drop(wins);
        let pb = pbufs.as_ref().map(|[d, s]| [d, s].map(|b| cut_map(b, b.len() / (pw * ph), pw, ph, &origins, ww, wh, device)));
        timings.gather_s += tg.elapsed().as_secs_f64();
        let tf = Instant::now();
        let out = timed_forward(model, input, pb, &mut timings);
        let tr = Instant::now();
        let rad = to_vec(out.radiance);
        let weights = if guided {
            let take = |t: Option<Tensor<4>>| t.map(|t| to_vec(t.narrow(1, 0, 1)));
            Some((take(out.diffuse.weights), take(out.specular.weights)))
        } else {
            None
        };
        timings.readback_s += tr.elapsed().as_secs_f64();
        timings.forward_s += tf.elapsed().as_secs_f64();
        // Output map of a window: (ww − 2m) × (wh − 2m); its pixel (0,0) is output coordinate
        // (x0, y0) (padded x0 + m).
        let (ow, oh) = (ww - 2 * m, wh - 2 * m);
        for (k, (&(tx, ty, bw, bh), &(x0, y0))) in chunk.iter().zip(&origins).enumerate() {
            for y in ty..ty + bh {
                for x in tx..tx + bw {
                    let (lx, ly) = (x - x0, y - y0);
                    let i = y * w + x;
                    for ch in 0..3 {
                        radiance[3 * i + ch] = clean(rad[((k * 3 + ch) * oh + ly) * ow + lx]);
                    }
                    if let Some((Some(d), Some(s))) = &weights {
                        let j = (k * oh + ly) * ow + lx;
                        wd[i] = d[j];
                        ws[i] = s[j];
                    }
                }
            }
        }
    }
    for (i, &pass) in image.passthrough.iter().enumerate() {
        if pass {
            for ch in 0..3 {
                radiance[3 * i + ch] = clean(noisy[3 * i + ch]);
            }
        }
    }
    let weights_g = guided.then(|| {
        let fix = |v: Vec<f32>| v.into_iter().map(|x| if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.5 }).collect();
        BranchMaps { diffuse: fix(wd), specular: fix(ws) }
    });
    timings.total_s = t0.elapsed().as_secs_f64();
    Ok(Denoised { width: w, height: h, radiance, weights_g, timings })
}

pub(super) fn clean(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, MAX_RADIANCE)
    }
}
