//! Validation during training: the test relMSE of a model over the fixed patch grid of every
//! validation shot at every sample count, overall and per count.

use burn::module::Module;

use super::augment::Dihedral;
use super::data::{batch_tensors, Dataset, PatchRef};
use super::{patches, TrainError, TrainOptions};
use crate::loss::rel_mse_test;
use crate::method::MethodModel;

/// The test relMSE ([`rel_mse_test`], what `pixguide eval` reports) over the fixed validation
/// grid of every val shot at every spp, mean over patches. The paper validates on linear
/// relMSE_val (method.md §7.3); on our short runs that chose checkpoints full of fireflies. `None` without validation shots.
pub fn validate(model: &MethodModel, data: &Dataset, opts: &TrainOptions) -> Result<Option<f64>, TrainError> {
    Ok(validate_by_spp(model, data, opts)?.map(|v| v.overall))
}

/// [`validate`]'s score, and the same mean at each of the dataset's sample counts.
#[derive(Clone, Debug, PartialEq)]
pub struct Validation {
    pub overall: f64,
    /// Mean over the patches at `data.spps[i]`.
    pub by_spp: Vec<f64>,
}

/// [`validate`] with the mean at each sample count as well.
pub fn validate_by_spp(model: &MethodModel, data: &Dataset, opts: &TrainOptions) -> Result<Option<Validation>, TrainError> {
    if data.val.is_empty() {
        return Ok(None);
    }
    let m = model.valid();
    let dev = opts.backend.device().expect("run() checked the backend");
    let margin = opts.config.margin();
    let grid = patches::grid(data.width, data.height, opts.patch);
    let with_desc = opts.method.needs_descriptors();
    let mut refs = Vec::new();
    for shot in 0..data.val.len() {
        for spp in 0..data.spps.len() {
            for &(x, y) in &grid {
                refs.push(PatchRef { shot, spp, x, y, t: Dihedral::IDENTITY });
            }
        }
    }
    let (mut sum, mut n) = (0.0f64, 0usize);
    let mut per_spp = vec![(0.0f64, 0usize); data.spps.len()];
    // Chunks never mix sample counts (tensor shapes must agree): refs are grouped by spp.
    let mut i = 0;
    while i < refs.len() {
        let mut j = i + 1;
        while j < refs.len() && j - i < opts.val_batch.max(1) && refs[j].spp == refs[i].spp && refs[j].shot == refs[i].shot {
            j += 1;
        }
        let chunk = &refs[i..j];
        let (input, target) = batch_tensors(&data.val, chunk, &data.spps, opts.patch, margin, with_desc, &dev)?;
        let out = m.forward(input);
        let v: f32 = rel_mse_test(out.radiance, target.total).into_scalar();
        sum += v as f64 * chunk.len() as f64;
        n += chunk.len();
        let s = &mut per_spp[refs[i].spp];
        s.0 += v as f64 * chunk.len() as f64;
        s.1 += chunk.len();
        i = j;
    }
    Ok(Some(Validation { overall: sum / n as f64, by_spp: per_spp.into_iter().map(|(s, k)| s / k.max(1) as f64).collect() }))
}
