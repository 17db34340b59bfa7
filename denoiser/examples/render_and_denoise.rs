//! Renders a shipped scene at a low sample count and denoises it with the shipped guided weights,
//! through the libraries alone (no `pixguide` binary): the renderer makes a `Frame`, the denoiser
//! takes it as it is, and the film crate writes the result.
//!
//! `cargo run --release -p denoiser --example render_and_denoise -- [out.exr] [spp]`
//! (defaults: render_and_denoise.exr 4). Renders at the size of the committed 8000-spp
//! reference (128²) and prints relMSE of the noisy and the denoised image against it.

use std::path::{Path, PathBuf};

use denoiser::infer::{self, InferOptions};
use denoiser::method::Method;
use denoiser::{metrics, weights};
use renderer::film::{exr_io, BufferRequest};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(args.first().map(String::as_str).unwrap_or("render_and_denoise.exr"));
    let spp: u32 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(4);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");

    // The guided model reads every buffer, the per-sample path descriptors included.
    let method = Method::Guided;
    let loaded = weights::load(&weights::default_path(method), &denoiser::cpu_device())?;
    // Rendered at the size of the committed reference, to score the result against it.
    let reference = exr_io::read_frame(&root.join("scenes/references/cornell-box.exr"))?;
    let mut scene = Scene::load(&root.join("scenes/cornell-box/scene.toml"))?;
    (scene.camera.width, scene.camera.height) = (reference.width, reference.height);
    let mut opts = RenderOptions::from_scene(&scene, BufferRequest::ALL);
    opts.spp = spp;
    let (mut frame, _) = integrator::render(&scene, &opts, &|_| {})?;
    let noisy = frame.radiance.mean.clone();

    let run = infer::denoise_frame(&mut frame, &loaded, &InferOptions::default(), &denoiser::cpu_device())?;
    exr_io::write_frame(&infer::denoised_frame(&run.denoised, frame.spp), &out)?;

    let (w, h) = (frame.width as usize, frame.height as usize);
    for (label, rgb) in [("noisy", &noisy), ("denoised", &run.denoised.radiance)] {
        let e = metrics::evaluate(rgb, &reference.radiance.mean, w, h, metrics::DEFAULT_BORDER);
        println!("{label:>9}: relMSE {:.5}, 1-SSIM {:.5}", e.rel_mse, e.one_minus_ssim);
    }
    println!("{} spp, {method} model: {} written in {:.2} s", frame.spp, out.display(), run.prepare_s + run.denoised.timings.total_s);
    Ok(())
}
