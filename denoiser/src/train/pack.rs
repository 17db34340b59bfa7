//! Compact copies of a training checkpoint, small enough to commit or copy at the end of a
//! sitting so that another machine can continue the run (a g checkpoint folder is 15 MiB,
//! its packed copy under 5).
//!
//! A checkpoint folder (`<output>.ckpt/`) holds f32 weights, the optimizer's state (Adam's two
//! moments: twice the weights) and each stage's best weights: 16 bytes a parameter. Packed,
//! 5 bytes a parameter:
//! - the weights and the best-stage weights become f16 (the precision of the shipped weight
//!   files); a tensor f16 cannot hold (a value beyond ±65504) stays f32. The rounding, 2⁻¹¹
//!   relative, is far below one Adam step at the campaign's learning rates;
//! - Adam's second moment takes one byte a value, log-quantised per block ([`encode_log8`]):
//!   Adam divides by its square root, so each weight's step size moves by under 3 %, and
//!   the resumed run's gradients overwrite 0.1 % of it a step (β₂ = 0.999);
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

/// Which way [`convert_pack`] converts an optimizer record.
#[derive(Clone, Copy, PartialEq)]
enum Direction {
    /// First moments left out, second moments in 8 bits ([`encode_log8`]), other floats bf16.
    Pack,
    /// Every float back to f32, second moments decoded, zero first moments restored.
    Unpack,
}

/// Suffix of the tensor holding a packed second moment's per-block log₂ range.
const LOG2_RANGE: &str = ".log2_range";
/// Values per block of [`encode_log8`].
const BLOCK: usize = 256;

/// Adam's second moment (non-negative, spread over many octaves) in one byte a value: per
/// block of 256, its log₂ quantised to 254 steps between the block's smallest and largest
/// positive value; 0 stands for 0 (8-bit optimizer states, Dettmers et al. 2022, quantise
/// block-wise for the same reason: one range per tensor would flatten its small values). A
/// block spanning 2⁴⁰ keeps each value within 2^(40/508) − 1 ≈ 5.6 % (2.8 % on the step size,
/// which divides by the square root). Returns the bytes and each block's (lo, hi).
fn encode_log8(v: &[f32]) -> (Vec<u8>, Vec<f32>) {
    let mut q = Vec::with_capacity(v.len());
    let mut ranges = Vec::with_capacity(2 * v.len().div_ceil(BLOCK));
    for block in v.chunks(BLOCK) {
        let logs = block.iter().filter(|x| **x > 0.0 && x.is_finite()).map(|x| x.log2());
        let (lo, hi) = logs.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), l| (lo.min(l), hi.max(l)));
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (0.0, 0.0) };
        ranges.extend([lo, hi]);
        let span = hi - lo;
        q.extend(block.iter().map(|&x| {
            if !(x > 0.0 && x.is_finite()) {
                0
            } else if span > 0.0 {
                1 + ((x.log2() - lo) / span * 254.0).round().clamp(0.0, 254.0) as u8
            } else {
                1
            }
        }));
    }
    (q, ranges)
}

/// Inverse of [`encode_log8`].
fn decode_log8(q: &[u8], ranges: &[f32]) -> Vec<f32> {
    q.chunks(BLOCK)
        .zip(ranges.chunks_exact(2))
        .flat_map(|(block, r)| {
            let (lo, span) = (r[0], r[1] - r[0]);
            block.iter().map(move |&b| if b == 0 { 0.0 } else { (lo + (b - 1) as f32 / 254.0 * span).exp2() })
        })
        .collect()
}

/// Rewrites a burnpack optimizer record (see [`Direction`]), scalars and metadata kept.
fn convert_pack(from: &Path, to: &Path, direction: Direction) -> Result<(), TrainError> {
    let reader = burn_pack::Reader::from_file_exact(from).map_err(|e| err(from, format!("{e:?}")))?;
    let scalars = reader.scalars().clone();
    let metadata = reader.metadata().clone();
    let mut parts = std::collections::BTreeMap::new();
    for t in reader.into_tensors().map_err(|e| err(from, format!("{e:?}")))? {
        let (name, dt, shape, id, bytes) = t.into_parts().map_err(|e| err(from, format!("{e:?}")))?;
        parts.insert(name, (dt, shape, id, bytes));
    }
    let values =
        |name: &str, data: TensorData| data.convert_dtype(DType::F32).try_to_vec::<f32>().map_err(|e| err(from, format!("{name}: {e:?}")));
    let mut tensors = Vec::new();
    let mut push = |name: String, data: TensorData, id: Option<u64>| {
        let (bytes, shape, dt) = data.into_parts();
        tensors.push(burn_pack::Tensor::new(name, dt, shape, id, bytes));
    };
    for (name, (dt, shape, id, bytes)) in &parts {
        let n = shape.num_elements();
        let data = TensorData::from_bytes(bytes.clone(), shape.clone(), *dt);
        let is_float = matches!(dt, DType::F32 | DType::BF16 | DType::F16);
        match direction {
            Direction::Pack if name.ends_with(FIRST_MOMENT) => {}
            Direction::Pack if name.ends_with(SECOND_MOMENT) && is_float => {
                let (q, ranges) = encode_log8(&values(name, data)?);
                let n_ranges = ranges.len();
                push(name.clone(), TensorData::new(q, shape.clone()), *id);
                push(format!("{name}{LOG2_RANGE}"), TensorData::new(ranges, [n_ranges]), None);
            }
            Direction::Pack => push(name.clone(), if is_float { data.convert_dtype(DType::BF16) } else { data }, *id),
            Direction::Unpack if name.ends_with(LOG2_RANGE) => {}
            Direction::Unpack => {
                let data = if name.ends_with(SECOND_MOMENT) && *dt == DType::U8 {
                    let Some((_, rshape, _, rbytes)) = parts.get(&format!("{name}{LOG2_RANGE}")) else {
                        return Err(err(from, format!("{name}: 8-bit second moment without its {LOG2_RANGE}")));
                    };
                    let ranges = values(name, TensorData::from_bytes(rbytes.clone(), rshape.clone(), DType::F32))?;
                    let q = data.try_to_vec::<u8>().map_err(|e| err(from, format!("{name}: {e:?}")))?;
                    if ranges.len() != 2 * n.div_ceil(BLOCK) {
                        return Err(err(from, format!("{name}: {} range values for {n} values", ranges.len())));
                    }
                    TensorData::new(decode_log8(&q, &ranges), shape.clone())
                } else if is_float {
                    data.convert_dtype(DType::F32)
                } else {
                    data
                };
                if let Some(param) = name.strip_suffix(SECOND_MOMENT) {
                    let m1 = format!("{param}{FIRST_MOMENT}");
                    if !parts.contains_key(&m1) {
                        push(m1, TensorData::zeros::<f32, _>(shape.clone()), *id);
                    }
                }
                push(name.clone(), data, *id);
            }
        }
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
    let mut out: Vec<crate::tensor_file::OwnedTensor> = Vec::new();
    for (name, t) in st.tensors() {
        let values = crate::tensor_file::tensor_floats(&name, t.dtype(), t.data()).map_err(|m| err(from, m))?;
        // Converted once; kept only if no finite value became infinite.
        let halves = (dtype == safetensors::Dtype::F16)
            .then(|| values.iter().map(|&v| half::f16::from_f32(v)).collect::<Vec<_>>())
            .filter(|h| h.iter().zip(&values).all(|(h, v)| h.is_finite() || !v.is_finite()));
        let (dt, raw) = match halves {
            Some(h) => (safetensors::Dtype::F16, h.iter().flat_map(|x| x.to_le_bytes()).collect()),
            None => (safetensors::Dtype::F32, values.iter().flat_map(|v| v.to_le_bytes()).collect()),
        };
        out.push((name, dt, t.shape().to_vec(), raw));
    }
    let meta: std::collections::HashMap<String, String> = meta.metadata().clone().unwrap_or_default();
    let data = crate::tensor_file::serialize_tensors(out, meta).map_err(|m| err(to, m))?;
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
        convert_pack(&ckpt.join(OPTIMIZER), &out.join(OPTIMIZER), Direction::Pack)?;
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
        convert_pack(&packed.join(OPTIMIZER), &ckpt.join(OPTIMIZER), Direction::Unpack)?;
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

    /// The 8-bit second moment keeps zeros, keeps every positive value within half a
    /// quantisation step of its block's log₂ span, and survives a block of one value, a block
    /// of zeros and a partial last block.
    #[test]
    fn second_moments_round_trip_within_their_block_resolution() {
        let mut v: Vec<f32> = (0..700).map(|i| 1e-12 * 1.1f32.powi(i % 290)).collect();
        v[3] = 0.0;
        v[300] = 1e-30;
        v[600..650].iter_mut().for_each(|x| *x = 0.0);
        v.extend([5e-7; 10]);
        let (q, ranges) = encode_log8(&v);
        assert_eq!((q.len(), ranges.len()), (v.len(), 2 * v.len().div_ceil(BLOCK)));
        let back = decode_log8(&q, &ranges);
        for (i, (a, b)) in v.iter().zip(&back).enumerate() {
            let r = &ranges[2 * (i / BLOCK)..];
            let half_step = (r[1] - r[0]) / 254.0 / 2.0;
            if *a == 0.0 {
                assert_eq!(*b, 0.0, "{i}");
            } else {
                assert!((b.log2() - a.log2()).abs() <= half_step + 1e-4, "{i}: {a} -> {b}");
            }
        }
        let (q, ranges) = encode_log8(&[5e-7; 10]);
        assert!(decode_log8(&q, &ranges).iter().all(|x| (x / 5e-7 - 1.0).abs() < 1e-5));
    }

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
