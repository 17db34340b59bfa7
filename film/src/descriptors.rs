//! Per-sample path descriptors (method.md §1.1): 37 raw floats per sample — the 36 inputs of the
//! path-manifold module plus the path's sampling probability — stored [y][x][sample][field].

use crate::{Error, Result};
use half::bf16;
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

/// Storage precision of a descriptor file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    Bf16,
}

impl Precision {
    /// Bytes per value.
    pub fn bytes(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::Bf16 => 2,
        }
    }

    /// Little-endian values of this precision into `out` (as many as both hold).
    pub fn decode(self, bytes: &[u8], out: &mut [f32]) {
        match self {
            Precision::F32 => bytes.chunks_exact(4).zip(out).for_each(|(c, o)| *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            Precision::Bf16 => bytes.chunks_exact(2).zip(out).for_each(|(c, o)| *o = bf16::from_le_bytes([c[0], c[1]]).to_f32()),
        }
    }
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
        self.write_safetensors_as(path, Precision::F32)
    }

    /// As [`Self::write_safetensors`], in the given precision. bf16 halves a training set's
    /// descriptors (most of its bytes). It keeps f32's exponent range, which the fields need:
    /// a path weight (a product of up to five sampling densities of near-specular lobes) or a
    /// firefly's radiance can pass 10³⁰, far beyond f16's 65504. Its 8-bit significand keeps
    /// every value to 0.4 % relative; the denoiser reads the fields through a logarithm
    /// divided by 10–90 (or, for roughness, directly), so the error stays under 10⁻³ of an
    /// input's range and well under the per-sample noise. Bounce-type bitmasks (integers up
    /// to 31) stay exact. NaN, which the integrator never writes, becomes 0 rather than a NaN
    /// in a network's input, and ±∞ saturates.
    pub fn write_safetensors_as(&self, path: &Path, precision: Precision) -> Result<()> {
        let (dtype, bytes): (safetensors::Dtype, Vec<u8>) = match precision {
            Precision::F32 => (safetensors::Dtype::F32, self.data.iter().flat_map(|v| v.to_le_bytes()).collect()),
            Precision::Bf16 => (
                safetensors::Dtype::BF16,
                self.data
                    .iter()
                    .flat_map(|&v| {
                        let v = if v.is_nan() { 0.0 } else { v.clamp(-bf16::MAX.to_f32(), bf16::MAX.to_f32()) };
                        bf16::from_f32(v).to_le_bytes()
                    })
                    .collect(),
            ),
        };
        let shape = vec![self.height as usize, self.width as usize, self.spp as usize, FIELDS];
        let view = safetensors::tensor::TensorView::new(dtype, shape, &bytes).map_err(|e| Error::image(path, e))?;
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
        let dtype_ok = matches!(t.dtype(), safetensors::Dtype::F32 | safetensors::Dtype::BF16);
        if !dtype_ok || shape.len() != 4 || shape[3] != FIELDS {
            return Err(Error::image(
                path,
                format!("tensor `descriptors` must be f32 or bf16 [H, W, S, {FIELDS}], found {:?} {:?}", t.dtype(), shape),
            ));
        }
        let precision = if t.dtype() == safetensors::Dtype::BF16 { Precision::Bf16 } else { Precision::F32 };
        let mut data = vec![0.0f32; t.data().len() / precision.bytes()];
        precision.decode(t.data(), &mut data);
        Ok(Descriptors { width: shape[1] as u32, height: shape[0] as u32, spp: shape[2] as u32, data })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bf16_files_keep_every_field_to_its_precision() {
        let path = std::env::temp_dir().join(format!("pixguide_desc_bf16_{}.safetensors", std::process::id()));
        let mut d = Descriptors::new(3, 2, 4);
        // Path weights and radiances span f32's exponent range; bitmasks are small integers.
        for (i, v) in d.data.iter_mut().enumerate() {
            *v = match i % FIELDS {
                c if (field::BOUNCE_TYPE..field::ROUGHNESS).contains(&c) => (i % 32) as f32,
                field::PATH_WEIGHT => 10f32.powi((i % 61) as i32 - 30) * 1.2345,
                _ => (i as f32 * 0.37).sin().abs() * 10f32.powi((i % 13) as i32 - 6),
            };
        }
        d.data[5] = f32::NAN;
        d.data[6] = f32::INFINITY;
        d.write_safetensors_as(&path, Precision::Bf16).unwrap();
        let r = Descriptors::read_safetensors(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!((r.width, r.height, r.spp), (3, 2, 4));
        for (i, (&a, &b)) in d.data.iter().zip(&r.data).enumerate() {
            match i {
                5 => assert_eq!(b, 0.0, "NaN becomes 0"),
                6 => assert!(b.is_finite() && b > 1e38, "∞ saturates: {b}"),
                _ if (field::BOUNCE_TYPE..field::ROUGHNESS).contains(&(i % FIELDS)) => assert_eq!(a, b, "bitmask {i}"),
                // Round to nearest with an 8-bit significand (7 bits stored): half an ulp is
                // 2⁻⁸ of the value's power of two, so at most 2⁻⁸ of the value.
                _ => assert!((a - b).abs() <= a.abs() * (1.0 / 256.0), "{i}: {a} read back as {b}"),
            }
        }
        // The file is half the f32 one's size (plus the same header).
        let p32 = path.with_extension("f32.safetensors");
        d.write_safetensors(&p32).unwrap();
        let n32 = std::fs::metadata(&p32).unwrap().len();
        std::fs::remove_file(&p32).ok();
        d.write_safetensors_as(&path, Precision::Bf16).unwrap();
        let n16 = std::fs::metadata(&path).unwrap().len();
        std::fs::remove_file(&path).ok();
        assert!(n16 * 2 < n32 + 1024, "{n16} vs {n32}");
    }
}
