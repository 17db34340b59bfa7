//! Tiled inference on a whole image (method.md §7.3), with bounded memory.
//!
//! **Border.** The KPCN columns use valid convolutions, so a full-size output needs `m` extra
//! input pixels on every side (m = [`DenoiserConfig::margin`]). The prepared input is extended by
//! *mirror reflection* (pixel −1 is pixel 1). Zero padding would let the kernel apply average
//! black into every border pixel (the kernel reads the uncropped noisy colour, and its weights are
//! a softmax that does not renormalise), and would show the networks zero normals/albedo/depth
//! that they never met in training; replicating the edge pixel would make the kernel weight the
//! noise of a single pixel many times. Mirroring keeps both the colour the kernel averages and the
//! guidance features real. (The forward-difference gradient channels are mirrored as stored, so
//! their sign flips along the mirrored axis inside the pad; they only steer the kernels there.)
//!
//! **Path-manifold module first, per pixel.** For models with one (p, both, guided), the
//! per-pixel P-buffers (f_P, v_P of each branch) are computed for the whole padded image before
//! any tile, in [`PathNet`]'s stages: the per-sample embedding over chunks of pixels (pointwise,
//! so no overlap), its per-pixel mean mirror-padded like the image, the U-Net over windows of
//! the padded mean map carrying [`pathnet_radius`] of context (window origins and sizes aligned
//! to 2^(levels−1) pixels so the 2×2 pooling grid stays in phase with the whole image), then the
//! per-sample head again (the embedding is recomputed rather than stored: storing it would cost
//! spp × E floats per pixel). Each sample is thus embedded twice and passed through the head
//! once, whatever the tile size. The per-sample stages run fused on the host, pixel by pixel in
//! parallel ([`PathMlp`]), not as tensor ops.
//!
//! **Tiles.** The padded image is then cut into windows, each giving a `tile × tile` block of
//! output. A window carries [`context`] pixels of input around its block: the KPCN margin plus
//! the receptive radius of E (same-padded convolutions); the P-buffers are cut from the
//! precomputed padded maps. Windows at the edge are shifted inward (never clipped) so that all
//! windows have one size and can be batched; one that reaches the padded image's edge sees the
//! same zero padding there that the whole-image run sees. Result: tiled output = the model's
//! forward on the whole padded image up to f32 rounding of differently-blocked arithmetic
//! (tested).
//!
//! Memory: only one U-Net window or one batch of windows is ever a tensor;
//! the prepared image itself (descriptors included) and the per-pixel maps stay planar on the CPU.
//!
//! [`PathNet`]: crate::pathnet::PathNet

use burn::tensor::{Device, Tensor};

use crate::method::{Method, MethodModel};
use crate::model::DenoiserConfig;
use crate::preprocess::PreparedImage;

mod frame;
mod path_mlp;
mod path_stage;
mod tiles;
mod timing;
mod window;

pub use frame::{denoise_frame, denoised_frame, FrameError, FrameRun};
pub use path_mlp::PathMlp;
pub use path_stage::pathnet_radius;
pub use tiles::{alignment, auto_tile, context, unet_window_side, window_side};
pub use timing::Timings;

/// Largest radiance written. Nothing physical comes near; it keeps squared errors of the output
/// finite in f32 and stands in for +Inf.
pub const MAX_RADIANCE: f32 = 1e18;

#[derive(Clone, Debug)]
pub struct InferOptions {
    /// Output block per window (pixels, square); 0 = [`auto_tile`]. Larger tiles waste less on
    /// context but need more memory; see docs/denoiser-design.md for measured figures.
    pub tile: usize,
    /// Windows per forward pass.
    pub batch: usize,
}

impl Default for InferOptions {
    fn default() -> Self {
        InferOptions { tile: 0, batch: 1 }
    }
}

/// The denoised image.
#[derive(Clone, Debug)]
pub struct Denoised {
    pub width: usize,
    pub height: usize,
    /// Linear RGB radiance, interleaved `[H, W, 3]` like `Frame::radiance.mean`; finite, ≥ 0.
    pub radiance: Vec<f32>,
    /// W_G per pixel `[H, W]` of the diffuse and the specular branch (guided models only).
    pub weights_g: Option<BranchMaps>,
    pub timings: Timings,
}

#[derive(Clone, Debug)]
pub struct BranchMaps {
    pub diffuse: Vec<f32>,
    pub specular: Vec<f32>,
}

#[derive(Debug, thiserror::Error)]
pub enum InferError {
    #[error("the {0} model needs per-sample path descriptors, but the frame has none (render with descriptors, or pass --descriptors)")]
    MissingDescriptors(Method),
    #[error("the noisy radiance has {got} values, expected {expected} (3 per pixel)")]
    NoisySize { got: usize, expected: usize },
    #[error("the model's networks do not form one of the methods g, p, both, guided")]
    BadModel,
    #[error("empty image")]
    Empty,
}

/// Denoises a prepared image. `noisy` is the frame's radiance (interleaved RGB), kept where the
/// prepared image marks a pixel as passthrough (camera ray hit nothing or an emitter, method.md
/// §7.3; only known when the frame had descriptors).
pub fn denoise(
    model: &MethodModel,
    config: &DenoiserConfig,
    image: &PreparedImage,
    noisy: &[f32],
    opts: &InferOptions,
    device: &Device,
) -> Result<Denoised, InferError> {
    tiles::denoise_tiled(model, config, image, noisy, opts, device)
}

/// A tensor's values read back into host memory, as f32.
fn to_vec(t: Tensor<4>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec::<f32>().unwrap_or_default()
}

#[cfg(test)]
mod tests;
