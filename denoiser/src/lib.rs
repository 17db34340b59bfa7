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
//! - [`ensemble`]: network E and the per-pixel blend of the two denoisers (inside the jointly trained model).
//! - [`gate`]: E over finished denoisers (g, p, OIDN), trained on their cached outputs.
//! - [`model`]: the network sizes (presets) of the whole framework.
//! - [`preprocess`]: network inputs from a rendered frame, targets from a reference (§2, §4.1).
//! - [`method`]: the compared methods (G, P, both, guided) as one model type.
//! - [`loss`]: L1, the path-disentangling loss, validation relMSE.
//! - [`infer`]: tiled whole-image inference with bounded memory; [`infer::denoise_frame`], a
//!   rendered frame to a denoised one in one call.
//! - [`metrics`]: relMSE, 1 − SSIM, relMSE_val (method.md §7.3).
//! - [`weights`]: weight files (safetensors, module-path names, config + provenance metadata).
//! - [`train`]: data, patch sampling, the staged schedule, checkpoints (docs/training.md).
//! - [`oidn`]: Intel Open Image Denoise, loaded at run time, as a baseline denoiser.
//! - [`names`]: the command-line names of methods, presets and ablations, parsed and printed.
//! - [`layers`]: convolution with deterministic init, input sanitising, cropping.
//! - [`rng`]: the seeded random stream of weight init and loss permutations.

pub mod names;

pub mod column;
pub mod engine;
pub mod ensemble;
pub mod gate;
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
pub mod quantize;
pub mod rng;
pub(crate) mod tensor_file;
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

/// The burn backend a run computes on. The model code is the same for all: burn's [`Device`]
/// dispatches every op. `Flex` (pure Rust, CPU) is always there; the others only with their
/// cargo feature of this crate (docs/training-tch.md): `Tch` (LibTorch on the CPU) and
/// `TchCuda` (LibTorch on CUDA GPU 0) with `tch` (`tools/install_libtorch.sh`), `Cuda`
/// (burn's CubeCL CUDA backend, GPU 0) with `cuda`, `Wgpu` (burn's wgpu backend, default
/// adapter) with `wgpu`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Backend {
    #[default]
    Flex,
    Tch,
    TchCuda,
    Cuda,
    Wgpu,
}

names::named!(Backend, "backend");

/// Why a backend is missing from this build: the feature to build with.
fn not_compiled(name: &str, feature: &str, how: &str) -> String {
    format!("backend {name} is not compiled in: build with `--features {feature}` ({how}; see docs/training-tch.md)")
}

impl Backend {
    /// Every backend, compiled in or not (names: [`Backend::name`], parsing: `FromStr`).
    pub const ALL: [Backend; 5] = [Self::Flex, Self::Tch, Self::TchCuda, Self::Cuda, Self::Wgpu];

    pub fn name(self) -> &'static str {
        match self {
            Self::Flex => "flex",
            Self::Tch => "tch",
            Self::TchCuda => "tch-cuda",
            Self::Cuda => "cuda",
            Self::Wgpu => "wgpu",
        }
    }

    /// Whether this build has the backend (a GPU backend may still find no GPU at run time).
    pub fn available(self) -> bool {
        match self {
            Self::Flex => true,
            Self::Tch | Self::TchCuda => cfg!(feature = "tch"),
            Self::Cuda => cfg!(feature = "cuda"),
            Self::Wgpu => cfg!(feature = "wgpu"),
        }
    }

    /// The backend's device without gradients, or why this build has none.
    #[allow(deprecated)] // burn 0.22 deprecates burn-tch in favour of its CubeCL backends
    pub fn device(self) -> Result<Device, String> {
        match self {
            Self::Flex => Ok(Device::flex()),
            #[cfg(feature = "tch")]
            Self::Tch => Ok(Device::libtorch()),
            #[cfg(feature = "tch")]
            Self::TchCuda => Ok(Device::libtorch_cuda(0)),
            #[cfg(not(feature = "tch"))]
            Self::Tch | Self::TchCuda => {
                Err(not_compiled(self.name(), "tch", "LibTorch from a PyTorch 2.9.0 venv: run tools/install_libtorch.sh"))
            }
            #[cfg(feature = "cuda")]
            Self::Cuda => Ok(Device::cuda(0)),
            #[cfg(not(feature = "cuda"))]
            Self::Cuda => Err(not_compiled("cuda", "cuda", "burn's CUDA backend; needs the CUDA toolkit at run time")),
            #[cfg(feature = "wgpu")]
            Self::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "wgpu"))]
            Self::Wgpu => Err(not_compiled("wgpu", "wgpu", "burn's wgpu backend: Vulkan, Metal or DX12")),
        }
    }

    /// The backend's device with autodiff, for training.
    pub fn training_device(self) -> Result<Device, String> {
        self.device().map(Device::autodiff)
    }
}

/// LibTorch's intra-op thread count (its default: the physical cores; `OMP_NUM_THREADS` sets it).
#[cfg(feature = "tch")]
pub fn torch_threads() -> usize {
    tch::get_num_threads().max(0) as usize
}

/// Sets LibTorch's intra-op thread count (flex uses rayon's pool: `RAYON_NUM_THREADS`).
#[cfg(feature = "tch")]
pub fn set_torch_threads(n: usize) {
    tch::set_num_threads(n as i32)
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
