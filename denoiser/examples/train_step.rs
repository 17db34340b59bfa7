//! Times one joint training step (forward + backward + Adam) of a preset on random data.
//!
//! `cargo run --release -p denoiser --example train_step -- [preset] [batch] [size] [spp] [steps] [method]`
//! (defaults: default 4 64 8 3 guided). Both branches, all losses of the method's first stage
//! (L1 per branch, plus L_path where the method has PathNets).

use std::time::Instant;

use denoiser::burn::grad_clipping::GradientClippingConfig;
use denoiser::burn::optim::{AdamConfig, GradientsParams};
use denoiser::burn::tensor::{Distribution, Tensor};
use denoiser::loss::{l1, path_disentangling_loss};
use denoiser::method::{Method, MethodModel};
use denoiser::model::{BranchInput, DenoiserConfig};
use denoiser::preprocess::InputTensors;
use denoiser::rng::SplitMix64;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let preset = args.first().map(String::as_str).unwrap_or("default");
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (b, size, spp, steps) = (num(1, 4), num(2, 64), num(3, 8), num(4, 3));
    let method = args.get(5).map(|s| Method::parse(s).unwrap_or_else(|| panic!("unknown method {s}"))).unwrap_or(Method::Guided);
    let cfg = DenoiserConfig::preset(preset).unwrap_or_else(|| panic!("unknown preset {preset}"));
    let device = denoiser::cpu_training_device();
    let mut model = MethodModel::init(&cfg, method, &device);
    let o = size - 2 * cfg.margin();
    println!(
        "preset {preset}: {:.2} M MAC/pixel forward at {spp} spp; batch {b}×{size}² → {o}² outputs",
        cfg.macs_per_pixel(spp) as f64 / 1e6
    );
    let u = Distribution::Uniform(0.0, 1.0);
    let input = |d: &_| BranchInput {
        colour: Tensor::random([b, 10, size, size], u, d),
        g_block: Tensor::random([b, 24, size, size], u, d),
        descriptors: Tensor::random([b, spp, 36, size, size], u, d),
    };
    let inputs = InputTensors { diffuse: input(&device), specular: input(&device), path_weight: Tensor::zeros([b, 1, size, size], &device) };
    let t_diff = Tensor::<4>::random([b, 3, o, o], u, &device);
    let t_spec = Tensor::<4>::random([b, 3, o, o], u, &device);
    let mut optim = AdamConfig::new()
        .with_epsilon(1e-8)
        .with_grad_clipping(Some(GradientClippingConfig::Value(1.0)))
        .init();
    let mut rng = SplitMix64::new(1);
    let mut times = Vec::new();
    for step in 0..=steps {
        let start = Instant::now();
        let out = model.forward(inputs.clone());
        let (d, s) = (out.diffuse, out.specular);
        let mut loss = l1(d.output, t_diff.clone()) + l1(s.output, t_spec.clone());
        if let (Some(dp), Some(sp)) = (d.path, s.path) {
            loss = loss
                + path_disentangling_loss(dp.samples, t_diff.clone(), &mut rng).mul_scalar(0.1)
                + path_disentangling_loss(sp.samples, t_spec.clone(), &mut rng).mul_scalar(0.1);
        }
        let value: f32 = loss.clone().into_scalar();
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optim.step(1e-4, model, grads);
        device.sync().expect("device sync");
        let dt = start.elapsed().as_secs_f64();
        println!("step {step}: {dt:.2} s, loss {value:.4}{}", if step == 0 { " (warm-up, not counted)" } else { "" });
        if step > 0 {
            times.push(dt);
        }
    }
    if !times.is_empty() {
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        println!("mean train step: {mean:.2} s over {} steps", times.len());
    }
}
