//! 8-bit storage of weight files, for shipping: every weight matrix or convolution kernel is
//! stored as signed bytes with one f32 scale per row (per output channel of a convolution), the
//! small tensors (biases, weight-norm gains, E's and the guides' few numbers) stay as they were.
//! That halves an f16 file, and so halves what each shipped model adds to the repository (issue
//! 12's 50 MB budget, docs/journal/training.md "Repository budget"). The rounding is at most half a
//! step of 1/127 of a row's largest magnitude; what it does to the denoised images is measured
//! in docs/journal/denoiser.md ("8-bit weight files").
//!
//! The file stays a safetensors file: the kernel `name` holds I8 values of its shape and
//! `name.int8_scale` the F32 scales of its rows; the metadata key [`KEY`] says so. Loading
//! (`weights::load`, one layer up) dequantises to f32 before the model sees the tensors.

use std::collections::HashMap;

use safetensors::{Dtype, SafeTensors};

use crate::tensor_file::{serialize_tensors as serialize, tensor_floats as floats, OwnedTensor};

/// Metadata key naming the storage; absent for f16/f32 files.
pub const KEY: &str = "pixguide.storage";
/// The one storage this module writes.
pub const INT8_ROWS: &str = "int8-rows";
const SCALE_SUFFIX: &str = ".int8_scale";
/// Tensors smaller than this stay unquantised: they cost little and some (guide strengths,
/// gains) are single numbers that a row scale would not help.
const MIN_ELEMENTS: usize = 256;

/// Whether the file's metadata marks 8-bit storage (an error for a storage this program does not
/// know).
pub fn is_quantized(bytes: &[u8]) -> Result<bool, String> {
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| e.to_string())?;
    match meta.metadata().as_ref().and_then(|m| m.get(KEY)) {
        None => Ok(false),
        Some(s) if s == INT8_ROWS => Ok(true),
        Some(s) => Err(format!("metadata `{KEY}`: unknown storage `{s}` (this program reads `{INT8_ROWS}`)")),
    }
}

/// A weight file's bytes with its kernels stored in 8 bits (metadata kept, [`KEY`] added).
pub fn quantize(bytes: &[u8]) -> Result<Vec<u8>, String> {
    if is_quantized(bytes)? {
        return Err("already stored in 8 bits".into());
    }
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| e.to_string())?;
    let st = SafeTensors::deserialize(bytes).map_err(|e| e.to_string())?;
    let mut out: Vec<OwnedTensor> = Vec::new();
    for (name, t) in st.tensors() {
        let shape = t.shape().to_vec();
        let n: usize = shape.iter().product();
        if shape.len() < 2 || n < MIN_ELEMENTS || shape[0] == 0 {
            out.push((name, t.dtype(), shape, t.data().to_vec()));
            continue;
        }
        let values = floats(&name, t.dtype(), t.data())?;
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(format!("tensor `{name}` holds {v}: a weight file must be finite"));
        }
        let row = n / shape[0];
        let mut q = Vec::with_capacity(n);
        let mut scales = Vec::with_capacity(shape[0]);
        for r in values.chunks_exact(row) {
            let s = r.iter().fold(0.0f32, |m, v| m.max(v.abs())) / 127.0;
            scales.push(s);
            q.extend(r.iter().map(|v| if s > 0.0 { (v / s).round().clamp(-127.0, 127.0) as i8 as u8 } else { 0 }));
        }
        out.push((format!("{name}{SCALE_SUFFIX}"), Dtype::F32, vec![shape[0]], scales.iter().flat_map(|s| s.to_le_bytes()).collect()));
        out.push((name, Dtype::I8, shape, q));
    }
    let mut meta = meta.metadata().clone().unwrap_or_default();
    meta.insert(KEY.into(), INT8_ROWS.into());
    serialize(out, meta)
}

/// The f32 weight file an 8-bit one stands for (metadata kept, [`KEY`] removed), or `None` for a
/// file not stored in 8 bits.
pub fn dequantize(bytes: &[u8]) -> Result<Option<Vec<u8>>, String> {
    if !is_quantized(bytes)? {
        return Ok(None);
    }
    let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| e.to_string())?;
    let st = SafeTensors::deserialize(bytes).map_err(|e| e.to_string())?;
    let tensors: HashMap<String, _> = st.tensors().into_iter().collect();
    let mut out: Vec<OwnedTensor> = Vec::new();
    for (name, t) in &tensors {
        if let Some(kernel) = name.strip_suffix(SCALE_SUFFIX) {
            if tensors.get(kernel).is_none_or(|k| k.dtype() != Dtype::I8) {
                return Err(format!("tensor `{name}`: scales of no 8-bit tensor `{kernel}`"));
            }
            continue;
        }
        if t.dtype() != Dtype::I8 {
            out.push((name.clone(), t.dtype(), t.shape().to_vec(), t.data().to_vec()));
            continue;
        }
        let shape = t.shape().to_vec();
        let rows = shape.first().copied().unwrap_or(0);
        let scale_name = format!("{name}{SCALE_SUFFIX}");
        let s = tensors.get(&scale_name).ok_or_else(|| format!("tensor `{name}`: its scales `{scale_name}` are missing"))?;
        let scales = floats(&scale_name, s.dtype(), s.data())?;
        if s.shape() != [rows] || rows == 0 {
            return Err(format!("tensor `{scale_name}`: shape {:?}, expected [{rows}] (one scale per row of `{name}`)", s.shape()));
        }
        if let Some(bad) = scales.iter().find(|s| !s.is_finite() || **s < 0.0) {
            return Err(format!("tensor `{scale_name}`: scale {bad}, expected finite and ≥ 0"));
        }
        let row = t.data().len() / rows;
        let values: Vec<u8> = t.data().iter().enumerate().flat_map(|(i, &q)| (q as i8 as f32 * scales[i / row]).to_le_bytes()).collect();
        out.push((name.clone(), Dtype::F32, shape, values));
    }
    let mut meta = meta.metadata().clone().unwrap_or_default();
    meta.remove(KEY);
    serialize(out, meta).map(Some)
}
