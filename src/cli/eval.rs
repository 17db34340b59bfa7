//! `pixguide eval`: the speed-versus-error evaluation of issue #6 — every held-out test scene
//! rendered at each spp, denoised in process by every method, scored against its reference;
//! written to docs/results.md with plots and pictures (eval_report.rs). Resumable through a
//! cache of finished measurements.

use super::denoise::InferArgs;
use super::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::infer::{self, Denoised};
use denoiser::method::Method;
use denoiser::metrics;
use denoiser::oidn::Oidn;
use denoiser::preprocess::{self, PreparedImage};
use denoiser::weights::{self, Loaded};
use renderer::film::{BufferRequest, Frame};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
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
    /// guided, guided-half, fix-n-train, full-n-full, radiance-only, oidn (Intel Open Image
    /// Denoise, the baseline: installed into target/oidn-venv from PyPI the first time, and left
    /// out with one line saying why if that fails).
    #[arg(long, default_value = "noisy,g,p,both,guided,guided-half,fix-n-train,full-n-full,radiance-only,oidn", value_delimiter = ',')]
    pub methods: Vec<String>,
    /// Folder of the weight files (`<method>-default.safetensors`, `guided-half.safetensors`, …:
    /// the names `pixguide train --all` writes).
    #[arg(long, default_value = "denoiser/weights")]
    pub weights_dir: PathBuf,
    /// Render seed of every noisy image.
    #[arg(long, default_value_t = 4242)]
    pub seed: u64,
    /// The results page; its PNGs go to a folder beside it named after it (docs/results/).
    #[arg(long, default_value = "docs/results.md")]
    pub out: PathBuf,
    /// Finished measurements, one JSON line each (default: `<PNG folder>/cache.jsonl`). A re-run
    /// skips what it holds; delete it to measure everything again.
    #[arg(long)]
    pub cache: Option<PathBuf>,
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

/// Methods `eval` knows: name, weight file stem, label in tables and plots.
pub const KNOWN: [(&str, &str, &str); 8] = [
    ("g", "g-default", "D_G (g)"),
    ("p", "p-default", "D_P (p)"),
    ("both", "both-default", "both-buffers"),
    ("guided", "guided-default", "guided"),
    ("guided-half", "guided-half", "guided (half)"),
    ("fix-n-train", "fix-n-train-default", "Fix-N-Train"),
    ("full-n-full", "full-n-full-default", "Full-N-Full"),
    ("radiance-only", "radiance-only-default", "E radiances only"),
];

/// Methods shown in the pictures, in order.
pub const PICTURE_METHODS: [&str; 6] = ["noisy", "g", "p", "both", "guided", "oidn"];

/// Label of the OIDN baseline in tables and plots.
pub const OIDN_LABEL: &str = "OIDN";

/// Methods of the runtime breakdown, in its row order per spp.
pub const BREAKDOWN_METHODS: [&str; 2] = ["guided", "oidn"];

/// The spp whose noisy error normalises every other (method.md §7.3).
pub const NORM_SPP: u32 = 2;

/// One evaluated method.
pub struct MethodSpec {
    pub name: String,
    pub label: String,
    /// Weight file (None for noisy and OIDN).
    pub file: Option<PathBuf>,
    /// Identity of the weights (size and FNV-1a hash of the file), "mc" for noisy, OIDN's
    /// version and settings for OIDN.
    pub id: String,
    pub loaded: Option<Loaded>,
    /// The OIDN baseline's library, loaded once per run.
    pub oidn: Option<Oidn>,
    /// Why the method is not evaluated, e.g. "no denoiser/weights/both-default.safetensors".
    pub missing: Option<String>,
}

impl MethodSpec {
    pub fn available(&self) -> bool {
        self.missing.is_none()
    }
    fn needs_descriptors(&self) -> bool {
        self.loaded.as_ref().is_some_and(|l| l.method.needs_descriptors())
    }
}

pub struct TestScene {
    pub name: String,
    pub path: PathBuf,
    pub reference: PathBuf,
    /// [`file_id`] of the reference: a re-rendered reference (a scene or renderer fix) makes
    /// every cached score of the scene stale.
    pub reference_id: String,
    pub width: u32,
    pub height: u32,
}

/// One finished measurement (a line of the cache).
#[derive(Clone, Debug, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct Record {
    /// "quality" or "breakdown".
    pub kind: String,
    pub scene: String,
    pub spp: u32,
    pub method: String,
    pub weights: String,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    /// [`TestScene::reference_id`] of a quality record's reference ("" for breakdowns, which
    /// measure time only).
    pub reference: String,
    pub rel_mse: f64,
    pub rel_mse_gamma: f64,
    pub one_minus_ssim: f64,
    /// Wall seconds of the render this method's input came from.
    pub render_s: f64,
    /// Preprocessing (method.md §2, §4.1).
    pub prepare_s: f64,
    /// Tiled inference, everything.
    pub denoise_s: f64,
    /// render + preprocessing + inference: the time of the method.
    pub time_s: f64,
    pub gather_s: f64,
    pub d_g_s: f64,
    pub d_p_s: f64,
    pub e_s: f64,
    pub readback_s: f64,
    /// UTC date of the measurement and the 1-minute load average right after it.
    pub date: String,
    pub load1: f64,
}

impl Record {
    fn key(&self) -> String {
        key(&self.kind, &self.scene, &self.reference, self.spp, &self.method, &self.weights, self.seed, self.width, self.height)
    }
}

#[allow(clippy::too_many_arguments)]
fn key(kind: &str, scene: &str, reference: &str, spp: u32, method: &str, weights: &str, seed: u64, w: u32, h: u32) -> String {
    format!("{kind}|{scene}@{reference}|{spp}|{method}|{weights}|{seed}|{w}x{h}")
}

/// 1-minute load average (0 where /proc is missing).
pub fn load1() -> f64 {
    std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok())).unwrap_or(0.0)
}

/// Size and FNV-1a 64 hash of a file: changes whenever the weights do.
fn file_id(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in &bytes {
        h = (h ^ *b as u64).wrapping_mul(0x100_0000_01b3);
    }
    Ok(format!("{}:{h:016x}", bytes.len()))
}

fn methods(a: &EvalArgs) -> Result<Vec<MethodSpec>> {
    let mut names: Vec<String> = vec!["noisy".into()];
    for m in a.methods.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
        if m != "noisy" && m != "oidn" && !KNOWN.iter().any(|k| k.0 == m) {
            bail!("--methods: unknown method `{m}` (expected noisy, {}, oidn)", KNOWN.map(|k| k.0).join(", "));
        }
        if !names.iter().any(|n| n == m) {
            names.push(m.to_string());
        }
    }
    let device = denoiser::cpu_device();
    let mut out = Vec::new();
    for name in names {
        if name == "oidn" {
            let label = OIDN_LABEL.to_string();
            match super::oidn_setup::load() {
                Ok((o, _)) => out.push(MethodSpec { name, label, file: None, id: super::oidn_setup::method_id(&o), loaded: None, oidn: Some(o), missing: None }),
                Err(e) => {
                    // One line, and the run goes on without it: the baseline is optional.
                    eprintln!("eval: leaving out OIDN: {e:#}");
                    out.push(MethodSpec { name, label, file: None, id: String::new(), loaded: None, oidn: None, missing: Some(format!("{e:#}")) });
                }
            }
            continue;
        }
        let Some(&(_, stem, label)) = KNOWN.iter().find(|k| k.0 == name) else {
            out.push(MethodSpec { name, label: "noisy (MC)".into(), file: None, id: "mc".into(), loaded: None, oidn: None, missing: None });
            continue;
        };
        let file = a.weights_dir.join(format!("{stem}.safetensors"));
        if !file.exists() {
            let missing = Some(format!("no {}", file.display()));
            out.push(MethodSpec { name: name.clone(), label: label.into(), file: Some(file), id: String::new(), loaded: None, oidn: None, missing });
            continue;
        }
        let loaded = weights::load(&file, &device).with_context(|| format!("loading the {name} weights"))?;
        let expect = Method::parse(&name).unwrap_or(Method::Guided);
        if loaded.method != expect {
            bail!("{} holds weights of the {} model, but `{name}` needs {expect} weights", file.display(), loaded.method);
        }
        let id = file_id(&file)?;
        out.push(MethodSpec { name, label: label.into(), file: Some(file), id, loaded: Some(loaded), oidn: None, missing: None });
    }
    Ok(out)
}

fn scenes(list: &Path) -> Result<Vec<TestScene>> {
    let text = std::fs::read_to_string(list).with_context(|| format!("reading the scene list {}", list.display()))?;
    let dir = list.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let path = dir.join(line);
        // The scene's name is its folder's (scenes/<name>/scene.toml).
        let name = path.parent().and_then(|p| p.file_name()).map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
        if !path.exists() {
            bail!("{} line {}: scene {} does not exist", list.display(), n + 1, path.display());
        }
        let json = dir.join("references").join(format!("{name}.json"));
        let reference = dir.join("references").join(format!("{name}.exr"));
        if !reference.exists() {
            bail!("no reference for the test scene {name}: {} does not exist (render it with `pixguide reference`)", reference.display());
        }
        let meta: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).with_context(|| format!("reading {}", json.display()))?)
            .with_context(|| format!("parsing {}", json.display()))?;
        let dim = |f: &str| -> Result<u32> {
            meta.get(f).and_then(|v| v.as_u64()).filter(|&v| v > 0 && v < 1 << 16).map(|v| v as u32).with_context(|| format!("{}: field `{f}` is missing or not a positive integer", json.display()))
        };
        let reference_id = file_id(&reference)?;
        out.push(TestScene { name, path, reference, reference_id, width: dim("width")?, height: dim("height")? });
    }
    if out.is_empty() {
        bail!("{} lists no scenes", list.display());
    }
    Ok(out)
}

fn read_cache(path: &Path) -> Result<HashMap<String, Record>> {
    let mut map = HashMap::new();
    let Ok(text) = std::fs::read_to_string(path) else { return Ok(map) };
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        // A line cut short by an interrupted run is skipped: it is measured again.
        match serde_json::from_str::<Record>(line) {
            Ok(r) => {
                map.insert(r.key(), r);
            }
            Err(e) => eprintln!("warning: {} line {}: {e}; ignored", path.display(), n + 1),
        }
    }
    Ok(map)
}

struct Cache {
    map: HashMap<String, Record>,
    file: std::fs::File,
}

impl Cache {
    fn open(path: &Path) -> Result<Cache> {
        super::denoise::ensure_parent(path)?;
        let map = read_cache(path)?;
        let file = std::fs::OpenOptions::new().create(true).append(true).open(path).with_context(|| format!("opening the cache {}", path.display()))?;
        Ok(Cache { map, file })
    }
    fn get(&self, k: &str) -> Option<&Record> {
        self.map.get(k)
    }
    fn put(&mut self, r: Record) -> Result<()> {
        writeln!(self.file, "{}", serde_json::to_string(&r)?)?;
        self.file.flush()?;
        self.map.insert(r.key(), r);
        Ok(())
    }
}

/// Renders `scene` at `spp` with the seed; the G-buffers and the diffuse/specular split always,
/// per-sample descriptors when asked. Returns the frame and its wall seconds.
fn render(scene: &Scene, spp: u32, seed: u64, descriptors: bool) -> Result<(Frame, f64)> {
    let mut opts = RenderOptions::from_scene(scene, BufferRequest { split: true, gbuffers: true, descriptors });
    opts.spp = spp;
    opts.seed = seed;
    let t = Instant::now();
    let (frame, _) = integrator::render(scene, &opts, &|_| {})?;
    Ok((frame, t.elapsed().as_secs_f64()))
}

/// The scene at `w × h`, after one untimed 1-spp render: the first render after loading pays
/// one-off costs (first touch of the scene's fresh memory, waking the thread pool) that would
/// otherwise land on the time of the first spp measured (seen: 0.30 s at 2 spp against 0.07 s
/// at 4 spp).
fn load_scene(s: &TestScene, w: u32, h: u32) -> Result<Scene> {
    let mut scene = Scene::load(&s.path).with_context(|| format!("loading {}", s.path.display()))?;
    scene.camera.width = w;
    scene.camera.height = h;
    render(&scene, 1, 0, false).with_context(|| format!("rendering {}", s.path.display()))?;
    Ok(scene)
}

/// Images kept for the pictures of one (scene, spp).
pub struct PictureData {
    pub scene: String,
    pub spp: u32,
    pub width: usize,
    pub height: usize,
    pub reference: Vec<f32>,
    /// (method name, label, radiance, relMSE).
    pub images: Vec<(String, String, Vec<f32>, f64)>,
    pub weights_g: Option<denoiser::infer::BranchMaps>,
}

/// What `run` measured, for the report.
pub struct Outcome {
    pub scenes: Vec<TestScene>,
    pub methods: Vec<MethodSpec>,
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
        self.records.get(&key("quality", scene, &s.reference_id, spp, &m.name, &m.id, seed, s.width, s.height))
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
    let scenes = scenes(&a.scenes)?;
    let methods = methods(&a)?;
    let pictures = picture_scenes(&a, &scenes);
    for p in &pictures {
        if !scenes.iter().any(|s| &s.name == p) {
            bail!("--pictures {p}: not a scene of {}", a.scenes.display());
        }
    }
    let breakdown_scene = a.breakdown_scene.clone().unwrap_or_else(|| scenes[0].name.clone());
    let breakdown_idx = scenes.iter().position(|s| s.name == breakdown_scene).with_context(|| format!("--breakdown-scene {breakdown_scene}: not a scene of {}", a.scenes.display()))?;
    let dir = png_dir(&a.out);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let cache_path = a.cache.clone().unwrap_or_else(|| dir.join("cache.jsonl"));
    let mut cache = Cache::open(&cache_path)?;
    let opts = a.infer.options();
    let device = denoiser::cpu_device();

    // Work list: per (scene, spp) the methods to measure, and whether pictures are due.
    struct Job {
        scene: usize,
        spp: u32,
        todo: Vec<usize>,
        picture: bool,
    }
    let avail: Vec<usize> = (0..methods.len()).filter(|&i| methods[i].available()).collect();
    let mut jobs = Vec::new();
    let mut cached = 0usize;
    for (si, s) in scenes.iter().enumerate() {
        let is_pic = pictures.contains(&s.name);
        let mut spps: Vec<u32> = a.spp.iter().copied().chain([NORM_SPP]).chain(if is_pic { a.picture_spp.clone() } else { vec![] }).collect();
        spps.sort_unstable();
        spps.dedup();
        for spp in spps {
            let in_table = a.spp.contains(&spp);
            let picture = is_pic && a.picture_spp.contains(&spp);
            let wanted: Vec<usize> = avail
                .iter()
                .copied()
                .filter(|&i| {
                    let n = methods[i].name.as_str();
                    n == "noisy" || in_table || (picture && PICTURE_METHODS.contains(&n))
                })
                .collect();
            let uncached = |i: usize| cache.get(&key("quality", &s.name, &s.reference_id, spp, &methods[i].name, &methods[i].id, a.seed, s.width, s.height)).is_none();
            // Pictures are redrawn when a file is missing, or when a picture method is measured
            // anew (new weights, or a method new to the page such as OIDN), whose panel would
            // otherwise be stale or absent.
            let redraw = picture
                && (picture_paths(&dir, &s.name, spp).iter().any(|p| !p.exists())
                    || wanted.iter().any(|&i| PICTURE_METHODS.contains(&methods[i].name.as_str()) && uncached(i)));
            let todo: Vec<usize> = wanted
                .iter()
                .copied()
                .filter(|&i| {
                    // Pictures need the images, which the cache does not keep: every picture
                    // method is measured again for a redraw.
                    (redraw && PICTURE_METHODS.contains(&methods[i].name.as_str())) || uncached(i)
                })
                .collect();
            cached += wanted.len() - todo.len();
            if !todo.is_empty() {
                // Every picture method is in `todo` when pictures are drawn, so they are never
                // drawn from a partial set.
                jobs.push(Job { scene: si, spp, todo, picture: redraw });
            }
        }
    }
    // The breakdown: (method, spp) of guided and of the OIDN baseline.
    let mut breakdown_todo = Vec::new();
    if a.breakdown_size > 0 {
        for g in (0..methods.len()).filter(|&i| BREAKDOWN_METHODS.contains(&methods[i].name.as_str()) && methods[i].available()) {
            for &spp in &a.spp {
                let k = key("breakdown", &breakdown_scene, "", spp, &methods[g].name, &methods[g].id, a.seed, a.breakdown_size, a.breakdown_size);
                if cache.get(&k).is_none() {
                    breakdown_todo.push((g, spp));
                } else {
                    cached += 1;
                }
            }
        }
    }

    let steps: usize = jobs.iter().map(|j| j.todo.len()).sum::<usize>() + breakdown_todo.len();
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
            weights_g: None,
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
            pb.set_message(format!("{} {} spp render", s.name, job.spp));
            let (mut frame, render_s) = render(scene, job.spp, a.seed, desc)?;
            renders += 1;
            if let Some((_, first, ..)) = inputs.first() {
                if first.radiance.mean != frame.radiance.mean {
                    bail!("{} at {} spp, seed {}: the render with path descriptors differs from the one without; descriptor recording must not change the samples", s.name, job.spp, a.seed);
                }
            }
            let tp = Instant::now();
            let prepared = preprocess::prepare_for_inference(&mut frame).with_context(|| format!("preprocessing {} at {} spp", s.name, job.spp))?;
            let prepare_s = tp.elapsed().as_secs_f64();
            inputs.push((desc, frame, render_s, prepared, prepare_s));
        }
        for &i in &job.todo {
            let m = &methods[i];
            let (_, frame, render_s, prepared, prepare_s) = inputs.iter().find(|x| x.0 == m.needs_descriptors()).expect("rendered above");
            let mut r = Record {
                kind: "quality".into(),
                scene: s.name.clone(),
                reference: s.reference_id.clone(),
                spp: job.spp,
                method: m.name.clone(),
                weights: m.id.clone(),
                seed: a.seed,
                width: s.width,
                height: s.height,
                render_s: *render_s,
                ..Default::default()
            };
            let image: Vec<f32>;
            let mut wg = None;
            match (&m.oidn, &m.loaded) {
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
                        .with_context(|| format!("denoising {} at {} spp with {}", s.name, job.spp, m.name))?;
                    r.denoise_s = td.elapsed().as_secs_f64();
                    r.prepare_s = *prepare_s;
                    r.time_s = render_s + prepare_s + r.denoise_s;
                    let t = &d.timings;
                    (r.gather_s, r.d_g_s, r.d_p_s, r.e_s, r.readback_s) = (t.gather_s, t.d_g_s, t.d_p_s, t.e_s, t.readback_s);
                    image = d.radiance;
                    wg = d.weights_g;
                }
            }
            let e = metrics::evaluate(&image, refr, w, h, metrics::DEFAULT_BORDER);
            (r.rel_mse, r.rel_mse_gamma, r.one_minus_ssim) = (e.rel_mse, e.rel_mse_gamma, e.one_minus_ssim);
            r.date = super::train::iso_date_utc();
            r.load1 = load1();
            load_samples.push(r.load1);
            say(format!(
                "{} {:>2} spp {:<14} relMSE {:.5}  1-SSIM {:.5}  {:.2} s",
                s.name, job.spp, m.name, r.rel_mse, r.one_minus_ssim, r.time_s
            ));
            if let Some(p) = picture.as_mut() {
                if PICTURE_METHODS.contains(&m.name.as_str()) {
                    p.images.push((m.name.clone(), m.label.clone(), image, r.rel_mse));
                    if m.name == "guided" {
                        p.weights_g = wg;
                    }
                }
            }
            cache.put(r)?;
            measured += 1;
            pb.inc(1);
        }
        if let Some(p) = picture {
            super::eval_report::write_pictures(&dir, &p)?;
        }
    }

    if !breakdown_todo.is_empty() {
        let s = &scenes[breakdown_idx];
        let size = a.breakdown_size;
        let scene = load_scene(s, size, size)?;
        for &(g, spp) in &breakdown_todo {
            let m = &methods[g];
            pb.set_message(format!("breakdown {} {spp} spp", m.name));
            let (mut frame, render_s) = render(&scene, spp, a.seed, m.needs_descriptors())?;
            renders += 1;
            let mut r = Record {
                kind: "breakdown".into(),
                scene: s.name.clone(),
                spp,
                method: m.name.clone(),
                weights: m.id.clone(),
                seed: a.seed,
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
                say(format!("breakdown {} {size}² {spp:>2} spp: render {:.2} s, preprocess {:.2} s, D_G {:.2} s, D_P {:.2} s, E {:.2} s", s.name, render_s, r.prepare_s, r.d_g_s, r.d_p_s, r.e_s));
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
    super::eval_report::write(&a, &outcome, &dir)?;
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

