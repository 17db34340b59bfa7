//! Compact copies of a training checkpoint, small enough to commit at the end of a session so
//! that another machine can continue the run (issue 12: the whole campaign may add at most
//! 50 MB to the repository, and every session leaves two runs in flight).
//!
//! A checkpoint folder (`<output>.ckpt/`) holds f32 weights, the optimizer's state (Adam's two
//! moments: twice the weights) and each stage's best weights: 16 bytes a parameter. Packed,
//! 6 bytes a parameter:
//! - the weights and the best-stage weights become f16 (the precision of the shipped weight
//!   files); a tensor f16 cannot hold (a value beyond ±65504) stays f32. The rounding, 2⁻¹¹
//!   relative, is far below one Adam step at the campaign's learning rates;
//! - Adam's second moment becomes bf16. Adam divides by its square root, so 2⁻⁸ relative
//!   error there moves a step by under 0.2 %, far below the gradients' step-to-step noise;
//! - Adam's first moment is left out and restored as zeros: it is an average over the last
//!   ~10 steps (β₁ = 0.9), which the resumed run rebuilds within them, while the second moment
//!   (β₂ = 0.999) remembers ~1000 steps and sets every weight's step size.
//!
//! Unpacking converts back to f32, and `pixguide train --resume` continues from it. The run
//! then differs from an uninterrupted one by those roundings and the first moment's restart;
//! a resume from the local checkpoint folder stays bit for bit.

use std::path::Path;

use burn::tensor::{DType, TensorData};

use super::checkpoint::write_atomically;
use super::TrainError;

fn err(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Checkpoint(format!("{}: {e}", path.display()))
}

/// Files of a checkpoint folder that are packed, and how.
const MODEL: &str = "model.safetensors";
const STATE: &str = "state.json";
const OPTIMIZER: &str = "optimizer.bpk";

/// Adam's moments in burn's optimizer record: `<param id>.momentum.moment_1` and `_2`.
const FIRST_MOMENT: &str = ".momentum.moment_1";
const SECOND_MOMENT: &str = ".momentum.moment_2";

/// What [`convert_pack`] does with Adam's first moments.
#[derive(Clone, Copy, PartialEq)]
enum FirstMoments {
    /// Leave them out (packing).
    Drop,
    /// Add zeros beside every second moment that has no first moment (unpacking).
    RestoreAsZeros,
}

/// Rewrites a burnpack file with its float tensors in `dtype`, scalars and metadata kept.
fn convert_pack(from: &Path, to: &Path, dtype: DType, first: FirstMoments) -> Result<(), TrainError> {
    let reader = burn_pack::Reader::from_file_exact(from).map_err(|e| err(from, format!("{e:?}")))?;
    let scalars = reader.scalars().clone();
    let metadata = reader.metadata().clone();
    let mut parts = Vec::new();
    for t in reader.into_tensors().map_err(|e| err(from, format!("{e:?}")))? {
        parts.push(t.into_parts().map_err(|e| err(from, format!("{e:?}")))?);
    }
    let names: std::collections::HashSet<String> = parts.iter().map(|p| p.0.clone()).collect();
    let mut tensors = Vec::new();
    for (name, dt, shape, id, bytes) in parts {
        if first == FirstMoments::Drop && name.ends_with(FIRST_MOMENT) {
            continue;
        }
        let zeros_shape = shape.clone();
        let data = TensorData::from_bytes(bytes, shape, dt);
        let data = if matches!(dt, DType::F32 | DType::BF16 | DType::F16) { data.convert_dtype(dtype) } else { data };
        if first == FirstMoments::RestoreAsZeros {
            if let Some(param) = name.strip_suffix(SECOND_MOMENT) {
                let m1 = format!("{param}{FIRST_MOMENT}");
                if !names.contains(&m1) {
                    let zeros = TensorData::zeros::<f32, _>(zeros_shape).convert_dtype(dtype);
                    let (bytes, shape, dt) = zeros.into_parts();
                    tensors.push(burn_pack::Tensor::new(m1, dt, shape, id, bytes));
                }
            }
        }
        let (bytes, shape, dt) = data.into_parts();
        tensors.push(burn_pack::Tensor::new(name, dt, shape, id, bytes));
    }
    let mut w = burn_pack::Writer::new(tensors).overwrite(true);
    for (k, v) in &scalars {
        w = w.with_scalar(k, *v);
    }
    for (k, v) in &metadata {
        w = w.with_metadata(k, v);
    }
    let bytes = w.into_bytes().map_err(|e| err(to, format!("{e:?}")))?;
    write_atomically(to, &bytes)
}

/// Rewrites a safetensors weight file with every tensor in `dtype` (F16 or F32), metadata kept.
/// A tensor with a finite value beyond f16's range stays f32, so packing never makes an
/// infinity.
fn convert_weights(from: &Path, to: &Path, dtype: safetensors::Dtype) -> Result<(), TrainError> {
    let bytes = std::fs::read(from).map_err(|e| err(from, e))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| err(from, e))?;
    let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| err(from, e))?;
    let mut out: Vec<(String, safetensors::Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    for (name, t) in st.tensors() {
        let values: Vec<f32> = match t.dtype() {
            safetensors::Dtype::F32 => t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            safetensors::Dtype::F16 => t.data().chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect(),
            d => return Err(err(from, format!("tensor `{name}` is {d:?}, expected f32 or f16"))),
        };
        let fits_f16 = values.iter().all(|&v| !v.is_finite() || half::f16::from_f32(v).is_finite());
        let (dt, raw) = match dtype {
            safetensors::Dtype::F16 if fits_f16 => {
                (safetensors::Dtype::F16, values.iter().flat_map(|&v| half::f16::from_f32(v).to_le_bytes()).collect())
            }
            _ => (safetensors::Dtype::F32, values.iter().flat_map(|v| v.to_le_bytes()).collect()),
        };
        out.push((name, dt, t.shape().to_vec(), raw));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    let views = out
        .iter()
        .map(|(n, dt, s, b)| Ok((n.clone(), safetensors::tensor::TensorView::new(*dt, s.clone(), b).map_err(|e| err(from, e))?)))
        .collect::<Result<Vec<_>, TrainError>>()?;
    let meta: std::collections::HashMap<String, String> = meta.metadata().clone().unwrap_or_default();
    let data = safetensors::serialize(views, Some(meta)).map_err(|e| err(to, e))?;
    write_atomically(to, &data)
}

fn best_stages(dir: &Path) -> Result<Vec<String>, TrainError> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| err(dir, e))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("best-stage") && n.ends_with(".safetensors"))
        .collect();
    v.sort();
    Ok(v)
}

/// Packs checkpoint folder `ckpt` into folder `out`; returns the packed bytes.
pub fn pack(ckpt: &Path, out: &Path) -> Result<u64, TrainError> {
    for f in [MODEL, STATE] {
        if !ckpt.join(f).exists() {
            return Err(err(&ckpt.join(f), "missing: not a checkpoint folder (`<output>.ckpt/` of `pixguide train`)"));
        }
    }
    std::fs::create_dir_all(out).map_err(|e| err(out, e))?;
    let bytes = std::fs::read(ckpt.join(STATE)).map_err(|e| err(&ckpt.join(STATE), e))?;
    write_atomically(&out.join(STATE), &bytes)?;
    convert_weights(&ckpt.join(MODEL), &out.join(MODEL), safetensors::Dtype::F16)?;
    if ckpt.join(OPTIMIZER).exists() {
        convert_pack(&ckpt.join(OPTIMIZER), &out.join(OPTIMIZER), DType::BF16, FirstMoments::Drop)?;
    }
    for b in best_stages(ckpt)? {
        convert_weights(&ckpt.join(&b), &out.join(&b), safetensors::Dtype::F16)?;
    }
    let mut total = 0;
    for e in std::fs::read_dir(out).map_err(|e| err(out, e))?.flatten() {
        total += e.metadata().map(|m| m.len()).unwrap_or(0);
    }
    Ok(total)
}

/// Unpacks a folder made by [`pack`] into checkpoint folder `ckpt` (f32 again), ready for
/// `pixguide train --resume`.
pub fn unpack(packed: &Path, ckpt: &Path) -> Result<(), TrainError> {
    for f in [MODEL, STATE] {
        if !packed.join(f).exists() {
            return Err(err(&packed.join(f), "missing: not a packed checkpoint (`pixguide checkpoint pack`)"));
        }
    }
    std::fs::create_dir_all(ckpt).map_err(|e| err(ckpt, e))?;
    if packed.join(OPTIMIZER).exists() {
        convert_pack(&packed.join(OPTIMIZER), &ckpt.join(OPTIMIZER), DType::F32, FirstMoments::RestoreAsZeros)?;
    }
    for b in best_stages(packed)? {
        convert_weights(&packed.join(&b), &ckpt.join(&b), safetensors::Dtype::F32)?;
    }
    convert_weights(&packed.join(MODEL), &ckpt.join(MODEL), safetensors::Dtype::F32)?;
    // The state last: it names the step the other files hold (checkpoint.rs).
    let bytes = std::fs::read(packed.join(STATE)).map_err(|e| err(&packed.join(STATE), e))?;
    write_atomically(&ckpt.join(STATE), &bytes)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_f32(path: &Path, name: &str, values: &[f32]) {
        let raw: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![values.len()], &raw).unwrap();
        std::fs::write(path, safetensors::serialize([(name.to_string(), view)], None).unwrap()).unwrap();
    }

    fn read(path: &Path) -> (safetensors::Dtype, Vec<f32>) {
        let bytes = std::fs::read(path).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let t = st.tensor("w").unwrap();
        let v = match t.dtype() {
            safetensors::Dtype::F16 => t.data().chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect(),
            _ => t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
        };
        (t.dtype(), v)
    }

    /// Weights become f16 within its rounding, except a tensor with a value f16 would turn into
    /// infinity, which stays f32 exactly.
    #[test]
    fn weights_pack_to_f16_unless_f16_would_overflow() {
        let dir = std::env::temp_dir().join(format!("pixguide-pack-f16-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let small = [0.1f32, -2.5, 3e-6, 0.0, 65000.0];
        write_f32(&dir.join("a.safetensors"), "w", &small);
        convert_weights(&dir.join("a.safetensors"), &dir.join("a16.safetensors"), safetensors::Dtype::F16).unwrap();
        let (dt, v) = read(&dir.join("a16.safetensors"));
        assert_eq!(dt, safetensors::Dtype::F16);
        for (a, b) in small.iter().zip(&v) {
            assert!((a - b).abs() <= a.abs() * 2f32.powi(-11) + 6e-8, "{a} -> {b}");
        }
        let big = [0.1f32, 1e6, -7.0];
        write_f32(&dir.join("b.safetensors"), "w", &big);
        convert_weights(&dir.join("b.safetensors"), &dir.join("b16.safetensors"), safetensors::Dtype::F16).unwrap();
        assert_eq!(read(&dir.join("b16.safetensors")), (safetensors::Dtype::F32, big.to_vec()));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
