//! Path-manifold module (method.md §4.2): embeds every sample's path descriptor, shares
//! context between pixels with a U-Net on the pixel-mean embedding, and maps each sample back to
//! a small non-negative P-buffer. The denoiser sees the per-pixel mean f_P and a variance v_P.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::module::{interpolate, max_pool2d};
use burn::tensor::ops::{InterpolateMode, InterpolateOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor};

use crate::layers::{conv_macs, sanitize, Activation, ConvStack, Init, Padding, INPUT_LIMIT};

/// Paper size by default (36 → 64 embedding, U-Net 64/128/256, 128 → 12 output).
#[derive(Config, Debug)]
pub struct PathNetConfig {
    /// Path-descriptor channels per sample (method.md §4.1).
    #[config(default = 36)]
    pub in_channels: usize,
    /// Width of the per-sample 1×1 embedding.
    #[config(default = 64)]
    pub embed_width: usize,
    /// Number of 1×1 layers of the embedding.
    #[config(default = 3)]
    pub embed_depth: usize,
    /// U-Net widths from the full-resolution level down to the bottom.
    #[config(default = "vec![64, 128, 256]")]
    pub unet_widths: Vec<usize>,
    /// Convolutions per U-Net block.
    #[config(default = 3)]
    pub convs_per_block: usize,
    /// U-Net convolution size (same padding).
    #[config(default = 3)]
    pub unet_kernel: usize,
    /// Hidden width of the per-sample output head.
    #[config(default = 128)]
    pub out_hidden: usize,
    /// P-buffer channels per sample.
    #[config(default = 12)]
    pub out_channels: usize,
    /// Weight normalisation on every convolution, as in the reference code.
    #[config(default = true)]
    pub weight_norm: bool,
}

impl PathNetConfig {
    /// Multiply-accumulates per pixel at `spp` samples (U-Net levels scaled by their area).
    pub fn macs_per_pixel(&self, spp: usize) -> u64 {
        let e = self.embed_width;
        let mut per_sample = conv_macs(self.in_channels, e, 1);
        per_sample += (self.embed_depth.saturating_sub(1) as u64) * conv_macs(e, e, 1);
        per_sample += conv_macs(e + self.unet_widths[0], self.out_hidden, 1);
        per_sample += conv_macs(self.out_hidden, self.out_channels, 1);
        let k = self.unet_kernel;
        let block = |cin: usize, cout: usize| conv_macs(cin, cout, k) + (self.convs_per_block as u64 - 1) * conv_macs(cout, cout, k);
        let w = &self.unet_widths;
        let mut unet = 0.0;
        for l in 0..w.len() {
            let cin = if l == 0 { e } else { w[l - 1] };
            unet += block(cin, w[l]) as f64 / 4f64.powi(l as i32);
            if l + 1 < w.len() {
                unet += block(w[l + 1] + w[l], w[l]) as f64 / 4f64.powi(l as i32);
            }
        }
        per_sample * spp as u64 + unet as u64
    }

    /// Convolution kernel weights (no biases or norm gains): a lower bound on the parameter
    /// count, which a weight file must hold.
    pub fn kernel_weights(&self) -> u64 {
        let e = self.embed_width;
        let mut total = conv_macs(self.in_channels, e, 1) + (self.embed_depth.saturating_sub(1) as u64) * conv_macs(e, e, 1);
        total += conv_macs(e + self.unet_widths[0], self.out_hidden, 1) + conv_macs(self.out_hidden, self.out_channels, 1);
        let k = self.unet_kernel;
        let block = |cin: usize, cout: usize| conv_macs(cin, cout, k) + (self.convs_per_block as u64 - 1) * conv_macs(cout, cout, k);
        let w = &self.unet_widths;
        for l in 0..w.len() {
            total += block(if l == 0 { e } else { w[l - 1] }, w[l]);
            if l + 1 < w.len() {
                total += block(w[l + 1] + w[l], w[l]);
            }
        }
        total
    }

    pub fn init(&self, seed: u64, device: &Device) -> PathNet {
        assert!(self.embed_depth >= 1 && !self.unet_widths.is_empty() && self.convs_per_block >= 1);
        let init = Init::TorchDefault;
        let wn = self.weight_norm;
        let relu = Activation::Relu;
        let mut embed_w = vec![self.in_channels];
        embed_w.extend(std::iter::repeat_n(self.embed_width, self.embed_depth));
        let block_widths = |cin: usize, cout: usize| {
            let mut v = vec![cin];
            v.extend(std::iter::repeat_n(cout, self.convs_per_block));
            v
        };
        let w = &self.unet_widths;
        let k = self.unet_kernel;
        let down = (0..w.len())
            .map(|l| {
                let cin = if l == 0 { self.embed_width } else { w[l - 1] };
                ConvStack::new(&block_widths(cin, w[l]), k, Padding::Same, init, init, wn, relu, seed, 10 + l as u64, device)
            })
            .collect();
        let up = (0..w.len() - 1)
            .map(|l| {
                ConvStack::new(&block_widths(w[l + 1] + w[l], w[l]), k, Padding::Same, init, init, wn, relu, seed, 20 + l as u64, device)
            })
            .collect();
        PathNet {
            embed: ConvStack::new(&embed_w, 1, Padding::Valid, init, init, wn, relu, seed, 1, device),
            down,
            up,
            head: ConvStack::new(
                &[self.embed_width + w[0], self.out_hidden, self.out_channels],
                1,
                Padding::Valid,
                init,
                init,
                wn,
                relu,
                seed,
                2,
                device,
            ),
        }
    }
}

/// What the path-manifold module hands on.
#[derive(Clone, Debug)]
pub struct PathOutput {
    /// Per-sample P-buffers `[B, S, 12, H, W]`, ≥ 0 (input of the disentangling loss).
    pub samples: Tensor<5>,
    /// f_P = mean over samples, `[B, 12, H, W]`.
    pub features: Tensor<4>,
    /// v_P = mean over channels of the unbiased sample variance, / S, gradient stopped,
    /// `[B, 1, H, W]`; zero at S = 1 where the unbiased variance is undefined.
    pub variance: Tensor<4>,
}

impl PathOutput {
    /// [f_P, v_P], the 13 pixel channels fed to D_P and E.
    pub fn pixel_buffer(&self) -> Tensor<4> {
        Tensor::cat(vec![self.features.clone(), self.variance.clone()], 1)
    }
}

/// See [`PathNetConfig`]. Activations: ReLU throughout, except LeakyReLU(0.01) after the last
/// U-Net convolution; the output head ends in a ReLU so P-buffers are non-negative.
#[derive(Module, Debug)]
pub struct PathNet {
    pub embed: ConvStack,
    pub down: Vec<ConvStack>,
    pub up: Vec<ConvStack>,
    pub head: ConvStack,
}

impl PathNet {
    /// Stage 1, pointwise per sample: descriptors `[B, S, 36, H, W]` → embedding
    /// `[B, S, E, H, W]`. Inference runs it on any chunk of pixels (e.g. `[1, S, 36, 1, n]`).
    pub fn embed(&self, descriptors: Tensor<5>) -> Tensor<5> {
        let [b, s, c, h, w] = descriptors.dims();
        let x = sanitize(descriptors, INPUT_LIMIT).reshape([b * s, c, h, w]);
        let e = self.embed.forward(x);
        let ew = e.dims()[1];
        e.reshape([b, s, ew, h, w])
    }

    /// Stage 2, per pixel: mean of the embedding over samples, `[B, E, H, W]` (the U-Net input).
    pub fn pixel_mean(e: &Tensor<5>) -> Tensor<4> {
        let [b, _, ew, h, w] = e.dims();
        e.clone().mean_dim(1).reshape([b, ew, h, w])
    }

    /// Stage 3, spatial: the U-Net on the pixel-mean embedding, `[B, E, H, W]` → g
    /// `[B, unet_widths[0], H, W]`. Its receptive radius is `infer::pathnet_radius`.
    pub fn unet(&self, x: Tensor<4>) -> Tensor<4> {
        let relu = Activation::Relu;
        let mut skips = Vec::with_capacity(self.down.len());
        let mut x = x;
        for (l, block) in self.down.iter().enumerate() {
            if l > 0 {
                x = max_pool2d(x, MaxPoolOptions::new([2, 2]).with_stride([2, 2]));
            }
            x = relu.apply(block.forward(x));
            skips.push(x.clone());
        }
        skips.pop();
        for l in (0..self.up.len()).rev() {
            let skip = skips.pop().expect("one skip per level");
            let [_, _, h, w] = skip.dims();
            let up = interpolate(x, InterpolateOptions::new(InterpolateMode::Bilinear).with_align_corners(false).with_output_size([h, w]));
            x = self.up[l].forward(Tensor::cat(vec![up, skip], 1));
            x = if l == 0 { Activation::LeakyRelu(0.01).apply(x) } else { relu.apply(x) };
        }
        x
    }

    /// Stage 4, pointwise per sample given g: the output head on cat(e, g) and the per-pixel
    /// mean f_P and variance v_P. `e` `[B, S, E, H, W]` from [`Self::embed`], `g` `[B, G, H, W]`
    /// from [`Self::unet`] at the same pixels.
    pub fn head_pool(&self, e: Tensor<5>, g: Tensor<4>) -> PathOutput {
        let [b, s, ew, h, w] = e.dims();
        let e = e.reshape([b * s, ew, h, w]);
        let gw = g.dims()[1];
        let g = g.reshape([b, 1, gw, h, w]).expand([b, s, gw, h, w]).reshape([b * s, gw, h, w]);
        let p = Activation::Relu.apply(self.head.forward(Tensor::cat(vec![e, g], 1)));
        let pc = p.dims()[1];
        let samples = p.reshape([b, s, pc, h, w]);
        let features = samples.clone().mean_dim(1).reshape([b, pc, h, w]);
        let variance = if s > 1 {
            samples.clone().detach().var(1).mean_dim(2).reshape([b, 1, h, w]).div_scalar(s as f32)
        } else {
            Tensor::zeros([b, 1, h, w], &samples.device())
        };
        PathOutput { samples, features, variance }
    }

    /// `descriptors` `[B, S, 36, H, W]` → [`PathOutput`]. Any H, W ≥ 1 work (pooling floors,
    /// upsampling returns to the skip's exact size). The four stages in order; inference
    /// (`infer/path_stage.rs`) runs the pointwise ones over pixel chunks and the U-Net over the
    /// whole image.
    pub fn forward(&self, descriptors: Tensor<5>) -> PathOutput {
        let e = self.embed(descriptors);
        let g = self.unet(Self::pixel_mean(&e));
        self.head_pool(e, g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::test_util::{tensor, to_vec};
    use crate::{cpu_device, cpu_training_device};

    pub(crate) fn tiny() -> PathNetConfig {
        PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 12, 16]).with_out_hidden(8).with_convs_per_block(2)
    }

    #[test]
    fn shapes_variance_and_odd_sizes() {
        let d = cpu_device();
        let net = tiny().init(3, &d);
        let mut rng = SplitMix64::new(1);
        for (s, h, w) in [(3, 9, 7), (1, 8, 8)] {
            let v: Vec<f64> = (0..2 * s * 36 * h * w).map(|_| rng.symmetric(1.0) as f64).collect();
            let out = net.forward(tensor(&v, [2, s, 36, h, w], &d));
            assert_eq!(out.samples.dims(), [2, s, 12, h, w]);
            assert_eq!(out.pixel_buffer().dims(), [2, 13, h, w]);
            let samples = to_vec(out.samples.clone());
            assert!(samples.iter().all(|&x| x >= 0.0 && x.is_finite()));
            let var = to_vec(out.variance.clone());
            if s == 1 {
                assert!(var.iter().all(|&x| x == 0.0));
            } else {
                // Check one pixel against a hand-computed unbiased variance / S.
                let (n, y, x) = (1, 4, 3);
                let at = |si: usize, c: usize| samples[(((n * s + si) * 12 + c) * h + y) * w + x];
                let mut acc = 0.0;
                for c in 0..12 {
                    let m: f64 = (0..s).map(|si| at(si, c)).sum::<f64>() / s as f64;
                    acc += (0..s).map(|si| (at(si, c) - m).powi(2)).sum::<f64>() / (s - 1) as f64;
                }
                let expect = acc / 12.0 / s as f64;
                let got = var[(n * h + y) * w + x];
                assert!((got - expect).abs() <= 1e-5 * expect.max(1e-3), "{got} vs {expect}");
            }
        }
    }

    /// v_P is a stop-gradient channel: a loss on it alone gives the weights no gradient.
    #[test]
    fn variance_channel_is_detached() {
        let d = cpu_training_device();
        let net = tiny().init(4, &d);
        let mut rng = SplitMix64::new(2);
        let v: Vec<f64> = (0..2 * 36 * 6 * 6).map(|_| rng.symmetric(1.0) as f64).collect();
        let out = net.forward(tensor(&v, [1, 2, 36, 6, 6], &d));
        let loss = out.variance.clone().sum() + out.features.clone().sum().mul_scalar(0.0);
        let grads = loss.backward();
        let g = net.head.layers[1].bias.val().grad(&grads).map(to_vec).unwrap_or_default();
        assert!(g.iter().all(|&x| x == 0.0), "variance leaked gradient: {g:?}");
        // And the mean does carry gradient (so the check above can fail).
        let out = net.forward(tensor(&v, [1, 2, 36, 6, 6], &d));
        let grads = out.features.sum().backward();
        let g = to_vec(net.head.layers[1].bias.val().grad(&grads).unwrap());
        assert!(g.iter().any(|&x| x != 0.0));
    }

    #[test]
    fn hostile_inputs_give_finite_outputs() {
        let d = cpu_device();
        let net = tiny().init(5, &d);
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e6, 0.0];
        let v: Vec<f64> = (0..2 * 36 * 5 * 5).map(|i| specials[i % 5]).collect();
        let out = net.forward(tensor(&v, [1, 2, 36, 5, 5], &d));
        assert!(to_vec(out.pixel_buffer()).iter().all(|x| x.is_finite()));
    }
}
