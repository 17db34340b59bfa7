//! Network E and the per-pixel blend (method.md §6.1): E sees both denoised images (gradient
//! stopped), the G-buffer block and the P-buffer, and predicts two softmax weights per pixel;
//! the branch output is I_E = W_G ⊙ I_G + W_P ⊙ I_P.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor};

use crate::kpcn::channels::{G_BLOCK, P_BLOCK};
use crate::layers::{center_crop, conv_macs, sanitize, Activation, ConvStack, Init, Padding, INPUT_LIMIT};

/// Paper size by default: 9 layers 5×5 same padding, width 50 (`paper-half`: 25).
#[derive(Config, Debug)]
pub struct EnsembleConfig {
    #[config(default = 9)]
    pub depth: usize,
    #[config(default = 50)]
    pub width: usize,
    #[config(default = 5)]
    pub conv_kernel: usize,
    /// Ablation "radiances only" (Seed Table 2): E sees just sg(I_G), sg(I_P).
    #[config(default = false)]
    pub radiance_only: bool,
}

impl EnsembleConfig {
    pub fn in_channels(&self) -> usize {
        if self.radiance_only {
            6
        } else {
            6 + G_BLOCK + P_BLOCK
        }
    }

    fn widths(&self) -> Vec<usize> {
        let mut w = vec![self.in_channels()];
        w.extend(std::iter::repeat_n(self.width, self.depth - 1));
        w.push(2);
        w
    }

    pub fn macs_per_pixel(&self) -> u64 {
        self.widths().windows(2).map(|p| conv_macs(p[0], p[1], self.conv_kernel)).sum()
    }

    /// Convolution kernel weights (no biases): a lower bound on the parameter count, which a
    /// weight file must hold. Every layer runs at full resolution, so it equals the MAC count.
    pub fn kernel_weights(&self) -> u64 {
        self.macs_per_pixel()
    }

    /// Xavier-uniform as for KPCN (gain √2 hidden, 1 output), zero biases.
    pub fn init(&self, seed: u64, device: &Device) -> EnsembleNet {
        assert!(self.depth >= 1);
        EnsembleNet {
            net: ConvStack::new(
                &self.widths(),
                self.conv_kernel,
                Padding::Same,
                Init::XavierUniform { gain: std::f64::consts::SQRT_2 },
                Init::XavierUniform { gain: 1.0 },
                false,
                Activation::Relu,
                seed,
                0x454e_5345,
                device,
            ),
            radiance_only: self.radiance_only,
        }
    }
}

/// Result of one blend.
#[derive(Clone, Debug)]
pub struct Blend {
    /// I_E `[B, 3, h, w]`.
    pub output: Tensor<4>,
    /// (W_G, W_P) `[B, 2, h, w]`, each in [0,1], summing to 1.
    pub weights: Tensor<4>,
}

#[derive(Module, Debug)]
pub struct EnsembleNet {
    pub net: ConvStack,
    pub radiance_only: bool,
}

/// I_E = W_G ⊙ I_G + W_P ⊙ I_P with `weights` `[B, 2, h, w]` broadcast over colour.
pub fn blend(i_g: Tensor<4>, i_p: Tensor<4>, weights: Tensor<4>) -> Tensor<4> {
    i_g * weights.clone().narrow(1, 0, 1) + i_p * weights.narrow(1, 1, 1)
}

impl EnsembleNet {
    /// Per-pixel softmax weights from E's (already assembled) input.
    pub fn weights(&self, input: Tensor<4>) -> Tensor<4> {
        softmax(self.net.forward(sanitize(input, INPUT_LIMIT)), 1)
    }

    /// Blends the two denoised images. `i_g`, `i_p` `[B, 3, h, w]`; `g_block` `[B, 24, H, W]` and
    /// `p_block` `[B, 13, H, W]` (D_G's and D_P's guidance, H ≥ h) are centre-cropped to h × w.
    ///
    /// The denoised images enter E's input detached, so the denoisers get gradient only through
    /// the blend, masked by W (Seed Eq. 5–6). The P-buffer is not detached: the PathNet also
    /// learns through E, as in the reference code (method.md §6.2 ⚠).
    pub fn forward(&self, i_g: Tensor<4>, i_p: Tensor<4>, g_block: Tensor<4>, p_block: Tensor<4>) -> Blend {
        self.forward_opts(i_g, i_p, g_block, p_block, true)
    }

    pub(crate) fn forward_opts(&self, i_g: Tensor<4>, i_p: Tensor<4>, g_block: Tensor<4>, p_block: Tensor<4>, detach: bool) -> Blend {
        let [_, _, h, w] = i_g.dims();
        let (sg, sp) = if detach { (i_g.clone().detach(), i_p.clone().detach()) } else { (i_g.clone(), i_p.clone()) };
        let mut parts = vec![sg, sp];
        if !self.radiance_only {
            parts.push(center_crop(g_block, h, w));
            parts.push(center_crop(p_block, h, w));
        }
        let weights = self.weights(Tensor::cat(parts, 1));
        Blend { output: blend(i_g, i_p, weights.clone()), weights }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::test_util::{grad_of, max_abs, tensor, to_vec};
    use crate::{cpu_device, cpu_training_device};

    fn rand_vec(n: usize, rng: &mut SplitMix64) -> Vec<f64> {
        (0..n).map(|_| rng.symmetric(1.0) as f64).collect()
    }

    fn tiny() -> EnsembleConfig {
        EnsembleConfig::new().with_depth(3).with_width(6).with_conv_kernel(3)
    }

    /// Gradient of Σ probe·blend(I_G, I_P, softmax(z)) w.r.t. I_G, I_P and z against central
    /// finite differences in f64.
    #[test]
    fn blend_gradient_matches_finite_differences() {
        let mut rng = SplitMix64::new(11);
        let (b, h, w) = (2, 3, 4);
        let n3 = b * 3 * h * w;
        let n2 = b * 2 * h * w;
        let (ig, ip, z, probe) = (rand_vec(n3, &mut rng), rand_vec(n3, &mut rng), rand_vec(n2, &mut rng), rand_vec(n3, &mut rng));
        let objective = |ig: &[f64], ip: &[f64], z: &[f64]| -> f64 {
            let mut acc = 0.0;
            for n in 0..b {
                for p in 0..h * w {
                    let (z0, z1) = (z[(n * 2) * h * w + p], z[(n * 2 + 1) * h * w + p]);
                    let m = z0.max(z1);
                    let (e0, e1) = ((z0 - m).exp(), (z1 - m).exp());
                    let (w0, w1) = (e0 / (e0 + e1), e1 / (e0 + e1));
                    for c in 0..3 {
                        let i = (n * 3 + c) * h * w + p;
                        acc += probe[i] * (w0 * ig[i] + w1 * ip[i]);
                    }
                }
            }
            acc
        };
        let d = cpu_training_device();
        let (tg, tp, tz) = (
            tensor(&ig, [b, 3, h, w], &d).require_grad(),
            tensor(&ip, [b, 3, h, w], &d).require_grad(),
            tensor(&z, [b, 2, h, w], &d).require_grad(),
        );
        let out = blend(tg.clone(), tp.clone(), softmax(tz.clone(), 1));
        let grads = (out * tensor(&probe, [b, 3, h, w], &d)).sum().backward();
        let hstep = 1e-5;
        let fd = |which: usize, i: usize| {
            let mut v = [ig.clone(), ip.clone(), z.clone()];
            v[which][i] += hstep;
            let plus = objective(&v[0], &v[1], &v[2]);
            v[which][i] -= 2.0 * hstep;
            (plus - objective(&v[0], &v[1], &v[2])) / (2.0 * hstep)
        };
        for (which, an) in [(0, grad_of(&tg, &grads)), (1, grad_of(&tp, &grads)), (2, grad_of(&tz, &grads))] {
            let num: Vec<f64> = (0..an.len()).map(|i| fd(which, i)).collect();
            let err = an.iter().zip(&num).fold(0.0f64, |m, (a, n)| m.max((a - n).abs()));
            // Same reasoning as the kernel check: f64 FD error ~1e-10, f32 analytic ~1e-6
            // relative, so 1e-4 of the gradient scale is a safe yet bug-catching bound.
            assert!(err <= 1e-4 * max_abs(&num), "input {which}: err {err}");
        }
    }

    /// E's loss reaches I_G only through the blend: dL/dI_G = W_G ⊙ dL/dI_E exactly. Without
    /// the detach the gradient differs, which shows the check can fail.
    #[test]
    fn denoised_inputs_are_stop_gradient() {
        let d = cpu_training_device();
        let e = tiny().init(3, &d);
        let mut rng = SplitMix64::new(5);
        let (b, h, w) = (1, 6, 6);
        let ig = rand_vec(b * 3 * h * w, &mut rng);
        let ip = rand_vec(b * 3 * h * w, &mut rng);
        let gb = rand_vec(b * 24 * (h + 2) * (w + 2), &mut rng);
        let pb = rand_vec(b * 13 * (h + 2) * (w + 2), &mut rng);
        let probe = rand_vec(b * 3 * h * w, &mut rng);
        let mut diffs = Vec::new();
        for detach in [true, false] {
            let tg = tensor(&ig, [b, 3, h, w], &d).require_grad();
            let tp = tensor(&ip, [b, 3, h, w], &d).require_grad();
            let blend = e.forward_opts(
                tg.clone(),
                tp.clone(),
                tensor(&gb, [b, 24, h + 2, w + 2], &d),
                tensor(&pb, [b, 13, h + 2, w + 2], &d),
                detach,
            );
            let wts = to_vec(blend.weights.clone());
            let grads = (blend.output * tensor(&probe, [b, 3, h, w], &d)).sum().backward();
            let gg = grad_of(&tg, &grads);
            let gp = grad_of(&tp, &grads);
            let mut worst = 0.0f64;
            for c in 0..3 {
                for p in 0..h * w {
                    let i = c * h * w + p;
                    worst = worst.max((gg[i] - wts[p] * probe[i]).abs());
                    worst = worst.max((gp[i] - wts[h * w + p] * probe[i]).abs());
                }
            }
            diffs.push(worst);
        }
        // With detach the two sides are the same f32 products: only rounding differences.
        assert!(diffs[0] < 1e-6, "gradient leaked through E's input: {}", diffs[0]);
        assert!(diffs[1] > 1e-4, "control without detach should differ: {}", diffs[1]);
    }

    #[test]
    fn weights_are_a_partition_of_unity_and_finite() {
        let d = cpu_device();
        let e = tiny().init(8, &d);
        let specials = [f64::NAN, f64::INFINITY, -1e6, 1e6, 0.0, 0.3];
        let v: Vec<f64> = (0..43 * 25).map(|i| specials[i % 6]).collect();
        let wts = to_vec(e.weights(tensor(&v, [1, 43, 5, 5], &d)));
        for p in 0..25 {
            let (a, b) = (wts[p], wts[25 + p]);
            assert!((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b));
            assert!((a + b - 1.0).abs() < 1e-6);
        }
    }
}
