//! `pixguide eval`: the speed-versus-error evaluation — every held-out test scene
//! rendered at each spp, denoised in process by every method, scored against its reference;
//! written to docs/results.md with plots and pictures (report.rs). Resumable through a
//! cache of finished measurements.
//!
//! Here: the arguments and the run. Beside it: the methods (methods.rs), the test scenes
//! (scenes.rs), the measurement cache (cache.rs), the results page (report.rs) and its
//! pictures (pictures.rs).

mod cache;
mod methods;
mod oracle;
mod pictures;
mod report;
mod scenes;
mod spread;

use super::denoise::InferArgs;
use super::progress;
use anyhow::{bail, Context, Result};
use cache::{key, Cache, ImageStore, Record};
use clap::Args;
use denoiser::infer::{self, Denoised};
use denoiser::metrics;
use denoiser::preprocess::{self, PreparedImage};
use methods::{EvalMethod, MethodSpec, BREAKDOWN_METHODS, PICTURE_METHODS};
use oracle::BoundSpec;
use renderer::film::Frame;
use renderer::scene::Scene;
use scenes::{load_scene, render, TestScene};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args)]
pub struct EvalArgs {
    /// List of test scenes (paths relative to the list's folder); references are read from
    /// `<list folder>/references/<scene>.exr` and `.json`.
    #[arg(long, default_value = "scenes/test.txt")]
    pub scenes: PathBuf,
    /// Samples per pixel of the quality table and the plots.
    #[arg(long, default_value = "2,4,8,16,32,64", value_delimiter = ',')]
    pub spp: Vec<u32>,
    /// Methods: noisy (plain Monte Carlo, always measured: it normalises the errors), g, p, both,
    /// guided (E over g and p), guided-oidn (E over OIDN, g and p), guided-joint (the jointly
    /// trained model), guided-half, fix-n-train, full-n-full, radiance-only, oidn (Intel Open Image
    /// Denoise, the baseline: installed into target/oidn-venv from PyPI the first time, and left
    /// out with one line saying why if that fails).
    #[arg(
        long,
        value_enum,
        default_value = "noisy,g,p,both,guided,guided-oidn,guided-joint,guided-half,fix-n-train,full-n-full,radiance-only,oidn",
        value_delimiter = ','
    )]
    pub methods: Vec<EvalMethod>,
    /// Folder of the weight files (`<method>-default.safetensors`, `guided-half.safetensors`, …:
    /// the names `pixguide train --all` writes).
    #[arg(long, default_value = "denoiser/weights")]
    pub weights_dir: PathBuf,
    /// Render seeds: every (scene, spp) is rendered, denoised and scored at each, and the page
    /// gives the mean over seeds with its spread. Pictures and the runtime breakdown use the
    /// first. (`--seed` is the same option.)
    #[arg(long = "seeds", alias = "seed", default_value = "4242", value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// The results page; its PNGs go to a folder beside it named after it (docs/results/).
    #[arg(long, default_value = "docs/results.md")]
    pub out: PathBuf,
    /// Finished measurements, one JSON line each (default: `<PNG folder>/cache.jsonl`). A re-run
    /// skips what it holds; delete it to measure everything again.
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Folder of the denoised images the bounds choose among (EXR, keyed like the cache), so a
    /// resumed run need not denoise again; delete it freely.
    #[arg(long, default_value = "target/eval-images")]
    pub images: PathBuf,
    /// Side of the square image of the runtime breakdown (0: no breakdown).
    #[arg(long, default_value_t = 256)]
    pub breakdown_size: u32,
    /// Scene of the runtime breakdown (default: the first of --scenes).
    #[arg(long)]
    pub breakdown_scene: Option<String>,
    /// Test scenes shown in pictures (noisy / G / P / both / guided / OIDN / reference, error and W_G
    /// maps), or `none` [default: those of cornell-box, glass-still-life that --scenes lists].
    #[arg(long, value_delimiter = ',')]
    pub pictures: Option<Vec<String>>,
    /// Samples per pixel of the pictures.
    #[arg(long, default_value = "2,32", value_delimiter = ',')]
    pub picture_spp: Vec<u32>,
    #[command(flatten)]
    pub infer: InferArgs,
    /// Don't show the progress bar or per-measurement lines.
    #[arg(short, long)]
    pub quiet: bool,
}

/// The spp whose noisy error normalises every other (method.md §7.3).
pub const NORM_SPP: u32 = 2;

/// 1-minute load average (0 where /proc is missing).
pub fn load1() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok())).unwrap_or(0.0)
}

/// Images kept for the pictures of one (scene, spp).
pub struct PictureData {
    pub scene: String,
    pub spp: u32,
    pub width: usize,
    pub height: usize,
    pub reference: Vec<f32>,
    /// (method, radiance, relMSE).
    pub images: Vec<(EvalMethod, Vec<f32>, f64)>,
    /// Weight maps of the methods that blend: (panel label, method name, `[H, W]` map).
    pub weights: Vec<(String, &'static str, Vec<f32>)>,
}

/// What `run` measured, for the report.
pub struct Outcome {
    pub scenes: Vec<TestScene>,
    pub methods: Vec<MethodSpec>,
    /// The block-oracle bounds measured (oracle.rs).
    pub bounds: Vec<BoundSpec>,
    pub records: HashMap<String, Record>,
    pub renders: usize,
    pub measured: usize,
    pub cached: usize,
    pub load_start: f64,
    pub load_end: f64,
    pub load_samples: Vec<f64>,
    pub wall_s: f64,
    pub breakdown_scene: String,
}

impl Outcome {
    pub fn quality(&self, scene: &str, spp: u32, m: &MethodSpec, seed: u64, s: &TestScene) -> Option<&Record> {
        self.records.get(&key("quality", scene, &s.reference_id, spp, m.name(), &m.id, seed, s.width, s.height))
    }
}

pub fn picture_paths(dir: &Path, scene: &str, spp: u32) -> [PathBuf; 3] {
    ["images", "errors", "weights"].map(|k| dir.join(format!("{scene}-{spp}spp-{k}.png")))
}

pub const DEFAULT_PICTURES: [&str; 2] = ["cornell-box", "glass-still-life"];

/// The picture scenes: as given (checked later against the list), or the defaults the list has.
pub fn picture_scenes(a: &EvalArgs, scenes: &[TestScene]) -> Vec<String> {
    match &a.pictures {
        Some(p) => p.iter().map(|s| s.trim().to_string()).filter(|s| !s.is_empty() && s != "none").collect(),
        None => DEFAULT_PICTURES.iter().filter(|d| scenes.iter().any(|s| s.name == **d)).map(|d| d.to_string()).collect(),
    }
}

pub fn png_dir(out: &Path) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "results".into());
    out.with_file_name(stem)
}

pub fn run(a: EvalArgs) -> Result<()> {
    let t0 = Instant::now();
    let load_start = load1();
    if a.spp.is_empty() || a.spp.contains(&0) {
        bail!("--spp: give positive sample counts, e.g. 2,4,8");
    }
    if a.picture_spp.contains(&0) {
        bail!("--picture-spp: give positive sample counts");
    }
    if a.seeds.is_empty() {
        bail!("--seeds: give at least one render seed, e.g. 4242,4243,4244");
    }
    if let Some(d) = a.seeds.iter().enumerate().find_map(|(i, s)| a.seeds[..i].contains(s).then_some(s)) {
        bail!("--seeds: {d} is given twice");
    }
    let seed0 = a.seeds[0];
    let scenes = scenes::scenes(&a.scenes)?;
    let methods = methods::methods(&a)?;
    let bounds = oracle::bounds(&methods);
    let pictures = picture_scenes(&a, &scenes);
    for p in &pictures {
        if !scenes.iter().any(|s| &s.name == p) {
            bail!("--pictures {p}: not a scene of {}", a.scenes.display());
        }
    }
    let breakdown_scene = a.breakdown_scene.clone().unwrap_or_else(|| scenes[0].name.clone());
    let breakdown_idx = scenes
        .iter()
        .position(|s| s.name == breakdown_scene)
        .with_context(|| format!("--breakdown-scene {breakdown_scene}: not a scene of {}", a.scenes.display()))?;
    let dir = png_dir(&a.out);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let cache_path = a.cache.clone().unwrap_or_else(|| dir.join("cache.jsonl"));
    let mut cache = Cache::open(&cache_path)?;
    let store = ImageStore::new(&a.images)?;
    let opts = a.infer.options();
    let device = denoiser::cpu_device();

    // Work list: per (scene, spp, seed) the methods to measure, the bounds to score, and whether
    // pictures are due.
    struct Job {
        scene: usize,
        spp: u32,
        seed: u64,
        todo: Vec<usize>,
        bounds: Vec<usize>,
        picture: bool,
    }
    let avail: Vec<usize> = (0..methods.len()).filter(|&i| methods[i].available()).collect();
    let method_of = |name: &str| methods.iter().position(|m| m.name() == oracle::producer(name));
    // An image a bound needs: the key of its producing method's measurement, and the file.
    let image_path = |s: &TestScene, spp: u32, seed: u64, name: &str| -> Option<PathBuf> {
        let m = &methods[method_of(name)?];
        let k = key("image", &s.name, &s.reference_id, spp, name, &m.id, seed, s.width, s.height);
        Some(store.path(&k, &s.name, spp, seed, name))
    };
    let bound_key = |s: &TestScene, spp: u32, seed: u64, b: &BoundSpec| {
        key("quality", &s.name, &s.reference_id, spp, &b.name, &b.id, seed, s.width, s.height)
    };
    let mut jobs = Vec::new();
    let mut cached = 0usize;
    for (si, s) in scenes.iter().enumerate() {
        let is_pic = pictures.contains(&s.name);
        let mut spps: Vec<u32> =
            a.spp.iter().copied().chain([NORM_SPP]).chain(if is_pic { a.picture_spp.clone() } else { vec![] }).collect();
        spps.sort_unstable();
        spps.dedup();
        for spp in spps {
            for &seed in &a.seeds {
                let in_table = a.spp.contains(&spp);
                let picture = is_pic && a.picture_spp.contains(&spp) && seed == seed0;
                let wanted: Vec<usize> = avail
                    .iter()
                    .copied()
                    .filter(|&i| {
                        let k = methods[i].kind;
                        k == EvalMethod::Noisy || in_table || (picture && PICTURE_METHODS.contains(&k))
                    })
                    .collect();
                let uncached = |i: usize| {
                    cache
                        .get(&key("quality", &s.name, &s.reference_id, spp, methods[i].name(), &methods[i].id, seed, s.width, s.height))
                        .is_none()
                };
                let job_bounds: Vec<usize> = if in_table {
                    (0..bounds.len()).filter(|&b| cache.get(&bound_key(s, spp, seed, &bounds[b])).is_none()).collect()
                } else {
                    Vec::new()
                };
                // A bound to score whose expert image is not stored has its producer measured again.
                let mut need_image = Vec::new();
                for &b in &job_bounds {
                    for e in &bounds[b].experts {
                        if image_path(s, spp, seed, e).is_none_or(|p| !p.exists()) {
                            need_image.extend(method_of(e));
                        }
                    }
                }
                // Pictures are redrawn when a file is missing, or when a picture method is measured
                // anew (new weights, or a method new to the page such as OIDN), whose panel would
                // otherwise be stale or absent.
                let redraw = picture
                    && (picture_paths(&dir, &s.name, spp).iter().any(|p| !p.exists())
                        || wanted.iter().any(|&i| PICTURE_METHODS.contains(&methods[i].kind) && uncached(i)));
                let todo: Vec<usize> = wanted
                    .iter()
                    .copied()
                    .filter(|&i| {
                        // Pictures need the images, which the cache does not keep: every picture
                        // method is measured again for a redraw.
                        (redraw && PICTURE_METHODS.contains(&methods[i].kind)) || uncached(i) || need_image.contains(&i)
                    })
                    .collect();
                cached += wanted.len() - todo.len() + (if in_table { bounds.len() - job_bounds.len() } else { 0 });
                if !todo.is_empty() || !job_bounds.is_empty() {
                    // Every picture method is in `todo` when pictures are drawn, so they are never
                    // drawn from a partial set.
                    jobs.push(Job { scene: si, spp, seed, todo, bounds: job_bounds, picture: redraw });
                }
            }
        }
    }
    // The breakdown: (method, spp) of guided and of the OIDN baseline.
    let mut breakdown_todo = Vec::new();
    if a.breakdown_size > 0 {
        for g in (0..methods.len()).filter(|&i| BREAKDOWN_METHODS.contains(&methods[i].kind) && methods[i].available()) {
            for &spp in &a.spp {
                let k = key(
                    "breakdown",
                    &breakdown_scene,
                    "",
                    spp,
                    methods[g].name(),
                    &methods[g].id,
                    seed0,
                    a.breakdown_size,
                    a.breakdown_size,
                );
                if cache.get(&k).is_none() {
                    breakdown_todo.push((g, spp));
                } else {
                    cached += 1;
                }
            }
        }
    }

    let steps: usize = jobs.iter().map(|j| j.todo.len() + j.bounds.len()).sum::<usize>() + breakdown_todo.len();
    let pb = progress::bar(steps as u64, "eval");
    if a.quiet {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let say = |msg: String| {
        if !a.quiet {
            pb.suspend(|| eprintln!("{msg}"));
        }
    };
    let (mut renders, mut measured) = (0usize, 0usize);
    let mut load_samples = Vec::new();
    // Whether OIDN has had its untimed warm-up run.
    let mut oidn_warm = false;
    let mut loaded_scene: Option<(usize, Scene)> = None;
    let mut reference: Option<(usize, Frame)> = None;
    for job in &jobs {
        let s = &scenes[job.scene];
        if loaded_scene.as_ref().map(|l| l.0) != Some(job.scene) {
            loaded_scene = Some((job.scene, load_scene(s, s.width, s.height)?));
            reference = Some((job.scene, super::denoise::read_reference(&s.reference, s.width, s.height)?));
        }
        let scene = &loaded_scene.as_ref().unwrap().1;
        let refr = &reference.as_ref().unwrap().1.radiance.mean;
        let (w, h) = (s.width as usize, s.height as usize);
        let plain = job.todo.iter().any(|&i| !methods[i].needs_descriptors());
        let with_desc = job.todo.iter().any(|&i| methods[i].needs_descriptors());
        let mut picture = job.picture.then(|| PictureData {
            scene: s.name.clone(),
            spp: job.spp,
            width: w,
            height: h,
            reference: refr.clone(),
            images: Vec::new(),
            weights: Vec::new(),
        });
        // Two renders with the same seed: without descriptors (the input, and the time, of noisy
        // and G) and with them (P, both, guided). Recording descriptors must not change the
        // radiance; checked, since the times of the two groups are only comparable if the
        // images are the same.
        let mut inputs: Vec<(bool, Frame, f64, PreparedImage, f64)> = Vec::new();
        for desc in [false, true] {
            if (desc && !with_desc) || (!desc && !plain) {
                continue;
            }
            pb.set_message(format!("{} {} spp seed {} render", s.name, job.spp, job.seed));
            let (mut frame, render_s) = render(scene, job.spp, job.seed, desc)?;
            renders += 1;
            if let Some((_, first, ..)) = inputs.first() {
                if first.radiance.mean != frame.radiance.mean {
                    bail!("{} at {} spp, seed {}: the render with path descriptors differs from the one without; descriptor recording must not change the samples", s.name, job.spp, job.seed);
                }
            }
            let tp = Instant::now();
            let prepared =
                preprocess::prepare_for_inference(&mut frame).with_context(|| format!("preprocessing {} at {} spp", s.name, job.spp))?;
            let prepare_s = tp.elapsed().as_secs_f64();
            inputs.push((desc, frame, render_s, prepared, prepare_s));
        }
        // This job's images that bounds choose among, by image name.
        let mut kept: HashMap<String, Vec<f32>> = HashMap::new();
        let is_expert = |name: &str| job.bounds.iter().any(|&b| bounds[b].experts.iter().any(|e| e == name));
        for &i in &job.todo {
            let m = &methods[i];
            let (_, frame, render_s, prepared, prepare_s) = inputs.iter().find(|x| x.0 == m.needs_descriptors()).expect("rendered above");
            let mut r = Record {
                kind: "quality".into(),
                scene: s.name.clone(),
                reference: s.reference_id.clone(),
                spp: job.spp,
                method: m.name().to_string(),
                weights: m.id.clone(),
                seed: job.seed,
                width: s.width,
                height: s.height,
                render_s: *render_s,
                ..Default::default()
            };
            let image: Vec<f32>;
            let mut maps: Vec<(String, &'static str, Vec<f32>)> = Vec::new();
            match (&m.oidn, &m.loaded) {
                _ if m.gated.is_some() => {
                    let g = m.gated.as_ref().expect("checked");
                    let set = denoiser::gate::run::Experts { g: g.g.as_ref(), p: g.p.as_ref(), oidn: g.oidn.as_ref() };
                    let td = Instant::now();
                    let outputs = denoiser::gate::run::run_experts_prepared(frame, Some(prepared), g.experts(), &set, &opts, &device)
                        .with_context(|| format!("denoising {} at {} spp with {}", s.name, job.spp, m.name()))?;
                    let (radiance, weights) = denoiser::gate::run::apply(&g.gate, frame, &outputs, &device)?;
                    r.denoise_s = td.elapsed().as_secs_f64();
                    r.prepare_s = *prepare_s;
                    r.time_s = render_s + prepare_s + r.denoise_s;
                    let n = (w * h).max(1);
                    r.mean_w = Some(
                        g.experts()
                            .iter()
                            .enumerate()
                            .map(|(k, e)| {
                                (e.name().to_string(), weights[k * n..(k + 1) * n].iter().map(|&v| v as f64).sum::<f64>() / n as f64)
                            })
                            .collect(),
                    );
                    for (k, e) in g.experts().iter().enumerate() {
                        maps.push((format!("W {e}"), m.name(), weights[k * n..(k + 1) * n].to_vec()));
                    }
                    image = radiance;
                }
                (Some(o), _) => {
                    let d = super::oidn_setup::denoise_timed(o, frame, &mut oidn_warm)
                        .with_context(|| format!("denoising {} at {} spp with OIDN", s.name, job.spp))?;
                    r.denoise_s = d.timings.total_s;
                    r.time_s = render_s + r.denoise_s;
                    image = d.radiance;
                }
                (None, None) => {
                    image = frame.radiance.mean.clone();
                    r.time_s = *render_s;
                }
                (None, Some(l)) => {
                    let td = Instant::now();
                    let d: Denoised = infer::denoise(&l.model, &l.config, prepared, &frame.radiance.mean, &opts, &device)
                        .with_context(|| format!("denoising {} at {} spp with {}", s.name, job.spp, m.name()))?;
                    r.denoise_s = td.elapsed().as_secs_f64();
                    r.prepare_s = *prepare_s;
                    r.time_s = render_s + prepare_s + r.denoise_s;
                    let t = &d.timings;
                    (r.gather_s, r.d_g_s, r.d_p_s, r.e_s, r.readback_s) = (t.gather_s, t.d_g_s, t.d_p_s, t.e_s, t.readback_s);
                    image = d.radiance;
                    r.mean_w = d.weights_g.as_ref().map(methods::mean_weights);
                    if let Some(wg) = d.weights_g {
                        maps.push(("W_G diffuse".into(), m.name(), wg.diffuse));
                        maps.push(("W_G specular".into(), m.name(), wg.specular));
                    }
                }
            }
            let e = metrics::evaluate(&image, refr, w, h, metrics::DEFAULT_BORDER);
            // Every stored image is one a bound of the page may need: a later run with the same
            // weights then scores its bounds without denoising again.
            if bounds.iter().any(|b| b.experts.iter().any(|e| e == m.name())) {
                if let Some(p) = image_path(s, job.spp, job.seed, m.name()) {
                    store.put(&p, w, h, &image)?;
                }
            }
            let keep = is_expert(m.name());
            (r.rel_mse, r.rel_mse_gamma, r.one_minus_ssim) = (e.rel_mse, e.rel_mse_gamma, e.one_minus_ssim);
            r.date = super::train::iso_date_utc();
            r.load1 = load1();
            load_samples.push(r.load1);
            say(format!(
                "{} {:>2} spp {:<14} relMSE {:.5}  1-SSIM {:.5}  {:.2} s",
                s.name,
                job.spp,
                m.name(),
                r.rel_mse,
                r.one_minus_ssim,
                r.time_s
            ));
            if keep {
                kept.insert(m.name().to_string(), image.clone());
            }
            if let Some(p) = picture.as_mut() {
                if PICTURE_METHODS.contains(&m.kind) {
                    p.images.push((m.kind, image, r.rel_mse));
                    p.weights.append(&mut maps);
                }
            }
            cache.put(r)?;
            measured += 1;
            pb.inc(1);
        }
        if let Some(p) = picture {
            pictures::write_pictures(&dir, &p)?;
        }
        for &b in &job.bounds {
            let bound = &bounds[b];
            pb.set_message(format!("{} {} spp seed {} {}", s.name, job.spp, job.seed, bound.name));
            let mut images = Vec::new();
            for e in &bound.experts {
                let img = match kept.remove(e) {
                    Some(v) => v,
                    None => image_path(s, job.spp, job.seed, e)
                        .and_then(|p| store.get(&p, w, h))
                        .with_context(|| format!("{}: no image of {e} for {} at {} spp, seed {}", bound.name, s.name, job.spp, job.seed))?,
                };
                images.push(img);
            }
            let refs: Vec<&[f32]> = images.iter().map(|v| v.as_slice()).collect();
            let o = oracle::block_oracle(&refs, refr, w, h, oracle::BLOCK)?;
            let e = metrics::evaluate(&o.image, refr, w, h, metrics::DEFAULT_BORDER);
            // Put the images back for the next bound over the same experts.
            for (name, img) in bound.experts.iter().zip(images) {
                kept.insert(name.clone(), img);
            }
            let r = Record {
                kind: "quality".into(),
                scene: s.name.clone(),
                reference: s.reference_id.clone(),
                spp: job.spp,
                method: bound.name.clone(),
                weights: bound.id.clone(),
                seed: job.seed,
                width: s.width,
                height: s.height,
                rel_mse: e.rel_mse,
                rel_mse_gamma: e.rel_mse_gamma,
                one_minus_ssim: e.one_minus_ssim,
                mean_w: Some(bound.experts.iter().cloned().zip(o.share).collect()),
                date: super::train::iso_date_utc(),
                load1: load1(),
                ..Default::default()
            };
            say(format!(
                "{} {:>2} spp {:<14} relMSE {:.5}  1-SSIM {:.5}  (bound, uses the reference)",
                s.name, job.spp, bound.name, r.rel_mse, r.one_minus_ssim
            ));
            cache.put(r)?;
            measured += 1;
            pb.inc(1);
        }
    }

    if !breakdown_todo.is_empty() {
        let s = &scenes[breakdown_idx];
        let size = a.breakdown_size;
        let scene = load_scene(s, size, size)?;
        for &(g, spp) in &breakdown_todo {
            let m = &methods[g];
            pb.set_message(format!("breakdown {} {spp} spp", m.name()));
            let (mut frame, render_s) = render(&scene, spp, seed0, m.needs_descriptors())?;
            renders += 1;
            let mut r = Record {
                kind: "breakdown".into(),
                scene: s.name.clone(),
                spp,
                method: m.name().to_string(),
                weights: m.id.clone(),
                seed: seed0,
                width: size,
                height: size,
                render_s,
                ..Default::default()
            };
            if let Some(o) = &m.oidn {
                r.denoise_s = super::oidn_setup::denoise_timed(o, &frame, &mut oidn_warm)?.timings.total_s;
                r.time_s = render_s + r.denoise_s;
                say(format!("breakdown {} {size}² {spp:>2} spp OIDN: render {render_s:.2} s, filter {:.2} s", s.name, r.denoise_s));
            } else {
                let l = m.loaded.as_ref().expect("available");
                let tp = Instant::now();
                let prepared = preprocess::prepare_for_inference(&mut frame)?;
                r.prepare_s = tp.elapsed().as_secs_f64();
                let td = Instant::now();
                let d = infer::denoise(&l.model, &l.config, &prepared, &frame.radiance.mean, &opts, &device)?;
                r.denoise_s = td.elapsed().as_secs_f64();
                r.time_s = render_s + r.prepare_s + r.denoise_s;
                let t = &d.timings;
                (r.gather_s, r.d_g_s, r.d_p_s, r.e_s, r.readback_s) = (t.gather_s, t.d_g_s, t.d_p_s, t.e_s, t.readback_s);
                say(format!(
                    "breakdown {} {size}² {spp:>2} spp: render {:.2} s, preprocess {:.2} s, D_G {:.2} s, D_P {:.2} s, E {:.2} s",
                    s.name, render_s, r.prepare_s, r.d_g_s, r.d_p_s, r.e_s
                ));
            }
            r.date = super::train::iso_date_utc();
            r.load1 = load1();
            load_samples.push(r.load1);
            cache.put(r)?;
            measured += 1;
            pb.inc(1);
        }
    }
    pb.finish_and_clear();

    let outcome = Outcome {
        scenes,
        methods,
        bounds,
        records: cache.map,
        renders,
        measured,
        cached,
        load_start,
        load_end: load1(),
        load_samples,
        wall_s: t0.elapsed().as_secs_f64(),
        breakdown_scene,
    };
    report::write(&a, &outcome, &dir)?;
    println!(
        "eval: {} measured, {} cached, {} renders, {:.1} s; wrote {} and {}",
        outcome.measured,
        outcome.cached,
        outcome.renders,
        outcome.wall_s,
        a.out.display(),
        dir.display()
    );
    Ok(())
}
