//! Frames: what a render produces, in memory (read directly by the denoiser), and their files.
//!
//! Every per-pixel buffer stores the sample mean and an unbiased estimate of the variance of
//! that mean (s²/S with s² the ddof-1 sample variance; 0 at 1 spp). Consumers that want the
//! population variance of the samples (method.md §2 uses ddof 0) get it as var·S²/(S−1)·(1/S)
//! = var·S/(S−1)… see [`PixelBuffer::population_variance_of_samples`].

pub mod channels;
pub mod descriptors;
pub mod exr_io;
pub mod png;

pub use descriptors::Descriptors;

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
    if x.is_finite() { x } else { 0.0 }
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
        let bufs = [Some(&self.radiance), self.diffuse.as_ref(), self.specular.as_ref(), self.albedo.as_ref(), self.normal.as_ref(), self.depth.as_ref()];
        bufs.iter().flatten().all(|b| b.mean.iter().chain(b.var.iter()).all(|v| v.is_finite()))
            && self.descriptors.as_ref().is_none_or(|d| d.data.iter().all(|v| v.is_finite()))
    }
}
