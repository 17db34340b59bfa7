//! Helpers every command that denoises or compares against a reference shares (`denoise`,
//! `render --denoise`, `eval`, the plots): the inference options, the model choice, loading a
//! weight file, the in-process denoising with its peak heap, the outputs and the error lines.

use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::infer::{self, Denoised, InferOptions};
use denoiser::method::Method;
use denoiser::metrics;
use denoiser::weights::{self, Loaded};
use renderer::film::{self, Frame};
use std::path::Path;

pub use super::gated::GatedKind;

/// Tiling options of inference (`denoise`, `render --denoise`, `eval`).
#[derive(Args, Clone)]
pub struct InferArgs {
    /// Output tile side of tiled inference (pixels); memory grows with its square. 0 = automatic
    /// (1024 for the default U-Net columns, 256 for KPCN columns, at any spp: the per-sample
    /// stages run in fixed-size chunks before tiling).
    #[arg(long, default_value_t = 0)]
    pub tile: usize,
    /// Tiles per network pass.
    #[arg(long, default_value_t = 1)]
    pub batch: usize,
    /// Where the networks' convolutions run: `engine` (direct kernels for this CPU's AVX-512,
    /// AVX2 or portable code; docs/inference-engine.md) or `burn` (the training framework's
    /// forward, the engine's reference). Both give the same image to f32 rounding.
    #[arg(long, default_value = "engine")]
    pub inference: Inference,
}

/// See [`InferArgs::inference`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Inference {
    Engine,
    Burn,
}

impl Inference {
    pub fn name(self) -> &'static str {
        match self {
            Inference::Engine => "engine",
            Inference::Burn => "burn",
        }
    }

    /// Sets the loaded model's columns to run where `self` says.
    pub fn apply(self, loaded: &mut Loaded) {
        let isa = (self == Inference::Engine).then(denoiser::engine::Isa::detect);
        denoiser::engine::use_engine(&mut loaded.model, isa);
    }
}

impl InferArgs {
    pub fn options(&self) -> InferOptions {
        InferOptions { tile: if self.tile == 0 { 0 } else { self.tile.max(8) }, batch: self.batch.max(1) }
    }
}

/// A denoiser the commands can run: one of our networks, a gate over several denoisers, or Open
/// Image Denoise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    /// One weight file: g, p, both, or the jointly trained guided model (`guided-joint`).
    Net(Method),
    /// Network E over frozen experts (`guided`: g and p; `guided-oidn`: OIDN, g and p).
    Gated(GatedKind),
    Oidn,
}

impl Model {
    /// Every model, in the order help texts list them.
    pub const ALL: [Model; 7] = [
        Model::Net(Method::G),
        Model::Net(Method::P),
        Model::Net(Method::Both),
        Model::Gated(GatedKind::Guided),
        Model::Gated(GatedKind::GuidedOidn),
        Model::Net(Method::Guided),
        Model::Oidn,
    ];

    pub fn name(self) -> &'static str {
        match self {
            // The name `guided` belongs to the gated model users run; the joint one keeps its own.
            Model::Net(Method::Guided) => "guided-joint",
            Model::Net(m) => m.name(),
            Model::Gated(k) => k.name(),
            Model::Oidn => "oidn",
        }
    }

    /// Whether the renderer must record per-sample path descriptors for it.
    pub fn needs_descriptors(self) -> bool {
        match self {
            Model::Net(m) => m.needs_descriptors(),
            Model::Gated(_) => true,
            Model::Oidn => false,
        }
    }
}

/// Names as `--model` and `--denoise` spell them.
impl clap::ValueEnum for Model {
    fn value_variants<'a>() -> &'a [Self] {
        &Model::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// Loads the weights for `method` (from `file`, or the default file), and checks that they are
/// weights of that method.
pub fn load_weights(method: Method, file: Option<&Path>) -> Result<Loaded> {
    let path = file.map(Path::to_path_buf).unwrap_or_else(|| weights::default_path(method));
    if !path.exists() {
        if file.is_some() {
            bail!("weight file {} does not exist", path.display());
        }
        bail!(
            "no weights for the {method} model: {} does not exist. Train them with \
             `pixguide train --method {method}` (docs/training.md), or pass --weights FILE",
            path.display()
        );
    }
    let loaded = weights::load(&path, &denoiser::cpu_device())?;
    if loaded.method != method {
        bail!("{} holds weights of the {} model, not {method} (choose --model {})", path.display(), loaded.method, loaded.method);
    }
    Ok(loaded)
}

/// Result of [`denoise_frame`] with its timing.
pub struct DenoiseRun {
    pub denoised: Denoised,
    /// Preprocessing (method.md §2, §4.1) seconds.
    pub prepare_s: f64,
    /// Heap bytes allocated above the level at the start, at the peak.
    pub peak_extra_bytes: usize,
}

/// [`infer::denoise_frame`] on the CPU, with the peak heap it took (only the binary has the
/// counting allocator).
pub fn denoise_frame(frame: &mut Frame, loaded: &Loaded, opts: &InferOptions) -> Result<DenoiseRun> {
    let base = crate::alloc_stats::reset_peak();
    let run = infer::denoise_frame(frame, loaded, opts, &denoiser::cpu_device())?;
    let peak_extra_bytes = crate::alloc_stats::peak().saturating_sub(base);
    Ok(DenoiseRun { denoised: run.denoised, prepare_s: run.prepare_s, peak_extra_bytes })
}

/// W_G of both branches side by side, viridis-coloured, each under a label.
pub fn write_weights_png(path: &Path, d: &Denoised) -> Result<()> {
    let Some(maps) = &d.weights_g else {
        bail!("--weights-png needs the guided model (only it blends two denoisers)");
    };
    let (w, h) = (d.width as u32, d.height as u32);
    let (gap, label) = (4u32, super::font::BAR_H);
    let sw = 2 * w + gap;
    let sh = h + label;
    let mut px = vec![32u8; (sw * sh * 3) as usize];
    for (k, (name, map)) in [("W_G diffuse", &maps.diffuse), ("W_G specular", &maps.specular)].into_iter().enumerate() {
        let x0 = k as u32 * (w + gap);
        for y in 0..h {
            for x in 0..w {
                let v = map[(y * w + x) as usize].clamp(0.0, 1.0) as f64;
                let c = colorous::VIRIDIS.eval_continuous(v);
                let o = (((label + y) * sw + x0 + x) * 3) as usize;
                px[o..o + 3].copy_from_slice(&[c.r, c.g, c.b]);
            }
        }
        // A narrower tile holds no legible label.
        if w >= 40 {
            super::font::bar_label(&mut px, sw, (x0, 0), w, name);
        }
    }
    ensure_parent(path)?;
    film::png::write_rgb8(path, sw, sh, px).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Creates the folder `path` will be written to.
pub fn ensure_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating the output folder {}", dir.display()))?;
    }
    Ok(())
}

/// Reads a reference EXR and checks its size against `w × h`.
pub fn read_reference(path: &Path, w: u32, h: u32) -> Result<Frame> {
    let r = film::exr_io::read_frame(path).with_context(|| format!("reading the reference {}", path.display()))?;
    if (r.width, r.height) != (w, h) {
        bail!("reference {} is {}×{} but the image is {w}×{h}", path.display(), r.width, r.height);
    }
    Ok(r)
}

/// One line of errors against the reference (method.md §7.3).
pub fn error_line(label: &str, rgb: &[f32], reference: &Frame) -> String {
    let (w, h) = (reference.width as usize, reference.height as usize);
    let e = metrics::evaluate(rgb, &reference.radiance.mean, w, h, metrics::DEFAULT_BORDER);
    format!("{label:>9}: relMSE {:.5} (gamma {:.5}), 1-SSIM {:.5}", e.rel_mse, e.rel_mse_gamma, e.one_minus_ssim)
}

pub fn print_denoise_summary(loaded: &Loaded, run: &DenoiseRun) {
    let t = &run.denoised.timings;
    println!(
        "denoise ({} model, preset {}): {:.2} s = preprocess {:.2} s + networks {:.2} s + tiling {:.2} s; {} tiles of {}² in windows of {}², peak heap +{:.0} MiB",
        loaded.method,
        if loaded.preset.is_empty() { "?" } else { &loaded.preset },
        run.prepare_s + t.total_s,
        run.prepare_s,
        t.forward_s,
        t.gather_s,
        t.windows,
        t.tile,
        t.window,
        run.peak_extra_bytes as f64 / (1024.0 * 1024.0)
    );
}

/// Writes the denoised radiance as EXR, and optionally a tone-mapped PNG and the W_G maps.
pub fn write_outputs(d: &Denoised, spp: u32, output: &Path, png: Option<&Path>, weights_png: Option<&Path>) -> Result<()> {
    ensure_parent(output)?;
    film::exr_io::write_frame(&infer::denoised_frame(d, spp), output).with_context(|| format!("writing {}", output.display()))?;
    if let Some(p) = png {
        ensure_parent(p)?;
        film::png::write_radiance(p, d.width as u32, d.height as u32, &d.radiance, 0.0)?;
    }
    if let Some(p) = weights_png {
        write_weights_png(p, d)?;
    }
    Ok(())
}

/// `git rev-parse HEAD` (+ "-dirty" with local changes), empty outside a repository.
pub fn git_commit() -> String {
    let run = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match run(&["rev-parse", "HEAD"]) {
        Some(h) => {
            let dirty = run(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
            if dirty {
                format!("{h}-dirty")
            } else {
                h
            }
        }
        None => String::new(),
    }
}

/// Now as ISO 8601 UTC (civil-from-days, Howard Hinnant's algorithm).
pub fn iso_date_utc() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs() as i64).unwrap_or(0);
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    format!("{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem / 60 % 60, rem % 60)
}
