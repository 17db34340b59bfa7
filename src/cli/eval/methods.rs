//! The methods `eval` compares: the table of known ones, and loading each one's weights (or the
//! OIDN library) into a [`MethodSpec`], with the identity its cached measurements are keyed by.

use super::cache::file_id;
use super::EvalArgs;
use anyhow::{bail, Context, Result};
use denoiser::method::Method;
use denoiser::oidn::Oidn;
use denoiser::weights::{self, Loaded};
use std::path::PathBuf;

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
    pub(super) fn needs_descriptors(&self) -> bool {
        self.loaded.as_ref().is_some_and(|l| l.method.needs_descriptors())
    }
}

pub(super) fn methods(a: &EvalArgs) -> Result<Vec<MethodSpec>> {
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
            match crate::cli::oidn_setup::load() {
                Ok((o, _)) => out.push(MethodSpec {
                    name,
                    label,
                    file: None,
                    id: crate::cli::oidn_setup::method_id(&o),
                    loaded: None,
                    oidn: Some(o),
                    missing: None,
                }),
                Err(e) => {
                    // One line, and the run goes on without it: the baseline is optional.
                    eprintln!("eval: leaving out OIDN: {e:#}");
                    out.push(MethodSpec {
                        name,
                        label,
                        file: None,
                        id: String::new(),
                        loaded: None,
                        oidn: None,
                        missing: Some(format!("{e:#}")),
                    });
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
            out.push(MethodSpec {
                name: name.clone(),
                label: label.into(),
                file: Some(file),
                id: String::new(),
                loaded: None,
                oidn: None,
                missing,
            });
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
