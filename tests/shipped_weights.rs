//! The shipped weights (denoiser/weights/) against a committed 8000-spp reference: the README's
//! main command must give an image clearly closer to the reference than the noisy render.

use std::path::{Path, PathBuf};

use denoiser::infer::{self, InferOptions};
use denoiser::metrics::{one_minus_ssim, rel_mse, ToneMap};
use denoiser::method::Method;
use renderer::film::{exr_io, BufferRequest};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Renders the cornell-box test scene at its reference size and 8 spp, denoises it with the
/// shipped `method` model and returns ((noisy, denoised) relMSE, (noisy, denoised) 1−SSIM),
/// tone map (a), no border.
fn errors(method: Method) -> ((f64, f64), (f64, f64)) {
    let weights = root().join(format!("denoiser/weights/{}-default.safetensors", method.name()));
    let device = denoiser::cpu_device();
    let loaded = denoiser::weights::load(&weights, &device).unwrap_or_else(|e| panic!("shipped weights {}: {e}", weights.display()));
    assert_eq!(loaded.method, method);
    let reference = exr_io::read_frame(&root().join("scenes/references/cornell-box.exr")).unwrap();
    let mut scene = Scene::load(Path::new(&root().join("scenes/cornell-box/scene.toml"))).unwrap();
    scene.camera.width = reference.width;
    scene.camera.height = reference.height;
    let request = BufferRequest { split: true, gbuffers: true, descriptors: method.needs_descriptors() };
    let opts = RenderOptions { spp: 8, seed: 4242, ..RenderOptions::from_scene(&scene, request) };
    let (frame, _) = integrator::render(&scene, &opts, &|_| {}).unwrap();
    let prepared = denoiser::preprocess::prepare(&frame).unwrap();
    let out = infer::denoise(&loaded.model, &loaded.config, &prepared, &frame.radiance.mean, &InferOptions::default(), &device).unwrap();
    assert!(out.radiance.iter().all(|v| v.is_finite()), "{method}: non-finite output");
    let (w, h) = (reference.width as usize, reference.height as usize);
    let noisy = rel_mse(&frame.radiance.mean, &reference.radiance.mean, w, h, ToneMap::Paper, 0);
    let denoised = rel_mse(&out.radiance, &reference.radiance.mean, w, h, ToneMap::Paper, 0);
    let s_noisy = one_minus_ssim(&frame.radiance.mean, &reference.radiance.mean, w, h, ToneMap::Paper, 0);
    let s_denoised = one_minus_ssim(&out.radiance, &reference.radiance.mean, w, h, ToneMap::Paper, 0);
    println!("{method}: relMSE noisy {noisy:.5} → denoised {denoised:.5} ({:.2}× lower); 1-SSIM {s_noisy:.4} → {s_denoised:.4} ({:.2}× lower)", noisy / denoised, s_noisy / s_denoised);
    ((noisy, denoised), (s_noisy, s_denoised))
}

/// The bar, for the current *preliminary* weights (docs/denoiser.md): 1−SSIM at least
/// SSIM_FACTOR× below the noisy render's, and relMSE below the noisy render's. Measured on the
/// shipped weights: 1−SSIM 3.9× (guided) / 3.6× (g) lower, relMSE only 1.20× / 1.04× lower —
/// the preliminary models remove the noise but blur and darken (a bias the relMSE sees), which
/// is the open problem. A broken model, preprocessing or inference loses the SSIM gain at
/// once (a pass-through or random model scores ≈ 1×). The render is seeded, so the test is
/// deterministic. Raise both bars when better-trained weights land.
const SSIM_FACTOR: f64 = 2.0;

fn check(method: Method) {
    let ((noisy, denoised), (s_noisy, s_denoised)) = errors(method);
    assert!(s_denoised * SSIM_FACTOR < s_noisy, "{method}: denoised 1-SSIM {s_denoised} not {SSIM_FACTOR}× below noisy {s_noisy}");
    assert!(denoised < noisy, "{method}: denoised relMSE {denoised} not below noisy {noisy}");
}

#[test]
fn shipped_guided_model_beats_the_noisy_render() {
    check(Method::Guided);
}

#[test]
fn shipped_g_model_beats_the_noisy_render() {
    check(Method::G);
}
