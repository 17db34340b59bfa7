//! The guided models as users run them (`render --denoise`, `denoise --model`, `eval`): a gate file
//! (network E, denoiser::gate) over the shipped experts, loaded together and checked to be the
//! experts the gate was trained with.

use anyhow::{bail, Context, Result};
use denoiser::gate::file::{self as gate_file, Gate};
use denoiser::gate::run::{self as gate_run, Experts};
use denoiser::gate::Expert;
use denoiser::infer::{Denoised, InferOptions, Timings};
use denoiser::method::Method;
use denoiser::oidn::Oidn;
use denoiser::weights::Loaded;
use renderer::film::Frame;
use std::path::{Path, PathBuf};

/// The two guided models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GatedKind {
    /// E over D_G and D_P: the paper's pixel-wise guidance.
    Guided,
    /// E over Open Image Denoise, D_G and D_P.
    GuidedOidn,
}

impl GatedKind {
    pub fn name(self) -> &'static str {
        match self {
            GatedKind::Guided => "guided",
            GatedKind::GuidedOidn => "guided-oidn",
        }
    }

    pub fn experts(self) -> &'static [Expert] {
        match self {
            GatedKind::Guided => &[Expert::G, Expert::P],
            GatedKind::GuidedOidn => &[Expert::Oidn, Expert::G, Expert::P],
        }
    }

    /// The shipped gate file.
    pub fn default_path(self) -> PathBuf {
        denoiser::weights::default_path(Method::G).with_file_name(format!("{}-e.safetensors", self.name()))
    }
}

/// A gate with its experts, ready to run.
pub struct GatedDenoiser {
    pub kind: GatedKind,
    pub gate: Gate,
    pub g: Option<Loaded>,
    pub p: Option<Loaded>,
    pub oidn: Option<Oidn>,
    /// Seconds spent loading OIDN's library (once per process).
    pub oidn_load_s: f64,
}

/// Loads the gate of `kind` (from `file`, or the shipped one) and the experts it names. The g and
/// p experts are the shipped weight files; they must be the very files the gate was trained over.
pub fn load(kind: GatedKind, file: Option<&Path>) -> Result<GatedDenoiser> {
    let path = file.map(Path::to_path_buf).unwrap_or_else(|| kind.default_path());
    if !path.exists() {
        bail!("no gate for the {} model: {} does not exist (train one with `pixguide train-gate`)", kind.name(), path.display());
    }
    let gate = gate_file::load(&path, &denoiser::cpu_device())?;
    if gate.header.experts != kind.experts() {
        bail!(
            "{} blends {:?}, but the {} model blends {:?}",
            path.display(),
            gate.header.experts.iter().map(|e| e.name()).collect::<Vec<_>>(),
            kind.name(),
            kind.experts().iter().map(|e| e.name()).collect::<Vec<_>>()
        );
    }
    let mut out = GatedDenoiser { kind, gate, g: None, p: None, oidn: None, oidn_load_s: 0.0 };
    for (e, id) in out.gate.header.experts.clone().iter().zip(out.gate.header.expert_ids.clone()) {
        let have = match e {
            Expert::G | Expert::P => {
                let m = if *e == Expert::G { Method::G } else { Method::P };
                let wp = denoiser::weights::default_path(m);
                let loaded = super::shared::load_weights(m, Some(&wp))?;
                let have = gate_file::file_id(&wp)?;
                if *e == Expert::G {
                    out.g = Some(loaded)
                } else {
                    out.p = Some(loaded)
                }
                have
            }
            Expert::Oidn => {
                let (o, s) = super::oidn_setup::load()?;
                let have = super::oidn_setup::method_id(&o);
                out.oidn = Some(o);
                out.oidn_load_s = s;
                have
            }
        };
        if have != id {
            bail!(
                "{}: the gate was trained over {e} weights {id}, but the {e} expert here is {have}; retrain the gate (`pixguide train-gate`)",
                path.display()
            );
        }
    }
    Ok(out)
}

/// A gated denoise with its parts' timings.
pub struct GatedRun {
    pub denoised: Denoised,
    /// `[K, H, W]` weights in the order of the gate's experts.
    pub weights: Vec<f32>,
    pub expert_seconds: Vec<f64>,
    pub prepare_s: f64,
    pub gate_s: f64,
}

impl GatedDenoiser {
    pub fn experts(&self) -> &[Expert] {
        &self.gate.header.experts
    }

    /// Runs the network experts' convolutions where `inference` says.
    pub fn use_inference(&mut self, inference: &super::shared::Inference) {
        for l in [self.g.as_mut(), self.p.as_mut()].into_iter().flatten() {
            inference.apply(l);
        }
    }

    pub fn run(&self, frame: &mut Frame, opts: &InferOptions) -> Result<GatedRun> {
        let set = Experts { g: self.g.as_ref(), p: self.p.as_ref(), oidn: self.oidn.as_ref() };
        let g = gate_run::denoise(&self.gate, frame, &set, opts, &denoiser::cpu_device()).context("gated denoising")?;
        let total = g.experts.prepare_s + g.experts.seconds.iter().sum::<f64>() + g.gate_s;
        let denoised = Denoised {
            width: frame.width as usize,
            height: frame.height as usize,
            radiance: g.radiance,
            weights_g: None,
            timings: Timings { total_s: total, ..Default::default() },
        };
        Ok(GatedRun { denoised, weights: g.weights, expert_seconds: g.experts.seconds, prepare_s: g.experts.prepare_s, gate_s: g.gate_s })
    }

    pub fn print_summary(&self, run: &GatedRun) {
        let parts: Vec<String> = self.experts().iter().zip(&run.expert_seconds).map(|(e, s)| format!("{} {s:.2} s", e.name())).collect();
        let n = run.denoised.width * run.denoised.height;
        let means: Vec<String> = self
            .experts()
            .iter()
            .enumerate()
            .map(|(k, e)| {
                format!("{} {:.2}", e.name(), run.weights[k * n..(k + 1) * n].iter().map(|&v| v as f64).sum::<f64>() / n.max(1) as f64)
            })
            .collect();
        println!(
            "denoise ({} model: E over {}): {:.2} s = preprocess {:.2} s + {} + E {:.2} s; mean weight {}",
            self.kind.name(),
            self.experts().iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
            run.denoised.timings.total_s,
            run.prepare_s,
            parts.join(" + "),
            run.gate_s,
            means.join(", ")
        );
    }
}

/// Each expert's weight map side by side, viridis from 0 (dark) to 1 (yellow), labelled.
pub fn write_weights_png(path: &Path, width: usize, height: usize, experts: &[Expert], weights: &[f32]) -> Result<()> {
    let (w, h) = (width as u32, height as u32);
    let (gap, label) = (4u32, super::font::BAR_H);
    let k = experts.len() as u32;
    let sw = k * w + (k - 1) * gap;
    let sh = h + label;
    let n = width * height;
    let mut px = vec![32u8; (sw * sh * 3) as usize];
    for (j, e) in experts.iter().enumerate() {
        let x0 = j as u32 * (w + gap);
        let map = &weights[j * n..(j + 1) * n];
        for y in 0..h {
            for x in 0..w {
                let c = colorous::VIRIDIS.eval_continuous(map[(y * w + x) as usize].clamp(0.0, 1.0) as f64);
                let o = (((label + y) * sw + x0 + x) * 3) as usize;
                px[o..o + 3].copy_from_slice(&[c.r, c.g, c.b]);
            }
        }
        if w >= 40 {
            super::font::bar_label(&mut px, sw, (x0, 0), w, &format!("W {}", e.name()));
        }
    }
    super::shared::ensure_parent(path)?;
    renderer::film::png::write_rgb8(path, sw, sh, px).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
