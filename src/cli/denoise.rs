//! `pixguide denoise`, and the in-process denoising that `pixguide render --denoise` shares.

use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::infer::{self, Denoised, InferOptions};
use denoiser::method::Method;
use denoiser::metrics;
use denoiser::weights::{self, Loaded};
use renderer::film::descriptors::Descriptors;
use renderer::film::{self, Frame};
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct DenoiseArgs {
    /// Noisy frame EXR written by `pixguide render --aovs` (needs the diffuse/specular split and
    /// the G-buffers).
    pub frame: PathBuf,
    /// Per-sample path descriptors (default: `<frame stem>.descriptors.safetensors` beside the
    /// frame). Needed by the p, both and guided models.
    #[arg(long)]
    pub descriptors: Option<PathBuf>,
    /// Denoiser: guided (the paper's method), g (KPCN on G-buffers), p (KPCN on P-buffers),
    /// both (KPCN on G- and P-buffers), or oidn (Intel Open Image Denoise, the baseline; installed
    /// into target/oidn-venv from PyPI the first time).
    #[arg(long, default_value = "guided")]
    pub model: Model,
    /// Weight file (default: denoiser/weights/<model>-default.safetensors).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Output EXR (denoised radiance).
    #[arg(short, long, default_value = "denoised.exr")]
    pub output: PathBuf,
    /// Also write a tone-mapped PNG preview here.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Write W_G (the G-buffer denoiser's share per pixel, guided model only) as a colour-mapped
    /// PNG: diffuse branch left, specular branch right, viridis from W_G = 0 (dark) to 1 (yellow).
    #[arg(long)]
    pub weights_png: Option<PathBuf>,
    /// Reference EXR: print relMSE and 1 − SSIM of the noisy and the denoised image.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    #[command(flatten)]
    pub infer: InferArgs,
}

/// Options shared with `render --denoise`.
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

/// A denoiser the commands can run: one of our networks, or Open Image Denoise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Model {
    Net(Method),
    Oidn,
}

impl Model {
    /// Every model, in the order help texts list them: the methods' own order, then OIDN.
    pub const ALL: [Model; 5] =
        [Model::Net(Method::G), Model::Net(Method::P), Model::Net(Method::Both), Model::Net(Method::Guided), Model::Oidn];

    pub fn name(self) -> &'static str {
        match self {
            Model::Net(m) => m.name(),
            Model::Oidn => "oidn",
        }
    }
}

/// The methods' names come from `Method` (denoiser/src/names.rs); only `oidn` is added here.
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
             `pixguide train --model {method}` (see docs/denoiser-design.md), or pass --weights FILE",
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

pub fn run(a: DenoiseArgs) -> Result<()> {
    let method = match a.model {
        Model::Net(m) => m,
        Model::Oidn => return run_oidn(&a),
    };
    // Weights first: a missing file should not cost the time of reading a large frame.
    let mut loaded = load_weights(method, a.weights.as_deref())?;
    a.infer.inference.apply(&mut loaded);
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
    if loaded.method.needs_descriptors() {
        let path = a.descriptors.clone().unwrap_or_else(|| {
            let stem = a.frame.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            a.frame.with_file_name(format!("{stem}.descriptors.safetensors"))
        });
        if !path.exists() {
            bail!(
                "the {} model needs per-sample path descriptors: {} does not exist (render with --aovs, pass --descriptors FILE, or use --model g)",
                loaded.method,
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
    let run = denoise_frame(&mut frame, &loaded, &a.infer.options()).with_context(|| format!("denoising {}", a.frame.display()))?;
    print_denoise_summary(&loaded, &run);
    write_outputs(&run.denoised, frame.spp, &a.output, a.png.as_deref(), a.weights_png.as_deref())?;
    if let Some(r) = &a.reference {
        let reference = read_reference(r, frame.width, frame.height)?;
        println!("{}", error_line("noisy", &frame.radiance.mean, &reference));
        println!("{}", error_line("denoised", &run.denoised.radiance, &reference));
    }
    Ok(())
}

/// `pixguide denoise --model oidn`: OIDN needs only the radiance, albedo and normal.
fn run_oidn(a: &DenoiseArgs) -> Result<()> {
    if a.weights.is_some() {
        bail!("--weights does not apply to --model oidn (OIDN brings its own weights)");
    }
    if a.weights_png.is_some() {
        bail!("--weights-png needs --model guided (only the guided model blends two denoisers)");
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
