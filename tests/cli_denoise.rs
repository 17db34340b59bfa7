//! End-to-end: `pixguide render --denoise` and `pixguide denoise` on a shipped scene, with tiny
//! randomly initialised weight files (the point is the plumbing — buffers, descriptors, weight
//! files, tiling, outputs, errors — not the image quality, which needs trained weights).

mod common;

use std::path::{Path, PathBuf};

use common::{failed, ok, out_dir, pixguide, s};

use denoiser::ensemble::EnsembleConfig;
use denoiser::kpcn::KpcnConfig;
use denoiser::method::{Method, MethodModel};
use denoiser::model::DenoiserConfig;
use denoiser::pathnet::PathNetConfig;
use denoiser::weights::{save, Provenance};
use renderer::film::exr_io::read_frame;

/// A randomly initialised tiny model of `method`, saved as a weight file.
fn tiny_weights(dir: &Path, method: Method) -> PathBuf {
    let cfg = DenoiserConfig::new(
        KpcnConfig::new(34).with_depth(3).with_width(8).with_conv_kernel(3).with_filter_size(5),
        PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8]).with_convs_per_block(1).with_out_hidden(8),
        EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
    );
    let model = MethodModel::init(&cfg, method, &denoiser::cpu_device());
    let path = dir.join(format!("{}-tiny.safetensors", method.name()));
    save(&path, &model, &cfg, "tiny", &Provenance { command: "tests/cli_denoise.rs".into(), ..Default::default() }).unwrap();
    path
}

fn assert_finite_image(path: &Path, w: u32, h: u32) {
    let f = read_frame(path).unwrap();
    assert_eq!((f.width, f.height), (w, h), "{}", path.display());
    assert!(f.radiance.mean.iter().all(|v| v.is_finite() && *v >= 0.0), "{} has non-finite or negative radiance", path.display());
    assert!(f.radiance.mean.iter().any(|v| *v > 0.0), "{} is black", path.display());
}

/// The main command: render at 2 spp and denoise with the guided model in one process; every
/// output is written, finite and of the scene's size, and the timings and errors are printed.
#[test]
fn render_and_denoise_in_one_process() {
    let d = out_dir("cli-denoise-render");
    let weights = tiny_weights(&d, Method::Guided);
    let reference = d.join("ref.exr");
    ok(&pixguide(&["render", "scenes/cornell-box/scene.toml", "--spp", "4", "--seed", "9", "-q", "-o", s(&reference)]), "reference render");
    let (out, png, wpng, noisy) = (d.join("den.exr"), d.join("den.png"), d.join("wg.png"), d.join("noisy.exr"));
    let stdout = ok(
        &pixguide(&[
            "render",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "2",
            "-q",
            "--denoise",
            "guided-joint",
            "--weights",
            s(&weights),
            "-o",
            s(&out),
            "--png",
            s(&png),
            "--weights-png",
            s(&wpng),
            "--noisy",
            s(&noisy),
            "--reference",
            s(&reference),
            "--tile",
            "96",
        ]),
        "render --denoise",
    );
    for needle in ["render:", "denoise (guided model", "noisy: relMSE", "denoised: relMSE", "1-SSIM"] {
        assert!(stdout.contains(needle), "`{needle}` missing from: {stdout}");
    }
    assert_finite_image(&out, 256, 256);
    let noisy_frame = read_frame(&noisy).unwrap();
    // The guided model needs the split, the G-buffers and the descriptors; they were recorded.
    assert!(noisy_frame.diffuse.is_some() && noisy_frame.albedo.is_some());
    let img = image::open(&wpng).unwrap();
    assert_eq!((img.width(), img.height()), (2 * 256 + 4, 256 + 16));
    assert!(png.metadata().unwrap().len() > 0);
}

/// `pixguide denoise` on a frame written by `render --aovs`: guided (descriptors found beside
/// the frame) and g (no descriptors needed) both write a finite image of the frame's size.
#[test]
fn denoise_command_on_an_aovs_frame() {
    let d = out_dir("cli-denoise-command");
    let frame = d.join("frame.exr");
    ok(&pixguide(&["render", "scenes/cornell-box/scene.toml", "--spp", "2", "--aovs", "-q", "-o", s(&frame)]), "render --aovs");
    for m in [Method::Guided, Method::G] {
        let w = tiny_weights(&d, m);
        let out = d.join(format!("{}.exr", m.name()));
        let model = if m == Method::Guided { "guided-joint" } else { m.name() };
        let stdout = ok(&pixguide(&["denoise", s(&frame), "--model", model, "--weights", s(&w), "-o", s(&out)]), "denoise");
        assert!(stdout.contains("windows"), "{stdout}");
        assert_finite_image(&out, 256, 256);
    }
    // P without its descriptor file: a clear error naming the missing file.
    let w = tiny_weights(&d, Method::P);
    std::fs::remove_file(d.join("frame.descriptors.safetensors")).unwrap();
    let err = failed(&pixguide(&["denoise", s(&frame), "--model", "p", "--weights", s(&w)]), "p without descriptors");
    assert!(err.contains("descriptors") && err.contains("frame.descriptors.safetensors"), "{err}");
}

#[test]
fn clear_errors() {
    let d = out_dir("cli-denoise-errors");
    // A frame without G-buffers.
    let plain = d.join("plain.exr");
    ok(&pixguide(&["render", "scenes/cornell-box/scene.toml", "--spp", "1", "-q", "-o", s(&plain)]), "render");
    let g = tiny_weights(&d, Method::G);
    let err = failed(&pixguide(&["denoise", s(&plain), "--model", "g", "--weights", s(&g)]), "denoise without G-buffers");
    assert!(err.contains("plain.exr") && err.contains("--aovs"), "{err}");
    // A missing weight file, in both commands.
    let missing = d.join("nope.safetensors");
    std::fs::remove_file(&missing).ok(); // left by an earlier run's garbage-file case below
    let err = failed(&pixguide(&["denoise", s(&plain), "--model", "g", "--weights", s(&missing)]), "missing weights");
    assert!(err.contains("nope.safetensors") && err.contains("does not exist"), "{err}");
    let err = failed(
        &pixguide(&[
            "render",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "1",
            "-q",
            "--denoise",
            "p",
            "--weights",
            s(&missing),
            "-o",
            s(&d.join("x.exr")),
        ]),
        "render with missing weights",
    );
    assert!(err.contains("nope.safetensors"), "{err}");
    // Weights of another model than asked for.
    let err = failed(
        &pixguide(&[
            "render",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "1",
            "-q",
            "--denoise",
            "guided-joint",
            "--weights",
            s(&g),
            "-o",
            s(&d.join("x.exr")),
        ]),
        "wrong model",
    );
    assert!(err.contains("g model") && err.contains("--model g"), "{err}");
    // A file that is not a weight file.
    std::fs::write(&missing, b"not weights").unwrap();
    let err = failed(&pixguide(&["denoise", s(&plain), "--model", "g", "--weights", s(&missing)]), "garbage weights");
    assert!(err.contains("nope.safetensors") && err.contains("safetensors"), "{err}");
}

/// The README's main command on the shipped models: `--denoise guided` is the gate E over the
/// shipped g and p. The output is finite and of the scene's size, the summary names both
/// experts and their mean weights, and the weight PNG has one panel per expert.
#[test]
fn render_with_the_shipped_gate() {
    let d = out_dir("cli-denoise-gate");
    let (out, wpng) = (d.join("den.exr"), d.join("w.png"));
    let stdout = ok(
        &pixguide(&[
            "render",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "2",
            "--size",
            "96x64",
            "-q",
            "--denoise",
            "guided",
            "-o",
            s(&out),
            "--weights-png",
            s(&wpng),
        ]),
        "render --denoise guided",
    );
    assert!(stdout.contains("denoise (guided model: E over g, p)") && stdout.contains("mean weight g "), "{stdout}");
    assert_finite_image(&out, 96, 64);
    let img = image::open(&wpng).unwrap();
    assert_eq!((img.width(), img.height()), (2 * 96 + 4, 64 + 16));
    // A gate file is not a column's weight file, nor the other way round: clear errors.
    let g = tiny_weights(&d, Method::G);
    let err = failed(
        &pixguide(&[
            "render",
            "scenes/cornell-box/scene.toml",
            "--spp",
            "1",
            "-q",
            "--denoise",
            "guided",
            "--weights",
            s(&g),
            "-o",
            s(&out),
        ]),
        "a column's file as a gate",
    );
    assert!(err.contains("not a gate file"), "{err}");
}
