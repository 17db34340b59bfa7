//! Rewrites a weight file with another edge-stopping variant in its configuration, the tensors
//! unchanged, and says so in its provenance notes. For inference-only changes of a guide's test
//! that leave the networks' parameters valid (docs/journal/denoiser.md, "Doubting black diffuse pixels").
//!
//! `cargo run --release -p denoiser --example set_edge_stopping -- IN OUT VARIANT "why"`
//! (VARIANT as the config spells it, e.g. `FeaturesAndFadingNoisyColourDoubtingBlack`).

use std::path::PathBuf;

use denoiser::mskp::EdgeStopping;
use denoiser::weights;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output, variant, why] = args.as_slice() else {
        return Err("usage: set_edge_stopping IN OUT VARIANT WHY".into());
    };
    let (input, output) = (PathBuf::from(input), PathBuf::from(output));
    let variant: EdgeStopping =
        serde_json::from_value(serde_json::Value::String(variant.clone())).map_err(|e| format!("VARIANT {variant:?}: {e}"))?;
    let device = denoiser::cpu_device();
    let mut loaded = weights::load(&input, &device)?;
    let Some(mskp) = loaded.config.mskp.as_mut() else {
        return Err(format!("{}: a KPCN model has no edge-stopping guides", input.display()).into());
    };
    let before = mskp.edge_stopping;
    mskp.edge_stopping = variant;
    let note = format!("edge_stopping {before:?} -> {variant:?} after training (inference only): {why}");
    let notes = &mut loaded.provenance.notes;
    *notes = if notes.is_empty() { note } else { format!("{notes}; {note}") };
    weights::save(&output, &loaded.model, &loaded.config, &loaded.preset, &loaded.provenance)?;
    // The saved file must load into the new variant and hold the same tensors.
    let back = weights::load(&output, &device)?;
    if back.config.mskp.as_ref().map(|m| m.edge_stopping) != Some(variant) {
        return Err(format!("{}: variant not stored", output.display()).into());
    }
    println!("{} -> {}: {before:?} -> {variant:?}", input.display(), output.display());
    Ok(())
}
