//! The training schedule of method.md §3 and §6.2, and the ablations of Seed Table 2.

pub use crate::loss::LossScale;
use crate::method::Method;
use crate::model::DenoiserConfig;

/// What a stage optimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum StageKind {
    /// Per-branch L1 on the branch outputs (demodulated diffuse, log specular)
    /// + w_path·L_path for each PathNet.
    Branches,
    /// L1 on the recombined linear radiance; no L_path (method.md §4.3).
    Finetune,
    /// L1 on the recombined radiance after the evaluation's tone map (a) of method.md §7.3
    /// ([`crate::loss::l1_tonemapped`]); the U-Net presets' finetune. Linear L1 lets a shadow
    /// pixel borrow its lit neighbour's light at almost no cost, while the test relMSE counts
    /// that as a large relative error (docs/journal/denoiser.md, "Error floors").
    FinetuneToneMapped,
    /// Guided: per-branch L1 on I_E + w_path·L_path, E and the rest at their own rates.
    Joint,
}

impl StageKind {
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Branches => "branches",
            StageKind::Finetune => "finetune",
            StageKind::FinetuneToneMapped => "finetune-tonemapped",
            StageKind::Joint => "joint",
        }
    }
}

/// One stage: its loss, length and learning rates. `lr_rest` = D_G / D_P / G+P columns and
/// PathNets; `lr_e` = the ensembling nets. `None` = frozen (no gradient, no update).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stage {
    pub kind: StageKind,
    pub steps: usize,
    pub lr_rest: Option<f64>,
    pub lr_e: Option<f64>,
    /// Weight of L_path (0 = not computed).
    pub w_path: f64,
    /// How the rates vary over the stage's steps.
    pub shape: LrShape,
    /// The branch or joint loss (its keys sit beside the stage's own in files and logs).
    #[serde(flatten)]
    pub loss: BranchLoss,
}

/// How each patch's branch or joint loss is formed. Files and logs without these keys mean the
/// paper's plain L1.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BranchLoss {
    /// How each patch's loss is scaled.
    #[serde(default)]
    pub loss_scale: LossScale,
    /// Weight of a relative L2 term ([`crate::loss::rel_l2`]) added to the loss of any scale
    /// (0 = not computed): it pulls sparse inputs towards the conditional mean where L1 settles
    /// for the darker median.
    #[serde(default)]
    pub rel_l2_weight: f64,
    /// Whether that term is added to each patch's L1 before a relative scale divides it by the
    /// input's error ([`crate::loss::relative_to_input`]), rather than added after, unscaled.
    #[serde(default)]
    pub rel_l2_inside: bool,
}

/// How a stage's learning rates vary over its steps.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum LrShape {
    /// The stage's rates throughout (the paper's schedule).
    Constant,
    /// Linear warm-up from 1/10 of the rates over the first `warmup` fraction of the steps,
    /// then cosine decay to 1/50 of them at the last step: a short run spends its first steps
    /// where a high rate is not yet stable and its last ones settling, instead of ending at the
    /// peak rate's noise floor.
    WarmupCosine { warmup: f64 },
}

impl Stage {
    /// A stage at constant rates with the paper's plain L1: what benchmarks, examples and
    /// tests of a single step use.
    pub fn constant(kind: StageKind, steps: usize, lr_rest: Option<f64>, lr_e: Option<f64>, w_path: f64) -> Self {
        Stage { kind, steps, lr_rest, lr_e, w_path, shape: LrShape::Constant, loss: BranchLoss::default() }
    }

    /// Multiplier of the stage's rates at 0-based `step`.
    pub fn lr_factor(&self, step: usize) -> f64 {
        match self.shape {
            LrShape::Constant => 1.0,
            LrShape::WarmupCosine { warmup } => {
                let n = self.steps.max(1) as f64;
                let w = (warmup * n).round().max(1.0);
                let k = step as f64;
                if k < w {
                    0.1 + 0.9 * k / w
                } else {
                    let t = ((k - w) / (n - w).max(1.0)).min(1.0);
                    0.02 + 0.98 * 0.5 * (1.0 + (std::f64::consts::PI * t).cos())
                }
            }
        }
    }
}

// The ablations name weight files too, so they live with the methods, below training.
pub use crate::method::Ablation;

/// The loss of the finetune stage (on the recombined radiance).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum FinetuneLoss {
    /// The paper's L1 on linear radiance.
    #[default]
    Linear,
    /// L1 after the evaluation's tone map.
    ToneMapped,
}

impl FinetuneLoss {
    pub const ALL: [FinetuneLoss; 2] = [FinetuneLoss::Linear, FinetuneLoss::ToneMapped];

    pub fn name(self) -> &'static str {
        match self {
            FinetuneLoss::Linear => "linear",
            FinetuneLoss::ToneMapped => "tonemapped",
        }
    }

    pub fn stage_kind(self) -> StageKind {
        match self {
            FinetuneLoss::Linear => StageKind::Finetune,
            FinetuneLoss::ToneMapped => StageKind::FinetuneToneMapped,
        }
    }
}

crate::names::named!(FinetuneLoss, "finetune loss");

/// Stage lengths and learning rates (defaults: method.md §3, §6.2 rates; CPU-sized lengths).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScheduleOptions {
    pub branch_steps: usize,
    pub finetune_steps: usize,
    pub joint_steps: usize,
    /// Steps of the from-scratch ablation (it has no pretraining, so it gets its own length).
    pub scratch_steps: usize,
    pub lr_branches: f64,
    pub lr_finetune: f64,
    pub lr_joint_e: f64,
    pub lr_joint_rest: f64,
    /// Rate of everything in Full-N-Full (our choice: the pretraining rate, since 1e-6 from
    /// scratch would not move within a CPU budget).
    pub lr_scratch: f64,
    pub w_path: f64,
    pub lr_shape: LrShape,
    /// The finetune stage's loss.
    #[serde(default)]
    pub finetune_loss: FinetuneLoss,
    /// Steps of a finetune of the whole guided model (E, columns and PathNets at
    /// `lr_finetune`, `finetune_loss` on the blended radiance) after its joint stage; 0 = none,
    /// the paper's schedule. The joint loss weighs each branch in its own units; this stage
    /// trains the blend on the measure the evaluation uses (docs/training.md, "Commands": `--guided-finetune-steps`).
    #[serde(default)]
    pub guided_finetune_steps: usize,
    /// The branch and joint losses.
    #[serde(flatten)]
    pub loss: BranchLoss,
}

impl Default for ScheduleOptions {
    fn default() -> Self {
        ScheduleOptions {
            // The proposal of docs/training.md for G and guided; `--all` sets each run's own.
            branch_steps: 1500,
            finetune_steps: 200,
            joint_steps: 400,
            scratch_steps: 400,
            lr_branches: 1e-4,
            lr_finetune: 1e-6,
            lr_joint_e: 1e-5,
            lr_joint_rest: 1e-6,
            lr_scratch: 1e-4,
            w_path: 0.1,
            lr_shape: LrShape::WarmupCosine { warmup: 0.05 },
            finetune_loss: FinetuneLoss::Linear,
            guided_finetune_steps: 0,
            loss: BranchLoss::default(),
        }
    }
}

impl ScheduleOptions {
    /// The defaults with the rates of `config`'s backbone: the paper's for a KPCN; for the
    /// multi-scale U-Net its measured peak ([`DenoiserConfig::peak_lr`]) for pretraining and
    /// from-scratch runs, and for the joint stage E at half of it (E starts fresh) and the
    /// pretrained columns and PathNets at a twentieth (they only adapt to the blend); its
    /// finetune is tone-mapped, at a fifth of the peak (measured 2026-11-25, docs/training.md).
    pub fn for_config(config: &DenoiserConfig) -> Self {
        let d = Self::default();
        if config.mskp.is_none() {
            return d;
        }
        let peak = config.peak_lr();
        ScheduleOptions {
            lr_branches: peak,
            lr_scratch: peak,
            lr_joint_e: peak / 2.0,
            lr_joint_rest: peak / 20.0,
            lr_finetune: peak / 5.0,
            finetune_loss: FinetuneLoss::ToneMapped,
            ..d
        }
    }
}

/// The stages for `method` (and an ablation, which implies the guided method).
pub fn plan(method: Method, ablation: Option<Ablation>, o: &ScheduleOptions) -> Vec<Stage> {
    let path = |m: Method| if m.needs_descriptors() { o.w_path } else { 0.0 };
    match (method, ablation) {
        (Method::Guided, None) | (Method::Guided, Some(Ablation::RadianceOnly)) => {
            let joint = Stage {
                kind: StageKind::Joint,
                steps: o.joint_steps,
                lr_rest: Some(o.lr_joint_rest),
                lr_e: Some(o.lr_joint_e),
                w_path: o.w_path,
                shape: o.lr_shape,
                loss: o.loss,
            };
            let finetune = (o.guided_finetune_steps > 0).then(|| Stage {
                kind: o.finetune_loss.stage_kind(),
                steps: o.guided_finetune_steps,
                lr_rest: Some(o.lr_finetune),
                lr_e: Some(o.lr_finetune),
                w_path: 0.0,
                shape: o.lr_shape,
                loss: finetune_loss(o),
            });
            std::iter::once(joint).chain(finetune).collect()
        }
        (_, Some(Ablation::FixNTrain)) => {
            // Frozen PathNets get no L_path either.
            vec![Stage {
                kind: StageKind::Joint,
                steps: o.joint_steps,
                lr_rest: None,
                lr_e: Some(o.lr_joint_e),
                w_path: 0.0,
                shape: o.lr_shape,
                loss: o.loss,
            }]
        }
        (_, Some(Ablation::FullNFull)) => {
            vec![Stage {
                kind: StageKind::Joint,
                steps: o.scratch_steps,
                lr_rest: Some(o.lr_scratch),
                lr_e: Some(o.lr_scratch),
                w_path: o.w_path,
                shape: o.lr_shape,
                loss: o.loss,
            }]
        }
        (m, _) => vec![
            Stage {
                kind: StageKind::Branches,
                steps: o.branch_steps,
                lr_rest: Some(o.lr_branches),
                lr_e: None,
                w_path: path(m),
                shape: o.lr_shape,
                loss: o.loss,
            },
            Stage {
                kind: o.finetune_loss.stage_kind(),
                steps: o.finetune_steps,
                lr_rest: Some(o.lr_finetune),
                lr_e: None,
                w_path: 0.0,
                shape: o.lr_shape,
                loss: finetune_loss(o),
            },
        ],
    }
}

/// The finetune losses are on radiance and take no relative L2 term.
fn finetune_loss(o: &ScheduleOptions) -> BranchLoss {
    BranchLoss { rel_l2_weight: 0.0, rel_l2_inside: false, ..o.loss }
}

/// Whether the method/ablation starts from pretrained G and P models.
pub fn needs_pretrained(method: Method, ablation: Option<Ablation>) -> bool {
    method == Method::Guided && ablation != Some(Ablation::FullNFull)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Warm-up from 1/10 to the peak, then a monotone cosine to 1/50 at the last step.
    #[test]
    fn warmup_cosine_shape() {
        let s = Stage {
            kind: StageKind::Branches,
            steps: 200,
            lr_rest: Some(1.0),
            lr_e: None,
            w_path: 0.0,
            shape: LrShape::WarmupCosine { warmup: 0.05 },
            loss: BranchLoss::default(),
        };
        assert!((s.lr_factor(0) - 0.1).abs() < 1e-12);
        assert!((s.lr_factor(10) - 1.0).abs() < 1e-12);
        assert!((s.lr_factor(199) - 0.02).abs() < 1e-3);
        let f: Vec<f64> = (0..200).map(|k| s.lr_factor(k)).collect();
        assert!(f[..10].windows(2).all(|w| w[1] > w[0]) && f[10..].windows(2).all(|w| w[1] <= w[0]));
        let c = Stage { shape: LrShape::Constant, ..s };
        assert!((0..200).all(|k| c.lr_factor(k) == 1.0));
    }
}
