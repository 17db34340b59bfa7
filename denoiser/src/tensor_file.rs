//! Raw safetensors tensors, below the model: what the 8-bit storage (`quantize`) and the
//! checkpoint packer (`train::pack`) read and write without building a model. The weight files
//! (`weights`) sit above both, so nothing here knows about models or their metadata.

use std::collections::HashMap;

/// A tensor read out of (or to be written into) a safetensors file: name, dtype, shape, bytes.
pub(crate) type OwnedTensor = (String, safetensors::Dtype, Vec<usize>, Vec<u8>);

/// The values of an F32 or F16 tensor as f32 (an error naming the tensor for other dtypes).
pub(crate) fn tensor_floats(name: &str, dtype: safetensors::Dtype, data: &[u8]) -> Result<Vec<f32>, String> {
    match dtype {
        safetensors::Dtype::F32 => Ok(data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()),
        safetensors::Dtype::F16 => Ok(data.chunks_exact(2).map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32()).collect()),
        d => Err(format!("tensor `{name}` is {d:?}, expected f32 or f16")),
    }
}

/// A safetensors file of `tensors` (written in name order, so the bytes do not depend on the
/// order they came in) with `meta`.
pub(crate) fn serialize_tensors(mut tensors: Vec<OwnedTensor>, meta: HashMap<String, String>) -> Result<Vec<u8>, String> {
    tensors.sort_by(|a, b| a.0.cmp(&b.0));
    let views = tensors
        .iter()
        .map(|(n, dt, s, b)| Ok((n.clone(), safetensors::tensor::TensorView::new(*dt, s.clone(), b).map_err(|e| format!("`{n}`: {e}"))?)))
        .collect::<Result<Vec<_>, String>>()?;
    safetensors::serialize(views, Some(meta)).map_err(|e| e.to_string())
}
