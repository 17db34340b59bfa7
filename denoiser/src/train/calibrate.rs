//! After training: the exponent γ of the guides' sample-count gain ([`crate::mskp::guide_gain`])
//! that scores best on the validation shots, with the networks' parameters left as trained.
//!
//! Why after training rather than by the test scenes: γ is one scalar per weight file, and the
//! held-out test scenes must not choose it. The validation shots are the measure training
//! already uses to keep its best checkpoint ([`super::validate`]); the calibration uses the same
//! score, so it can only pick a γ that training's own criterion prefers.

use super::data::Dataset;
use super::{validate_by_spp, TrainError, TrainOptions, Validation};
use crate::method::MethodModel;

/// The candidates `pixguide calibrate` tries by default: 0 (no gain, the weights as trained) to
/// 3, finest around 1. The shipped edge-noise models scored best at 1 (g), 1.25 (guided) and
/// 2.5 (p) (docs/journal/denoiser.md, "Guide strength grows with the sample count"); the grid brackets
/// them.
pub const DEFAULT_EXPONENTS: [f64; 9] = [0.0, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0];

/// Every candidate's validation, and the one kept.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// (γ, its validation) in the order tried.
    pub tried: Vec<(f64, Validation)>,
    /// The γ of the lowest overall score (the first on a tie, so 0 wins a tie with the
    /// weights as trained).
    pub best: f64,
}

/// Scores `model` on the validation shots of `data` with each exponent in turn (`progress`
/// hears each result as it comes). `None` without validation shots or candidates; an error if a
/// shot's descriptors cannot be read. The model is
/// left with the best exponent set.
pub fn calibrate_guide_gain(
    model: &mut MethodModel,
    data: &Dataset,
    opts: &TrainOptions,
    exponents: &[f64],
    progress: &mut dyn FnMut(f64, &Validation),
) -> Result<Option<Calibration>, TrainError> {
    let mut tried = Vec::with_capacity(exponents.len());
    for &g in exponents {
        model.set_guide_gain_exponent(g);
        let Some(v) = validate_by_spp(model, data, opts)? else { return Ok(None) };
        progress(g, &v);
        tried.push((g, v));
    }
    let Some(best) = tried.iter().fold(None::<&(f64, Validation)>, |b, t| match b {
        Some(b) if b.1.overall <= t.1.overall => Some(b),
        _ => Some(t),
    }) else {
        return Ok(None);
    };
    let best = best.0;
    model.set_guide_gain_exponent(best);
    Ok(Some(Calibration { tried, best }))
}
