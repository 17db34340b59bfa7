//! `pixguide train-gate`: network E over frozen experts (denoiser::gate). The experts run once on
//! every shot of the dataset (cached beside it, reused by later runs with the same weights), then
//! only E trains; the state with the best validation relMSE is written.

use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::gate::cache::{self, CachedImage};
use denoiser::gate::file::{self as gate_file, GateHeader};
use denoiser::gate::run::Experts;
use denoiser::gate::train::{train, GateTrainOptions, GateValidation};
use denoiser::gate::Expert;
use denoiser::infer::InferOptions;
use denoiser::method::Method;
use denoiser::weights::{self, Provenance};
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub struct TrainGateArgs {
    /// Dataset folder (`pixguide dataset`), ideally shots the experts never trained on (another
    /// --seed): E must learn where each expert fails on new images.
    #[arg(long)]
    pub data: PathBuf,
    /// Experts to blend, comma-separated: g, p, oidn (`g,p` is the guided model; `oidn,g,p`
    /// guided-oidn).
    #[arg(long, value_delimiter = ',', default_value = "g,p")]
    pub experts: Vec<String>,
    /// Output gate file.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Folder of the experts' cached outputs (default: `<data>/gate-cache`).
    #[arg(long)]
    pub cache: Option<PathBuf>,
    /// Weight files of the g and p experts (default: the shipped ones).
    #[arg(long)]
    pub g_weights: Option<PathBuf>,
    #[arg(long)]
    pub p_weights: Option<PathBuf>,
    #[arg(long, default_value_t = 3000)]
    pub steps: usize,
    #[arg(long, default_value_t = 8)]
    pub batch: usize,
    /// Crop side of the training patches.
    #[arg(long, default_value_t = 64)]
    pub crop: usize,
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Validate (whole validation shots) every this many steps.
    #[arg(long, default_value_t = 250)]
    pub val_every: usize,
    /// E's widths per level, full resolution first.
    #[arg(long, value_delimiter = ',', default_value = "16,32,32")]
    pub widths: Vec<usize>,
    /// ε of the loss's relMSE (the results page's is 1e-4).
    #[arg(long, default_value_t = 1e-4)]
    pub eps: f64,
    /// Noise on the logits while training (standard deviation; 0 = none).
    #[arg(long, default_value_t = 0.0)]
    pub logit_noise: f64,
    #[arg(short, long)]
    pub quiet: bool,
}

fn parse_experts(names: &[String]) -> Result<Vec<Expert>> {
    let mut out = Vec::new();
    for n in names {
        let e = Expert::parse(n.trim()).with_context(|| format!("--experts: unknown expert `{n}` (g, p or oidn)"))?;
        if out.contains(&e) {
            bail!("--experts: `{n}` given twice");
        }
        out.push(e);
    }
    if out.len() < 2 {
        bail!("--experts: a gate needs at least two experts");
    }
    Ok(out)
}

/// The experts' identities, as a gate file and the cache record them.
pub fn expert_ids(experts: &[Expert], g: Option<&Path>, p: Option<&Path>, oidn: Option<&denoiser::oidn::Oidn>) -> Result<Vec<String>> {
    experts
        .iter()
        .map(|e| {
            Ok(match e {
                Expert::G => gate_file::file_id(g.context("g weights")?)?,
                Expert::P => gate_file::file_id(p.context("p weights")?)?,
                Expert::Oidn => super::oidn_setup::method_id(oidn.context("OIDN")?),
            })
        })
        .collect()
}

fn weights_path(m: Method, given: &Option<PathBuf>) -> PathBuf {
    given.clone().unwrap_or_else(|| weights::default_path(m))
}

pub fn run(a: TrainGateArgs) -> Result<()> {
    let experts = parse_experts(&a.experts)?;
    let t0 = std::time::Instant::now();
    // Every expert the cache can hold is loaded, so one cache serves g,p and oidn,g,p runs alike.
    let (gp, pp) = (weights_path(Method::G, &a.g_weights), weights_path(Method::P, &a.p_weights));
    let g = super::shared::load_weights(Method::G, Some(&gp))?;
    let p = super::shared::load_weights(Method::P, Some(&pp))?;
    let oidn = match super::oidn_setup::load() {
        Ok((o, _)) => Some(o),
        Err(e) if !experts.contains(&Expert::Oidn) => {
            eprintln!("train-gate: the cache leaves out OIDN: {e:#}");
            None
        }
        Err(e) => return Err(e.context("the oidn expert needs Open Image Denoise")),
    };
    let all: Vec<Expert> = cache::CACHED.into_iter().filter(|e| *e != Expert::Oidn || oidn.is_some()).collect();
    let ids = expert_ids(&all, Some(&gp), Some(&pp), oidn.as_ref())?;
    let ids_key = all.iter().zip(&ids).map(|(e, i)| format!("{e}={i}")).collect::<Vec<_>>().join(";");
    let cache_dir = a.cache.clone().unwrap_or_else(|| a.data.join("gate-cache"));
    let set = Experts { g: Some(&g), p: Some(&p), oidn: oidn.as_ref() };
    let bar = super::progress::bar(0, "experts on every shot");
    if a.quiet {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let shots =
        cache::build(&a.data, &cache_dir, &set, &ids_key, &InferOptions::default(), &denoiser::cpu_device(), &mut |done, total, _| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
    bar.finish_and_clear();
    let cache_s = t0.elapsed().as_secs_f64();
    let images = |split: &str| -> Vec<&CachedImage> { shots.iter().filter(|s| s.split == split).flat_map(|s| &s.images).collect() };
    let (tr, val) = (images("train"), images("val"));
    if tr.is_empty() {
        bail!("{}: no training shots", a.data.display());
    }
    println!(
        "train-gate: experts {} on {} training and {} validation images, cached in {:.0} s ({})",
        experts.iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
        tr.len(),
        val.len(),
        cache_s,
        cache_dir.display()
    );
    let opts = GateTrainOptions {
        experts: experts.clone(),
        widths: a.widths.clone(),
        steps: a.steps,
        batch: a.batch,
        crop: a.crop,
        lr: a.lr,
        seed: a.seed,
        val_every: a.val_every,
        eps: a.eps,
        logit_noise: a.logit_noise,
    };
    let log_path = PathBuf::from(format!("{}.log.jsonl", a.output.display()));
    super::shared::ensure_parent(&a.output)?;
    let mut log = std::io::BufWriter::new(std::fs::File::create(&log_path).with_context(|| format!("creating {}", log_path.display()))?);
    let bar = super::progress::bar(a.steps as u64, "training E");
    if a.quiet {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let t1 = std::time::Instant::now();
    let mut best = f64::INFINITY;
    let mut last = std::time::Instant::now();
    let names: Vec<&str> = experts.iter().map(|e| e.name()).collect();
    let trained = train(&tr, &val, &opts, &mut |step, loss, v: Option<&GateValidation>| {
        bar.set_position(step as u64);
        if step > 0 {
            // Each step's seconds, as `train` logs them, so `pixguide plot-training` reads this log.
            let seconds = last.elapsed().as_secs_f64();
            let _ = writeln!(log, "{}", serde_json::json!({"event": "step", "stage": 0, "step": step, "loss": loss, "seconds": seconds}));
        }
        last = std::time::Instant::now();
        if let Some(v) = v {
            let is_best = v.rel_mse < best;
            best = best.min(v.rel_mse);
            let _ = writeln!(
                log,
                "{}",
                serde_json::json!({"event": "val", "stage": 0, "step": step, "total_step": step, "rel_mse": v.rel_mse,
                    "by_spp": v.by_spp, "best": is_best, "seconds": t1.elapsed().as_secs_f64(),
                    "experts": names, "mean_weights": v.mean_weights, "experts_by_spp": v.experts_by_spp})
            );
            let _ = log.flush();
            bar.suspend(|| print_validation(v, &names));
        }
    })
    .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let provenance = Provenance {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        seed: a.seed,
        dataset: a.data.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
        wall_time_s: t0.elapsed().as_secs_f64(),
        validation_rel_mse: trained.best.rel_mse,
        steps: trained.best.step as u64,
        git_commit: super::shared::git_commit(),
        date: super::shared::iso_date_utc(),
        notes: format!(
            "E over frozen experts; cache {:.0} s, training {:.0} s; best validation at step {} of {}",
            cache_s, trained.seconds, trained.best.step, a.steps
        ),
    };
    let header = GateHeader {
        expert_ids: expert_ids(&experts, Some(&gp), Some(&pp), oidn.as_ref())?,
        experts,
        widths: a.widths.clone(),
        provenance,
    };
    gate_file::save(&a.output, &trained.net, &header)?;
    println!(
        "train-gate: wrote {} (best validation relMSE {:.5} at step {}; {:.0} s in all, {:.0} s of it the cache); log {}",
        a.output.display(),
        trained.best.rel_mse,
        trained.best.step,
        t0.elapsed().as_secs_f64(),
        cache_s,
        log_path.display()
    );
    Ok(())
}

fn print_validation(v: &GateValidation, names: &[&str]) {
    let spp: Vec<String> = v
        .by_spp
        .iter()
        .zip(&v.experts_by_spp)
        .zip(&v.mean_weights)
        .map(|(((s, r), (_, e)), (_, w))| {
            let best = e.iter().cloned().fold(f64::INFINITY, f64::min);
            let ws: Vec<String> = names.iter().zip(w).map(|(n, w)| format!("{n} {w:.2}")).collect();
            format!("{s}spp {:.4} ({:.3}× best expert; W {})", r, r / best, ws.join(" "))
        })
        .collect();
    println!("step {:>5}: val relMSE {:.5} | {}", v.step, v.rel_mse, spp.join(" | "));
}
