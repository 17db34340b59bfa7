//! Training E over cached expert outputs (cache.rs): random crops of the training shots, the loss
//! being the results page's own measure (relMSE after tone map (a) of method.md §7.3) of the
//! blend, Adam, and every `val_every` steps the whole validation shots through the inference path
//! ([`super::run::gate_weights`]); the best validation state is kept.

use std::time::Instant;

use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor, TensorData};

use super::cache::CachedImage;
use super::run::gate_weights;
use super::{blend, feature_channels, features, Expert, GateConfig, GateNet};
use crate::metrics::{rel_mse, ToneMap};
use crate::rng::SplitMix64;

#[derive(Clone, Debug)]
pub struct GateTrainOptions {
    pub experts: Vec<Expert>,
    pub widths: Vec<usize>,
    pub steps: usize,
    pub batch: usize,
    /// Crop side (a multiple of the net's alignment).
    pub crop: usize,
    pub lr: f64,
    pub seed: u64,
    pub val_every: usize,
    /// ε of the loss's relMSE denominator (the page's is 1e-4).
    pub eps: f64,
    /// Standard deviation of Gaussian noise added to the logits while training (0: none): it
    /// keeps the gate from settling early on one expert (method.md §13).
    pub logit_noise: f64,
}

/// One validation pass.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GateValidation {
    pub step: usize,
    /// Mean relMSE over validation images, overall and per spp.
    pub rel_mse: f64,
    pub by_spp: Vec<(u32, f64)>,
    /// Mean weight per expert, per spp (experts in the options' order).
    pub mean_weights: Vec<(u32, Vec<f64>)>,
    /// The same relMSE of each expert alone, per spp (for comparison).
    pub experts_by_spp: Vec<(u32, Vec<f64>)>,
}

/// A training image's tensors' ingredients, planar.
struct Prepared {
    w: usize,
    h: usize,
    feats: Vec<f32>,
    /// K × 3 planes.
    experts: Vec<f32>,
    /// Tone-mapped reference, 3 planes.
    target: Vec<f32>,
    /// 1 where the loss counts (not a pass-through pixel).
    mask: Vec<f32>,
}

fn planar(rgb: &[f32], n: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; 3 * n];
    for i in 0..n {
        for c in 0..3 {
            out[c * n + i] = rgb[3 * i + c];
        }
    }
    out
}

fn prepare(im: &CachedImage, experts: &[Expert]) -> Prepared {
    let n = im.width * im.height;
    let imgs = im.expert_images(experts);
    let feats = features(&im.gate_frame(), &imgs);
    let experts: Vec<f32> = imgs.iter().flat_map(|e| planar(e, n)).collect();
    let tm: Vec<f32> = crate::metrics::tonemap(&im.reference, ToneMap::Paper).into_iter().map(|v| v as f32).collect();
    let mask = (0..n).map(|i| if im.passthrough.get(i).copied().unwrap_or(false) { 0.0 } else { 1.0 }).collect();
    Prepared { w: im.width, h: im.height, feats, experts, target: planar(&tm, n), mask }
}

fn crop(src: &[f32], planes: usize, w: usize, h: usize, x: usize, y: usize, s: usize, out: &mut Vec<f32>) {
    for p in 0..planes {
        for r in y..y + s {
            out.extend_from_slice(&src[p * w * h + r * w + x..p * w * h + r * w + x + s]);
        }
    }
}

/// Tone map (a) of method.md §7.3 on `[B, 3, H, W]` linear radiance, differentiable.
fn tonemap(x: Tensor<4>) -> Tensor<4> {
    let x = x.clamp_min(0.0);
    let lum = x.clone().narrow(1, 0, 1).mul_scalar(0.2126)
        + x.clone().narrow(1, 1, 1).mul_scalar(0.7152)
        + x.clone().narrow(1, 2, 1).mul_scalar(0.0722);
    let t = x / lum.div_scalar(1.5).add_scalar(1.0);
    // The small offset keeps the power's gradient finite at black.
    t.add_scalar(1e-6).powf_scalar(1.0 / 2.2).clamp(0.0, 1.0)
}

/// Mean W per expert and relMSE of the gate and of each expert on whole validation images.
pub fn validate(
    net: &GateNet,
    config: &GateConfig,
    val: &[&CachedImage],
    experts: &[Expert],
    step: usize,
    device: &Device,
) -> GateValidation {
    let mut spps: Vec<u32> = val.iter().map(|i| i.spp).collect();
    spps.sort_unstable();
    spps.dedup();
    let k = experts.len();
    let mut acc: Vec<(f64, Vec<f64>, Vec<f64>, usize)> = vec![(0.0, vec![0.0; k], vec![0.0; k], 0); spps.len()];
    for im in val {
        let s = spps.iter().position(|&x| x == im.spp).unwrap_or(0);
        let imgs = im.expert_images(experts);
        let feats = features(&im.gate_frame(), &imgs);
        let wts = gate_weights(net, config, &feats, im.width, im.height, device);
        let out = blend(&imgs, &wts, &im.radiance, &im.passthrough);
        let a = &mut acc[s];
        a.0 += rel_mse(&out, &im.reference, im.width, im.height, ToneMap::Paper, 0);
        let n = im.width * im.height;
        for e in 0..k {
            a.1[e] += wts[e * n..(e + 1) * n].iter().map(|&v| v as f64).sum::<f64>() / n as f64;
            a.2[e] += rel_mse(imgs[e], &im.reference, im.width, im.height, ToneMap::Paper, 0);
        }
        a.3 += 1;
    }
    let by_spp: Vec<(u32, f64)> = spps.iter().zip(&acc).map(|(&s, a)| (s, a.0 / a.3.max(1) as f64)).collect();
    let rel = by_spp.iter().map(|x| x.1).sum::<f64>() / by_spp.len().max(1) as f64;
    GateValidation {
        step,
        rel_mse: rel,
        by_spp,
        mean_weights: spps.iter().zip(&acc).map(|(&s, a)| (s, a.1.iter().map(|v| v / a.3.max(1) as f64).collect())).collect(),
        experts_by_spp: spps.iter().zip(&acc).map(|(&s, a)| (s, a.2.iter().map(|v| v / a.3.max(1) as f64).collect())).collect(),
    }
}

/// The trained gate (best validation state) and every validation pass.
pub struct Trained {
    pub net: GateNet,
    pub config: GateConfig,
    pub best: GateValidation,
    pub history: Vec<GateValidation>,
    /// (step, training loss) every step.
    pub losses: Vec<(usize, f32)>,
    pub seconds: f64,
}

/// Trains E. `progress(step, loss, validation)` after every step.
pub fn train(
    train: &[&CachedImage],
    val: &[&CachedImage],
    opts: &GateTrainOptions,
    progress: &mut dyn FnMut(usize, f32, Option<&GateValidation>),
) -> Result<Trained, String> {
    let t0 = Instant::now();
    let k = opts.experts.len();
    let config = GateConfig::new(feature_channels(k), k).with_widths(opts.widths.clone());
    let s = opts.crop;
    if s == 0 || !s.is_multiple_of(config.alignment()) {
        return Err(format!("--crop {s} must be a positive multiple of {}", config.alignment()));
    }
    let data: Vec<Prepared> = train.iter().filter(|im| im.width >= s && im.height >= s).map(|im| prepare(im, &opts.experts)).collect();
    if data.is_empty() {
        return Err(format!("no training image of at least {s}×{s}"));
    }
    let dev = crate::cpu_training_device();
    let valid_dev = crate::cpu_device();
    let mut net = config.init(opts.seed, &dev);
    let mut optim = crate::train::optimizer();
    let mut rng = SplitMix64::derive(opts.seed, 0x4741_5445);
    let c = config.in_channels;
    let b = opts.batch.max(1);
    let mut best = validate(&net.valid(), &config, val, &opts.experts, 0, &valid_dev);
    let mut best_net = net.valid();
    let mut history = vec![best.clone()];
    progress(0, f32::NAN, Some(&best));
    let mut losses = Vec::new();
    for step in 1..=opts.steps {
        let (mut f, mut e, mut t, mut m) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..b {
            let d = &data[rng.below(data.len())];
            let (x, y) = (rng.below(d.w - s + 1), rng.below(d.h - s + 1));
            crop(&d.feats, c, d.w, d.h, x, y, s, &mut f);
            crop(&d.experts, 3 * k, d.w, d.h, x, y, s, &mut e);
            crop(&d.target, 3, d.w, d.h, x, y, s, &mut t);
            crop(&d.mask, 1, d.w, d.h, x, y, s, &mut m);
        }
        let f = Tensor::<4>::from_data(TensorData::new(f, [b, c, s, s]), &dev);
        let e = Tensor::<4>::from_data(TensorData::new(e, [b, 3 * k, s, s]), &dev);
        let t = Tensor::<4>::from_data(TensorData::new(t, [b, 3, s, s]), &dev);
        let m = Tensor::<4>::from_data(TensorData::new(m, [b, 1, s, s]), &dev);
        let mut logits = net.logits(f);
        if opts.logit_noise > 0.0 {
            let noise: Vec<f32> = (0..b * k * s * s).map(|_| gaussian(&mut rng) * opts.logit_noise as f32).collect();
            logits = logits + Tensor::<4>::from_data(TensorData::new(noise, [b, k, s, s]), &dev);
        }
        let w = softmax(logits, 1);
        let mut out = e.clone().narrow(1, 0, 3) * w.clone().narrow(1, 0, 1);
        for j in 1..k {
            out = out + e.clone().narrow(1, 3 * j, 3) * w.clone().narrow(1, j, 1);
        }
        let err = (tonemap(out) - t.clone()).powf_scalar(2.0) / (t.clone() * t).add_scalar(opts.eps);
        let count = m.clone().sum().into_scalar::<f32>() * 3.0 + 1.0;
        let loss = (err * m).sum().div_scalar(count);
        let value: f32 = loss.clone().into_scalar();
        if !value.is_finite() {
            return Err(format!("non-finite loss at step {step}"));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        net = optim.step(opts.lr, net, grads);
        losses.push((step, value));
        let v = (opts.val_every > 0 && (step % opts.val_every == 0 || step == opts.steps))
            .then(|| validate(&net.valid(), &config, val, &opts.experts, step, &valid_dev));
        if let Some(v) = &v {
            history.push(v.clone());
            if v.rel_mse < best.rel_mse || best.step == 0 && !val.is_empty() && v.rel_mse <= best.rel_mse {
                best = v.clone();
                best_net = net.valid();
            }
        }
        progress(step, value, v.as_ref());
    }
    if val.is_empty() {
        best_net = net.valid();
    }
    Ok(Trained { net: best_net, config, best, history, losses, seconds: t0.elapsed().as_secs_f64() })
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut SplitMix64) -> f32 {
    let u1 = rng.next_f64().max(1e-300);
    let u2 = rng.next_f64();
    ((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()) as f32
}
