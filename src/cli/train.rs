//! `pixguide train`: trains one denoiser (G, P, both, guided, or a guided ablation) on a
//! `pixguide dataset` folder with the staged schedule of method.md §3/§6.2; resumable.

use super::progress;
use super::train_log::{rounded, LogLine};
// `eval` names these by this module's path; they live in `shared`.
pub use super::shared::{git_commit, iso_date_utc};
use crate::{alloc_stats, malloc_release};
use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::method::Method;
use denoiser::model::{DenoiserConfig, Preset};
use denoiser::train::data::{Dataset, LoadOptions};
use denoiser::train::patches::Sampling;
use denoiser::train::schedule::{self, Ablation, BranchLoss, FinetuneLoss, LossScale, LrShape, ScheduleOptions};
use denoiser::train::{self as tr, Event, TrainOptions};
use denoiser::weights::{self, Provenance};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// `--lr-schedule`: the shape of the rate within a stage (`LrShape`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LrSchedule {
    Cosine,
    Constant,
}

#[derive(Args, Clone)]
pub struct TrainArgs {
    /// Dataset folder written by `pixguide dataset` (shots.jsonl, train/, val/).
    #[arg(long)]
    pub data: PathBuf,
    /// The method to train.
    #[arg(long, default_value = "g")]
    pub method: Method,
    /// Guided ablation: full-n-full (from scratch), fix-n-train (only E trains),
    /// radiance-only (E sees only I_G, I_P).
    #[arg(long)]
    pub ablation: Option<Ablation>,
    /// Trained G model (weights file) the guided model starts from; with --method g, the model
    /// this run continues from (warm start: new stages, fresh optimiser).
    #[arg(long)]
    pub from_g: Option<PathBuf>,
    /// Trained P model the guided model starts from; with --method p, the warm start.
    #[arg(long)]
    pub from_p: Option<PathBuf>,
    /// With --method both, the both-buffers model this run continues from (warm start).
    #[arg(long, conflicts_with_all = ["from_g", "from_p"])]
    pub from_both: Option<PathBuf>,
    /// With --method guided, the trained guided model this run continues from (warm start,
    /// E included): e.g. `--joint-steps 0 --guided-finetune-steps N` finetunes it.
    #[arg(long, conflicts_with_all = ["from_g", "from_p", "from_both"])]
    pub from_guided: Option<PathBuf>,
    /// Network sizes: default (multi-scale kernel-predicting U-Net columns), half (50 % of
    /// default's channels), swap (default with the patented low-band-swap compositor at five
    /// scales, opt-in), edge (default at five scales with edge-stopping kernels and
    /// joint-bilateral upsampling), edge-noise (edge with the colour's differences measured in
    /// units of its noise), kpcn (the CPU-sized KPCN), paper-half (50 % of the paper's) or
    /// paper.
    #[arg(long, default_value = "default")]
    pub preset: Preset,
    /// Channel widths of the U-Net columns' levels, from full resolution down, in place of the
    /// preset's (as many levels as it has: 24,32,48,64,80 for the U-Net presets). The weight
    /// file records them, so inference needs no option.
    #[arg(long, value_delimiter = ',', conflicts_with = "all")]
    pub widths: Option<Vec<usize>>,
    /// D_P's level widths where they differ from the other columns' (--widths or the preset's):
    /// a guided model joining a D_G trained wider than its D_P. The P model it starts from
    /// (--from-p) must have these widths.
    #[arg(long, value_delimiter = ',', conflicts_with = "all")]
    pub p_widths: Option<Vec<usize>>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output weights (safetensors). A log `<output>.log.jsonl` is written next to it.
    #[arg(short, long, required_unless_present = "all")]
    pub output: Option<PathBuf>,
    /// Train the whole comparison in sequence into --out-dir: g, p, both, guided, fix-n-train,
    /// radiance-only, full-n-full, then g/p/guided at the half preset. Finished models are
    /// skipped, so rerunning continues; --minutes is then the budget of the whole plan.
    #[arg(long, conflicts_with_all = ["output", "method", "ablation", "from_g", "from_p", "preset"])]
    pub all: bool,
    /// Multiply every step count of the --all plan (e.g. 0.01 for a smoke test).
    #[arg(long, default_value_t = 1.0)]
    pub all_scale: f64,
    /// Folder of the --all weights (`<variant>-<preset>.safetensors`).
    #[arg(long, default_value = "denoiser/weights")]
    pub out_dir: PathBuf,
    /// Checkpoint folder (default `<output>.ckpt`).
    #[arg(long)]
    pub checkpoint_dir: Option<PathBuf>,
    /// Continue from the checkpoint folder if it holds a run with the same options.
    #[arg(long)]
    pub resume: bool,
    /// Input patch side in pixels (the output is smaller by twice the model margin).
    #[arg(long, default_value_t = 96)]
    pub patch: usize,
    /// Patches per step (the default 2×96² feeds as many pixels as 4×64² and lets the coarsest
    /// of the U-Net's five kernel scales see 6×6 px instead of 4×4).
    #[arg(long, default_value_t = 2)]
    pub batch: usize,
    /// Sample counts to train on (default: every noisy_<S>spp.exr of the dataset).
    #[arg(long, value_delimiter = ',')]
    pub spp: Vec<usize>,
    /// Patch corners: importance (method.md §7.2 map) or uniform.
    #[arg(long, value_enum, default_value_t = Sampling::Importance)]
    pub sampling: Sampling,
    /// Steps of the per-branch stage (G, P, both).
    #[arg(long)]
    pub branch_steps: Option<usize>,
    /// Steps of the total-radiance finetune stage (G, P, both).
    #[arg(long)]
    pub finetune_steps: Option<usize>,
    /// Steps of the joint stage (guided, fix-n-train, radiance-only).
    #[arg(long)]
    pub joint_steps: Option<usize>,
    /// Steps of full-n-full (guided from scratch).
    #[arg(long)]
    pub scratch_steps: Option<usize>,
    /// Guided and radiance-only: steps of a finetune of the whole model after the joint stage,
    /// with --finetune-loss at --lr-finetune on the blended radiance [default: 0, the paper's
    /// schedule]. With --joint-steps 0 and --from-guided it finetunes a trained guided model.
    #[arg(long)]
    pub guided_finetune_steps: Option<usize>,
    /// Peak rate of the per-branch stage [default: the backbone's measured peak: 1e-3 for
    /// the U-Net presets, the paper's 1e-4 for KPCN ones]. Joint and from-scratch rates follow
    /// the backbone too (docs/journal/training.md, "Learning rate").
    #[arg(long)]
    pub lr_branches: Option<f64>,
    #[arg(long)]
    pub lr_finetune: Option<f64>,
    /// Loss of the finetune stage: linear (the paper's L1 on radiance) or tonemapped (L1 after
    /// the evaluation's tone map) [default: tonemapped for the U-Net presets, linear for KPCN
    /// ones].
    #[arg(long, value_enum)]
    pub finetune_loss: Option<FinetuneLoss>,
    /// How the branch and joint losses weigh each patch: absolute (the paper's L1) or
    /// relative-to-input (each patch's L1 divided by its noisy input's, so every sample count
    /// counts alike) or relative-to-sqrt-input (divided by the square root of it: in between);
    /// docs/journal/denoiser.md, "A loss relative to the input". relative-l2: not an L1 but the squared
    /// error over the output's square + 0.01 (Noise2Noise's relMSE loss; docs/denoiser.md, "A
    /// relative L2 loss").
    #[arg(long, value_enum, default_value_t = LossScale::Absolute)]
    pub loss_scale: LossScale,
    /// Weight of a relative L2 term (Noise2Noise's relMSE loss) added to the branch and joint
    /// losses of any --loss-scale: it pulls sparse inputs towards the mean, where L1 keeps the
    /// darker median (docs/journal/denoiser.md, "L1 plus a relative L2 term"). 0 = not computed.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub rel_l2_weight: f64,
    /// Add the relative L2 term to each patch's L1 before a relative --loss-scale divides it by
    /// the input's error, so that it too weighs every sample count alike (without this flag it
    /// is added after, unscaled, and the 2-spp patches rule it).
    #[arg(long, requires = "rel_l2_weight")]
    pub rel_l2_inside: bool,
    /// Learning rate of E in the joint stage.
    #[arg(long)]
    pub lr_joint_e: Option<f64>,
    /// Learning rate of D_G, D_P and the PathNets in the joint stage.
    #[arg(long)]
    pub lr_joint_rest: Option<f64>,
    #[arg(long)]
    pub lr_scratch: Option<f64>,
    /// Learning-rate shape within each stage: cosine (linear warm-up over --warmup of the
    /// stage's steps from 1/10 of the rate, then cosine decay to 1/50) or constant (the paper's).
    #[arg(long, value_enum, default_value_t = LrSchedule::Cosine)]
    pub lr_schedule: LrSchedule,
    /// Warm-up fraction of each stage's steps (with --lr-schedule cosine).
    #[arg(long, default_value_t = 0.05)]
    pub warmup: f64,
    /// Train on unmoved patches (no random flips and rotations).
    #[arg(long)]
    pub no_augment: bool,
    /// Validate every N steps (0 = once per epoch).
    #[arg(long, default_value_t = 0)]
    pub val_every: usize,
    /// Stop a stage after this many validations without improvement.
    #[arg(long)]
    pub patience: Option<usize>,
    #[arg(long, default_value_t = 100)]
    pub checkpoint_every: usize,
    /// Wall-clock budget of this run in minutes (split over the stages by their steps).
    #[arg(long)]
    pub minutes: Option<f64>,
    /// End this session after N steps with a checkpoint (continue later with --resume).
    #[arg(long)]
    pub stop_after: Option<usize>,
    /// End this session after M minutes of wall time with a checkpoint, without cutting the
    /// run short (continue later with --resume): a run planned over several sessions. Unlike
    /// --minutes, which fits the whole run into a budget, the planned steps still run.
    #[arg(long)]
    pub session_minutes: Option<f64>,
    /// Use at most this many training shots.
    #[arg(long)]
    pub max_train_shots: Option<usize>,
    #[arg(short, long)]
    pub quiet: bool,
    /// Backend of the training steps: flex (pure Rust, CPU; always built), tch (LibTorch on the
    /// CPU) or tch-cuda (LibTorch on CUDA GPU 0), both with `--features tch`; cuda (burn's CUDA
    /// backend, `--features cuda`) or wgpu (`--features wgpu`). See docs/training-tch.md. Same
    /// model code and weight files on all.
    #[arg(long, value_enum, default_value_t = denoiser::Backend::Flex)]
    pub backend: denoiser::Backend,
}

/// The `--backend` choice, or an error naming the cargo feature a missing backend needs.
fn backend(a: &TrainArgs) -> Result<denoiser::Backend> {
    let b = a.backend;
    b.device().map_err(|e| anyhow::anyhow!("--backend {}: {e}", a.backend))?;
    Ok(b)
}

fn schedule_options(a: &TrainArgs, config: &DenoiserConfig) -> ScheduleOptions {
    let mut o = ScheduleOptions::for_config(config);
    let set = |dst: &mut usize, v: Option<usize>| {
        if let Some(v) = v {
            *dst = v
        }
    };
    set(&mut o.branch_steps, a.branch_steps);
    set(&mut o.finetune_steps, a.finetune_steps);
    set(&mut o.joint_steps, a.joint_steps);
    set(&mut o.scratch_steps, a.scratch_steps);
    set(&mut o.guided_finetune_steps, a.guided_finetune_steps);
    let setf = |dst: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *dst = v
        }
    };
    setf(&mut o.lr_branches, a.lr_branches);
    setf(&mut o.lr_finetune, a.lr_finetune);
    setf(&mut o.lr_joint_e, a.lr_joint_e);
    setf(&mut o.lr_joint_rest, a.lr_joint_rest);
    setf(&mut o.lr_scratch, a.lr_scratch);
    if let Some(l) = a.finetune_loss {
        o.finetune_loss = l;
    }
    o.loss = BranchLoss { loss_scale: a.loss_scale, rel_l2_weight: a.rel_l2_weight, rel_l2_inside: a.rel_l2_inside };
    o.lr_shape = match a.lr_schedule {
        LrSchedule::Constant => LrShape::Constant,
        LrSchedule::Cosine => LrShape::WarmupCosine { warmup: a.warmup },
    };
    o
}

/// The preset's config with its U-Net columns' level widths replaced by `widths` and D_P's by
/// `p_widths` (each if given).
fn with_widths(mut config: DenoiserConfig, widths: Option<&[usize]>, p_widths: Option<&[usize]>) -> Result<DenoiserConfig> {
    for (flag, given) in [("--widths", widths), ("--p-widths", p_widths)] {
        let Some(given) = given else { continue };
        let Some(mskp) = config.mskp.as_mut() else { bail!("{flag}: this preset has KPCN columns, not U-Net ones") };
        if given.len() != mskp.widths.len() || given.contains(&0) {
            bail!("{flag} {given:?}: expected {} positive widths (the preset's are {:?})", mskp.widths.len(), mskp.widths);
        }
        if flag == "--widths" {
            mskp.widths = given.to_vec();
        } else {
            config.p_widths = Some(given.to_vec());
        }
    }
    Ok(config)
}

/// One run of the --all plan: variant, method, ablation, preset, its stage lengths
/// (branch, finetune, joint-or-scratch steps) and the estimated seconds per step on this
/// machine without other load (docs/training.md), which sets its share of a --minutes budget.
struct PlanItem {
    method: Method,
    ablation: Option<Ablation>,
    preset: Preset,
    steps: [usize; 3],
    secs_per_step: f64,
}

const fn item(method: Method, ablation: Option<Ablation>, preset: Preset, steps: [usize; 3], secs_per_step: f64) -> PlanItem {
    PlanItem { method, ablation, preset, steps, secs_per_step }
}

/// The runs of 2026-11-25 (docs/journal/denoiser.md, "The swap models"): step counts that fill
/// ≈ 30–36 min per pretraining run and ≈ 16 min per joint run at the seconds per step measured
/// there (one thread each, two runs side by side, patch 96, batch 2); g ends with the
/// tone-mapped finetune. both keeps its earlier count: no both run of the current U-Net has
/// trained stably yet (docs/training.md). ≈ 3 h for the whole plan.
const PLAN: [PlanItem; 10] = [
    item(Method::G, None, Preset::Default, [2900, 400, 0], 0.63),
    item(Method::P, None, Preset::Default, [600, 0, 0], 3.4),
    item(Method::Both, None, Preset::Default, [250, 0, 0], 3.5),
    item(Method::Guided, None, Preset::Default, [0, 0, 200], 4.5),
    item(Method::Guided, Some(Ablation::FixNTrain), Preset::Default, [0, 0, 200], 1.5),
    item(Method::Guided, Some(Ablation::RadianceOnly), Preset::Default, [0, 0, 200], 4.5),
    item(Method::Guided, Some(Ablation::FullNFull), Preset::Default, [0, 0, 400], 5.0),
    // The half models get their default twins' step counts, so the sizes differ only in width.
    item(Method::G, None, Preset::Half, [2900, 400, 0], 0.45),
    item(Method::P, None, Preset::Half, [600, 0, 0], 2.5),
    item(Method::Guided, None, Preset::Half, [0, 0, 200], 3.5),
];

fn run_all(a: TrainArgs) -> Result<()> {
    let scaled = |n: usize| if n == 0 { 0 } else { ((n as f64 * a.all_scale).round() as usize).max(1) };
    let steps = |it: &PlanItem| -> usize { it.steps.iter().map(|&n| scaled(n)).sum() };
    let weight: Vec<f64> = PLAN.iter().map(|it| it.secs_per_step * steps(it) as f64).collect();
    println!(
        "plan: {} runs, {:.0} steps, estimated {:.0} min without other load",
        PLAN.len(),
        PLAN.iter().map(|it| steps(it) as f64).sum::<f64>(),
        weight.iter().sum::<f64>() / 60.0
    );
    let path = |method: Method, ablation: Option<Ablation>, preset: Preset| {
        a.out_dir.join(format!("{}.safetensors", weights::file_stem(method, ablation, preset)))
    };
    let start = Instant::now();
    let mut cache = DataCache::new();
    for (k, it) in PLAN.iter().enumerate() {
        let out = path(it.method, it.ablation, it.preset);
        if out.exists() {
            println!("[{}/{}] {} exists, skipped", k + 1, PLAN.len(), out.display());
            continue;
        }
        let mut r = a.clone();
        r.all = false;
        r.output = Some(out);
        r.method = it.method;
        r.ablation = it.ablation;
        r.preset = it.preset;
        r.checkpoint_dir = None;
        let [b, f, j] = it.steps.map(scaled);
        r.branch_steps = Some(b);
        r.finetune_steps = Some(f);
        r.joint_steps = Some(j);
        r.scratch_steps = Some(j);
        r.resume = true;
        if it.method == Method::Guided && it.ablation != Some(Ablation::FullNFull) {
            r.from_g = Some(path(Method::G, None, it.preset));
            r.from_p = Some(path(Method::P, None, it.preset));
        }
        // Each run's share of the whole budget, in proportion to its expected cost; whatever
        // earlier runs left unused goes to the later ones.
        if let Some(total) = a.minutes {
            let left = total - start.elapsed().as_secs_f64() / 60.0;
            let share: f64 = weight[k] / weight[k..].iter().sum::<f64>();
            r.minutes = Some((left * share).max(0.5));
        }
        println!(
            "[{}/{}] {} ({}){}",
            k + 1,
            PLAN.len(),
            it.ablation.map_or(it.method.name(), |ab| ab.name()),
            it.preset,
            r.minutes.map(|m| format!(", budget {m:.1} min")).unwrap_or_default()
        );
        run_one(r, &mut cache)?;
    }
    println!("plan done in {:.1} min", start.elapsed().as_secs_f64() / 60.0);
    Ok(())
}

pub fn run(a: TrainArgs) -> Result<()> {
    // Before the dataset is read: a backend this build lacks fails at once.
    backend(&a)?;
    if a.all {
        return run_all(a);
    }
    run_one(a, &mut DataCache::new())
}

/// How often a run hands its allocator's free pages back to the system, besides after loading
/// and each validation: jemalloc without decay (the campaign's fastest allocator) otherwise grew
/// each process by 0.7 GB a minute; refaulting one step's tensors every half minute costs little.
const RELEASE_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

/// Reads the training set `a.data` (with or without path descriptors) with a progress bar and
/// reports its size.
fn load_dataset(a: &TrainArgs, descriptors: bool, sampling: Sampling) -> Result<Dataset> {
    let t_load = Instant::now();
    let heap0 = alloc_stats::current();
    let load = LoadOptions { spps: a.spp.clone(), descriptors, patch: a.patch, sampling, max_train: a.max_train_shots };
    let lpb = progress::bar(0, "loading shots");
    if a.quiet {
        lpb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let data = Dataset::load(&a.data, &load, &mut |i, n| {
        lpb.set_length(n as u64);
        lpb.set_position(i as u64);
    })?;
    lpb.finish_and_clear();
    malloc_release::release();
    eprintln!(
        "{}: {} train + {} val shots {}×{} at {:?} spp loaded in {:.1} s ({:.0} MiB prepared, heap +{:.0} MiB)",
        a.data.display(),
        data.train.len(),
        data.val.len(),
        data.width,
        data.height,
        data.spps,
        t_load.elapsed().as_secs_f64(),
        data.bytes() as f64 / (1 << 20) as f64,
        (alloc_stats::current().saturating_sub(heap0)) as f64 / (1 << 20) as f64
    );
    Ok(data)
}

/// Datasets already read in this process, by whether they hold path descriptors: `--all` reads
/// each kind once for all its runs instead of once per run (20–43 s each).
type DataCache = Vec<(bool, Dataset)>;

fn run_one(a: TrainArgs, cache: &mut DataCache) -> Result<()> {
    let output = a.output.clone().context("--output is required")?;
    let (mut method, ablation) = (a.method, a.ablation);
    if ablation.is_some() {
        // g is the default: `--ablation X` alone means the guided method.
        if method != Method::Guided && method != Method::G {
            bail!("--ablation applies to the guided method");
        }
        method = Method::Guided;
    }
    let config = with_widths(a.preset.config(), a.widths.as_deref(), a.p_widths.as_deref())?;
    if !(0.0..1.0).contains(&a.warmup) {
        bail!("--warmup {}: expected a fraction in [0, 1)", a.warmup);
    }
    if a.rel_l2_inside && a.loss_scale.input_power().is_none() {
        bail!("--rel-l2-inside needs a --loss-scale relative to the input (it is {})", a.loss_scale);
    }
    let sampling = a.sampling;
    let stages = schedule::plan(method, ablation, &schedule_options(&a, &config));
    let name = match ablation {
        Some(ab) => ab.name().to_string(),
        None => method.name().to_string(),
    };
    let command: Vec<String> = std::env::args().collect();
    let mut metadata = BTreeMap::new();
    metadata.insert("method".to_string(), method.name().to_string());
    metadata.insert("variant".to_string(), name.clone());
    metadata.insert("preset".to_string(), a.preset.to_string());
    metadata.insert("config".to_string(), serde_json::to_string(&config)?);
    metadata.insert("seed".to_string(), a.seed.to_string());
    metadata.insert("dataset".to_string(), a.data.display().to_string());
    metadata.insert("command".to_string(), command.join(" "));
    let backend = backend(&a)?;
    metadata.insert("backend".to_string(), backend.name().to_string());
    let opts = TrainOptions {
        backend,
        method,
        ablation,
        config,
        seed: a.seed,
        patch: a.patch,
        batch: a.batch,
        stages,
        augment: !a.no_augment,
        val_every: a.val_every,
        val_batch: 8,
        patience: a.patience,
        checkpoint_every: a.checkpoint_every,
        minutes: a.minutes,
        pause_after: a.stop_after,
        pause_after_minutes: a.session_minutes,
        metadata: metadata.clone(),
    };

    let device = backend.training_device().map_err(anyhow::Error::msg)?;
    let model = match (&a.from_both, &a.from_guided) {
        (Some(f), _) if method == Method::Both => tr::warm_start(&opts, f, &device)?,
        (Some(_), _) => bail!("--from-both goes with --method both"),
        (_, Some(f)) if method == Method::Guided => tr::warm_start(&opts, f, &device)?,
        (_, Some(_)) => bail!("--from-guided goes with --method guided"),
        (None, None) => tr::initial_model(&opts, a.from_g.as_deref(), a.from_p.as_deref(), &device)?,
    };
    let descriptors = method.needs_descriptors();
    let k = match cache.iter().position(|c| c.0 == descriptors) {
        Some(k) => k,
        None => {
            cache.push((descriptors, load_dataset(&a, descriptors, sampling)?));
            cache.len() - 1
        }
    };
    let data = &cache[k].1;
    let data_mib = data.bytes() as f64 / (1 << 20) as f64;

    let ckpt = a.checkpoint_dir.clone().unwrap_or_else(|| tr::default_checkpoint_dir(&output));
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let log_path = {
        let mut s = output.as_os_str().to_owned();
        s.push(".log.jsonl");
        PathBuf::from(s)
    };
    let mut log =
        std::fs::OpenOptions::new().create(true).append(true).open(&log_path).with_context(|| format!("opening {}", log_path.display()))?;
    let total: usize = opts.stages.iter().map(|s| s.steps).sum();
    let pb = progress::bar(total as u64, &format!("train {name}"));
    pb.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} {msg} ETA {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    pb.set_prefix(format!("train {name}"));
    if a.quiet {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let stage_offsets: Vec<usize> = opts
        .stages
        .iter()
        .scan(0, |acc, s| {
            let o = *acc;
            *acc += s.steps;
            Some(o)
        })
        .collect();
    let heap_peak0 = alloc_stats::reset_peak();
    let (mut ema, mut rate, mut last_val) = (None::<f64>, None::<f64>, None::<f64>);
    let mut stage_time: Vec<(f64, usize)> = vec![(0.0, 0); opts.stages.len()];
    let mut log_err = None;
    let mut last_release = Instant::now();
    let mut on_event = |e: Event| {
        let line = match &e {
            Event::StageStart { index, stage, from_step, steps_per_epoch } => {
                pb.set_position((stage_offsets[*index] + from_step) as u64);
                LogLine::Stage {
                    stage: *index,
                    kind: stage.kind.name(),
                    steps: stage.steps,
                    from_step: *from_step,
                    steps_per_epoch: *steps_per_epoch,
                    lr_rest: stage.lr_rest,
                    lr_e: stage.lr_e,
                }
            }
            Event::Step { stage, step, steps: _, loss, seconds, patches } => {
                if last_release.elapsed() >= RELEASE_EVERY {
                    malloc_release::release();
                    last_release = Instant::now();
                }
                ema = Some(ema.map_or(*loss, |m| 0.95 * m + 0.05 * loss));
                let r = *patches as f64 / seconds.max(1e-9);
                rate = Some(rate.map_or(r, |m| 0.9 * m + 0.1 * r));
                stage_time[*stage].0 += seconds;
                stage_time[*stage].1 += 1;
                pb.set_position((stage_offsets[*stage] + step) as u64);
                pb.set_message(format!(
                    "{} loss {:.4} {:.2} patch/s{}",
                    opts.stages[*stage].kind.name(),
                    ema.unwrap(),
                    rate.unwrap(),
                    last_val.map(|v| format!(" val {v:.4}")).unwrap_or_default()
                ));
                LogLine::Step { stage: *stage, step: *step, loss: *loss, seconds: rounded(*seconds, 4) }
            }
            Event::Validation { stage, step, total_step, rel_mse, by_spp, best, seconds } => {
                last_val = Some(*rel_mse);
                malloc_release::release();
                LogLine::Val {
                    stage: *stage,
                    step: *step,
                    total_step: *total_step,
                    rel_mse: *rel_mse,
                    by_spp: by_spp.clone(),
                    best: *best,
                    seconds: rounded(*seconds, 2),
                }
            }
            Event::Checkpoint { path } => LogLine::Checkpoint { dir: path.display().to_string() },
            Event::StageEnd { index, steps, reason } => {
                if *reason != "steps done" {
                    pb.println(format!("stage {index} ({}) ended at step {steps}: {reason}", opts.stages[*index].kind.name()));
                }
                LogLine::StageEnd { stage: *index, steps: *steps, reason }
            }
        };
        let line = serde_json::to_string(&line).unwrap_or_default();
        if let Err(err) = writeln!(log, "{line}") {
            log_err.get_or_insert(err);
        }
    };
    let outcome = tr::run(data, &opts, model, Some(&ckpt), a.resume, &mut on_event)?;
    pb.finish_and_clear();
    if outcome.paused {
        println!(
            "paused after {} steps (--stop-after or --session-minutes); checkpoint in {} (continue with --resume)",
            outcome.total_steps,
            ckpt.display()
        );
        return Ok(());
    }
    if let Some(e) = log_err {
        eprintln!("warning: could not write {}: {e}", log_path.display());
    }
    let peak = alloc_stats::peak().saturating_sub(heap_peak0);
    metadata.insert("steps".to_string(), outcome.total_steps.to_string());
    metadata.insert("wall_seconds".to_string(), format!("{:.1}", outcome.seconds));
    metadata.insert("val_rel_mse".to_string(), outcome.best_val.map(|v| format!("{v:.6}")).unwrap_or_else(|| "none".into()));
    metadata.insert("stages".to_string(), serde_json::to_string(&opts.stages)?);
    let provenance = Provenance {
        command: command.join(" "),
        seed: a.seed,
        dataset: a.data.display().to_string(),
        wall_time_s: outcome.seconds,
        // Provenance convention: 0 = unknown (JSON has no NaN).
        validation_rel_mse: outcome.best_val.unwrap_or(0.0),
        steps: outcome.total_steps as u64,
        git_commit: git_commit(),
        date: iso_date_utc(),
        notes: format!(
            "variant {name}; stages {}; patch {}, batch {}, spp {:?}, sampling {}; {} train + {} val shots; backend {}",
            serde_json::to_string(&opts.stages)?,
            a.patch,
            a.batch,
            data.spps,
            a.sampling,
            data.train.len(),
            data.val.len(),
            opts.backend.name()
        ),
    };
    weights::save(&output, &outcome.model, &tr::effective_config(&opts), a.preset.name(), &provenance)?;
    let per_stage: Vec<String> = opts
        .stages
        .iter()
        .zip(&stage_time)
        .filter(|(_, t)| t.1 > 0)
        .map(|(s, t)| format!("{} {:.2} s/step", s.kind.name(), t.0 / t.1 as f64))
        .collect();
    println!(
        "trained {name} ({}): {} steps in {:.1} min [{}], best val relMSE {}, train heap peak {:.0} MiB (+{data_mib:.0} MiB data); weights {}, log {}",
        a.preset,
        outcome.total_steps,
        outcome.seconds / 60.0,
        per_stage.join(", "),
        outcome.best_val.map(|v| format!("{v:.5}")).unwrap_or_else(|| "n/a (no validation ran: no val shots?)".into()),
        peak as f64 / (1 << 20) as f64,
        output.display(),
        log_path.display()
    );
    Ok(())
}

/// A finite weight ≥ 0, for the loss-term flags.
fn non_negative(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(w) if w.is_finite() && w >= 0.0 => Ok(w),
        Ok(w) => Err(format!("{w} is not a finite weight ≥ 0")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::with_widths;
    use denoiser::kpcn::Variant;
    use denoiser::model::Preset;

    /// --widths replaces the U-Net levels' widths and nothing else, and refuses a wrong count,
    /// a zero width and a KPCN preset.
    #[test]
    fn widths_replace_the_presets_and_are_checked() {
        let base = Preset::EdgeNoise.config();
        let wide = with_widths(base.clone(), Some(&[36, 48, 72, 96, 120]), None).unwrap();
        assert_eq!(wide.mskp.as_ref().unwrap().widths, vec![36, 48, 72, 96, 120]);
        let mut same = wide.clone();
        same.mskp.as_mut().unwrap().widths = base.mskp.as_ref().unwrap().widths.clone();
        assert_eq!(serde_json::to_string(&same).unwrap(), serde_json::to_string(&base).unwrap());
        // The columns dominate the cost, and their 3×3 convolutions grow with width².
        let ratio = wide.macs_per_pixel(8) as f64 / base.macs_per_pixel(8) as f64;
        assert!(ratio > 1.5 && ratio < 2.25, "{ratio}");
        assert!(with_widths(base.clone(), Some(&[36, 48, 72, 96]), None).is_err());
        assert!(with_widths(base.clone(), Some(&[36, 0, 72, 96, 120]), None).is_err());
        assert!(with_widths(Preset::Kpcn.config(), Some(&[36, 48, 72, 96, 120]), None).is_err());
        assert_eq!(serde_json::to_string(&with_widths(base.clone(), None, None).unwrap()).unwrap(), serde_json::to_string(&base).unwrap());
        // --p-widths sets D_P's widths alone: D_G and the both-buffers column keep --widths.
        let narrow = base.mskp.as_ref().unwrap().widths.clone();
        let mixed = with_widths(base.clone(), Some(&[36, 48, 72, 96, 120]), Some(&narrow)).unwrap();
        assert_eq!(mixed.mskp_for(Variant::G).unwrap().widths, vec![36, 48, 72, 96, 120]);
        assert_eq!(mixed.mskp_for(Variant::GP).unwrap().widths, vec![36, 48, 72, 96, 120]);
        assert_eq!(mixed.mskp_for(Variant::P).unwrap().widths, narrow);
        assert!(with_widths(base.clone(), None, Some(&[36, 48])).is_err());
        assert!(with_widths(Preset::Kpcn.config(), None, Some(&[36, 48, 72, 96, 120])).is_err());
    }
}
