//! Times one joint training step (forward + backward + Adam) of a preset on random data.
//!
//! `cargo run --release -p denoiser --example train_step -- [preset] [batch] [size] [spp] [steps] [method] [backend]`
//! (defaults: default 4 64 8 3 guided flex; the backend also from `PIXGUIDE_BACKEND`). Both
//! branches, all losses of the method's first stage (L1 per branch, plus L_path where the method
//! has PathNets). `backend` tch needs `--features tch` (docs/training-tch.md).
//!
//! GFLOP/s convention: 2 FLOP per multiply-accumulate; backward ≈ 2× forward, so a training step
//! counts 3× the forward FLOPs. Forward MACs are the networks' own counts (convolutions and
//! kernel taps; no softmax, pooling, losses or Adam), each over the pixels it computes on:
//! a U-Net column and the PathNet over the whole input patch (same padding), E over the output,
//! a KPCN column layer by layer as its valid convolutions shrink the patch.

use std::time::Instant;

use denoiser::burn::grad_clipping::GradientClippingConfig;
use denoiser::burn::optim::{AdamConfig, GradientsParams};
use denoiser::burn::tensor::{Distribution, Tensor};
use denoiser::kpcn::{KpcnConfig, Variant};
use denoiser::layers::conv_macs;
use denoiser::method::{Method, MethodModel, Part};
use denoiser::model::{BranchInput, DenoiserConfig, Preset};
use denoiser::preprocess::{InputTensors, TargetTensors};
use denoiser::rng::SplitMix64;
use denoiser::train::schedule::{Stage, StageKind};
use denoiser::train::stage_loss;
use denoiser::Backend;

/// Forward MACs of one KPCN column over a `b`×`size`² input (valid convolutions).
fn kpcn_macs(c: &KpcnConfig, b: usize, size: usize) -> f64 {
    let r = c.conv_kernel / 2;
    let mut widths = vec![c.in_channels];
    widths.extend(std::iter::repeat_n(c.width, c.depth - 1));
    widths.push(c.filter_size * c.filter_size);
    let mut total = 0.0;
    for (l, w) in widths.windows(2).enumerate() {
        let side = (size - 2 * r * (l + 1)) as f64;
        total += conv_macs(w[0], w[1], c.conv_kernel) as f64 * side * side;
    }
    let out = (size - 2 * c.margin()) as f64;
    total += (c.filter_size * c.filter_size * 3) as f64 * out * out;
    total * b as f64
}

/// Forward MACs of `method`'s networks (both branches) on a batch (see the file header), per
/// network: [PathNet, D_G, D_P or both-buffers column, E].
fn step_forward_macs(cfg: &DenoiserConfig, method: Method, b: usize, size: usize, spp: usize) -> [f64; 4] {
    let input = (b * size * size) as f64;
    let o = (size - 2 * cfg.margin()) as f64;
    let output = b as f64 * o * o;
    let column = |v: Variant| match cfg.mskp_for(v) {
        Some(_) => cfg.column_macs(v) as f64 * input,
        None => kpcn_macs(&cfg.kpcn_for(v), b, size),
    };
    let path = if method.needs_descriptors() { cfg.pathnet.macs_per_pixel(spp) as f64 * input } else { 0.0 };
    let per_branch = match method {
        Method::G => [0.0, column(Variant::G), 0.0, 0.0],
        Method::P => [path, 0.0, column(Variant::P), 0.0],
        Method::Both => [path, 0.0, column(Variant::GP), 0.0],
        Method::Guided => [path, column(Variant::G), column(Variant::P), cfg.ensemble.macs_per_pixel() as f64 * output],
    };
    per_branch.map(|m| 2.0 * m)
}

/// CPU compute threads of the backend: rayon's pool for flex, LibTorch's intra-op threads for
/// tch; 0 for a GPU backend.
fn threads(backend: Backend) -> usize {
    match backend {
        Backend::Flex => rayon::current_num_threads(),
        #[cfg(feature = "tch")]
        Backend::Tch => denoiser::torch_threads(),
        // GPU backends (and tch without the feature, which never gets here).
        _ => 0,
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map(String::as_str).unwrap_or("default");
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (b, size, spp, steps) = (num(1, 4), num(2, 64), num(3, 8), num(4, 3));
    let method = args.get(5).map(|s| s.parse::<Method>().unwrap_or_else(|e| panic!("{e}"))).unwrap_or(Method::Guided);
    let cfg = preset.parse::<Preset>().unwrap_or_else(|e| panic!("{e}")).config();
    let backend_name = args.get(6).cloned().or_else(|| std::env::var("PIXGUIDE_BACKEND").ok()).unwrap_or_else(|| "flex".into());
    let backend = backend_name.parse::<Backend>().unwrap_or_else(|e| panic!("{e}"));
    let device = backend.training_device().unwrap_or_else(|e| panic!("{e}"));
    let mut model = MethodModel::init(&cfg, method, &device);
    let o = size - 2 * cfg.margin();
    let part_macs = step_forward_macs(&cfg, method, b, size, spp);
    let fwd_macs: f64 = part_macs.iter().sum();
    let step_flop = 3.0 * 2.0 * fwd_macs;
    println!(
        "preset {preset}, method {method}, backend {} ({} threads): {:.2} M MAC/pixel forward (whole guided framework) at {spp} spp; batch {b}×{size}² → {o}² outputs",
        backend.name(),
        threads(backend),
        cfg.macs_per_pixel(spp) as f64 / 1e6
    );
    println!(
        "this method's networks: {:.3} G MAC forward per step → {:.2} GFLOP per training step (2 FLOP/MAC, backward ≈ 2× forward: step = 3× forward)",
        fwd_macs / 1e9,
        step_flop / 1e9
    );
    let u = Distribution::Uniform(0.0, 1.0);
    let input = |d: &_| BranchInput {
        colour: Tensor::random([b, 10, size, size], u, d),
        g_block: Tensor::random([b, 24, size, size], u, d),
        descriptors: Tensor::random([b, spp, 36, size, size], u, d),
        spp,
    };
    let inputs =
        InputTensors { diffuse: input(&device), specular: input(&device), path_weight: Tensor::zeros([b, 1, size, size], &device) };
    let t_diff = Tensor::<4>::random([b, 3, o, o], u, &device);
    let t_spec = Tensor::<4>::random([b, 3, o, o], u, &device);
    // The first stage's loss (per-branch L1, + 0.1·L_path where the method has PathNets), as training computes it.
    let targets = TargetTensors { total: t_diff.clone() + t_spec.clone(), diffuse: t_diff, specular: t_spec };
    let stage = Stage::constant(StageKind::Branches, 1, None, None, 0.1);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).with_grad_clipping(Some(GradientClippingConfig::Value(1.0))).init();
    let mut rng = SplitMix64::new(1);
    let mut times = Vec::new();
    // Mean ms per counted step of: forward PathNet, D_G, D_P (or both-buffers), E (+ recombine),
    // losses, backward, Adam. Both backends execute eagerly on the CPU, so wall time around a
    // call is that call's.
    let mut parts = [0f64; 7];
    for step in 0..=steps {
        let start = Instant::now();
        let mut lap = [0f64; 7];
        let out = model.forward_timed(inputs.clone(), None, &mut |part, t| {
            let k = match part {
                Part::Path => 0,
                Part::DG => 1,
                Part::DP => 2,
                Part::E => 3,
            };
            lap[k] += t;
        });
        let t_loss = Instant::now();
        let loss = stage_loss(out, &targets, &stage, None, &mut rng);
        let value: f32 = loss.clone().into_scalar();
        lap[4] = t_loss.elapsed().as_secs_f64();
        let t_back = Instant::now();
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        lap[5] = t_back.elapsed().as_secs_f64();
        let t_adam = Instant::now();
        model = optim.step(1e-4, model, grads);
        device.sync().expect("device sync");
        lap[6] = t_adam.elapsed().as_secs_f64();
        let dt = start.elapsed().as_secs_f64();
        println!("step {step}: {:.0} ms, loss {value:.4}{}", dt * 1e3, if step == 0 { " (warm-up, not counted)" } else { "" });
        if step > 0 {
            times.push(dt);
            for (p, l) in parts.iter_mut().zip(lap) {
                *p += l;
            }
        }
    }
    if !times.is_empty() {
        let n = times.len() as f64;
        let names = ["fwd PathNet", "fwd D_G", "fwd D_P/G+P", "fwd E+recombine", "losses", "backward", "Adam"];
        let list: Vec<String> = names.iter().zip(parts).filter(|(_, t)| *t > 0.0).map(|(k, t)| format!("{k} {:.0}", t / n * 1e3)).collect();
        println!("breakdown, mean ms per step: {}", list.join(", "));
        // Forward GFLOP/s per network, and backward's at 2× the forward FLOPs.
        let mut rates: Vec<String> = names[..4]
            .iter()
            .zip(parts)
            .zip(part_macs)
            .filter(|((_, t), m)| *t > 0.0 && *m > 0.0)
            .map(|((k, t), m)| format!("{k} {:.1}", 2.0 * m / (t / n) / 1e9))
            .collect();
        rates.push(format!("backward {:.1}", 2.0 * 2.0 * fwd_macs / (parts[5] / n) / 1e9));
        println!("GFLOP/s by part: {}", rates.join(", "));
    }
    if !times.is_empty() {
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        let min = times.iter().cloned().fold(f64::INFINITY, f64::min);
        let mut sorted = times.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted[sorted.len() / 2];
        println!("mean train step: {mean:.2} s over {} steps", times.len());
        println!(
            "RESULT preset={preset} method={method} batch={b} size={size} spp={spp} backend={} threads={} mean_ms={:.0} median_ms={:.0} min_ms={:.0} gflop_step={:.2} gflops_mean={:.1} gflops_median={:.1} gflops_best={:.1}",
            backend.name(),
            threads(backend),
            mean * 1e3,
            median * 1e3,
            min * 1e3,
            step_flop / 1e9,
            step_flop / mean / 1e9,
            step_flop / median / 1e9,
            step_flop / min / 1e9
        );
    }
}
