//! Per-sample path descriptors (method.md §1.1): 37 raw floats per sample — the 36 inputs of the
//! path-manifold module plus the path's sampling probability — stored [y][x][sample][field].

use crate::{Error, Result};
use std::collections::HashMap;
use std::path::Path;

/// Number of floats per sample.
pub const FIELDS: usize = 37;
/// Maximum number of path vertices described (5 bounces).
pub const VERTICES: usize = 6;

/// Field offsets within one sample's record.
pub mod field {
    /// Radiance without weight: ∏ f·cos over the vertices × emission of the emitter the path
    /// ended on (3).
    pub const RADIANCE_NO_WEIGHT: usize = 0;
    /// Emission of the emitter / environment texel the path ended on (3).
    pub const LIGHT_INTENSITY: usize = 3;
    /// f·|cos| of the sampled continuation at each vertex, 6 × RGB vertex-major (18).
    pub const THROUGHPUT: usize = 6;
    /// Bounce-type bitmask at each vertex (reflection 1, transmission 2, diffuse 4, glossy 8,
    /// specular 16), as float (6).
    pub const BOUNCE_TYPE: usize = 24;
    /// GGX alpha of the sampled lobe at each vertex (Lambert 1, smooth 0) (6).
    pub const ROUGHNESS: usize = 30;
    /// Product of the BSDF-sampling probabilities along the path (1) — not one of the 36.
    pub const PATH_WEIGHT: usize = 36;
}

#[derive(Clone, Debug, PartialEq)]
pub struct Descriptors {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub data: Vec<f32>,
}

impl Descriptors {
    pub fn new(width: u32, height: u32, spp: u32) -> Self {
        let n = width as usize * height as usize * spp as usize * FIELDS;
        Descriptors { width, height, spp, data: vec![0.0; n] }
    }

    /// The record of sample `s` of pixel `i` (row-major pixel index).
    pub fn sample(&self, i: usize, s: usize) -> &[f32] {
        let o = (i * self.spp as usize + s) * FIELDS;
        &self.data[o..o + FIELDS]
    }

    /// Writes a safetensors file with one f32 tensor `descriptors` of shape [H, W, S, 37] and the
    /// field layout in the metadata.
    pub fn write_safetensors(&self, path: &Path) -> Result<()> {
        let bytes: Vec<u8> = self.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let shape = vec![self.height as usize, self.width as usize, self.spp as usize, FIELDS];
        let view = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, shape, &bytes).map_err(|e| Error::image(path, e))?;
        // One metadata entry only: safetensors keeps metadata in a HashMap, whose iteration
        // order (and so the file's bytes) would vary between runs with two or more keys.
        let mut meta = HashMap::new();
        meta.insert(
            "format".to_string(),
            "pixguide path descriptors v1; fields: 0-2 radiance_no_weight RGB, 3-5 light_intensity RGB, 6-23 throughput 6x RGB vertex-major, 24-29 bounce_type bitmask, 30-35 roughness, 36 path_weight".to_string(),
        );
        let data = safetensors::serialize([("descriptors", view)], Some(meta)).map_err(|e| Error::image(path, e))?;
        crate::exr_io::write_atomically(path, &data)
    }

    pub fn read_safetensors(path: &Path) -> Result<Descriptors> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let st = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| Error::image(path, e))?;
        let t = st.tensor("descriptors").map_err(|e| Error::image(path, format!("tensor `descriptors`: {e}")))?;
        let shape = t.shape();
        if t.dtype() != safetensors::Dtype::F32 || shape.len() != 4 || shape[3] != FIELDS {
            return Err(Error::image(
                path,
                format!("tensor `descriptors` must be f32 [H, W, S, {FIELDS}], found {:?} {:?}", t.dtype(), shape),
            ));
        }
        let data = t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        Ok(Descriptors { width: shape[1] as u32, height: shape[0] as u32, spp: shape[2] as u32, data })
    }
}
