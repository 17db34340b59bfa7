//! `pixguide bench-denoise`: the denoisers' cost on one rendered frame, OIDN in the same run.
//!
//! Per sample count it renders the frame once (every buffer the methods read), then runs each
//! model — g, p, guided on the inference engine and on burn, and Open Image Denoise — in turn,
//! `--repeat` rounds in the same order, and prints per model the median seconds, seconds per
//! megapixel, the ratio to OIDN's median, the process's peak resident memory during the run
//! (VmHWM, reset before each run through /proc/self/clear_refs) and above what was resident
//! before it, the counted heap's peak, and a per-stage breakdown with each stage's achieved
//! GMAC/s (denoiser::engine::profile; docs/inference-engine.md explains the counts).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use denoiser::engine::{profile, Isa};
use denoiser::infer::InferOptions;
use denoiser::method::Method;
use denoiser::weights::Loaded;
use renderer::film::{BufferRequest, Frame};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;

use super::shared::{self as dn, Model};

#[derive(Args)]
pub struct BenchDenoiseArgs {
    /// Scene to render.
    #[arg(long, default_value = "scenes/glossy-room/scene.toml")]
    pub scene: PathBuf,
    /// Image size, WIDTHxHEIGHT (e.g. 256x192 for a run of about a minute).
    #[arg(long, default_value = "1024x768", value_parser = crate::cli::bench_mitsuba::parse_size)]
    pub size: (u32, u32),
    /// Samples per pixel, one frame each (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "2,8,64")]
    pub spp: Vec<u32>,
    /// Models to run (comma-separated: g, p, both, guided, oidn).
    #[arg(long, value_delimiter = ',', default_value = "g,p,guided,oidn")]
    pub models: Vec<Model>,
    /// Where the networks run (comma-separated): `engine` (the default of `render` and
    /// `denoise`), `burn` (the training framework's forward), or both for an A/B comparison.
    #[arg(long, value_delimiter = ',', default_value = "engine,burn")]
    pub inference: Vec<dn::Inference>,
    /// Rounds; every model runs once per round, in the same order, and the median is reported.
    #[arg(long, default_value_t = 1)]
    pub repeat: u32,
    /// Render seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instead: time single 3×3 convolutions (layer sizes of the g column) on the engine at each
    /// instruction set and on burn, interleaved, and print GMAC/s and ratios.
    #[arg(long)]
    pub conv: bool,
}

/// One configuration measured: a model, and for our networks where they run.
struct Entry {
    label: String,
    run: Runner,
    secs: Vec<f64>,
    hwm: Vec<(u64, u64)>,
    heap: Vec<usize>,
    stages: Vec<profile::Stage>,
}

enum Runner {
    Net(Box<Loaded>),
    Gated(Box<super::gated::GatedDenoiser>),
    Oidn(denoiser::oidn::Oidn),
}

/// The process's resident set now and its high-water mark, in bytes (/proc/self/status).
fn rss() -> (u64, u64) {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        s.lines().find(|l| l.starts_with(name)).and_then(|l| l.split_whitespace().nth(1)).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0)
            * 1024
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Resets VmHWM to the current resident set (Linux ≥ 4.0); false where that is not possible.
fn reset_hwm() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        f64::NAN
    } else {
        s[s.len() / 2]
    }
}

fn cpu_model() -> String {
    let s = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    s.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|m| m.trim().to_string()).unwrap_or_default()
}

pub fn run(a: BenchDenoiseArgs) -> Result<()> {
    let threads = rayon::current_num_threads();
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!(
        "bench-denoise: {} at {}x{}; CPU {} ({}), {threads} threads; engine ISA {}; load average {}",
        a.scene.display(),
        a.size.0,
        a.size.1,
        cpu_model(),
        Isa::available().iter().map(|i| i.name()).collect::<Vec<_>>().join("/"),
        Isa::detect().name(),
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
    if a.conv {
        return conv_bench(a.repeat.max(3));
    }
    let mut entries = Vec::new();
    for &m in &a.models {
        match m {
            Model::Oidn => match super::oidn_setup::load() {
                Ok((oidn, _)) => entries.push(Entry::new(format!("oidn {}", oidn.version()), Runner::Oidn(oidn))),
                Err(e) => eprintln!("warning: OIDN skipped: {e:#}"),
            },
            Model::Gated(kind) => {
                for &inf in &a.inference {
                    let mut g = super::gated::load(kind, None)?;
                    g.use_inference(&inf);
                    entries.push(Entry::new(format!("{} ({})", kind.name(), inf.name()), Runner::Gated(Box::new(g))));
                }
            }
            Model::Net(method) => {
                for &inf in &a.inference {
                    let mut loaded = dn::load_weights(method, None)?;
                    inf.apply(&mut loaded);
                    entries.push(Entry::new(format!("{method} ({})", inf.name()), Runner::Net(Box::new(loaded))));
                }
            }
        }
    }
    let needs_descriptors = a.models.iter().any(|m| m.needs_descriptors());
    let mut scene = Scene::load(&a.scene)?;
    (scene.camera.width, scene.camera.height) = a.size;
    let mp = a.size.0 as f64 * a.size.1 as f64 / 1e6;
    if !reset_hwm() {
        eprintln!("warning: cannot reset the peak resident set (/proc/self/clear_refs): peaks are over the whole process");
    }
    for &spp in &a.spp {
        let mut opts = RenderOptions::from_scene(&scene, BufferRequest { split: true, gbuffers: true, descriptors: needs_descriptors });
        opts.spp = spp;
        opts.seed = a.seed;
        let t = Instant::now();
        let (frame, _) = integrator::render(&scene, &opts, &|_| {})?;
        println!("\n{spp} spp: rendered in {:.1} s", t.elapsed().as_secs_f64());
        for e in &mut entries {
            e.clear();
        }
        for _ in 0..a.repeat.max(1) {
            for e in &mut entries {
                e.measure(&frame, spp as usize)?;
            }
        }
        report(&entries, mp);
    }
    Ok(())
}

impl Entry {
    fn new(label: String, run: Runner) -> Self {
        Entry { label, run, secs: Vec::new(), hwm: Vec::new(), heap: Vec::new(), stages: Vec::new() }
    }

    fn clear(&mut self) {
        (self.secs, self.hwm, self.heap, self.stages) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    }

    /// One run on a copy of `frame` (inference consumes the descriptors).
    fn measure(&mut self, frame: &Frame, spp: usize) -> Result<()> {
        let mut f = frame.clone();
        let (before, _) = rss();
        reset_hwm();
        let heap0 = crate::alloc_stats::reset_peak();
        match &self.run {
            Runner::Oidn(oidn) => {
                // The first execution on a fresh device pays one-off costs; not a frame's.
                if self.secs.is_empty() {
                    super::oidn_setup::denoise_frame(oidn, &f)?;
                    reset_hwm();
                }
                let t = Instant::now();
                super::oidn_setup::denoise_frame(oidn, &f)?;
                let s = t.elapsed().as_secs_f64();
                self.secs.push(s);
                // OIDN's default network, by the count of docs/method.md §14.
                let px = (f.width * f.height) as f64;
                self.stages = vec![profile::Stage { name: "OIDN (≈125 k MAC/px)".into(), seconds: s, macs: 125e3 * px, calls: 1 }];
            }
            Runner::Net(loaded) => {
                profile::start();
                let t = Instant::now();
                let run = denoiser::infer::denoise_frame(&mut f, loaded, &InferOptions::default(), &denoiser::cpu_device())
                    .with_context(|| format!("denoising with {}", self.label))?;
                let s = t.elapsed().as_secs_f64();
                let mut stages = profile::take();
                let tm = &run.denoised.timings;
                let px = (f.width * f.height) as f64;
                let c = &loaded.config;
                if tm.path_s > 0.0 {
                    stages.push(profile::Stage {
                        name: "path-manifold module".into(),
                        seconds: tm.path_s,
                        macs: 2.0 * c.pathnet.macs_per_pixel(spp) as f64 * px,
                        calls: 1,
                    });
                }
                let e_macs = if loaded.method == Method::Guided { 2.0 * c.ensemble.macs_per_pixel() as f64 * px } else { 0.0 };
                stages.push(profile::Stage { name: "E, blend, recombine".into(), seconds: tm.e_s, macs: e_macs, calls: 1 });
                stages.push(profile::Stage { name: "preprocess".into(), seconds: run.prepare_s, macs: 0.0, calls: 1 });
                let listed: f64 = stages.iter().map(|st| st.seconds).sum();
                stages.push(profile::Stage {
                    name: "other (tiling, readback, …)".into(),
                    seconds: (s - listed).max(0.0),
                    macs: 0.0,
                    calls: 1,
                });
                self.secs.push(s);
                self.stages = stages;
            }
            Runner::Gated(g) => {
                profile::start();
                let t = Instant::now();
                let run = g.run(&mut f, &InferOptions::default()).with_context(|| format!("denoising with {}", self.label))?;
                let s = t.elapsed().as_secs_f64();
                let mut stages = profile::take();
                for (e, secs) in g.experts().iter().zip(&run.expert_seconds) {
                    stages.push(profile::Stage { name: format!("expert {} (whole)", e.name()), seconds: *secs, macs: 0.0, calls: 1 });
                }
                let px = (f.width * f.height) as f64;
                let e_macs = g.gate.config.macs_per_pixel() * px;
                stages.push(profile::Stage { name: "E (features, net, blend)".into(), seconds: run.gate_s, macs: e_macs, calls: 1 });
                stages.push(profile::Stage { name: "preprocess".into(), seconds: run.prepare_s, macs: 0.0, calls: 1 });
                self.secs.push(s);
                self.stages = stages;
            }
        }
        let (_, hwm) = rss();
        self.hwm.push((hwm, hwm.saturating_sub(before)));
        self.heap.push(crate::alloc_stats::peak().saturating_sub(heap0));
        Ok(())
    }
}

fn report(entries: &[Entry], mp: f64) {
    let oidn = entries.iter().find(|e| matches!(e.run, Runner::Oidn(_))).map(|e| median(&e.secs));
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    println!("{:<18} {:>8} {:>8} {:>8} {:>10} {:>12} {:>10}", "model", "time [s]", "s/MP", "× OIDN", "VmHWM MiB", "+above MiB", "heap MiB");
    for e in entries {
        let t = median(&e.secs);
        let ratio = oidn.map_or("-".to_string(), |o| format!("{:.1}", t / o));
        let (hwm, above) = e.hwm.iter().fold((0, 0), |(a, b), &(h, x)| (a.max(h), b.max(x)));
        let heap = e.heap.iter().max().copied().unwrap_or(0);
        println!(
            "{:<18} {:>8.2} {:>8.2} {:>8} {:>10.0} {:>12.0} {:>10.0}",
            e.label,
            t,
            t / mp,
            ratio,
            mib(hwm),
            mib(above),
            mib(heap as u64)
        );
    }
    println!("stages (last round):");
    for e in entries {
        let total: f64 = e.stages.iter().map(|s| s.seconds).sum::<f64>().max(1e-9);
        for s in &e.stages {
            let rate = if s.macs > 0.0 && s.seconds > 0.0 { format!("{:.1} GMAC/s", s.macs / s.seconds / 1e9) } else { "-".into() };
            println!(
                "  {:<18} {:<28} {:>7.3} s {:>5.1} % {:>9.2} GMAC {:>14}",
                e.label,
                s.name,
                s.seconds,
                100.0 * s.seconds / total,
                s.macs / 1e9,
                rate
            );
        }
    }
}

/// Single 3×3 convolutions with bias and ReLU on random data: the engine at each instruction set
/// against burn's conv2d, each layer's implementations run in turn `repeat` times, medians.
fn conv_bench(repeat: u32) -> Result<()> {
    use burn::tensor::{Tensor, TensorData};
    use denoiser::engine::{conv, ConvWeights, Planes};
    let d = denoiser::cpu_device();
    // (height, width, in, out): g's level-0 block and decoder input, level 2, the bottleneck.
    let layers = [(384, 512, 24, 24), (384, 512, 56, 24), (96, 128, 112, 48), (24, 32, 80, 80)];
    println!("{:<22} {:>10} {:>10} {:>10}", "layer h×w cin→cout", "impl", "GMAC/s", "× burn");
    for (h, w, cin, cout) in layers {
        let mut rng = denoiser::rng::SplitMix64::new(1);
        let mut r = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.symmetric(1.0)).collect() };
        let (x, wt, b) = (r(cin * h * w), r(cout * cin * 9), r(cout));
        let macs = (h * w * cin * cout * 9) as f64;
        let xt = Tensor::<4>::from_data(TensorData::new(x.clone(), [1, cin, h, w]), &d);
        let wtt = Tensor::<4>::from_data(TensorData::new(wt.clone(), [cout, cin, 3, 3]), &d);
        let bt = Tensor::<1>::from_data(TensorData::new(b.clone(), [cout]), &d);
        let planes = Planes::from_planar(&x, cin, h, w);
        let cw = ConvWeights::new(&wt, &b, cout, cin, 3);
        let isas = Isa::available();
        let mut times = vec![Vec::new(); isas.len() + 1];
        for _ in 0..repeat {
            for (i, &isa) in isas.iter().enumerate() {
                let t = Instant::now();
                std::hint::black_box(conv(isa, &[&planes], &cw, true));
                times[i].push(t.elapsed().as_secs_f64());
            }
            let t = Instant::now();
            let y = burn::tensor::module::conv2d(
                xt.clone(),
                wtt.clone(),
                Some(bt.clone()),
                burn::tensor::ops::ConvOptions::new([1, 1], [1, 1], [1, 1], 1),
            );
            let y = burn::tensor::activation::relu(y).into_data();
            std::hint::black_box(y);
            times[isas.len()].push(t.elapsed().as_secs_f64());
        }
        let burn_t = median(&times[isas.len()]);
        let names: Vec<&str> = isas.iter().map(|i| i.name()).chain(["burn"]).collect();
        for (name, t) in names.iter().zip(&times) {
            let m = median(t);
            println!("{:<22} {:>10} {:>10.1} {:>10.2}", format!("{h}×{w} {cin}→{cout}"), name, macs / m / 1e9, burn_t / m);
        }
    }
    Ok(())
}
