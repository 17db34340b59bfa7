//! Building blocks shared by the networks: a 2-D convolution with deterministic initialisation
//! and optional weight normalisation, input sanitising and centre cropping.

use burn::module::{Module, Param};
use burn::tensor::activation::{leaky_relu, relu};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::rng::SplitMix64;

/// How a convolution's weights are initialised.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Init {
    /// Xavier/Glorot uniform, bound = gain·√(6/(fan_in+fan_out)), bias 0 (KPCN and E, method.md §3).
    XavierUniform { gain: f64 },
    /// PyTorch's `Conv2d` default: weight and bias U(±1/√fan_in). The PathNet's effective init,
    /// because its weight normalisation replaces the Xavier call (method.md §4.2).
    TorchDefault,
}

/// Spatial padding of a convolution (stride 1, odd kernels only).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Padding {
    /// No padding: each layer trims kernel/2 pixels per side.
    Valid,
    /// Zero padding of kernel/2: output size = input size.
    Same,
}

/// Hidden-layer non-linearity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Activation {
    Relu,
    LeakyRelu(f64),
    Identity,
}

impl Activation {
    pub fn apply<const D: usize>(self, x: Tensor<D>) -> Tensor<D> {
        match self {
            Activation::Relu => relu(x),
            Activation::LeakyRelu(slope) => leaky_relu(x, slope),
            Activation::Identity => x,
        }
    }
}

/// Everything needed to build one [`Conv`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConvSpec {
    pub in_channels: usize,
    pub out_channels: usize,
    pub kernel: usize,
    pub padding: Padding,
    pub init: Init,
    pub weight_norm: bool,
}

/// Stride-1 2-D convolution with bias. With weight normalisation (Salimans & Kingma 2016) the
/// stored `weight` is the direction v and the effective kernel is g·v/‖v‖ per output channel;
/// g starts at ‖v‖ so the initial effective weights equal v, as in PyTorch's `weight_norm`.
#[derive(Module, Debug)]
pub struct Conv {
    pub weight: Param<Tensor<4>>,
    pub bias: Param<Tensor<1>>,
    pub norm_gain: Option<Param<Tensor<1>>>,
    pub padding: usize,
}

impl Conv {
    /// Builds the layer. `tag` selects this layer's own random stream under `seed`.
    pub fn new(spec: ConvSpec, seed: u64, tag: u64, device: &Device) -> Self {
        assert!(spec.kernel % 2 == 1, "convolution kernels must be odd (got {})", spec.kernel);
        assert!(spec.in_channels > 0 && spec.out_channels > 0, "convolution needs channels");
        let mut rng = SplitMix64::derive(seed, tag);
        let k2 = spec.kernel * spec.kernel;
        let fan_in = (spec.in_channels * k2) as f64;
        let fan_out = (spec.out_channels * k2) as f64;
        let n = spec.out_channels * spec.in_channels * k2;
        let (w_bound, b_bound) = match spec.init {
            Init::XavierUniform { gain } => (gain * (6.0 / (fan_in + fan_out)).sqrt(), 0.0),
            Init::TorchDefault => (1.0 / fan_in.sqrt(), 1.0 / fan_in.sqrt()),
        };
        let w: Vec<f32> = (0..n).map(|_| rng.symmetric(w_bound)).collect();
        let b: Vec<f32> = (0..spec.out_channels).map(|_| if b_bound > 0.0 { rng.symmetric(b_bound) } else { 0.0 }).collect();
        let norm_gain = spec.weight_norm.then(|| {
            let g: Vec<f32> = w
                .chunks(spec.in_channels * k2)
                .map(|row| row.iter().map(|&v| (v as f64) * (v as f64)).sum::<f64>().sqrt() as f32)
                .collect();
            Param::from_tensor(Tensor::from_data(TensorData::new(g, [spec.out_channels]), device))
        });
        let shape = [spec.out_channels, spec.in_channels, spec.kernel, spec.kernel];
        Self {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, shape), device)),
            bias: Param::from_tensor(Tensor::from_data(TensorData::new(b, [spec.out_channels]), device)),
            norm_gain,
            padding: match spec.padding {
                Padding::Valid => 0,
                Padding::Same => spec.kernel / 2,
            },
        }
    }

    /// The effective kernel, `[out, in, k, k]`.
    pub fn effective_weight(&self) -> Tensor<4> {
        let v = self.weight.val();
        match &self.norm_gain {
            None => v,
            Some(g) => {
                let out = v.dims()[0];
                // The 1e-20 keeps the sqrt gradient finite if a direction ever collapses to 0.
                let norm = v.clone().square().sum_dims(&[1, 2, 3]).add_scalar(1e-20).sqrt();
                v * (g.val().reshape([out, 1, 1, 1]) / norm)
            }
        }
    }

    /// `[B, in, H, W]` → `[B, out, H', W']` with H' = H (same) or H − k + 1 (valid).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let p = self.padding;
        conv2d(x, self.effective_weight(), Some(self.bias.val()), ConvOptions::new([1, 1], [p, p], [1, 1], 1))
    }

    pub fn out_channels(&self) -> usize {
        self.weight.dims()[0]
    }
}

/// Multiply-accumulates per output pixel of a stack of convolutions, for the cost estimates in
/// the docs (bias and activations ignored).
pub fn conv_macs(in_channels: usize, out_channels: usize, kernel: usize) -> u64 {
    (in_channels * out_channels * kernel * kernel) as u64
}

/// Largest magnitude any network input may have after [`sanitize`]. Generous for every channel
/// of method.md §2/§4.1 (log-domain and demodulated values of real renders stay far below), yet
/// small enough that 9 Xavier layers cannot push an f32 activation to overflow.
pub const INPUT_LIMIT: f32 = 1.0e4;

/// Replaces NaN by 0 and clamps to ±`limit` (so ±Inf → ±limit). Every network entry point runs
/// its inputs through this: a single bad sample must not poison a whole batch, and the method's
/// own choice (1e38, method.md §1.1) would overflow the first convolution.
pub fn sanitize<const D: usize>(x: Tensor<D>, limit: f32) -> Tensor<D> {
    let nan = x.clone().is_nan();
    x.mask_fill(nan, 0.0).clamp(-limit, limit)
}

/// [`sanitize`] of one value, for stages that run on the host (`infer::PathMlp`).
pub fn sanitize_value(v: f32, limit: f32) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(-limit, limit)
    }
}

/// Centre crop of the last two (spatial) dimensions to `h × w`. An odd margin puts the extra
/// pixel at the bottom/right, matching the kernel-apply op's offset.
pub fn center_crop<const D: usize>(x: Tensor<D>, h: usize, w: usize) -> Tensor<D> {
    let dims = x.dims();
    let (hi, wi) = (dims[D - 2], dims[D - 1]);
    assert!(h <= hi && w <= wi, "crop {h}×{w} larger than tensor {hi}×{wi}");
    if h == hi && w == wi {
        return x;
    }
    x.narrow(D - 2, (hi - h) / 2, h).narrow(D - 1, (wi - w) / 2, w)
}

/// A plain chain of convolutions: `activation` after every layer but the last.
#[derive(Module, Debug)]
pub struct ConvStack {
    pub layers: Vec<Conv>,
    #[module(skip)]
    pub activation: Activation,
}

impl ConvStack {
    /// `widths` = [in, hidden…, out]; one layer per consecutive pair.
    pub fn new(
        widths: &[usize],
        kernel: usize,
        padding: Padding,
        hidden_init: Init,
        output_init: Init,
        weight_norm: bool,
        activation: Activation,
        seed: u64,
        tag: u64,
        device: &Device,
    ) -> Self {
        assert!(widths.len() >= 2, "a convolution stack needs at least one layer");
        let n = widths.len() - 1;
        let layers = (0..n)
            .map(|i| {
                let spec = ConvSpec {
                    in_channels: widths[i],
                    out_channels: widths[i + 1],
                    kernel,
                    padding,
                    init: if i + 1 == n { output_init } else { hidden_init },
                    weight_norm,
                };
                Conv::new(spec, seed, tag.wrapping_mul(1000).wrapping_add(i as u64), device)
            })
            .collect();
        Self { layers, activation }
    }

    pub fn forward(&self, mut x: Tensor<4>) -> Tensor<4> {
        let n = self.layers.len();
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(x);
            if i + 1 < n {
                x = self.activation.apply(x);
            }
        }
        x
    }
}

#[cfg(test)]
#[allow(deprecated)]
mod tests {
    use super::*;
    use crate::cpu_device;

    #[test]
    fn sanitize_replaces_non_finite() {
        let d = cpu_device();
        let x = Tensor::<1>::from_data(TensorData::new(vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e6, -2.0, 0.0], [6]), &d);
        let y: Vec<f32> = sanitize(x, 100.0).into_data().to_vec::<f32>().unwrap();
        assert_eq!(y, vec![0.0, 100.0, -100.0, 100.0, -2.0, 0.0]);
    }

    #[test]
    fn weight_norm_starts_at_the_direction() {
        let d = cpu_device();
        let spec =
            ConvSpec { in_channels: 3, out_channels: 4, kernel: 3, padding: Padding::Same, init: Init::TorchDefault, weight_norm: true };
        let c = Conv::new(spec, 1, 2, &d);
        let v: Vec<f32> = c.weight.val().into_data().to_vec::<f32>().unwrap();
        let w: Vec<f32> = c.effective_weight().into_data().to_vec::<f32>().unwrap();
        for (a, b) in v.iter().zip(&w) {
            // g = ‖v‖ in f32, so g/‖v‖ = 1 up to a few ulps.
            assert!((a - b).abs() <= 1e-6 * a.abs().max(1e-3), "{a} vs {b}");
        }
    }
}
