//! The methods `eval` compares: the table of known ones, and loading each one's weights (or the
//! OIDN library) into a [`MethodSpec`], with the identity its cached measurements are keyed by.

use super::cache::file_id;
use super::EvalArgs;
use anyhow::{bail, Context, Result};
use denoiser::method::Method;
use denoiser::model::Preset;
use denoiser::oidn::Oidn;
use denoiser::train::schedule::Ablation;
use denoiser::weights::{self, Loaded};
use std::path::PathBuf;

/// The methods `eval` compares; `ALL` and `name()` are the only place their names are written
/// (`--methods` parses them, the cache keys and the page print them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvalMethod {
    /// Plain Monte Carlo, always measured: it normalises the errors.
    Noisy,
    G,
    P,
    Both,
    /// The gate E over the shipped g and p (src/cli/gated.rs).
    Guided,
    /// The gate E over OIDN, g and p.
    GuidedOidn,
    /// The jointly trained guided model (E inside one weight file with its own g and p).
    GuidedJoint,
    GuidedHalf,
    FixNTrain,
    FullNFull,
    RadianceOnly,
    /// Intel Open Image Denoise, the baseline.
    Oidn,
}

impl EvalMethod {
    pub const ALL: [EvalMethod; 12] = [
        EvalMethod::Noisy,
        EvalMethod::G,
        EvalMethod::P,
        EvalMethod::Both,
        EvalMethod::Guided,
        EvalMethod::GuidedOidn,
        EvalMethod::GuidedJoint,
        EvalMethod::GuidedHalf,
        EvalMethod::FixNTrain,
        EvalMethod::FullNFull,
        EvalMethod::RadianceOnly,
        EvalMethod::Oidn,
    ];

    pub fn name(self) -> &'static str {
        match self {
            EvalMethod::Noisy => "noisy",
            EvalMethod::G => "g",
            EvalMethod::P => "p",
            EvalMethod::Both => "both",
            EvalMethod::Guided => "guided",
            EvalMethod::GuidedOidn => "guided-oidn",
            EvalMethod::GuidedJoint => "guided-joint",
            EvalMethod::GuidedHalf => "guided-half",
            EvalMethod::FixNTrain => "fix-n-train",
            EvalMethod::FullNFull => "full-n-full",
            EvalMethod::RadianceOnly => "radiance-only",
            EvalMethod::Oidn => "oidn",
        }
    }

    /// Label in tables and plots.
    pub fn label(self) -> &'static str {
        match self {
            EvalMethod::Noisy => "noisy (MC)",
            EvalMethod::G => "D_G (g)",
            EvalMethod::P => "D_P (p)",
            EvalMethod::Both => "both-buffers",
            EvalMethod::Guided => "guided (E over g, p)",
            EvalMethod::GuidedOidn => "guided-oidn (E over OIDN, g, p)",
            EvalMethod::GuidedJoint => "guided, joint E",
            EvalMethod::GuidedHalf => "guided (half)",
            EvalMethod::FixNTrain => "Fix-N-Train",
            EvalMethod::FullNFull => "Full-N-Full",
            EvalMethod::RadianceOnly => "E radiances only",
            EvalMethod::Oidn => "OIDN",
        }
    }

    /// The gated model of a guided method (a gate file over the shipped experts).
    pub fn gated(self) -> Option<crate::cli::gated::GatedKind> {
        match self {
            EvalMethod::Guided => Some(crate::cli::gated::GatedKind::Guided),
            EvalMethod::GuidedOidn => Some(crate::cli::gated::GatedKind::GuidedOidn),
            _ => None,
        }
    }

    /// The model a learned method loads: its method, ablation and preset, which name its weight
    /// file ([`weights::file_stem`], the names `pixguide train --all` writes).
    pub fn model(self) -> Option<(Method, Option<Ablation>, Preset)> {
        match self {
            EvalMethod::Noisy | EvalMethod::Oidn | EvalMethod::Guided | EvalMethod::GuidedOidn => None,
            EvalMethod::G => Some((Method::G, None, Preset::Default)),
            EvalMethod::P => Some((Method::P, None, Preset::Default)),
            EvalMethod::Both => Some((Method::Both, None, Preset::Default)),
            EvalMethod::GuidedJoint => Some((Method::Guided, None, Preset::Default)),
            EvalMethod::GuidedHalf => Some((Method::Guided, None, Preset::Half)),
            EvalMethod::FixNTrain => Some((Method::Guided, Some(Ablation::FixNTrain), Preset::Default)),
            EvalMethod::FullNFull => Some((Method::Guided, Some(Ablation::FullNFull), Preset::Default)),
            EvalMethod::RadianceOnly => Some((Method::Guided, Some(Ablation::RadianceOnly), Preset::Default)),
        }
    }
}

impl std::fmt::Display for EvalMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl clap::ValueEnum for EvalMethod {
    fn value_variants<'a>() -> &'a [Self] {
        &EvalMethod::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

/// Methods shown in the pictures, in order.
pub const PICTURE_METHODS: [EvalMethod; 8] = [
    EvalMethod::Noisy,
    EvalMethod::G,
    EvalMethod::P,
    EvalMethod::Both,
    EvalMethod::Guided,
    EvalMethod::GuidedOidn,
    EvalMethod::GuidedJoint,
    EvalMethod::Oidn,
];

/// Methods of the runtime breakdown, in its row order per spp.
pub const BREAKDOWN_METHODS: [EvalMethod; 2] = [EvalMethod::GuidedJoint, EvalMethod::Oidn];

/// One evaluated method.
pub struct MethodSpec {
    pub kind: EvalMethod,
    /// Weight file (None for noisy and OIDN).
    pub file: Option<PathBuf>,
    /// Identity of the weights (size and FNV-1a hash of the file), "mc" for noisy, OIDN's
    /// version and settings for OIDN.
    pub id: String,
    pub loaded: Option<Loaded>,
    /// A guided model's gate and experts.
    pub gated: Option<crate::cli::gated::GatedDenoiser>,
    /// The OIDN baseline's library, loaded once per run.
    pub oidn: Option<Oidn>,
    /// Why the method is not evaluated, e.g. "no denoiser/weights/both-default.safetensors".
    pub missing: Option<String>,
}

impl MethodSpec {
    /// The method's name, as the cache keys and the page spell it.
    pub fn name(&self) -> &'static str {
        self.kind.name()
    }
    pub fn label(&self) -> &'static str {
        self.kind.label()
    }
    pub fn available(&self) -> bool {
        self.missing.is_none()
    }
    pub(super) fn needs_descriptors(&self) -> bool {
        self.gated.is_some() || self.loaded.as_ref().is_some_and(|l| l.method.needs_descriptors())
    }
}

pub(super) fn methods(a: &EvalArgs) -> Result<Vec<MethodSpec>> {
    let mut kinds = vec![EvalMethod::Noisy];
    for &m in &a.methods {
        if !kinds.contains(&m) {
            kinds.push(m);
        }
    }
    let device = denoiser::cpu_device();
    let mut out = Vec::new();
    let spec = |kind| MethodSpec { kind, file: None, id: String::new(), loaded: None, gated: None, oidn: None, missing: None };
    for kind in kinds {
        if let Some(g) = kind.gated() {
            let file = a.weights_dir.join(g.default_path().file_name().expect("a file name"));
            match crate::cli::gated::load(g, Some(&file)) {
                Ok(gd) => {
                    let id = file_id(&file)?;
                    out.push(MethodSpec { id, gated: Some(gd), file: Some(file), ..spec(kind) });
                }
                Err(e) => {
                    eprintln!("eval: leaving out {kind}: {e:#}");
                    out.push(MethodSpec { missing: Some(format!("{e:#}")), file: Some(file), ..spec(kind) });
                }
            }
            continue;
        }
        let Some((expect, ablation, preset)) = kind.model() else {
            if kind == EvalMethod::Noisy {
                out.push(MethodSpec { id: "mc".into(), ..spec(kind) });
                continue;
            }
            match crate::cli::oidn_setup::load() {
                Ok((o, _)) => out.push(MethodSpec { id: crate::cli::oidn_setup::method_id(&o), oidn: Some(o), ..spec(kind) }),
                Err(e) => {
                    // One line, and the run goes on without it: the baseline is optional.
                    eprintln!("eval: leaving out OIDN: {e:#}");
                    out.push(MethodSpec { missing: Some(format!("{e:#}")), ..spec(kind) });
                }
            }
            continue;
        };
        let file = a.weights_dir.join(format!("{}.safetensors", weights::file_stem(expect, ablation, preset)));
        if !file.exists() {
            out.push(MethodSpec { missing: Some(format!("no {}", file.display())), file: Some(file), ..spec(kind) });
            continue;
        }
        let loaded = weights::load(&file, &device).with_context(|| format!("loading the {kind} weights"))?;
        if loaded.method != expect {
            bail!("{} holds weights of the {} model, but `{kind}` needs {expect} weights", file.display(), loaded.method);
        }
        let id = file_id(&file)?;
        out.push(MethodSpec { id, loaded: Some(loaded), file: Some(file), ..spec(kind) });
    }
    Ok(out)
}

/// Mean weight per expert of a guided model's run, for the page's weight table: W_G and
/// W_P = 1 − W_G averaged over the image, per branch.
pub(super) fn mean_weights(wg: &denoiser::infer::BranchMaps) -> Vec<(String, f64)> {
    let mean = |v: &[f32]| if v.is_empty() { 0.0 } else { v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64 };
    let (d, s) = (mean(&wg.diffuse), mean(&wg.specular));
    vec![("D_G diffuse".into(), d), ("D_P diffuse".into(), 1.0 - d), ("D_G specular".into(), s), ("D_P specular".into(), 1.0 - s)]
}
