//! `pixguide quantize`: a trained weight file rewritten with its kernels in 8 bits, half the
//! size of the f16 file `pixguide train` writes, for shipping (denoiser/src/quantize.rs).

use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct QuantizeArgs {
    /// A weight file written by `pixguide train` (f16 or f32).
    pub weights: PathBuf,
    /// Where to write the 8-bit file (its training log, `<weights>.log.jsonl`, is not copied).
    #[arg(short, long)]
    pub output: PathBuf,
}

pub fn run(a: QuantizeArgs) -> Result<()> {
    if a.output == a.weights {
        bail!("{}: --output must differ from the input, which stays the training run's record", a.output.display());
    }
    // Loading first checks that the file is a complete pixguide model, not just safetensors.
    denoiser::weights::load(&a.weights, &denoiser::cpu_device())?;
    let bytes = std::fs::read(&a.weights).with_context(|| format!("reading {}", a.weights.display()))?;
    let out = denoiser::quantize::quantize(&bytes).map_err(|m| anyhow::anyhow!("{}: {m}", a.weights.display()))?;
    let tmp = a.output.with_extension("safetensors.tmp");
    std::fs::write(&tmp, &out).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, &a.output).with_context(|| format!("writing {}", a.output.display()))?;
    denoiser::weights::load(&a.output, &denoiser::cpu_device()).with_context(|| format!("reading back {}", a.output.display()))?;
    println!(
        "{} ({:.2} MB) → {} ({:.2} MB, 8-bit kernels)",
        a.weights.display(),
        bytes.len() as f64 / 1e6,
        a.output.display(),
        out.len() as f64 / 1e6
    );
    Ok(())
}
