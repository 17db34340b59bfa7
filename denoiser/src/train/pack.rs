//! Compact copies of a training checkpoint, small enough to commit at the end of a session so
//! that another machine can continue the run (issue 12: the whole campaign may add at most
//! 50 MB to the repository).
//!
//! A checkpoint folder (`<output>.ckpt/`) holds f32 weights, the optimizer's state (Adam's two
//! moments: twice the weights) and each stage's best weights. Packed:
//! - `model.safetensors` and `state.json` are copied as they are: the weights stay exact;
//! - the optimizer's tensors become bf16 (a third of the folder's bytes saved). Adam divides
//!   by the square root of its second moment, so 2⁻⁸ relative error there moves a step by
//!   under 0.2 %, far below the step-to-step noise of the gradients;
//! - best-stage weights become f16, the precision the shipped weight files have anyway.
//!
//! Unpacking converts back to f32, and `pixguide train --resume` continues from it. The run
//! then differs from an uninterrupted one by those roundings only; a resume from the local
//! checkpoint folder stays bit for bit.

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

/// Rewrites a burnpack file with its float tensors in `dtype`, scalars and metadata kept.
fn convert_pack(from: &Path, to: &Path, dtype: DType) -> Result<(), TrainError> {
    let reader = burn_pack::Reader::from_file_exact(from).map_err(|e| err(from, format!("{e:?}")))?;
    let scalars = reader.scalars().clone();
    let metadata = reader.metadata().clone();
    let tensors = reader
        .into_tensors()
        .map_err(|e| err(from, format!("{e:?}")))?
        .into_iter()
        .map(|t| {
            let (name, dt, shape, id, bytes) = t.into_parts().map_err(|e| err(from, format!("{e:?}")))?;
            let data = TensorData::from_bytes(bytes, shape, dt);
            let data = if matches!(dt, DType::F32 | DType::BF16 | DType::F16) { data.convert_dtype(dtype) } else { data };
            let (bytes, shape, dt) = data.into_parts();
            Ok(burn_pack::Tensor::new(name, dt, shape, id, bytes))
        })
        .collect::<Result<Vec<_>, TrainError>>()?;
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
fn convert_weights(from: &Path, to: &Path, dtype: safetensors::Dtype) -> Result<(), TrainError> {
    let bytes = std::fs::read(from).map_err(|e| err(from, e))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| err(from, e))?;
    let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| err(from, e))?;
    let mut out: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    for (name, t) in st.tensors() {
        let values: Vec<f32> = match t.dtype() {
            safetensors::Dtype::F32 => t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            safetensors::Dtype::F16 => t.data().chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect(),
            d => return Err(err(from, format!("tensor `{name}` is {d:?}, expected f32 or f16"))),
        };
        let raw = match dtype {
            safetensors::Dtype::F16 => values.iter().flat_map(|&v| half::f16::from_f32(v).to_le_bytes()).collect(),
            _ => values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        };
        out.push((name, t.shape().to_vec(), raw));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    let views = out
        .iter()
        .map(|(n, s, b)| Ok((n.clone(), safetensors::tensor::TensorView::new(dtype, s.clone(), b).map_err(|e| err(from, e))?)))
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
    for f in [MODEL, STATE] {
        let bytes = std::fs::read(ckpt.join(f)).map_err(|e| err(&ckpt.join(f), e))?;
        write_atomically(&out.join(f), &bytes)?;
    }
    if ckpt.join(OPTIMIZER).exists() {
        convert_pack(&ckpt.join(OPTIMIZER), &out.join(OPTIMIZER), DType::BF16)?;
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
        convert_pack(&packed.join(OPTIMIZER), &ckpt.join(OPTIMIZER), DType::F32)?;
    }
    for b in best_stages(packed)? {
        convert_weights(&packed.join(&b), &ckpt.join(&b), safetensors::Dtype::F32)?;
    }
    // The state last: it names the step the other files hold (checkpoint.rs).
    for f in [MODEL, STATE] {
        let bytes = std::fs::read(packed.join(f)).map_err(|e| err(&packed.join(f), e))?;
        write_atomically(&ckpt.join(f), &bytes)?;
    }
    Ok(())
}
