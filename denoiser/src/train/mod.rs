//! Training (method.md §3, §6.2, §7.2–§7.3): data in memory, patch batches, the staged
//! schedule, validation with best-checkpoint selection and early stopping, resumable
//! checkpoints.
//!
//! - [`data`]: shots of a `pixguide dataset` folder, prepared once; cutting batches.
//! - [`patches`]: the importance map and patch corners; the validation grid.
//! - [`schedule`]: stages (branches → finetune; joint) and the ablations.
//! - [`augment`]: the 8 flips/rotations of a patch, every buffer moved consistently.
//! - [`checkpoint`]: weight files, optimizer state, run state; atomic writes.
//! - [`calibrate`]: after training, the guides' sample-count gain fitted on the validation shots.
//!
//! Determinism: every random draw of step k of stage j (spp, shots, corners, the permutations
//! of the disentangling loss) comes from `SplitMix64::derive(seed ^ j-tag, k)`, so a run is a
//! function of (seed, options) and resuming at step k needs no RNG state beyond k.

pub mod augment;
pub mod calibrate;
pub mod checkpoint;
pub mod data;
pub mod pack;
pub mod patches;
pub mod schedule;
pub mod stored;
mod validate;

pub use validate::{validate, validate_by_spp, Validation};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use burn::grad_clipping::GradientClippingConfig;
use burn::module::{Module, ModuleVisitor, ParamId};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor};

use crate::kpcn::Variant;
use crate::loss::{l1, l1_tonemapped, path_disentangling_loss, rel_l2, relative_to_input};
use crate::method::{BranchNets, Method, MethodModel, MethodOutput};
use crate::model::DenoiserConfig;
use crate::preprocess::TargetTensors;
use crate::rng::SplitMix64;
use augment::Dihedral;
use checkpoint::{CheckpointPaths, RunState};
use data::{batch_tensors, Dataset, PatchRef};
use schedule::{Ablation, LossScale, Stage, StageKind};

#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("dataset: {0}")]
    Data(String),
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("non-finite loss ({loss}) in stage {stage} at step {step}; batch at {spp} spp: {patches}")]
    NonFinite { loss: f32, stage: String, step: usize, spp: usize, patches: String },
    #[error("{0}")]
    Options(String),
}

/// Everything that defines a run (besides the data and the initial model).
#[derive(Clone, Debug)]
pub struct TrainOptions {
    pub method: Method,
    pub ablation: Option<Ablation>,
    pub config: DenoiserConfig,
    pub seed: u64,
    /// Input patch side (the output is `patch − 2·margin`).
    pub patch: usize,
    pub batch: usize,
    pub stages: Vec<Stage>,
    /// Move each training patch by a random one of the 8 flips/rotations ([`augment`]).
    pub augment: bool,
    /// Validate every this many steps (0 = once per epoch: every training patch of the
    /// non-overlapping grid at every spp seen once, in expectation).
    pub val_every: usize,
    /// Patches per validation forward pass.
    pub val_batch: usize,
    /// End a stage after this many validations without improvement.
    pub patience: Option<usize>,
    /// Write a checkpoint every this many steps (0 = only at stage ends).
    pub checkpoint_every: usize,
    /// Wall-clock budget of the whole run; each stage gets its share in proportion to its
    /// steps and ends early (gracefully, with a checkpoint) when over it.
    pub minutes: Option<f64>,
    /// End this session after this many steps (with a checkpoint), as if interrupted; a later
    /// `resume` continues. Not part of the run's identity.
    pub pause_after: Option<usize>,
    /// End this session after this many minutes of its own wall time, likewise: a run planned
    /// over several sessions keeps its schedule (its steps fix the learning-rate curve) and
    /// pauses when a session's time is up. Not part of the run's identity.
    pub pause_after_minutes: Option<f64>,
    /// Extra metadata written into weight files (provenance).
    pub metadata: BTreeMap<String, String>,
    /// The burn backend steps and validation run on. Not part of the run's identity: a
    /// checkpoint written on one backend resumes on another.
    pub backend: crate::Backend,
}

impl TrainOptions {
    /// A run of `method` with `config`'s networks on `patch`² patches, `batch` at a time,
    /// through `stages`; the rest quiet: the config's seed, no augmentation, validation once
    /// per epoch in passes of 8 patches, no patience, budget, pause or provenance, checkpoints
    /// only at stage ends, the flex backend. Callers set what they need with `..`.
    pub fn new(method: Method, config: DenoiserConfig, patch: usize, batch: usize, stages: Vec<Stage>) -> Self {
        TrainOptions {
            method,
            ablation: None,
            seed: config.seed,
            config,
            patch,
            batch,
            stages,
            augment: false,
            val_every: 0,
            val_batch: 8,
            patience: None,
            checkpoint_every: 0,
            minutes: None,
            pause_after: None,
            pause_after_minutes: None,
            metadata: BTreeMap::new(),
            backend: crate::Backend::Flex,
        }
    }

    /// The parts a resume must agree on.
    fn fingerprint(&self) -> String {
        format!(
            "{}|{:?}|{:?}|{}|{}|{}|{:?}{}",
            self.method,
            self.ablation,
            serde_json::to_string(&self.config).unwrap_or_default(),
            self.seed,
            self.patch,
            self.batch,
            self.stages,
            if self.augment { "|augment" } else { "" }
        )
    }
}

/// What the trainer reports while it runs.
#[derive(Clone, Debug)]
pub enum Event<'a> {
    StageStart {
        index: usize,
        stage: &'a Stage,
        from_step: usize,
        steps_per_epoch: usize,
    },
    Step {
        stage: usize,
        step: usize,
        steps: usize,
        loss: f64,
        seconds: f64,
        patches: usize,
    },
    /// `seconds`: wall time of the run so far, summed over resumed sessions (validation
    /// included), so curves can be drawn against time as well as steps.
    Validation {
        stage: usize,
        step: usize,
        total_step: usize,
        rel_mse: f64,
        /// (samples per pixel, the same mean over that count's patches), per dataset spp: the
        /// issue's floors are per spp.
        by_spp: Vec<(usize, f64)>,
        best: bool,
        seconds: f64,
    },
    Checkpoint {
        path: &'a Path,
    },
    StageEnd {
        index: usize,
        steps: usize,
        reason: &'static str,
    },
}

pub struct Outcome {
    /// Best-validation weights of the last stage (the last weights if nothing validated).
    pub model: MethodModel,
    pub best_val: Option<f64>,
    pub total_steps: usize,
    pub seconds: f64,
    /// The session ended at `pause_after` or `pause_after_minutes`; resume to finish.
    pub paused: bool,
}

/// The network sizes of a run: the preset with the run's seed, and E's radiance-only flag for
/// that ablation. Weight files must be saved with this config.
pub fn effective_config(opts: &TrainOptions) -> DenoiserConfig {
    let mut cfg = opts.config.clone();
    cfg.seed = opts.seed;
    if opts.ablation == Some(Ablation::RadianceOnly) {
        cfg.ensemble.radiance_only = true;
    }
    cfg
}

/// Loads a pretrained G or P model (a `crate::weights` file) for the guided model, checking
/// that its method and its network sizes are the ones this run needs.
fn load_pretrained(path: &Path, want: Method, cfg: &DenoiserConfig, device: &Device) -> Result<MethodModel, TrainError> {
    let l = crate::weights::load(path, device).map_err(|e| TrainError::Options(e.to_string()))?;
    if l.method != want {
        return Err(TrainError::Options(format!("{}: holds a {} model, expected {want}", path.display(), l.method)));
    }
    // The columns this run takes from the file (D_G and/or D_P, at their own widths) and the
    // PathNet.
    let variants: &[Variant] = match want {
        Method::P => &[Variant::P],
        Method::Both => &[Variant::GP],
        Method::Guided => &[Variant::G, Variant::P],
        Method::G => &[Variant::G],
    };
    let sizes = |c: &DenoiserConfig| {
        let mut s = vec![serde_json::to_string(&c.kpcn), serde_json::to_string(&c.pathnet)];
        s.extend(variants.iter().map(|&v| serde_json::to_string(&c.mskp_for(v))));
        if want == Method::Guided {
            s.push(serde_json::to_string(&c.ensemble));
        }
        s.into_iter().map(Result::unwrap_or_default).collect::<Vec<_>>()
    };
    if sizes(&l.config) != sizes(cfg) {
        return Err(TrainError::Options(format!(
            "{}: trained with other network sizes (preset `{}`) than this run's; pass the matching --preset",
            path.display(),
            l.preset
        )));
    }
    Ok(l.model)
}

/// The fresh or pretrained model a run starts from. Guided models (except Full-N-Full) take
/// D_G from the G model and D_P + PathNet from the P model of each branch; E starts fresh.
pub fn initial_model(
    opts: &TrainOptions,
    from_g: Option<&Path>,
    from_p: Option<&Path>,
    device: &Device,
) -> Result<MethodModel, TrainError> {
    let cfg = effective_config(opts);
    if opts.ablation.is_some() && opts.method != Method::Guided {
        return Err(TrainError::Options(format!("ablations apply to the guided method, not {}", opts.method)));
    }
    let mut model = MethodModel::init(&cfg, opts.method, device);
    // A single-column method may start from a trained model of its own kind (warm start).
    match (opts.method, from_g, from_p) {
        (Method::G, Some(f), None) | (Method::P, None, Some(f)) => model = warm_start(opts, f, device)?,
        (Method::Guided, _, _) | (_, None, None) => {}
        (m, _, _) => {
            return Err(TrainError::Options(format!(
                "a {m} model can start only from a {m} model: --from-g goes with --method g or guided, --from-p with p or guided"
            )))
        }
    }
    if schedule::needs_pretrained(opts.method, opts.ablation) {
        let (Some(g), Some(p)) = (from_g, from_p) else {
            return Err(TrainError::Options("the guided method starts from trained G and P models: give --from-g and --from-p".into()));
        };
        let gm = load_pretrained(g, Method::G, &cfg, device)?;
        let pm = load_pretrained(p, Method::P, &cfg, device)?;
        let take = |dst: &mut BranchNets, g: BranchNets, p: BranchNets| {
            dst.d_g = g.d_g;
            dst.d_p = p.d_p;
            dst.path = p.path;
        };
        take(&mut model.diffuse, gm.diffuse, pm.diffuse);
        take(&mut model.specular, gm.specular, pm.specular);
    }
    Ok(model)
}

/// A run that continues from a trained model of its own method and sizes (warm start: the run's
/// stages, a fresh optimiser): g, p, both, or a whole guided model (E included), which a
/// guided finetune starts from.
pub fn warm_start(opts: &TrainOptions, from: &Path, device: &Device) -> Result<MethodModel, TrainError> {
    if opts.ablation.is_some() {
        return Err(TrainError::Options(format!(
            "{}: ablations start from G and P models, not from a trained {} model",
            from.display(),
            opts.method
        )));
    }
    load_pretrained(from, opts.method, &effective_config(opts), device)
}

/// Sets which sub-modules get gradients in `stage` (frozen = no gradient at all, which also
/// saves their backward pass).
fn configure(model: MethodModel, stage: &Stage) -> MethodModel {
    let (rest, e) = (stage.lr_rest.is_some(), stage.lr_e.is_some());
    let set = |b: BranchNets| BranchNets {
        d_g: b.d_g.map(|m| m.set_require_grad(rest)),
        d_p: b.d_p.map(|m| m.set_require_grad(rest)),
        d_gp: b.d_gp.map(|m| m.set_require_grad(rest)),
        path: b.path.map(|m| m.set_require_grad(rest)),
        e: b.e.map(|m| m.set_require_grad(e)),
    };
    MethodModel { diffuse: set(model.diffuse), specular: set(model.specular) }
}

#[derive(Default)]
struct Ids(Vec<ParamId>);
impl ModuleVisitor for Ids {
    fn visit_float<const D: usize>(&mut self, param: &burn::module::Param<Tensor<D>>) {
        self.0.push(param.id);
    }
}

fn e_ids(model: &MethodModel) -> Vec<ParamId> {
    let mut ids = Ids::default();
    for b in [&model.diffuse, &model.specular] {
        if let Some(e) = &b.e {
            e.visit(&mut ids);
        }
    }
    ids.0
}

/// The noisy colour of each branch of a batch, `[B, 3, H, W]` in branch units: the denominators
/// of the relative loss scales ([`crate::loss::LossScale::input_power`]).
pub struct NoisyColour {
    pub diffuse: Tensor<4>,
    pub specular: Tensor<4>,
}

impl NoisyColour {
    /// The first three channels of each branch's colour block (D or ln(1 + P), preprocess.rs),
    /// if `stage` scales its loss by them.
    pub fn for_stage(input: &crate::preprocess::InputTensors, stage: &Stage) -> Option<Self> {
        stage.loss.loss_scale.input_power().map(|_| NoisyColour {
            diffuse: input.diffuse.colour.clone().narrow(1, 0, 3),
            specular: input.specular.colour.clone().narrow(1, 0, 3),
        })
    }
}

/// The loss of `stage` for one forward pass; `noisy` is needed by a relative loss scale
/// ([`NoisyColour::for_stage`]).
pub fn stage_loss(out: MethodOutput, t: &TargetTensors, stage: &Stage, noisy: Option<NoisyColour>, rng: &mut SplitMix64) -> Tensor<1> {
    match stage.kind {
        StageKind::Finetune => l1(out.radiance, t.total.clone()),
        StageKind::FinetuneToneMapped => l1_tonemapped(out.radiance, t.total.clone()),
        StageKind::Branches | StageKind::Joint => {
            let (d, s) = (out.diffuse.output, out.specular.output);
            let power = stage.loss.loss_scale.input_power();
            let inside = stage.loss.rel_l2_inside && power.is_some();
            let mut loss = match (stage.loss.loss_scale, power, noisy) {
                (LossScale::RelativeL2, ..) => rel_l2(d.clone(), t.diffuse.clone()) + rel_l2(s.clone(), t.specular.clone()),
                (_, Some(power), Some(n)) => relative_to_input(
                    &[(d.clone(), n.diffuse, t.diffuse.clone()), (s.clone(), n.specular, t.specular.clone())],
                    power,
                    if inside { stage.loss.rel_l2_weight as f32 } else { 0.0 },
                ),
                (_, Some(_), None) => panic!("a relative loss scale needs the noisy colour (NoisyColour::for_stage)"),
                (_, None, _) => l1(d.clone(), t.diffuse.clone()) + l1(s.clone(), t.specular.clone()),
            };
            if stage.loss.rel_l2_weight > 0.0 && !inside {
                loss = loss + (rel_l2(d, t.diffuse.clone()) + rel_l2(s, t.specular.clone())).mul_scalar(stage.loss.rel_l2_weight);
            }
            if stage.w_path > 0.0 {
                for (p, target) in [(out.diffuse.path, &t.diffuse), (out.specular.path, &t.specular)] {
                    if let Some(p) = p {
                        loss = loss + path_disentangling_loss(p.samples, target.clone(), rng).mul_scalar(stage.w_path);
                    }
                }
            }
            loss
        }
    }
}

/// Stream tag of stage `k` (distinct streams per stage, same seed).
fn stage_seed(seed: u64, k: usize) -> u64 {
    seed ^ (k as u64 + 1).wrapping_mul(0xA24B_AED4_963E_E407)
}

/// The patches of step `step` of stage `k`: one spp for the whole batch (tensors need equal
/// shapes), shots uniform, corners from each shot's sampler.
pub fn draw_batch(data: &Dataset, opts: &TrainOptions, k: usize, step: usize) -> (Vec<PatchRef>, SplitMix64) {
    let mut rng = SplitMix64::derive(stage_seed(opts.seed, k), step as u64);
    let spp = rng.below(data.spps.len());
    let refs = (0..opts.batch)
        .map(|_| {
            let shot = rng.below(data.train.len());
            let (x, y) = data.train[shot].sampler.sample(&mut rng);
            let t = if opts.augment { Dihedral(rng.below(8) as u8) } else { Dihedral::IDENTITY };
            PatchRef { shot, spp, x, y, t }
        })
        .collect();
    (refs, rng)
}

fn describe(data: &Dataset, refs: &[PatchRef]) -> String {
    refs.iter().map(|r| format!("{} @({},{})", data.train[r.shot].name, r.x, r.y)).collect::<Vec<_>>().join(", ")
}

/// One optimisation step on a given batch. Returns the updated model and the loss value, or the
/// non-finite loss (the caller names the batch).
pub fn train_step(
    model: MethodModel,
    optim: &mut ModuleOptimizer,
    input: crate::preprocess::InputTensors,
    target: &TargetTensors,
    stage: &Stage,
    lr_factor: f64,
    e_params: &[ParamId],
    rng: &mut SplitMix64,
) -> Result<(MethodModel, f32), f32> {
    let noisy = NoisyColour::for_stage(&input, stage);
    let out = model.forward(input);
    let loss = stage_loss(out, target, stage, noisy, rng);
    let value: f32 = loss.clone().into_scalar();
    if !value.is_finite() {
        return Err(value);
    }
    let mut grads = loss.backward();
    let mut model = model;
    if let Some(lr) = stage.lr_e {
        let g = GradientsParams::from_params(&mut grads, &model, e_params);
        model = optim.step(lr * lr_factor, model, g);
    }
    if let Some(lr) = stage.lr_rest {
        let g = GradientsParams::from_grads(grads, &model);
        model = optim.step(lr * lr_factor, model, g);
    }
    Ok((model, value))
}

/// Adam as method.md §3: β = (0.9, 0.999), ε = 1e-8, no decay, gradient values clipped to ±1.
pub fn optimizer() -> ModuleOptimizer {
    AdamConfig::new()
        .with_beta_1(0.9)
        .with_beta_2(0.999)
        .with_epsilon(1e-8)
        .with_grad_clipping(Some(GradientClippingConfig::Value(1.0)))
        .init()
}

/// Runs the schedule from `model` (or from the checkpoint in `ckpt_dir` when `resume` and one
/// exists).
pub fn run(
    data: &Dataset,
    opts: &TrainOptions,
    model: MethodModel,
    ckpt_dir: Option<&Path>,
    resume: bool,
    events: &mut dyn FnMut(Event),
) -> Result<Outcome, TrainError> {
    if opts.patch <= 2 * opts.config.margin() {
        return Err(TrainError::Options(format!("patch {} leaves no output with the {} px margin", opts.patch, opts.config.margin())));
    }
    if opts.batch == 0 {
        return Err(TrainError::Options("batch must be ≥ 1".into()));
    }
    let device = opts.backend.training_device().map_err(TrainError::Options)?;
    let ckpt = ckpt_dir.map(|d| CheckpointPaths { dir: d.to_path_buf() });
    let started = Instant::now();
    let mut model = model;
    let mut optim = optimizer();
    let mut st = RunState {
        stage: 0,
        step: 0,
        total_steps: 0,
        best_val: None,
        best_step: None,
        since_best: 0,
        elapsed: 0.0,
        param_ids: BTreeMap::new(),
        options: opts.fingerprint(),
    };
    if let (Some(c), true) = (&ckpt, resume) {
        if c.state().exists() {
            let s = checkpoint::load_state(&c.state())?;
            if s.options != st.options {
                return Err(TrainError::Checkpoint(format!(
                    "{} was written by a run with other options; use another --checkpoint-dir or the same options",
                    c.state().display()
                )));
            }
            let (m, _) = checkpoint::load_weights(&c.weights(), model, Some(&s.param_ids))?;
            model = m;
            if c.optimizer().exists() {
                optim = checkpoint::load_optimizer(&c.optimizer(), optim)?;
            }
            st = s;
        }
    }
    let total_planned: usize = opts.stages.iter().map(|s| s.steps).sum::<usize>().max(1);
    let margin = opts.config.margin();
    let with_desc = opts.method.needs_descriptors();
    let epoch = (data.train.len() * data.spps.len() * patches::grid(data.width, data.height, opts.patch).len()).div_ceil(opts.batch).max(1);
    let val_every = if opts.val_every == 0 { epoch } else { opts.val_every };
    let session_elapsed = st.elapsed;
    let elapsed = |started: &Instant| session_elapsed + started.elapsed().as_secs_f64();

    let mut best_model: Option<MethodModel> = None;
    let mut session_steps = 0usize;
    while st.stage < opts.stages.len() {
        let k = st.stage;
        let stage = &opts.stages[k];
        if stage.steps == 0 {
            st.stage += 1;
            continue;
        }
        model = configure(model, stage);
        let e_params = e_ids(&model);
        events(Event::StageStart { index: k, stage, from_step: st.step, steps_per_epoch: epoch });
        let cum: usize = opts.stages[..=k].iter().map(|s| s.steps).sum();
        let deadline = opts.minutes.map(|m| m * 60.0 * cum as f64 / total_planned as f64);
        let mut reason = "steps done";
        while st.step < stage.steps {
            // Only reached over the deadline when the stage starts there (nothing to validate);
            // otherwise the check after each step below ends the stage.
            if deadline.is_some_and(|d| elapsed(&started) >= d) {
                reason = "time budget";
                break;
            }
            let session_over = opts.pause_after_minutes.is_some_and(|m| started.elapsed().as_secs_f64() >= m * 60.0);
            if opts.pause_after.is_some_and(|p| session_steps >= p) || session_over {
                if let Some(c) = &ckpt {
                    st.elapsed = elapsed(&started);
                    save_checkpoint(c, &model, &optim, &mut st, &opts.metadata)?;
                }
                return Ok(Outcome { model, best_val: st.best_val, total_steps: st.total_steps, seconds: elapsed(&started), paused: true });
            }
            // The best validation belongs to the weights the model holds until this stage
            // takes its first step: a stage that takes none (zero steps, or started past its
            // deadline) leaves the previous stage's best as the run's.
            if st.step == 0 && k > 0 {
                st.best_val = None;
                st.best_step = None;
                st.since_best = 0;
            }
            session_steps += 1;
            let t0 = Instant::now();
            let (refs, mut rng) = draw_batch(data, opts, k, st.step);
            let (input, target) = batch_tensors(&data.train, &refs, &data.spps, opts.patch, margin, with_desc, &device)?;
            let (m, loss) = match train_step(model, &mut optim, input, &target, stage, stage.lr_factor(st.step), &e_params, &mut rng) {
                Ok(r) => r,
                Err(loss) => {
                    return Err(TrainError::NonFinite {
                        loss,
                        stage: stage.kind.name().into(),
                        step: st.step,
                        spp: data.spps[refs[0].spp],
                        patches: describe(data, &refs),
                    });
                }
            };
            model = m;
            st.step += 1;
            st.total_steps += 1;
            events(Event::Step {
                stage: k,
                step: st.step,
                steps: stage.steps,
                loss: loss as f64,
                seconds: t0.elapsed().as_secs_f64(),
                patches: refs.len(),
            });
            // A stage cut by the budget validates its last step too: the stage continues from
            // its best validated weights, so otherwise every step since the last validation
            // would be thrown away.
            let out_of_time = deadline.is_some_and(|d| elapsed(&started) >= d);
            if st.step.is_multiple_of(val_every) || st.step == stage.steps || out_of_time {
                if let Some(Validation { overall: v, by_spp }) = validate_by_spp(&model, data, opts)? {
                    let best = st.best_val.is_none_or(|b| v < b);
                    if best {
                        st.best_val = Some(v);
                        st.best_step = Some(st.step);
                        st.since_best = 0;
                        best_model = Some(model.clone());
                        if let Some(c) = &ckpt {
                            checkpoint::save_weights(&c.best(k), &model, &opts.metadata)?;
                        }
                    } else {
                        st.since_best += 1;
                    }
                    events(Event::Validation {
                        stage: k,
                        step: st.step,
                        total_step: st.total_steps,
                        rel_mse: v,
                        by_spp: data.spps.iter().copied().zip(by_spp).collect(),
                        best,
                        seconds: elapsed(&started),
                    });
                    if opts.patience.is_some_and(|p| st.since_best >= p) {
                        reason = "early stop";
                        break;
                    }
                }
            }
            if out_of_time && st.step < stage.steps {
                reason = "time budget";
                break;
            }
            if opts.checkpoint_every > 0 && st.step.is_multiple_of(opts.checkpoint_every) && st.step < stage.steps {
                if let Some(c) = &ckpt {
                    st.elapsed = elapsed(&started);
                    save_checkpoint(c, &model, &optim, &mut st, &opts.metadata)?;
                    events(Event::Checkpoint { path: &c.dir });
                }
            }
        }
        events(Event::StageEnd { index: k, steps: st.step, reason });
        // Continue from the stage's best validated weights (method.md §3: keep the best).
        if let Some(b) = best_model.take() {
            model = b;
        } else if let (Some(c), Some(_)) = (&ckpt, st.best_val) {
            // Resumed after the best validation: it is only on disk.
            if c.best(k).exists() {
                model = checkpoint::load_weights(&c.best(k), model, None)?.0;
            }
        }
        // A stage of zero steps (e.g. --finetune-steps 0) keeps the previous stage's best.
        st.stage += 1;
        st.step = 0;
        if let Some(c) = &ckpt {
            st.elapsed = elapsed(&started);
            save_checkpoint(c, &model, &optim, &mut st, &opts.metadata)?;
            events(Event::Checkpoint { path: &c.dir });
        }
    }
    Ok(Outcome { model, best_val: st.best_val, total_steps: st.total_steps, seconds: elapsed(&started), paused: false })
}

fn save_checkpoint(
    c: &CheckpointPaths,
    model: &MethodModel,
    optim: &ModuleOptimizer,
    st: &mut RunState,
    meta: &BTreeMap<String, String>,
) -> Result<(), TrainError> {
    st.param_ids = checkpoint::param_ids(model);
    checkpoint::save_weights(&c.weights(), model, meta)?;
    checkpoint::save_optimizer(&c.optimizer(), optim)?;
    checkpoint::save_state(&c.state(), st)
}

/// Default checkpoint folder next to an output file: `<output>.ckpt/`.
pub fn default_checkpoint_dir(output: &Path) -> PathBuf {
    let mut s = output.as_os_str().to_owned();
    s.push(".ckpt");
    PathBuf::from(s)
}

#[cfg(test)]
mod tests;
