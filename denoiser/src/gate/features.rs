//! What E sees at each pixel: planar `[C, H, W]` features from the noisy frame and the experts'
//! outputs. One function for training (from the cache) and inference (from a rendered frame), so
//! both see the same numbers.

use crate::layers::sanitize_value;

/// The noisy frame's buffers the gate reads, interleaved like `film::Frame`'s (`[H, W, c]`).
#[derive(Clone, Copy, Debug)]
pub struct GateFrame<'a> {
    pub width: usize,
    pub height: usize,
    pub spp: u32,
    /// Radiance (3) and the variance of its mean (3).
    pub radiance: &'a [f32],
    pub radiance_var: &'a [f32],
    /// Diffuse and specular radiance (3 each).
    pub diffuse: &'a [f32],
    pub specular: &'a [f32],
    /// Albedo (3), camera-space normal (3), depth (1) at the first non-specular vertex.
    pub albedo: &'a [f32],
    pub normal: &'a [f32],
    pub depth: &'a [f32],
}

/// Channels per expert: its output (3) and its distance from the noisy input in noise units (1).
const PER_EXPERT: usize = 4;
/// Noisy diffuse and specular (6), relative noise (1), albedo, normal, depth (7), sample count (1).
const SHARED: usize = 15;
/// Largest feature value; keeps Inf and huge radiance out of the network.
const LIMIT: f32 = 50.0;

/// Feature channels for `k` experts.
pub fn feature_channels(k: usize) -> usize {
    PER_EXPERT * k + SHARED
}

/// log(1 + max(x, 0)), finite: radiance spans orders of magnitude and E must compare it across
/// scenes of any brightness.
fn lg(x: f32) -> f32 {
    sanitize_value(x.max(0.0).ln_1p(), LIMIT)
}

/// Planar `[feature_channels(K), H, W]` features of `frame` and the experts' outputs (interleaved
/// RGB each, `[H, W, 3]`).
pub fn features(frame: &GateFrame, experts: &[&[f32]]) -> Vec<f32> {
    let n = frame.width * frame.height;
    let k = experts.len();
    let mut out = vec![0.0f32; feature_channels(k) * n];
    let plane = |c: usize| c * n..(c + 1) * n;
    for i in 0..n {
        let rgb = |b: &[f32]| [b[3 * i], b[3 * i + 1], b[3 * i + 2]];
        let noisy = rgb(frame.radiance);
        let var = rgb(frame.radiance_var).map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 });
        for (e, img) in experts.iter().enumerate() {
            let x = rgb(img);
            for c in 0..3 {
                out[plane(3 * e + c)][i] = lg(x[c]);
            }
            // (x − noisy)² / σ², per channel, averaged: ≈ 1 where the expert removed only noise
            // (and the variance estimate is right), large where it removed signal too. The small
            // relative floor keeps converged pixels (σ² → 0) from dividing by zero.
            let mut chi = 0.0f32;
            for c in 0..3 {
                let d = x[c] - noisy[c];
                chi += d * d / (var[c] + 1e-4 * noisy[c] * noisy[c] + 1e-8);
            }
            out[plane(3 * k + e)][i] = lg(chi / 3.0);
        }
        let s = PER_EXPERT * k;
        let (d, sp) = (rgb(frame.diffuse), rgb(frame.specular));
        for c in 0..3 {
            out[plane(s + c)][i] = lg(d[c]);
            out[plane(s + 3 + c)][i] = lg(sp[c]);
        }
        let mean_sq = noisy.iter().map(|v| v * v).sum::<f32>() / 3.0;
        let mean_var = var.iter().sum::<f32>() / 3.0;
        out[plane(s + 6)][i] = lg(mean_var / (mean_sq + 1e-3));
        let (a, nm) = (rgb(frame.albedo), rgb(frame.normal));
        for c in 0..3 {
            out[plane(s + 7 + c)][i] = sanitize_value(a[c], LIMIT);
            out[plane(s + 10 + c)][i] = sanitize_value(nm[c], LIMIT);
        }
        out[plane(s + 13)][i] = sanitize_value(frame.depth[i], LIMIT);
        out[plane(s + 14)][i] = (frame.spp.max(1) as f32).log2() / 6.0;
    }
    out
}
