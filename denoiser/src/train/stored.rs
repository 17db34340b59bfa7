//! A training shot's prepared inputs kept in bf16 while a run holds the whole dataset in memory.
//!
//! The campaign's dataset is 6 GB of prepared f32 planes in each training process, the same
//! data in both of the two that run side by side; at half that, both fit this machine's memory
//! with the allocator that makes descriptor steps 1.7× faster (docs/training.md, "Memory
//! allocator"). bf16, not f16: its exponent is f32's, so variances of fireflies and other
//! large values cannot overflow; its 8-bit mantissa (relative rounding ≤ 2⁻⁸) is far below the
//! Monte Carlo noise of any input, the least noisy being 64 spp. A patch is widened back to f32
//! when it is cut; inference (`pixguide denoise`, `eval`) never rounds.

use crate::preprocess::PreparedImage;
use half::bf16;

/// [`PreparedImage`] without descriptors (training reads those from their file), planes in bf16.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredImage {
    width: usize,
    height: usize,
    spp: usize,
    diffuse: Vec<bf16>,
    specular: Vec<bf16>,
    g_block: Vec<bf16>,
    path_weight: Vec<bf16>,
    passthrough: Vec<bool>,
}

fn narrow(v: &[f32]) -> Vec<bf16> {
    v.iter().map(|&x| bf16::from_f32(x)).collect()
}

fn widen(v: &[bf16]) -> Vec<f32> {
    v.iter().map(|x| x.to_f32()).collect()
}

impl StoredImage {
    pub fn new(img: &PreparedImage) -> StoredImage {
        StoredImage {
            width: img.width,
            height: img.height,
            spp: img.spp,
            diffuse: narrow(&img.diffuse),
            specular: narrow(&img.specular),
            g_block: narrow(&img.g_block),
            path_weight: narrow(&img.path_weight),
            passthrough: img.passthrough.clone(),
        }
    }

    /// The image in f32, as the networks take it.
    pub fn prepared(&self) -> PreparedImage {
        PreparedImage {
            width: self.width,
            height: self.height,
            spp: self.spp,
            diffuse: widen(&self.diffuse),
            specular: widen(&self.specular),
            g_block: widen(&self.g_block),
            path_weight: widen(&self.path_weight),
            descriptors: None,
            records: None,
            passthrough: self.passthrough.clone(),
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        2 * (self.diffuse.len() + self.specular.len() + self.g_block.len() + self.path_weight.len()) + self.passthrough.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_round_trip_within_bf16_rounding_and_keep_huge_values() {
        let n = 6;
        let vals = |k: usize| -> Vec<f32> { (0..k * n).map(|i| (i as f32 - 7.3) * 1.37f32.powi(i as i32 % 40)).collect() };
        let img = PreparedImage {
            width: 3,
            height: 2,
            spp: 4,
            diffuse: vals(10),
            specular: vals(10).into_iter().map(|v| v * 1e30).collect(),
            g_block: vals(24),
            path_weight: vec![0.25; n],
            descriptors: None,
            records: None,
            passthrough: vec![true, false, false, true, false, false],
        };
        let back = StoredImage::new(&img).prepared();
        assert_eq!((back.width, back.height, back.spp, &back.passthrough), (3, 2, 4, &img.passthrough));
        for (a, b) in [(&img.diffuse, &back.diffuse), (&img.specular, &back.specular), (&img.g_block, &back.g_block)] {
            assert_eq!(a.len(), b.len());
            for (x, y) in a.iter().zip(b.iter()) {
                // Round to nearest with 8 significant bits: at most half a unit in the last place, 2⁻⁸ relative.
                assert!((x - y).abs() <= x.abs() * 2f32.powi(-8), "{x} came back as {y}");
                assert!(y.is_finite());
            }
        }
        assert_eq!(back.path_weight, img.path_weight, "exactly representable values come back exactly");
        assert_eq!(StoredImage::new(&img).bytes(), 2 * 45 * n + n);
    }
}
