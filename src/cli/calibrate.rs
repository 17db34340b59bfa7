//! `pixguide calibrate`: fits the exponent of a trained U-Net model's guide gain
//! (`denoiser::mskp::guide_gain`) on a dataset's validation shots and writes the model with it.
//! The tensors are not touched; the file's config and provenance notes say what changed.

use super::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use denoiser::train::calibrate::{calibrate_guide_gain, DEFAULT_EXPONENTS};
use denoiser::train::data::{Dataset, LoadOptions};
use denoiser::train::patches::Sampling;
use denoiser::train::TrainOptions;
use denoiser::weights;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Clone)]
pub struct CalibrateArgs {
    /// Dataset folder written by `pixguide dataset`; only its validation shots are read.
    #[arg(long)]
    pub data: PathBuf,
    /// Trained weights (a U-Net preset with edge-stopping guides).
    #[arg(long)]
    pub weights: PathBuf,
    /// Where to write the calibrated weights (may be the same file).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Exponents γ to try; the gain at N spp is (N/2)^γ.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_EXPONENTS.to_vec())]
    pub exponents: Vec<f64>,
    /// Validation patch side: use the one the model was trained with (its validation scores
    /// are then comparable with the training log's).
    #[arg(long, default_value_t = 96)]
    pub patch: usize,
    /// Backend of the validation passes (flex, or tch with `--features tch`).
    #[arg(long, value_enum, default_value_t = denoiser::Backend::Flex)]
    pub backend: denoiser::Backend,
}

pub fn run(a: CalibrateArgs) -> Result<()> {
    if a.exponents.is_empty() || a.exponents.iter().any(|g| !g.is_finite() || *g < 0.0 || *g > 4.0) {
        bail!("--exponents: expected finite values in [0, 4], got {:?}", a.exponents);
    }
    let backend = a.backend;
    let device = backend.training_device().map_err(|e| anyhow::anyhow!("--backend {}: {e}", a.backend))?;
    let mut loaded = weights::load(&a.weights, &device).with_context(|| format!("reading {}", a.weights.display()))?;
    let Some(mskp) = loaded.config.mskp.as_ref() else {
        bail!("{}: a KPCN model has no edge-stopping guides to calibrate", a.weights.display());
    };
    if mskp.edge_stopping == denoiser::mskp::EdgeStopping::Off {
        bail!("{}: preset {} has no edge-stopping guides to calibrate", a.weights.display(), loaded.preset);
    }
    let before = mskp.guide_gain_exponent;
    let method = loaded.method;
    let load = LoadOptions {
        spps: Vec::new(),
        descriptors: method.needs_descriptors(),
        patch: a.patch,
        sampling: Sampling::Uniform,
        max_train: Some(0),
    };
    let t0 = Instant::now();
    let data = Dataset::load(&a.data, &load, &mut |_, _| {})?;
    eprintln!("{}: {} validation shots {}×{} at {:?} spp", a.data.display(), data.val.len(), data.width, data.height, data.spps);
    let opts = TrainOptions { backend, ..TrainOptions::new(method, loaded.config.clone(), a.patch, 1, Vec::new()) };
    let bar = progress::bar(a.exponents.len() as u64, "calibrating");
    let spps = data.spps.clone();
    let cal = calibrate_guide_gain(&mut loaded.model, &data, &opts, &a.exponents, &mut |g, v| {
        let by: Vec<String> = spps.iter().zip(&v.by_spp).map(|(s, e)| format!("{s}: {e:.5}")).collect();
        let line = format!("γ {g:<6} validation {:.5}  ({})", v.overall, by.join(", "));
        bar.suspend(|| eprintln!("{line}"));
        bar.inc(1);
    })?
    .context("no validation shots in the dataset")?;
    bar.finish_and_clear();
    let best = cal.best;
    let score = |g: f64| cal.tried.iter().find(|t| t.0 == g).map(|t| t.1.overall);
    println!(
        "kept γ = {best} (validation {:.5}; γ = 0: {})",
        score(best).unwrap_or(f64::NAN),
        score(0.0).map_or("not tried".into(), |v| format!("{v:.5}"))
    );
    loaded.config.mskp.as_mut().expect("checked above").guide_gain_exponent = best;
    let tried: Vec<String> = cal.tried.iter().map(|(g, v)| format!("{g}: {:.5}", v.overall)).collect();
    let note = format!(
        "guide_gain_exponent {before} -> {best} after training (inference only), fitted by `pixguide calibrate` on the {} validation shots of {} at patch {} (validation test relMSE per γ: {})",
        data.val.len(),
        a.data.display(),
        a.patch,
        tried.join(", ")
    );
    let notes = &mut loaded.provenance.notes;
    *notes = if notes.is_empty() { note } else { format!("{notes}; {note}") };
    weights::save(&a.output, &loaded.model, &loaded.config, &loaded.preset, &loaded.provenance)
        .with_context(|| format!("writing {}", a.output.display()))?;
    eprintln!("{} written in {:.0} s", a.output.display(), t0.elapsed().as_secs_f64());
    Ok(())
}
