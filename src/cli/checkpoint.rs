//! `pixguide checkpoint pack|unpack`: a training run's checkpoint folder made small enough to
//! commit (weights in f16, the optimizer's second moments in 8 bits, its first moments dropped:
//! about 5 bytes a parameter), and back, so that a run
//! continues on another machine (denoiser/src/train/pack.rs says what is rounded and why).

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use denoiser::train::pack;
use std::path::PathBuf;

#[derive(Args)]
pub struct CheckpointArgs {
    #[command(subcommand)]
    pub action: Action,
}

#[derive(Subcommand)]
pub enum Action {
    /// Pack a checkpoint folder (`<output>.ckpt/` of `pixguide train`) into OUTPUT.
    Pack {
        checkpoint: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Unpack a packed folder into a checkpoint folder that `pixguide train --resume` continues
    /// from (`<output>.ckpt/` of the run, or its `--checkpoint-dir`).
    Unpack {
        packed: PathBuf,
        #[arg(short, long)]
        output: PathBuf,
    },
}

pub fn run(a: CheckpointArgs) -> Result<()> {
    match a.action {
        Action::Pack { checkpoint, output } => {
            let bytes = pack::pack(&checkpoint, &output).with_context(|| format!("packing {}", checkpoint.display()))?;
            println!("packed {} into {} ({:.1} MiB)", checkpoint.display(), output.display(), bytes as f64 / (1u64 << 20) as f64);
        }
        Action::Unpack { packed, output } => {
            pack::unpack(&packed, &output).with_context(|| format!("unpacking {}", packed.display()))?;
            println!("unpacked {} into {}; continue with `pixguide train … --resume`", packed.display(), output.display());
        }
    }
    Ok(())
}
