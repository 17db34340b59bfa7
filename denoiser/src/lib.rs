//! Pixel-wise guidance Monte Carlo denoiser (Han et al. 2023) on burn 0.22.
//!
//! The crate holds the networks, the differentiable ops, the losses, preprocessing, training and
//! tiled inference. Facts and their sources: docs/method.md §2–§7 and §12; where this crate sits
//! in the whole flow: docs/architecture.md; design decisions and measured costs:
//! docs/denoiser-design.md.
//!
//! Layout convention: every image tensor is NCHW `[batch, channels, height, width]`; per-sample
//! tensors are `[batch, samples, channels, height, width]`. All transforms are in the branch
//! domain of method.md §2 (demodulated diffuse, log specular) unless a function says otherwise.
//!
//! Modules:
//! - [`kernel`]: softmax kernel prediction filter (the KPCN reconstruction op).
//! - [`column`]: a denoising column (D_G, D_P, G+P baseline) of either backbone.
//! - [`kpcn`]: the KPCN backbone, the columns' input channels, the diffuse/specular recombination.
//! - [`mskp`]: the multi-scale kernel-predicting U-Net backbone.
//! - [`pathnet`]: the path-manifold module producing the P-buffer.
//! - [`ensemble`]: network E and the per-pixel blend of the two denoisers.
//! - [`model`]: the network sizes (presets) of the whole framework.
//! - [`preprocess`]: network inputs from a rendered frame, targets from a reference (§2, §4.1).
//! - [`method`]: the compared methods (G, P, both, guided) as one model type.
//! - [`loss`]: L1, the path-disentangling loss, validation relMSE.
//! - [`infer`]: tiled whole-image inference with bounded memory.
//! - [`metrics`]: relMSE, 1 − SSIM, relMSE_val (method.md §7.3).
//! - [`weights`]: weight files (safetensors, module-path names, config + provenance metadata).
//! - [`train`]: data, patch sampling, the staged schedule, checkpoints (docs/training.md).
//! - [`oidn`]: Intel Open Image Denoise, loaded at run time, as a baseline denoiser.
//! - [`layers`]: convolution with deterministic init, input sanitising, cropping.
//! - [`rng`]: the seeded random stream of weight init and loss permutations.

pub mod column;
pub mod ensemble;
pub mod infer;
pub mod kernel;
pub mod kpcn;
pub mod layers;
pub mod loss;
pub mod method;
pub mod metrics;
pub mod model;
pub mod mskp;
pub mod oidn;
pub mod pathnet;
pub mod preprocess;
pub mod rng;
pub mod train;
pub mod weights;

pub use burn;
pub use burn::tensor::{Device, Tensor};

/// ε_a of method.md §2: added to the albedo for demodulation and remodulation.
pub const ALBEDO_EPS: f32 = 0.00316;

/// The CPU device used by default (burn's pure-Rust flex backend), without gradients.
pub fn cpu_device() -> Device {
    Device::flex()
}

/// The CPU device with autodiff, for training.
pub fn cpu_training_device() -> Device {
    Device::flex().autodiff()
}

#[cfg(test)]
#[allow(deprecated)]
pub(crate) mod test_util {
    use burn::tensor::{Device, Gradients, Tensor, TensorData};

    pub fn tensor<const D: usize>(v: &[f64], dims: [usize; D], device: &Device) -> Tensor<D> {
        let data: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        Tensor::from_data(TensorData::new(data, dims), device)
    }

    pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f64> {
        let v: Vec<f32> = t.into_data().convert::<f32>().to_vec::<f32>().unwrap();
        v.into_iter().map(f64::from).collect()
    }

    pub fn grad_of<const D: usize>(t: &Tensor<D>, grads: &Gradients) -> Vec<f64> {
        to_vec(t.grad(grads).expect("tensor has no gradient"))
    }

    pub fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0, |m, x| m.max(x.abs()))
    }
}
