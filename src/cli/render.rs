//! `pixguide render`.

use super::progress;
use super::shared::{self as dn, InferArgs, Model};
use anyhow::{Context, Result};
use clap::Args;
use denoiser::method::Method;
use denoiser::oidn::Oidn;
use denoiser::weights::Loaded;
use renderer::film::{self, BufferRequest, Frame};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct RenderArgs {
    /// Scene file (.toml, .gltf, .glb).
    pub scene: PathBuf,
    /// Samples per pixel (default: the scene's).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Random seed (default: the scene's). The same seed gives the same image bit for bit.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Maximum bounces (default: the scene's, normally 5).
    #[arg(long)]
    pub max_bounces: Option<u32>,
    /// Image size WxH instead of the scene's (e.g. the size of a --reference). The view keeps
    /// the scene's field of view along its axis (vertical for TOML and glTF, Mitsuba's fov_axis,
    /// horizontal by default, for XML), so a wider image shows more at the sides.
    #[arg(long, value_parser = crate::cli::dataset::parse_size)]
    pub size: Option<(u32, u32)>,
    /// Output EXR (radiance with variance; with --aovs every buffer).
    #[arg(short, long, default_value = "out.exr")]
    pub output: PathBuf,
    /// Also write a tone-mapped PNG preview here.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Exposure of the PNG preview in stops.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Emit every denoiser input: diffuse/specular split and G-buffers in the EXR, per-sample path
    /// descriptors in `<output>.descriptors.safetensors`, a PNG of each buffer and a contact sheet.
    #[arg(long)]
    pub aovs: bool,
    /// Denoise in the same process: guided (g and p blended per pixel by the ensembling network
    /// E: the paper's method), guided-oidn (E over OIDN, g and p), g, p, both, guided-joint (E
    /// trained jointly with its own g and p), oidn (Intel Open Image Denoise, the baseline), or
    /// none. `-o` and `--png` then get the denoised image. Records only the buffers the model
    /// needs (per-sample descriptors for every model but g and oidn).
    #[arg(long, default_value = "none")]
    pub denoise: DenoiseModel,
    /// Weight file for --denoise (default: denoiser/weights/<model>-default.safetensors; for guided
    /// and guided-oidn the gate, default denoiser/weights/<model>-e.safetensors).
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// With --denoise: also write the noisy frame here.
    #[arg(long)]
    pub noisy: Option<PathBuf>,
    /// Reference EXR: print relMSE and 1 − SSIM (method.md §7.3) of the noisy and the denoised image.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// With --denoise guided or guided-oidn: write each denoiser's share per pixel as a
    /// colour-mapped PNG, one panel per expert (guided-joint: W_G, diffuse and specular branch).
    #[arg(long)]
    pub weights_png: Option<PathBuf>,
    #[command(flatten)]
    pub infer: InferArgs,
    /// Don't show the progress bar.
    #[arg(short, long)]
    pub quiet: bool,
    /// Refuse to render a scene with features the loader would approximate (a Mitsuba texture on
    /// a parameter that takes a colour, anisotropic roughness, …): each becomes an error naming
    /// its file, line and substitution instead of a warning.
    #[arg(long)]
    pub strict: bool,
}

/// `--denoise` value: a model, or none. (A newtype because clap reads `Option<T>` fields as
/// "flag may be absent", not as a value that can be "none".)
#[derive(Clone, Copy, Debug)]
pub struct DenoiseModel(pub Option<Model>);

impl clap::ValueEnum for DenoiseModel {
    fn value_variants<'a>() -> &'a [Self] {
        const ALL: [DenoiseModel; 8] = {
            let m = Model::ALL;
            [
                DenoiseModel(Some(m[0])),
                DenoiseModel(Some(m[1])),
                DenoiseModel(Some(m[2])),
                DenoiseModel(Some(m[3])),
                DenoiseModel(Some(m[4])),
                DenoiseModel(Some(m[5])),
                DenoiseModel(Some(m[6])),
                DenoiseModel(None),
            ]
        };
        &ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.0.map_or("none", Model::name)))
    }
}

/// The denoiser of `--denoise`, ready to run.
enum Denoiser {
    /// Boxed: the weights header makes `Loaded` large next to `Oidn`.
    Net(Box<Loaded>),
    Gated(Box<super::gated::GatedDenoiser>),
    /// With the seconds its loading took.
    Oidn(Oidn, f64),
}

pub fn run(a: RenderArgs) -> Result<()> {
    if a.weights_png.is_some() && !matches!(a.denoise.0, Some(Model::Net(Method::Guided) | Model::Gated(_))) {
        anyhow::bail!("--weights-png needs --denoise guided, guided-oidn or guided-joint (only they blend denoisers)");
    }
    // Weights (or OIDN) before the render, so that a missing file costs nothing.
    let loaded = match a.denoise.0 {
        None => None,
        Some(Model::Net(m)) => {
            let mut loaded = dn::load_weights(m, a.weights.as_deref())?;
            a.infer.inference.apply(&mut loaded);
            Some(Denoiser::Net(Box::new(loaded)))
        }
        Some(Model::Gated(k)) => {
            let mut gated = super::gated::load(k, a.weights.as_deref())?;
            gated.use_inference(&a.infer.inference);
            Some(Denoiser::Gated(Box::new(gated)))
        }
        Some(Model::Oidn) => {
            if a.weights.is_some() {
                anyhow::bail!("--weights does not apply to --denoise oidn (OIDN brings its own weights)");
            }
            let (oidn, load_s) = super::oidn_setup::load()?;
            Some(Denoiser::Oidn(oidn, load_s))
        }
    };
    for out in [Some(&a.output), a.png.as_ref(), a.noisy.as_ref()].into_iter().flatten() {
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("creating the output folder {}", dir.display()))?;
        }
    }
    let mut scene = if a.strict { Scene::load_strict(&a.scene)? } else { Scene::load(&a.scene)? };
    if let Some((w, h)) = a.size {
        // The camera derives its angles from its fov axis and the image size (Camera::ray).
        scene.camera.width = w;
        scene.camera.height = h;
    }
    let request = match (a.aovs, a.denoise.0) {
        (true, _) => BufferRequest::ALL,
        (false, Some(m @ (Model::Net(_) | Model::Gated(_)))) => {
            BufferRequest { split: true, gbuffers: true, descriptors: m.needs_descriptors() }
        }
        (false, Some(Model::Oidn)) => BufferRequest { split: false, gbuffers: true, descriptors: false },
        (false, None) => BufferRequest::RADIANCE_ONLY,
    };
    let mut opts = RenderOptions::from_scene(&scene, request);
    opts.spp = a.spp.unwrap_or(opts.spp);
    opts.seed = a.seed.unwrap_or(opts.seed);
    opts.max_bounces = a.max_bounces.unwrap_or(opts.max_bounces);

    let pixels = scene.camera.width as u64 * scene.camera.height as u64;
    let pb = progress::bar(pixels, &format!("render {}spp", opts.spp));
    if a.quiet {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let t_render = std::time::Instant::now();
    let (mut frame, stats) = integrator::render(&scene, &opts, &|n| pb.set_position(n))?;
    let render_s = t_render.elapsed().as_secs_f64();
    pb.finish_and_clear();
    if frame.nonfinite_samples > 0 {
        eprintln!("warning: {} samples had non-finite radiance and were dropped", frame.nonfinite_samples);
    }

    if a.aovs {
        write_aovs(&frame, &a.output, a.exposure)?;
    }
    println!("{}: {}x{} at {} spp: {}", a.scene.display(), frame.width, frame.height, frame.spp, stats.summary());
    println!("render: {render_s:.2} s");
    let Some(loaded) = loaded else {
        film::exr_io::write_frame(&frame, &a.output)?;
        if let Some(png) = &a.png {
            film::png::write_radiance(png, frame.width, frame.height, &frame.radiance.mean, a.exposure)?;
        }
        if let Some(r) = &a.reference {
            let reference = dn::read_reference(r, frame.width, frame.height)?;
            println!("{}", dn::error_line("noisy", &frame.radiance.mean, &reference));
        }
        return Ok(());
    };
    if let Some(noisy) = &a.noisy {
        film::exr_io::write_frame(&frame, noisy)?;
    }
    let denoised = match loaded {
        Denoiser::Net(loaded) => {
            let run = dn::denoise_frame(&mut frame, &loaded, &a.infer.options())?;
            dn::print_denoise_summary(&loaded, &run);
            run.denoised
        }
        Denoiser::Gated(g) => {
            let run = g.run(&mut frame, &a.infer.options())?;
            g.print_summary(&run);
            if let Some(p) = &a.weights_png {
                super::gated::write_weights_png(p, run.denoised.width, run.denoised.height, g.experts(), &run.weights)?;
            }
            run.denoised
        }
        Denoiser::Oidn(oidn, load_s) => {
            let d = super::oidn_setup::denoise_frame(&oidn, &frame)?;
            super::oidn_setup::print_summary(&oidn, load_s, &d);
            d
        }
    };
    let weights_png = if denoised.weights_g.is_some() { a.weights_png.as_deref() } else { None };
    dn::write_outputs(&denoised, frame.spp, &a.output, None, weights_png)?;
    if let Some(png) = &a.png {
        film::png::write_radiance(png, frame.width, frame.height, &denoised.radiance, a.exposure)?;
    }
    if let Some(r) = &a.reference {
        let reference = dn::read_reference(r, frame.width, frame.height)?;
        println!("{}", dn::error_line("noisy", &frame.radiance.mean, &reference));
        println!("{}", dn::error_line("denoised", &denoised.radiance, &reference));
    }
    Ok(())
}

fn sibling(output: &Path, suffix: &str) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into());
    output.with_file_name(format!("{stem}{suffix}"))
}

/// Descriptor file, one PNG per buffer, and a contact sheet of all of them with labels.
fn write_aovs(frame: &Frame, output: &Path, exposure: f32) -> Result<()> {
    if let Some(d) = &frame.descriptors {
        d.write_safetensors(&sibling(output, ".descriptors.safetensors"))?;
    }
    let (w, h) = (frame.width, frame.height);
    let mut tiles: Vec<(&str, Vec<f32>)> = vec![("radiance", frame.radiance.mean.iter().map(|v| v * 2f32.powf(exposure)).collect())];
    let mut add = |name: &'static str, buf: &Option<film::PixelBuffer>, signed: bool, radiance: bool| {
        if let Some(b) = buf {
            let rgb = if radiance {
                b.mean.iter().map(|v| v * 2f32.powf(exposure)).collect()
            } else {
                film::png::normalised_rgb(&b.mean, b.channels, signed)
            };
            tiles.push((name, rgb));
            tiles.push((Box::leak(format!("{name} variance").into_boxed_str()), film::png::normalised_rgb(&b.var, b.channels, false)));
        }
    };
    add("diffuse", &frame.diffuse, false, true);
    add("specular", &frame.specular, false, true);
    add("albedo", &frame.albedo, false, false);
    add("normal", &frame.normal, true, false);
    add("depth", &frame.depth, false, false);
    for (name, rgb) in &tiles {
        let path = sibling(output, &format!(".{}.png", name.replace(' ', "-")));
        film::png::write_radiance(&path, w, h, rgb, 0.0).with_context(|| format!("writing {}", path.display()))?;
    }
    let sheet = contact_sheet(&tiles, w, h);
    film::png::write_rgb8(&sibling(output, ".contact.png"), sheet.0, sheet.1, sheet.2)?;
    Ok(())
}

/// Lays tiles out 4 per row, each under a label bar.
fn contact_sheet(tiles: &[(&str, Vec<f32>)], w: u32, h: u32) -> (u32, u32, Vec<u8>) {
    let cols = 4u32.min(tiles.len() as u32).max(1);
    let rows = (tiles.len() as u32).div_ceil(cols);
    let label_h = super::font::BAR_H;
    let (sw, sh) = (cols * w, rows * (h + label_h));
    let mut px = vec![32u8; (sw * sh * 3) as usize];
    for (k, (name, rgb)) in tiles.iter().enumerate() {
        let (cx, cy) = ((k as u32 % cols) * w, (k as u32 / cols) * (h + label_h));
        let rgb8 = film::png::tonemap_rgb8(rgb, 0.0);
        for y in 0..h {
            let dst = (((cy + label_h + y) * sw + cx) * 3) as usize;
            let src = (y * w * 3) as usize;
            px[dst..dst + (w * 3) as usize].copy_from_slice(&rgb8[src..src + (w * 3) as usize]);
        }
        super::font::bar_label(&mut px, sw, (cx, cy), w, name);
    }
    (sw, sh, px)
}
