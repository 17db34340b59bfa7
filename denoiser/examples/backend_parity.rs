//! Weights trained on one backend give the same images on the other (needs `--features tch`).
//!
//! `cargo run --release -p denoiser --features tch --example backend_parity -- [preset] [method] [steps] [size] [spp]`
//! (defaults: default guided 3 96 4).
//!
//! 1. The same initial model (the init is deterministic in the seed and backend-independent)
//!    takes `steps` Adam steps on tch and, separately, on flex, on the same deterministic random
//!    batch; the two trained parameter sets are compared (f32 arithmetic in another order: they
//!    drift apart a little with every step).
//! 2. Each trained model is saved as a weight file (f16, `weights::save`), loaded on flex and on
//!    tch, and denoises the same rendered frame (cornell-box, `size`² at `spp` spp, all buffers)
//!    through `infer::denoise`; the two images are compared. Exit status 1 if any image pair
//!    differs by more than 1e-3 relative to the image's largest value.

use std::path::PathBuf;

use denoiser::burn::grad_clipping::GradientClippingConfig;
use denoiser::burn::optim::{AdamConfig, GradientsParams};
use denoiser::burn::tensor::{Device, Tensor, TensorData};
use denoiser::infer::{self, InferOptions};
use denoiser::method::{Method, MethodModel};
use denoiser::model::{BranchInput, DenoiserConfig, Preset};
use denoiser::preprocess::{InputTensors, TargetTensors};
use denoiser::rng::SplitMix64;
use denoiser::train::checkpoint::parameters;
use denoiser::train::schedule::{Stage, StageKind};
use denoiser::train::stage_loss;
use denoiser::weights::{self, Provenance};
use denoiser::Backend;
use renderer::film::BufferRequest;
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;

fn random<const D: usize>(rng: &mut SplitMix64, dims: [usize; D], device: &Device) -> Tensor<D> {
    let n: usize = dims.iter().product();
    let v: Vec<f32> = (0..n).map(|_| rng.next_f64() as f32).collect();
    Tensor::from_data(TensorData::new(v, dims), device)
}

/// `steps` Adam steps of the method's first-stage losses on one fixed random batch.
fn train(cfg: &DenoiserConfig, method: Method, steps: usize, b: usize, size: usize, spp: usize, backend: Backend) -> MethodModel {
    let device = backend.training_device().expect("backend compiled in");
    let mut model = MethodModel::init(cfg, method, &device);
    let o = size - 2 * cfg.margin();
    let mut data = SplitMix64::new(42);
    let mut input = |d: &Device| BranchInput {
        colour: random(&mut data, [b, 10, size, size], d),
        g_block: random(&mut data, [b, 24, size, size], d),
        descriptors: random(&mut data, [b, spp, 36, size, size], d),
        spp,
    };
    let (diffuse, specular) = (input(&device), input(&device));
    let inputs = InputTensors { diffuse, specular, path_weight: Tensor::zeros([b, 1, size, size], &device) };
    let t_diff = random(&mut data, [b, 3, o, o], &device);
    let t_spec = random(&mut data, [b, 3, o, o], &device);
    // The first stage's loss (per-branch L1, + 0.1·L_path where the method has PathNets), as training computes it.
    let targets = TargetTensors { total: t_diff.clone() + t_spec.clone(), diffuse: t_diff, specular: t_spec };
    let stage = Stage::constant(StageKind::Branches, 1, None, None, 0.1);
    let mut optim = AdamConfig::new().with_epsilon(1e-8).with_grad_clipping(Some(GradientClippingConfig::Value(1.0))).init();
    let mut rng = SplitMix64::new(1);
    for step in 0..steps {
        let out = model.forward(inputs.clone());
        let loss = stage_loss(out, &targets, &stage, None, &mut rng);
        let value: f32 = loss.clone().into_scalar();
        println!("  {} step {step}: loss {value:.6}", backend.name());
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optim.step(cfg.peak_lr(), model, grads);
    }
    model
}

/// Largest absolute difference and largest absolute value of `b`.
fn max_diff(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len());
    let d = a.iter().zip(b).fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    (d, b.iter().fold(0f32, |m, y| m.max(y.abs())))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map(String::as_str).unwrap_or("default");
    let method = args.get(1).map(|s| s.parse::<Method>().unwrap_or_else(|e| panic!("{e}"))).unwrap_or(Method::Guided);
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (steps, size, spp) = (num(2, 3), num(3, 96), num(4, 4));
    let cfg = preset.parse::<Preset>().unwrap_or_else(|e| panic!("{e}")).config();
    let backends = [Backend::Tch, Backend::Flex];
    for bk in backends {
        bk.device().unwrap_or_else(|e| panic!("{e}"));
    }

    // One frame for every comparison.
    let scene_path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.toml");
    let mut scene = Scene::load(&scene_path).expect("cornell-box scene");
    scene.camera.width = size as u32;
    scene.camera.height = size as u32;
    let mut ro = RenderOptions::from_scene(&scene, BufferRequest::ALL);
    ro.spp = spp as u32;
    ro.seed = 7;
    let (mut frame, _) = integrator::render(&scene, &ro, &|_| {}).expect("render");
    let noisy = frame.radiance.mean.clone();
    let prepared = denoiser::preprocess::prepare_for_inference(&mut frame).expect("prepare");

    println!("preset {preset}, method {method}: {steps} Adam steps on a 2×{size}² batch at {spp} spp on each backend");
    let trained: Vec<(Backend, MethodModel)> = backends.iter().map(|&bk| (bk, train(&cfg, method, steps, 2, size, spp, bk))).collect();
    let (pa, pb) = (parameters(&trained[0].1), parameters(&trained[1].1));
    let (mut dw, mut wmax) = (0f32, 0f32);
    for (a, b) in pa.iter().zip(&pb) {
        assert_eq!(a.0, b.0);
        let (d, m) = max_diff(&a.3, &b.3);
        dw = dw.max(d);
        wmax = wmax.max(m);
    }
    let init = parameters(&MethodModel::init(&cfg, method, &Backend::Flex.device().unwrap()));
    let moved = init.iter().zip(&pa).fold(0f32, |m, (i, a)| m.max(max_diff(&i.3, &a.3).0));
    println!(
        "trained parameters, tch vs flex: max |Δw| = {dw:.3e} (largest |w| {wmax:.3}; largest move of a weight in training {moved:.3e})"
    );

    let dir = std::env::temp_dir().join(format!("pixguide-parity-{}", std::process::id()));
    let mut worst = 0f32;
    let mut on_flex = Vec::new();
    for (trained_on, model) in &trained {
        let path = dir.join(format!("{}-{method}.safetensors", trained_on.name()));
        let prov =
            Provenance { command: format!("backend_parity, trained on {}", trained_on.name()), steps: steps as u64, ..Default::default() };
        weights::save(&path, model, &cfg, preset, &prov).expect("save weights");
        let mut images = Vec::new();
        for bk in backends {
            let device = bk.device().unwrap();
            let loaded = weights::load(&path, &device).expect("load weights");
            let t = std::time::Instant::now();
            let out = infer::denoise(&loaded.model, &loaded.config, &prepared, &noisy, &InferOptions { tile: 0, batch: 1 }, &device)
                .expect("denoise");
            println!("  weights trained on {}, denoised on {}: {:.2} s", trained_on.name(), bk.name(), t.elapsed().as_secs_f64());
            images.push(out);
        }
        let (d, m) = max_diff(&images[0].radiance, &images[1].radiance);
        let mean = images[0].radiance.iter().zip(&images[1].radiance).map(|(x, y)| (x - y).abs() as f64).sum::<f64>()
            / images[0].radiance.len() as f64;
        println!(
            "weights trained on {}: image on tch vs flex ({size}², {} values): max |Δ| = {d:.3e}, mean |Δ| = {mean:.3e}, largest value {m:.3}, max |Δ|/max = {:.3e}",
            trained_on.name(),
            images[0].radiance.len(),
            d / m.max(1e-12)
        );
        if let (Some(a), Some(b)) = (&images[0].weights_g, &images[1].weights_g) {
            let (dd, _) = max_diff(&a.diffuse, &b.diffuse);
            let (ds, _) = max_diff(&a.specular, &b.specular);
            println!("  W_G maps: max |Δ| diffuse {dd:.3e}, specular {ds:.3e}");
        }
        worst = worst.max(d / m.max(1e-12));
        on_flex.push(images.pop().unwrap().radiance);
    }
    let (d, m) = max_diff(&on_flex[0], &on_flex[1]);
    println!("for scale: tch-trained vs flex-trained weights, both denoised on flex: max |Δ| = {d:.3e} (largest value {m:.3})");
    let _ = std::fs::remove_dir_all(&dir);
    if worst > 1e-3 {
        println!("FAIL: images differ by {worst:.3e} of their largest value (> 1e-3)");
        std::process::exit(1);
    }
    println!("OK: same images on both backends (max |Δ|/max {worst:.3e} ≤ 1e-3)");
}
