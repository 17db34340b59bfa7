//! Running a gate on a frame: the experts first (each as users run it alone), then E's weights over
//! the whole image in windows, then the blend.

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use film::Frame;

use super::file::Gate;
use super::{blend, features, Expert, GateConfig, GateFrame, GateNet};
use crate::infer::{self, InferOptions};
use crate::oidn::Oidn;
use crate::preprocess::{self, PreparedImage};
use crate::weights::Loaded;

/// The loaded experts a gate may call on.
#[derive(Clone, Copy, Default)]
pub struct Experts<'a> {
    pub g: Option<&'a Loaded>,
    pub p: Option<&'a Loaded>,
    pub oidn: Option<&'a Oidn>,
}

/// The experts' outputs on one frame.
#[derive(Clone, Debug)]
pub struct ExpertOutputs {
    /// Linear radiance `[H, W, 3]` per expert, in the order asked for.
    pub images: Vec<Vec<f32>>,
    /// Pixels that keep the noisy value (no hit, or an emitter hit directly; empty if unknown).
    pub passthrough: Vec<bool>,
    /// Wall seconds per expert, and of the preprocessing they share.
    pub seconds: Vec<f64>,
    pub prepare_s: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum GateError {
    #[error("the gate needs the {0} expert, and it was not loaded")]
    MissingExpert(Expert),
    #[error("the gate needs the frame's {0} buffer (render with the denoiser's buffers: --aovs, or --denoise)")]
    MissingBuffer(&'static str),
    #[error("the gate's experts are {file:?}, but {given:?} were given")]
    ExpertMismatch { file: Vec<Expert>, given: Vec<Expert> },
    #[error(transparent)]
    Frame(#[from] infer::FrameError),
    #[error(transparent)]
    Infer(#[from] infer::InferError),
    #[error(transparent)]
    Prepare(#[from] preprocess::PrepareError),
    #[error("Open Image Denoise: {0}")]
    Oidn(#[from] crate::oidn::OidnError),
}

/// The buffers of `frame` the gate reads.
pub fn gate_frame(frame: &Frame) -> Result<GateFrame<'_>, GateError> {
    fn need<'f>(b: &'static str, x: &'f Option<film::PixelBuffer>) -> Result<&'f [f32], GateError> {
        x.as_ref().map(|p| &p.mean[..]).ok_or(GateError::MissingBuffer(b))
    }
    Ok(GateFrame {
        width: frame.width as usize,
        height: frame.height as usize,
        spp: frame.spp,
        radiance: &frame.radiance.mean,
        radiance_var: &frame.radiance.var,
        diffuse: need("diffuse", &frame.diffuse)?,
        specular: need("specular", &frame.specular)?,
        albedo: need("albedo", &frame.albedo)?,
        normal: need("normal", &frame.normal)?,
        depth: need("depth", &frame.depth)?,
    })
}

/// Runs `which` experts on `frame`. Preprocessing is shared and moves the descriptors out of the
/// frame (as [`infer::denoise_frame`] does); the other buffers stay.
pub fn run_experts(
    frame: &mut Frame,
    which: &[Expert],
    experts: &Experts,
    opts: &InferOptions,
    device: &Device,
) -> Result<ExpertOutputs, GateError> {
    let nets = which.iter().any(|e| *e != Expert::Oidn);
    let t = Instant::now();
    let prepared = if nets { Some(preprocess::prepare_for_inference(frame)?) } else { None };
    let prepare_s = t.elapsed().as_secs_f64();
    let mut out = run_experts_prepared(frame, prepared.as_ref(), which, experts, opts, device)?;
    out.prepare_s = prepare_s;
    Ok(out)
}

/// [`run_experts`] on a frame already prepared (`prepared`, needed by the g and p experts), as
/// `pixguide eval` has it; `prepare_s` is left at 0.
pub fn run_experts_prepared(
    frame: &Frame,
    prepared: Option<&PreparedImage>,
    which: &[Expert],
    experts: &Experts,
    opts: &InferOptions,
    device: &Device,
) -> Result<ExpertOutputs, GateError> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let mut images = Vec::new();
    let mut seconds = Vec::new();
    for &e in which {
        let t = Instant::now();
        let image = match e {
            Expert::Oidn => {
                let o = experts.oidn.ok_or(GateError::MissingExpert(e))?;
                let albedo = frame.albedo.as_ref().ok_or(GateError::MissingBuffer("albedo"))?;
                let normal = frame.normal.as_ref().ok_or(GateError::MissingBuffer("normal"))?;
                o.denoise(&frame.radiance.mean, &albedo.mean, &normal.mean, w, h)?
            }
            Expert::G | Expert::P => {
                let loaded = if e == Expert::G { experts.g } else { experts.p }.ok_or(GateError::MissingExpert(e))?;
                let image = prepared.ok_or(GateError::MissingBuffer("prepared network input"))?;
                if loaded.method.needs_descriptors() && image.records.is_none() && image.descriptors.is_none() {
                    return Err(infer::InferError::MissingDescriptors(loaded.method).into());
                }
                infer::denoise(&loaded.model, &loaded.config, image, &frame.radiance.mean, opts, device)?.radiance
            }
        };
        // Non-finite or negative output from any expert must not reach the blend.
        images.push(image.into_iter().map(|v| if v.is_finite() { v.clamp(0.0, infer::MAX_RADIANCE) } else { 0.0 }).collect());
        seconds.push(t.elapsed().as_secs_f64());
    }
    let passthrough = prepared.map(|p| p.passthrough.clone()).unwrap_or_default();
    Ok(ExpertOutputs { images, passthrough, seconds, prepare_s: 0.0 })
}

/// Output side of one window of E; E's receptive radius (about 20 px for three levels) is well
/// inside the context, so windows give the whole-image result.
const TILE: usize = 256;
const CONTEXT: usize = 32;

fn reflect(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - m }) as usize
}

/// E's softmax weights `[K, H, W]` from planar features `[C, H, W]`, window by window (mirror
/// padding past the image edges).
pub fn gate_weights(net: &GateNet, config: &GateConfig, feats: &[f32], width: usize, height: usize, device: &Device) -> Vec<f32> {
    let c = config.in_channels;
    let k = config.experts;
    let n = width * height;
    let align = config.alignment();
    let mut out = vec![0.0f32; k * n];
    for y0 in (0..height).step_by(TILE) {
        for x0 in (0..width).step_by(TILE) {
            let (tw, th) = (TILE.min(width - x0), TILE.min(height - y0));
            let ww = (tw + 2 * CONTEXT).div_ceil(align) * align;
            let wh = (th + 2 * CONTEXT).div_ceil(align) * align;
            let mut buf = vec![0.0f32; c * ww * wh];
            for ch in 0..c {
                let plane = &feats[ch * n..(ch + 1) * n];
                for wy in 0..wh {
                    let sy = reflect(y0 as isize + wy as isize - CONTEXT as isize, height);
                    for wx in 0..ww {
                        let sx = reflect(x0 as isize + wx as isize - CONTEXT as isize, width);
                        buf[(ch * wh + wy) * ww + wx] = plane[sy * width + sx];
                    }
                }
            }
            let x = Tensor::<4>::from_data(TensorData::new(buf, [1, c, wh, ww]), device);
            let wts: Vec<f32> = net.weights(x).into_data().convert::<f32>().try_to_vec::<f32>().unwrap_or_default();
            for e in 0..k {
                for ty in 0..th {
                    for tx in 0..tw {
                        out[e * n + (y0 + ty) * width + x0 + tx] = wts[(e * wh + ty + CONTEXT) * ww + tx + CONTEXT];
                    }
                }
            }
        }
    }
    out
}

/// A gated denoise: the blended radiance `[H, W, 3]` and the weights `[K, H, W]`.
#[derive(Clone, Debug)]
pub struct Gated {
    pub radiance: Vec<f32>,
    pub weights: Vec<f32>,
    pub experts: ExpertOutputs,
    /// Wall seconds of E (features, network, blend).
    pub gate_s: f64,
}

/// Runs the gate's experts on `frame`, then E, then the blend.
pub fn denoise(gate: &Gate, frame: &mut Frame, experts: &Experts, opts: &InferOptions, device: &Device) -> Result<Gated, GateError> {
    let outputs = run_experts(frame, &gate.header.experts, experts, opts, device)?;
    let t = Instant::now();
    let (radiance, weights) = apply(gate, frame, &outputs, device)?;
    Ok(Gated { radiance, weights, experts: outputs, gate_s: t.elapsed().as_secs_f64() })
}

/// E and the blend over experts' outputs already computed.
pub fn apply(gate: &Gate, frame: &Frame, outputs: &ExpertOutputs, device: &Device) -> Result<(Vec<f32>, Vec<f32>), GateError> {
    let gf = gate_frame(frame)?;
    let refs: Vec<&[f32]> = outputs.images.iter().map(|v| &v[..]).collect();
    let feats = features(&gf, &refs);
    let weights = gate_weights(&gate.net, &gate.config, &feats, gf.width, gf.height, device);
    let radiance = blend(&refs, &weights, gf.radiance, &outputs.passthrough);
    Ok((radiance.into_iter().map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 }).collect(), weights))
}
