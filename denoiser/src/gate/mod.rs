//! The gate: network E of the pixel-wise guidance, over any set of finished denoisers (experts).
//!
//! Why a gate over finished images, not inside one jointly trained model: E must learn where each
//! expert is *wrong on new images*. Inside the joint model E saw only patches its experts had been
//! fitted to, gave D_G a weight of 0.9–1 everywhere (at 2 spp as at 64) and so added nothing to D_G
//! (docs/denoiser.md, "The gate"). Here the experts are frozen and run exactly as users run them
//! (`g`, `p`, Open Image Denoise), their outputs on shots they never saw are computed once and
//! cached, and only E trains, on the metric the results page reports.
//!
//! E sees, per pixel ([`features`]): every expert's output, the noisy diffuse and specular
//! radiance, how far each expert is from the noisy input in units of the input's own noise (an
//! expert that removed signal along with the noise sits many standard deviations away), the
//! relative noise, the G-buffers and the sample count. A small U-Net ([`GateNet`]) turns them into
//! one logit per expert; the softmax over them weights the experts' linear radiance. Its last
//! layer starts at zero, so training starts from the plain average of the experts, never from one
//! of them.

pub mod cache;
pub mod features;
pub mod file;
pub mod net;
pub mod run;
pub mod train;

#[cfg(test)]
mod tests;

pub use features::{feature_channels, features, GateFrame};
pub use net::{GateConfig, GateNet};

/// A denoiser the gate can blend.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Expert {
    /// The column on G-buffers (`g`, denoiser/weights/g-default.safetensors).
    G,
    /// The column on P-buffers (`p`, denoiser/weights/p-default.safetensors).
    P,
    /// Intel Open Image Denoise (RT filter, hdr, quality high) on the noisy radiance with our
    /// albedo and normal.
    Oidn,
}

impl Expert {
    pub fn name(self) -> &'static str {
        match self {
            Expert::G => "g",
            Expert::P => "p",
            Expert::Oidn => "oidn",
        }
    }

    pub fn parse(s: &str) -> Option<Expert> {
        [Expert::G, Expert::P, Expert::Oidn].into_iter().find(|e| e.name() == s)
    }
}

impl std::fmt::Display for Expert {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Blends `experts` (interleaved RGB `[H, W, 3]` each) with per-pixel `weights` (`[K, H, W]`
/// planar, summing to 1 per pixel). Pixels marked in `passthrough` keep `noisy` (no hit, or an
/// emitter seen directly: every expert keeps the noisy value there, and so does the blend,
/// exactly). The result is finite and ≥ 0 wherever the experts are.
pub fn blend(experts: &[&[f32]], weights: &[f32], noisy: &[f32], passthrough: &[bool]) -> Vec<f32> {
    let n = noisy.len() / 3;
    let mut out = vec![0.0f32; 3 * n];
    for (i, px) in out.chunks_exact_mut(3).enumerate() {
        if passthrough.get(i).copied().unwrap_or(false) {
            px.copy_from_slice(&noisy[3 * i..3 * i + 3]);
            continue;
        }
        for (k, e) in experts.iter().enumerate() {
            let w = weights[k * n + i];
            if w == 0.0 {
                continue;
            }
            for c in 0..3 {
                px[c] += w * e[3 * i + c];
            }
        }
    }
    out
}
