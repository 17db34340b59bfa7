//! `pixguide denoise`: a frame written by `render --aovs`, denoised by one of our models or OIDN.

use anyhow::{bail, Context, Result};
use clap::Args;
use renderer::film;
use renderer::film::descriptors::Descriptors;
use std::path::PathBuf;

use super::shared::{denoise_frame, error_line, load_weights, print_denoise_summary, write_outputs, Model};
// `eval` still names these by this module's path; they live in `shared`.
pub use super::shared::{ensure_parent, read_reference, InferArgs};

#[derive(Args)]
pub struct DenoiseArgs {
    /// Noisy frame EXR written by `pixguide render --aovs` (needs the diffuse/specular split and
    /// the G-buffers).
    pub frame: PathBuf,
    /// Per-sample path descriptors (default: `<frame stem>.descriptors.safetensors` beside the
    /// frame). Needed by the p, both and guided models.
    #[arg(long)]
    pub descriptors: Option<PathBuf>,
    /// Denoiser: g (a kernel-predicting U-Net on the G-buffers: albedo, normal, depth), p (the
    /// same network on the P-buffers a path-manifold network makes from per-sample path
    /// descriptors), both (one network on G- and P-buffers), guided (g and p blended per pixel
    /// by the ensembling network E: the paper's method), guided-oidn (E over OIDN, g and p),
    /// guided-joint (the older guided model, E trained jointly with its own g and p), or oidn
    /// (Intel Open Image Denoise, the baseline; installed into target/oidn-venv from PyPI the
    /// first time).
    #[arg(long, default_value = "guided")]
    pub model: Model,
    /// Weight file (default: denoiser/weights/<model>-default.safetensors; for guided and
    /// guided-oidn the gate file, default denoiser/weights/<model>-e.safetensors).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Output EXR (denoised radiance).
    #[arg(short, long, default_value = "denoised.exr")]
    pub output: PathBuf,
    /// Also write a tone-mapped PNG preview here.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Write each denoiser's share per pixel (guided, guided-oidn, guided-joint) as a
    /// colour-mapped PNG, one panel per expert (guided-joint: W_G of the diffuse and specular
    /// branch), viridis from 0 (dark) to 1 (yellow).
    #[arg(long)]
    pub weights_png: Option<PathBuf>,
    /// Reference EXR: print relMSE and 1 − SSIM of the noisy and the denoised image.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    #[command(flatten)]
    pub infer: InferArgs,
}

pub fn run(a: DenoiseArgs) -> Result<()> {
    // Weights first: a missing file should not cost the time of reading a large frame.
    let (loaded, gated) = match a.model {
        Model::Net(m) => {
            let mut loaded = load_weights(m, a.weights.as_deref())?;
            a.infer.inference.apply(&mut loaded);
            (Some(loaded), None)
        }
        Model::Gated(k) => {
            let mut gated = super::gated::load(k, a.weights.as_deref())?;
            gated.use_inference(&a.infer.inference);
            (None, Some(gated))
        }
        Model::Oidn => return run_oidn(&a),
    };
    let mut frame = film::exr_io::read_frame(&a.frame).with_context(|| format!("reading {}", a.frame.display()))?;
    for (name, b) in [
        ("diffuse", &frame.diffuse),
        ("specular", &frame.specular),
        ("albedo", &frame.albedo),
        ("normal", &frame.normal),
        ("depth", &frame.depth),
    ] {
        if b.is_none() {
            bail!("{} has no {name} buffer: the denoiser needs the frame written by `pixguide render --aovs`", a.frame.display());
        }
    }
    if a.model.needs_descriptors() {
        let path = a.descriptors.clone().unwrap_or_else(|| {
            let stem = a.frame.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            a.frame.with_file_name(format!("{stem}.descriptors.safetensors"))
        });
        if !path.exists() {
            bail!(
                "the {} model needs per-sample path descriptors: {} does not exist (render with --aovs, pass --descriptors FILE, or use --model g)",
                a.model.name(),
                path.display()
            );
        }
        let d = Descriptors::read_safetensors(&path).with_context(|| format!("reading {}", path.display()))?;
        if d.width != frame.width || d.height != frame.height || d.spp < frame.spp {
            bail!(
                "{}: descriptors are {}×{} at {} spp but {} is {}×{} at {} spp",
                path.display(),
                d.width,
                d.height,
                d.spp,
                a.frame.display(),
                frame.width,
                frame.height,
                frame.spp
            );
        }
        frame.descriptors = Some(d);
    }
    let denoised = if let Some(g) = gated {
        let run = g.run(&mut frame, &a.infer.options()).with_context(|| format!("denoising {}", a.frame.display()))?;
        g.print_summary(&run);
        write_outputs(&run.denoised, frame.spp, &a.output, a.png.as_deref(), None)?;
        if let Some(p) = &a.weights_png {
            super::gated::write_weights_png(p, run.denoised.width, run.denoised.height, g.experts(), &run.weights)?;
        }
        run.denoised
    } else {
        let loaded = loaded.expect("a network model");
        let run = denoise_frame(&mut frame, &loaded, &a.infer.options()).with_context(|| format!("denoising {}", a.frame.display()))?;
        print_denoise_summary(&loaded, &run);
        write_outputs(&run.denoised, frame.spp, &a.output, a.png.as_deref(), a.weights_png.as_deref())?;
        run.denoised
    };
    if let Some(r) = &a.reference {
        let reference = read_reference(r, frame.width, frame.height)?;
        println!("{}", error_line("noisy", &frame.radiance.mean, &reference));
        println!("{}", error_line("denoised", &denoised.radiance, &reference));
    }
    Ok(())
}

/// `pixguide denoise --model oidn`: OIDN needs only the radiance, albedo and normal.
fn run_oidn(a: &DenoiseArgs) -> Result<()> {
    if a.weights.is_some() {
        bail!("--weights does not apply to --model oidn (OIDN brings its own weights)");
    }
    if a.weights_png.is_some() {
        bail!("--weights-png needs --model guided, guided-oidn or guided-joint (only they blend denoisers)");
    }
    // The library before the frame: a failed install should not cost the time of reading it.
    let (oidn, load_s) = super::oidn_setup::load()?;
    let frame = film::exr_io::read_frame(&a.frame).with_context(|| format!("reading {}", a.frame.display()))?;
    let d = super::oidn_setup::denoise_frame(&oidn, &frame).with_context(|| format!("denoising {}", a.frame.display()))?;
    super::oidn_setup::print_summary(&oidn, load_s, &d);
    write_outputs(&d, frame.spp, &a.output, a.png.as_deref(), None)?;
    if let Some(r) = &a.reference {
        let reference = read_reference(r, frame.width, frame.height)?;
        println!("{}", error_line("noisy", &frame.radiance.mean, &reference));
        println!("{}", error_line("denoised", &d.radiance, &reference));
    }
    Ok(())
}
