//! Tiled inference on a whole image (method.md §7.3), with bounded memory.
//!
//! **Border.** The KPCN columns use valid convolutions, so a full-size output needs `m` extra
//! input pixels on every side (m = [`DenoiserConfig::margin`]). The prepared input is extended by
//! *mirror reflection* (pixel −1 is pixel 1). Zero padding would let the kernel apply average
//! black into every border pixel (the kernel reads the uncropped noisy colour, and its weights are
//! a softmax that does not renormalise), and would show the networks zero normals/albedo/depth
//! that they never met in training; replicating the edge pixel would make the kernel weight the
//! noise of a single pixel many times. Mirroring keeps both the colour the kernel averages and the
//! guidance features real. (The forward-difference gradient channels are mirrored as stored, so
//! their sign flips along the mirrored axis inside the pad; they only steer the kernels there.)
//!
//! **Path-manifold module first, per pixel.** For models with one (p, both, guided), the
//! per-pixel P-buffers (f_P, v_P of each branch) are computed for the whole padded image before
//! any tile, in [`PathNet`]'s stages: the per-sample embedding over chunks of pixels (pointwise,
//! so no overlap), its per-pixel mean mirror-padded like the image, the U-Net over windows of
//! the padded mean map carrying [`pathnet_radius`] of context (window origins and sizes aligned
//! to 2^(levels−1) pixels so the 2×2 pooling grid stays in phase with the whole image), then the
//! per-sample head over chunks again (the embedding is recomputed rather than stored: storing it
//! would cost spp × E floats per pixel). Each sample is thus embedded twice and passed through
//! the head once, whatever the tile size — before, every overlapping window recomputed them.
//!
//! **Tiles.** The padded image is then cut into windows, each giving a `tile × tile` block of
//! output. A window carries [`context`] pixels of input around its block: the KPCN margin plus
//! the receptive radius of E (same-padded convolutions); the P-buffers are cut from the
//! precomputed padded maps. Windows at the edge are shifted inward (never clipped) so that all
//! windows have one size and can be batched; one that reaches the padded image's edge sees the
//! same zero padding there that the whole-image run sees. Result: tiled output = the model's
//! forward on the whole padded image up to f32 rounding of differently-blocked arithmetic
//! (tested).
//!
//! Memory: only one chunk of samples, one U-Net window or one batch of windows is ever a tensor;
//! the prepared image itself (descriptors included) and the per-pixel maps stay planar on the CPU.

use std::time::Instant;

use burn::tensor::{Device, Tensor};

use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::method::{Method, MethodModel, MethodOutput, Part};
use crate::model::DenoiserConfig;
use crate::pathnet::PathNet;
use crate::preprocess::{InputTensors, PreparedImage, DESCRIPTOR_CHANNELS};

/// Largest radiance written. Nothing physical comes near; it keeps squared errors of the output
/// finite in f32 and stands in for +Inf.
pub const MAX_RADIANCE: f32 = 1e18;

#[derive(Clone, Debug)]
pub struct InferOptions {
    /// Output block per window (pixels, square); 0 = [`auto_tile`]. Larger tiles waste less on
    /// context but need more memory; see docs/denoiser-design.md for measured figures.
    pub tile: usize,
    /// Windows per forward pass.
    pub batch: usize,
}

impl Default for InferOptions {
    fn default() -> Self {
        InferOptions { tile: 0, batch: 1 }
    }
}

/// The denoised image.
#[derive(Clone, Debug)]
pub struct Denoised {
    pub width: usize,
    pub height: usize,
    /// Linear RGB radiance, interleaved `[H, W, 3]` like `Frame::radiance.mean`; finite, ≥ 0.
    pub radiance: Vec<f32>,
    /// W_G per pixel `[H, W]` of the diffuse and the specular branch (guided models only).
    pub weights_g: Option<BranchMaps>,
    pub timings: Timings,
}

#[derive(Clone, Debug)]
pub struct BranchMaps {
    pub diffuse: Vec<f32>,
    pub specular: Vec<f32>,
}

#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// Output tile side used.
    pub tile: usize,
    /// Cutting windows out of the prepared image and building tensors.
    pub gather_s: f64,
    /// Network forward passes (including reading results back); the sum of d_g, d_p, e, readback.
    pub forward_s: f64,
    /// D_G columns of both branches (KPCN on G-buffers).
    pub d_g_s: f64,
    /// Path-manifold modules plus the D_P columns (method p, guided) or the G+P columns (both).
    pub d_p_s: f64,
    /// Of `d_p_s`, the path-manifold modules alone (both branches, whole image).
    pub path_s: f64,
    /// E and the blend (guided), and the recombination of the two branches (every method).
    pub e_s: f64,
    /// Reading the results back into host memory.
    pub readback_s: f64,
    /// Everything.
    pub total_s: f64,
    pub windows: usize,
    /// Window side in pixels (input), for the record.
    pub window: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum InferError {
    #[error("the {0} model needs per-sample path descriptors, but the frame has none (render with descriptors, or pass --descriptors)")]
    MissingDescriptors(Method),
    #[error("the noisy radiance has {got} values, expected {expected} (3 per pixel)")]
    NoisySize { got: usize, expected: usize },
    #[error("the model's networks do not form one of the methods g, p, both, guided")]
    BadModel,
    #[error("empty image")]
    Empty,
}

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
/// stages run in chunks of [`CHUNK_SAMPLE_PIXELS`].
pub fn auto_tile(config: &DenoiserConfig) -> usize {
    if config.mskp.is_some() { 1024 } else { 256 }
}

/// Samples × pixels per chunk of the per-sample stages of the path-manifold module. Each
/// sample-pixel holds ~36 + 3·E + 2·(E + G) + hidden + 12 floats of activations (≈ 1 KB for
/// the default preset), so a chunk is ~130 MB whatever the image size and spp; large enough
/// that the 1×1 convolutions run as big matrix products.
pub const CHUNK_SAMPLE_PIXELS: usize = 1 << 17;

/// Mirror index into 0..n for any integer (period 2n−2).
fn reflect(i: isize, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let j = i.rem_euclid(period);
    (if j < n as isize { j } else { period - j }) as usize
}

fn align_up(x: usize, a: usize) -> usize {
    x.div_ceil(a) * a
}

/// The `w × h` window whose top-left corner is at padded coordinates (x0, y0); padded
/// coordinate p maps to image coordinate reflect(p − pad).
/// Descriptors are cut only if `descriptors` (the tiled pass reads precomputed P-buffers).
fn window(img: &PreparedImage, pad: usize, x0: usize, y0: usize, w: usize, h: usize, descriptors: bool) -> PreparedImage {
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

fn to_vec(t: Tensor<4>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap_or_default()
}

fn clean(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, MAX_RADIANCE)
    }
}

/// Where a window of `size` pixels goes so that it contains the block starting at padded
/// coordinate `p` plus `c` pixels of context, with its origin a multiple of `a` and the window
/// inside `0..padded` (shifted inward at the edge, never clipped).
fn window_origin(p: usize, c: usize, a: usize, size: usize, padded: usize) -> usize {
    (p.saturating_sub(c) / a * a).min(padded - size)
}

/// Planar `[ch, h, w]` map → `[1, ch, wh, ww]` tensor of the window at (x0, y0), for each window.
fn cut_map(map: &[f32], ch: usize, w: usize, h: usize, origins: &[(usize, usize)], ww: usize, wh: usize, device: &Device) -> Tensor<4> {
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

/// One branch's P-buffer [f_P, v_P] `[13, ph, pw]` (planar) on the padded grid: padded pixel
/// (x, y) is image pixel (reflect(x − m), reflect(y − m)), as in [`window`]. Same arithmetic as
/// [`PathNet::forward`] on the whole padded image, staged so that memory stays bounded: the
/// pointwise stages over chunks of `chunk` sample-pixels, the U-Net over `tile` blocks with
/// `radius` pixels of context in windows of side `side` (see [`unet_window_side`]), aligned to `a`.
#[allow(clippy::too_many_arguments)]
fn path_buffer(
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

/// Denoises a prepared image. `noisy` is the frame's radiance (interleaved RGB), kept where the
/// prepared image marks a pixel as passthrough (camera ray hit nothing or an emitter, method.md
/// §7.3; only known when the frame had descriptors).
pub fn denoise(
    model: &MethodModel,
    config: &DenoiserConfig,
    image: &PreparedImage,
    noisy: &[f32],
    opts: &InferOptions,
    device: &Device,
) -> Result<Denoised, InferError> {
    denoise_chunked(model, config, image, noisy, opts, CHUNK_SAMPLE_PIXELS, device)
}

/// [`denoise`] with the chunk size of the per-sample stages as a parameter (tests use small
/// chunks so that chunk boundaries fall inside rows).
fn denoise_chunked(
    model: &MethodModel,
    config: &DenoiserConfig,
    image: &PreparedImage,
    noisy: &[f32],
    opts: &InferOptions,
    chunk: usize,
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
            Some([pd, ps].map(|net| path_buffer(net, image, (m, pw, ph), unet, chunk, device)))
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

/// [`MethodModel::forward_timed`] with each network's time booked in `t` (the runtime breakdown
/// of the paper's Table 1). Only networks that exist report, so a method's breakdown shows 0 for
/// the ones it lacks.
fn timed_forward(model: &MethodModel, input: InputTensors, pbufs: Option<[Tensor<4>; 2]>, t: &mut Timings) -> MethodOutput {
    model.forward_timed(input, pbufs, &mut |part, secs| match part {
        Part::Path => {
            t.path_s += secs;
            t.d_p_s += secs;
        }
        Part::DG => t.d_g_s += secs,
        Part::DP => t.d_p_s += secs,
        Part::E => t.e_s += secs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ensemble::EnsembleConfig;
    use crate::kpcn::KpcnConfig;
    use crate::mskp::MsKpConfig;
    use crate::pathnet::PathNetConfig;
    use crate::rng::SplitMix64;

    fn tiny() -> DenoiserConfig {
        DenoiserConfig::new(
            KpcnConfig::new(34).with_depth(2).with_width(8).with_conv_kernel(3).with_filter_size(3),
            // Three U-Net levels so pooling alignment matters.
            PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8, 8]).with_convs_per_block(1).with_out_hidden(8),
            EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
        )
        .with_seed(5)
    }

    fn random_image(w: usize, h: usize, s: usize, seed: u64) -> PreparedImage {
        let mut rng = SplitMix64::new(seed);
        let mut r = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.next_f64() as f32).collect() };
        let n = w * h;
        PreparedImage {
            width: w,
            height: h,
            spp: s,
            diffuse: r(COLOUR_BLOCK * n),
            specular: r(COLOUR_BLOCK * n),
            g_block: r(G_BLOCK * n),
            path_weight: r(n),
            descriptors: Some(r(s * DESCRIPTOR_CHANNELS * n)),
            records: None,
            passthrough: (0..n).map(|i| i % 11 == 0).collect(),
        }
    }

    #[test]
    fn reflect_mirrors_without_repeating_the_edge() {
        let v: Vec<usize> = (-3..8).map(|i| reflect(i, 4)).collect();
        assert_eq!(v, [3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1]);
        assert_eq!(reflect(-5, 1), 0);
    }

    /// Small tiles (many windows, shifted edge windows, a partial last tile) give the same image
    /// as one window covering the whole padded image, for every method. Tolerance 1e-4 relative
    /// (+1e-5 absolute): the same arithmetic on differently sized tensors may be blocked
    /// differently by the matmul kernels, which changes f32 rounding (~1e-6 per op); a missing
    /// context pixel or a pooling grid out of phase changes values at the 1e-2 level.
    #[test]
    fn tiled_equals_untiled() {
        let d = crate::cpu_device();
        // Larger than two windows in each direction (window = tile + 2·(margin + E radius), and
        // U-Net windows ≈ tile + 2·15 here), so there are interior, shifted-edge and partial
        // blocks in both passes.
        let (w, h) = (125, 111);
        let img = random_image(w, h, 2, 1);
        let noisy: Vec<f32> = (0..3 * w * h).map(|i| i as f32 * 1e-3).collect();
        for m in Method::ALL {
            let cfg = tiny();
            let model = MethodModel::init(&cfg, m, &d);
            let whole = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 1000, batch: 1 }, &d).unwrap();
            assert_eq!(whole.timings.windows, 1);
            let tiled = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 8, batch: 3 }, &d).unwrap();
            assert!(tiled.timings.windows > 10 && 2 * tiled.timings.window < w.min(h) + 20, "{:?}", tiled.timings);
            let close = |a: &[f32], b: &[f32], what: &str| {
                for (i, (x, y)) in a.iter().zip(b).enumerate() {
                    assert!((x - y).abs() <= 1e-5 + 1e-4 * y.abs(), "{m} {what} [{i}]: tiled {x} vs whole {y}");
                }
            };
            close(&tiled.radiance, &whole.radiance, "radiance");
            if let (Some(a), Some(b)) = (&tiled.weights_g, &whole.weights_g) {
                close(&a.diffuse, &b.diffuse, "W_G diffuse");
                close(&a.specular, &b.specular, "W_G specular");
            }
            assert_eq!(whole.weights_g.is_some(), m == Method::Guided);
            // Passthrough pixels keep the noisy value.
            assert_eq!(&tiled.radiance[33..36], &noisy[33..36]);
        }
    }

    /// Inference from the renderer's records (normalised as read, `prepare_for_inference`) gives
    /// bit for bit what it gives from the normalised planes (`prepare`), tiled or not, for
    /// every method; records with more samples than the image use their first `spp`.
    #[test]
    fn records_equal_planes() {
        let d = crate::cpu_device();
        let (w, h, s) = (70, 53, 3);
        let mut rec = renderer::film::descriptors::Descriptors::new(w as u32, h as u32, s as u32 + 1);
        let mut rng = SplitMix64::new(8);
        for v in rec.data.iter_mut() {
            *v = (rng.next_f64() * 20.0 - 5.0) as f32;
        }
        let mut planes = random_image(w, h, s, 3);
        let all: Vec<usize> = (0..w * h).collect();
        planes.descriptors = Some(crate::preprocess::normalised_columns(&rec, s, &all));
        let mut records = planes.clone();
        records.descriptors = None;
        records.records = Some(rec);
        let noisy = vec![0.5f32; 3 * w * h];
        let cfg = tiny();
        for m in [Method::P, Method::Both, Method::Guided] {
            let model = MethodModel::init(&cfg, m, &d);
            for tile in [1000, 16] {
                let o = InferOptions { tile, batch: 2 };
                let a = denoise(&model, &cfg, &planes, &noisy, &o, &d).unwrap();
                let b = denoise(&model, &cfg, &records, &noisy, &o, &d).unwrap();
                assert_eq!(a.radiance, b.radiance, "{m}, tile {tile}");
            }
        }
    }

    /// The per-network timed forward computes exactly what `MethodModel::forward` computes, for
    /// every method, and books time only to the networks the method has.
    #[test]
    fn timed_forward_matches_forward() {
        let d = crate::cpu_device();
        let cfg = tiny();
        let img = random_image(30, 26, 2, 9);
        for m in Method::ALL {
            let model = MethodModel::init(&cfg, m, &d);
            let mut t = Timings::default();
            let a = to_vec(timed_forward(&model, PreparedImage::to_tensors(&[&img], &d), None, &mut t).radiance);
            let b = to_vec(model.forward(PreparedImage::to_tensors(&[&img], &d)).radiance);
            assert_eq!(a, b, "{m}");
            assert_eq!(t.d_g_s > 0.0, matches!(m, Method::G | Method::Guided), "{m} {t:?}");
            assert_eq!(t.d_p_s > 0.0, m != Method::G, "{m} {t:?}");
            assert_eq!(t.path_s > 0.0, m != Method::G, "{m} {t:?}");
            assert!(t.path_s <= t.d_p_s, "{m} {t:?}");
            assert!(t.e_s > 0.0, "{m} {t:?}");
        }
    }

    /// The context bound is tight enough to matter: with too little context the tiled result
    /// differs from the whole-image one (so the test above can fail).
    #[test]
    fn context_is_needed() {
        let d = crate::cpu_device();
        let cfg = tiny();
        let model = MethodModel::init(&cfg, Method::Guided, &d);
        let (w, h) = (40, 40);
        let mut img = random_image(w, h, 2, 2);
        img.passthrough.clear();
        let noisy = vec![0.0; 3 * w * h];
        let whole = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 1000, batch: 1 }, &d).unwrap();
        // Same tiling but a window that only covers the KPCN margin: emulate by a config whose
        // PathNet radius is understated is not possible from outside, so compare against a
        // crop-and-run of one inner block with margin-only context.
        let m = cfg.margin();
        let (x0, y0, b) = (16, 16, 8);
        let win = window(&img, m, x0, y0, b + 2 * m, b + 2 * m, true);
        let out = model.forward(PreparedImage::to_tensors(&[&win], &d));
        let rad = to_vec(out.radiance);
        let mut max_diff = 0.0f32;
        for y in 0..b {
            for x in 0..b {
                let i = (y0 + y) * w + x0 + x;
                max_diff = max_diff.max((rad[y * b + x] - whole.radiance[3 * i]).abs());
            }
        }
        assert!(max_diff > 1e-3, "margin-only context matched ({max_diff}); the U-Net/E context would be unnecessary");
    }

    /// NaN/Inf/1e6 radiance features, zero albedo, a black frame and 1 spp: the output is finite
    /// and non-negative, and W_G lies in [0, 1].
    #[test]
    fn finite_on_hostile_input() {
        let d = crate::cpu_device();
        let cfg = tiny();
        let model = MethodModel::init(&cfg, Method::Guided, &d);
        let (w, h) = (20, 13);
        let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e6, 0.0, -1e6];
        let mut hostile = random_image(w, h, 1, 3);
        for (i, v) in hostile.diffuse.iter_mut().enumerate() {
            *v = specials[i % specials.len()];
        }
        for (i, v) in hostile.specular.iter_mut().enumerate() {
            *v = specials[(i + 1) % specials.len()];
        }
        // Zero albedo: the G block's albedo planes (channels 14..24).
        let n = w * h;
        hostile.g_block[14 * n..].iter_mut().for_each(|v| *v = 0.0);
        if let Some(ds) = hostile.descriptors.as_mut() {
            ds.iter_mut().enumerate().for_each(|(i, v)| *v = specials[i % specials.len()]);
        }
        let mut black = random_image(w, h, 1, 4);
        for v in black.diffuse.iter_mut().chain(black.specular.iter_mut()).chain(black.g_block.iter_mut()) {
            *v = 0.0;
        }
        let noisy: Vec<f32> = (0..3 * n).map(|i| specials[i % specials.len()]).collect();
        for img in [hostile, black] {
            let out = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 8, batch: 2 }, &d).unwrap();
            assert!(out.radiance.iter().all(|x| x.is_finite() && *x >= 0.0));
            let wg = out.weights_g.unwrap();
            assert!(wg.diffuse.iter().chain(&wg.specular).all(|x| (0.0..=1.0).contains(x)));
        }
    }

    /// The automatic tile depends on the backbone only, not on spp (windows hold per-pixel
    /// inputs only): 256 for KPCN columns, 1024 for U-Net columns, whose receptive radius is far
    /// larger. The tiled pass's context is the column's radius plus E's, without the
    /// path-manifold U-Net's.
    #[test]
    fn windows_carry_the_receptive_radius() {
        let c = DenoiserConfig::kpcn_cpu();
        assert_eq!(context(&c, Method::G), 7);
        assert_eq!(context(&c, Method::Guided), 7 + 5);
        assert_eq!(pathnet_radius(&c), 29);
        assert_eq!(window_side(&c, Method::Guided, 256), 280);
        assert_eq!(unet_window_side(&c, Method::Guided, 256), 320);
        assert_eq!(auto_tile(&c), 256);
        let ms = DenoiserConfig::cpu_default();
        assert_eq!(auto_tile(&ms), 1024);
        let r = ms.column_radius();
        assert_eq!(context(&ms, Method::G), r);
        assert_eq!(window_side(&ms, Method::G, 1024) % 16, 0);
        assert!(window_side(&ms, Method::G, 1024) >= 1024 + 2 * r + 15);
        assert_eq!(alignment(&ms, Method::P), 16);
    }

    /// The staged path (P-buffers for the whole image in chunks, U-Net windows, then tiled
    /// KPCN/E) gives what `MethodModel::forward` gives on the whole mirror-padded image, for
    /// every method, at 1, 3 and 8 spp, with one window or 8-px tiles, and with chunks that end
    /// mid-row (50 sample-pixels) or hold the whole image. Tolerance 1e-4 relative + 1e-5
    /// absolute, as in `tiled_equals_untiled`: only the blocking of the arithmetic differs
    /// (chunked 1×1 convolutions, windowed U-Net), which changes f32 rounding at ~1e-6 per op.
    /// The check can fail: mirror-padding the mean embedding one pixel off (all else unchanged)
    /// makes it fail (p, 1 spp, one window: 1.2611 vs 1.2609 at the first pixel it reaches).
    /// With U-Net columns the image is larger than a window, so tiles of 16 and 24 px cut it
    /// into several windows that carry the columns' receptive radius and keep their pooling
    /// grids in phase.
    #[test]
    fn staged_equals_model_forward() {
        let mskp = tiny().with_mskp(Some(MsKpConfig::new(34).with_widths(vec![6, 8]).with_kernel_scales(2).with_filter_size(3).with_margin(2)));
        // The shipped compositor, at three kernel scales so that two of them swap a low band.
        let swap = MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
        let swap = tiny().with_mskp(Some(swap.with_compositor(crate::mskp::ScaleCompositor::LowPassSwap)));
        // Edge-stopping kernels and joint-bilateral upsampling read guides at every level.
        let edge = MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
        let edge = tiny().with_mskp(Some(edge.with_edge_stopping(crate::mskp::EdgeStopping::FeaturesAndColour)));
        // The noise-normalised colour guides, one with a pooled variance that reads past the kernel.
        let noise = MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
        let noise = tiny().with_mskp(Some(noise.with_edge_stopping(crate::mskp::EdgeStopping::FeaturesAndNoisyColour)));
        for (cfg, (w, h), tiles) in [(tiny(), (37, 29), [8, 13]), (mskp, (80, 72), [16, 24]), (swap, (120, 104), [16, 24]), (edge, (120, 104), [16, 24]), (noise, (120, 104), [16, 24])] {
            staged_equals_model_forward_for(&cfg, w, h, tiles);
        }
    }

    fn staged_equals_model_forward_for(cfg: &DenoiserConfig, w: usize, h: usize, tiles: [usize; 2]) {
        let d = crate::cpu_device();
        let cfg = cfg.clone();
        let m = cfg.margin();
        if cfg.mskp.is_some() {
            assert!(window_side(&cfg, Method::Guided, tiles[1]) < w + 2 * m, "the U-Net case must cut the image into several windows");
        }
        for method in Method::ALL {
            let model = MethodModel::init(&cfg, method, &d);
            let a = alignment(&cfg, method);
            let (pw, ph) = (align_up(w + 2 * m, a), align_up(h + 2 * m, a));
            for spp in [1, 3, 8] {
                let img = random_image(w, h, spp, 40 + spp as u64);
                let noisy = vec![0.25f32; 3 * w * h];
                // Reference: the model on the whole padded image, output cropped to the frame.
                let padded = window(&img, m, 0, 0, pw, ph, true);
                let reference = to_vec(model.forward(PreparedImage::to_tensors(&[&padded], &d)).radiance);
                let (ow, oh) = (pw - 2 * m, ph - 2 * m);
                for (tile, chunk) in [(1000, CHUNK_SAMPLE_PIXELS), (tiles[0], 50), (tiles[1], CHUNK_SAMPLE_PIXELS)] {
                    let out = denoise_chunked(&model, &cfg, &img, &noisy, &InferOptions { tile, batch: 2 }, chunk, &d).unwrap();
                    for y in 0..h {
                        for x in 0..w {
                            let i = y * w + x;
                            for ch in 0..3 {
                                let want = if img.passthrough[i] { noisy[3 * i + ch] } else { clean(reference[(ch * oh + y) * ow + x]) };
                                let got = out.radiance[3 * i + ch];
                                assert!(
                                    (got - want).abs() <= 1e-5 + 1e-4 * want.abs(),
                                    "{method} spp {spp} tile {tile} chunk {chunk} ({x},{y},{ch}): {got} vs {want}"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn clear_errors() {
        let d = crate::cpu_device();
        let cfg = tiny();
        let model = MethodModel::init(&cfg, Method::P, &d);
        let mut img = random_image(9, 9, 1, 5);
        img.descriptors = None;
        let e = denoise(&model, &cfg, &img, &vec![0.0; 243], &InferOptions::default(), &d).unwrap_err();
        assert!(e.to_string().contains("descriptors"), "{e}");
        let e = denoise(&model, &cfg, &img, &[0.0; 5], &InferOptions::default(), &d).unwrap_err();
        assert!(e.to_string().contains("expected 243"), "{e}");
        // A G model needs no descriptors, and a 1×1 image works (mirroring a single pixel).
        let g = MethodModel::init(&cfg, Method::G, &d);
        let one = random_image(1, 1, 1, 6);
        let out = denoise(&g, &cfg, &one, &[0.5; 3], &InferOptions::default(), &d).unwrap();
        assert_eq!(out.radiance.len(), 3);
    }
}
