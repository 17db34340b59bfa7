//! Frames: what a render produces, in memory (read directly by the denoiser), and their files.
//! A crate of its own so that the denoiser can read frames without depending on the renderer
//! (its BVH, scene loaders and their dependencies).
//!
//! Every per-pixel buffer stores the sample mean and an unbiased estimate of the variance of
//! that mean (s²/S with s² the ddof-1 sample variance; 0 at 1 spp). Consumers that want the
//! population variance of the samples (method.md §2 uses ddof 0) get it as var·S²/(S−1)·(1/S)
//! = var·S/(S−1)… see [`PixelBuffer::population_variance_of_samples`].

pub mod channels;
pub mod descriptor_file;
pub mod descriptors;
pub mod error;
pub mod exr_io;

pub use descriptor_file::DescriptorFile;
pub use descriptors::{Descriptors, Precision};
pub use error::{Error, Result};

/// Largest accepted image side and pixel count of a render; the EXR reader refuses larger
/// frames before allocating them, and the scene loaders refuse larger resolutions.
pub const MAX_RESOLUTION_SIDE: u32 = 16384;
pub const MAX_RESOLUTION_PIXELS: u64 = 1 << 26;

/// Online mean/variance in f64 (Welford), so 8000-spp references with fireflies stay exact.
#[derive(Clone, Copy, Debug, Default)]
pub struct Welford {
    pub n: u32,
    pub mean: f64,
    m2: f64,
}

impl Welford {
    pub fn push(&mut self, x: f32) {
        self.n += 1;
        let x = x as f64;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }
    /// Unbiased variance of the mean: s²/n with s² = M2/(n−1); 0 for n < 2.
    pub fn variance_of_mean(&self) -> f64 {
        if self.n < 2 {
            0.0
        } else {
            (self.m2 / (self.n - 1) as f64 / self.n as f64).max(0.0)
        }
    }
}

/// A per-pixel buffer of `channels` interleaved channels: mean and variance of the mean.
#[derive(Clone, Debug, PartialEq)]
pub struct PixelBuffer {
    pub channels: usize,
    pub mean: Vec<f32>,
    pub var: Vec<f32>,
}

impl PixelBuffer {
    pub fn new(channels: usize, pixels: usize) -> Self {
        PixelBuffer { channels, mean: vec![0.0; channels * pixels], var: vec![0.0; channels * pixels] }
    }

    pub fn pixel(&self, i: usize) -> &[f32] {
        &self.mean[i * self.channels..(i + 1) * self.channels]
    }

    /// Writes the statistics of pixel `i` from one accumulator per channel.
    pub fn set(&mut self, i: usize, acc: &[Welford]) {
        debug_assert_eq!(acc.len(), self.channels);
        for (c, w) in acc.iter().enumerate() {
            self.mean[i * self.channels + c] = finite_or_zero(w.mean as f32);
            self.var[i * self.channels + c] = finite_or_zero(w.variance_of_mean() as f32);
        }
    }

    /// Converts the stored variance of the mean back into the population (ddof 0) variance of
    /// the samples divided by S, the quantity method.md §2 feeds the denoiser.
    pub fn population_variance_of_mean(&self, spp: u32) -> Vec<f32> {
        let s = spp as f32;
        let k = if spp < 2 { 0.0 } else { (s - 1.0) / s };
        self.var.iter().map(|v| v * k).collect()
    }
}

fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

/// What a consumer of a render needs besides radiance. Anything not asked for is neither
/// computed nor allocated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BufferRequest {
    /// Diffuse and specular radiance (method.md §1.3).
    pub split: bool,
    /// Albedo, shading normal and depth at the first non-specular vertex.
    pub gbuffers: bool,
    /// Per-sample path descriptors (method.md §1.1, §4.1).
    pub descriptors: bool,
}

impl BufferRequest {
    pub const RADIANCE_ONLY: BufferRequest = BufferRequest { split: false, gbuffers: false, descriptors: false };
    pub const ALL: BufferRequest = BufferRequest { split: true, gbuffers: true, descriptors: true };
}

/// The result of a render, in memory.
#[derive(Clone, Debug)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Linear RGB radiance.
    pub radiance: PixelBuffer,
    /// Diffuse / specular radiance (diffuse + specular = radiance per sample).
    pub diffuse: Option<PixelBuffer>,
    pub specular: Option<PixelBuffer>,
    /// Albedo (RGB, [0,1]) at the first non-specular vertex; 0 where the path escaped first.
    pub albedo: Option<PixelBuffer>,
    /// Shading normal at the first non-specular vertex in camera space (x right, y up, z toward
    /// the camera), facing the incoming ray; 0 where the path escaped first.
    pub normal: Option<PixelBuffer>,
    /// Path length to the first non-specular vertex divided by 10·scene radius (method.md
    /// §1.1); −0.1 where the path escaped first.
    pub depth: Option<PixelBuffer>,
    /// 10·scene radius: multiply `depth` by it to get world units.
    pub depth_scale: f32,
    pub descriptors: Option<Descriptors>,
    /// Samples whose radiance came out non-finite and were replaced by zero (should be 0).
    pub nonfinite_samples: u64,
}

impl Frame {
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// True when every stored value is finite (a render must never produce anything else).
    pub fn all_finite(&self) -> bool {
        let bufs = [
            Some(&self.radiance),
            self.diffuse.as_ref(),
            self.specular.as_ref(),
            self.albedo.as_ref(),
            self.normal.as_ref(),
            self.depth.as_ref(),
        ];
        bufs.iter().flatten().all(|b| b.mean.iter().chain(b.var.iter()).all(|v| v.is_finite()))
            && self.descriptors.as_ref().is_none_or(|d| d.data.iter().all(|v| v.is_finite()))
    }
}

impl PixelBuffer {
    /// Merges the statistics of `other` (from `n_other` samples per pixel) into `self` (from
    /// `n_self`), as if all samples had been accumulated together (Chan et al.'s pairwise update).
    pub fn merge(&mut self, n_self: u32, other: &PixelBuffer, n_other: u32) {
        let (na, nb) = (n_self as f64, n_other as f64);
        let n = na + nb;
        for i in 0..self.mean.len() {
            let (ma, mb) = (self.mean[i] as f64, other.mean[i] as f64);
            let m2a = self.var[i] as f64 * na * (na - 1.0).max(0.0);
            let m2b = other.var[i] as f64 * nb * (nb - 1.0).max(0.0);
            let d = mb - ma;
            let mean = ma + d * nb / n;
            let m2 = m2a + m2b + d * d * na * nb / n;
            self.mean[i] = mean as f32;
            self.var[i] = if n < 2.0 { 0.0 } else { (m2 / (n - 1.0) / n) as f32 };
        }
    }
}

impl Frame {
    /// Merges a frame of the same size and buffers rendered with other samples (e.g. the next
    /// chunk of a long reference render). Descriptors are not merged.
    pub fn merge(&mut self, other: &Frame) -> Result<()> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(Error::Invalid("cannot merge frames of different sizes".into()));
        }
        let (na, nb) = (self.spp, other.spp);
        self.radiance.merge(na, &other.radiance, nb);
        let pairs = [
            (&mut self.diffuse, &other.diffuse),
            (&mut self.specular, &other.specular),
            (&mut self.albedo, &other.albedo),
            (&mut self.normal, &other.normal),
            (&mut self.depth, &other.depth),
        ];
        for (a, b) in pairs {
            match (a.as_mut(), b) {
                (Some(a), Some(b)) => a.merge(na, b, nb),
                (None, None) => {}
                _ => return Err(Error::Invalid("cannot merge frames with different buffers".into())),
            }
        }
        self.spp += other.spp;
        self.nonfinite_samples += other.nonfinite_samples;
        self.descriptors = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_statistics_equal_one_pass() {
        let xs: Vec<f32> = (0..37).map(|i| ((i * 7919) % 101) as f32 * 0.1 - 2.0).collect();
        let stats = |v: &[f32]| {
            let mut w = Welford::default();
            v.iter().for_each(|&x| w.push(x));
            let mut b = PixelBuffer::new(1, 1);
            b.set(0, &[w]);
            b
        };
        let all = stats(&xs);
        let mut a = stats(&xs[..10]);
        a.merge(10, &stats(&xs[10..]), 27);
        assert!(
            (a.mean[0] - all.mean[0]).abs() < 1e-5 && (a.var[0] - all.var[0]).abs() < 1e-5 * all.var[0].abs().max(1.0),
            "{a:?} vs {all:?}"
        );
    }
}
