//! Multi-scale kernel-predicting U-Net: the compute-efficient backbone for D_G, D_P and the
//! both-buffers column (docs/denoiser-design.md, "The multi-scale backbone").
//!
//! Why: a KPCN column spends all its compute on full-resolution convolutions whose output can
//! only average a window of its depth. Here a U-Net (3×3 same-padded convolutions, 2×2
//! max-pooling, bilinear upsampling, skip concatenation) sees ≥ 64 px of context for a fraction of
//! the multiply-accumulates, and its decoder predicts at each of the finest `kernel_scales` levels
//! a small k×k softmax kernel that filters the colour pyramid at that level (2×2 box
//! downsampling). The filtered levels are composited coarse to fine with a per-pixel weight
//! α = sigmoid(·) predicted at the finer level, in one of two ways ([`ScaleCompositor`]):
//!
//!   convex blend (`default`):   out_s = (1 − α_s)·f_s + α_s·up(out_{s+1})
//!   low-band swap (`swap`):     out_s = f_s + α_s·(up(out_{s+1}) − up(down(f_s)))
//!
//! with out_{S−1} = f_{S−1}. The convex blend keeps every level a convex combination of input
//! colours (softmax kernels, box averages, bilinear weights, α ∈ (0,1)), so the column can neither
//! create energy nor overshoot, and the identity (α = 0, a one-hot centre kernel at full
//! resolution) is in reach; but wherever α > 0 it blurs the fine level's edges. The swap replaces
//! only the fine level's own low-pass band, so those edges survive even at α = 1; its output can
//! undershoot at an edge (inference clamps radiance at 0). The swap is Vogels et al. 2018's scale
//! compositor, ⚠ the subject of US patent 10,699,382 (docs/method.md §12): it is opt-in (the
//! `swap` preset, kernels at all 5 levels) until the project decides it may ship it; the
//! measured difference is in docs/denoiser.md ("The swap models").
//!
//! Borders: each level is reflect-padded before filtering, so the kernels never read zeros and the
//! image edge is not darkened (the KPCN's ⚠ of docs/method.md §3). The network output is cropped
//! by `margin` per side like the KPCN's, so training and tiled inference treat both columns alike.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::module::{avg_pool2d, interpolate, max_pool2d};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions, MaxPoolOptions, PadMode};
use burn::tensor::{Device, Tensor};

use crate::kernel::apply_kernel;
use crate::layers::{center_crop, conv_macs, Activation, Conv, ConvSpec, ConvStack, Init, Padding};

/// Sizes of one multi-scale column.
#[derive(Config, Debug)]
pub struct MsKpConfig {
    /// Input channels; the first 3 are the colour that gets filtered.
    pub in_channels: usize,
    /// U-Net widths from the full-resolution level down to the bottleneck (one level each).
    #[config(default = "vec![24, 32, 48, 64, 80]")]
    pub widths: Vec<usize>,
    /// 3×3 convolutions per U-Net block.
    #[config(default = 2)]
    pub convs_per_block: usize,
    /// Levels (from full resolution) at which a kernel is predicted and applied.
    #[config(default = 3)]
    pub kernel_scales: usize,
    /// Predicted filter size k (odd) at every scale.
    #[config(default = 5)]
    pub filter_size: usize,
    /// Pixels cropped per side from the output (the context training and inference give it).
    #[config(default = 8)]
    pub margin: usize,
    /// How the filtered levels are composited. Weight files written before this field existed
    /// have the convex blend, so that is what a missing field means; only the opt-in `swap`
    /// preset uses the swap, which is covered by US patent 10,699,382 (docs/method.md §12).
    #[config(default = "ScaleCompositor::ConvexBlend")]
    pub compositor: ScaleCompositor,
}

/// The coarse-to-fine composite of [`MsKpNet::composite`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ScaleCompositor {
    /// out_s = (1 − α)·f_s + α·up(out_{s+1}): blurs edges wherever α > 0 (2026-11-24 models).
    ConvexBlend,
    /// Vogels et al. 2018: out_s = f_s + α·(up(out_{s+1}) − up(down(f_s))). ⚠ The scale
    /// compositor of US patent 10,699,382; opt-in (`swap` preset), never the default.
    LowPassSwap,
}

const CONV: usize = 3;

impl MsKpConfig {
    fn levels(&self) -> usize {
        self.widths.len()
    }

    /// Output channels of the head at scale `s`: k² kernel logits, plus the blend logit α_s
    /// except at the coarsest kernel scale.
    fn head_channels(&self, s: usize) -> usize {
        self.filter_size * self.filter_size + usize::from(s + 1 < self.kernel_scales)
    }

    /// Multiply-accumulates per output pixel (levels weighted by their area, filter taps
    /// included).
    pub fn macs_per_pixel(&self) -> u64 {
        let w = &self.widths;
        let c = self.convs_per_block as u64;
        let block = |cin: usize, cout: usize| conv_macs(cin, cout, CONV) + (c - 1) * conv_macs(cout, cout, CONV);
        let mut total = 0.0;
        for l in 0..self.levels() {
            let area = 4f64.powi(l as i32);
            let cin = if l == 0 { self.in_channels } else { w[l - 1] };
            total += block(cin, w[l]) as f64 / area;
            if l + 1 < self.levels() {
                total += block(w[l + 1] + w[l], w[l]) as f64 / area;
            }
            if l < self.kernel_scales {
                let taps = (self.filter_size * self.filter_size) as u64;
                total += (conv_macs(w[l], self.head_channels(l), 1) + 3 * taps) as f64 / area;
            }
        }
        total as u64
    }

    /// Receptive radius (pixels per side) of one output pixel, a bound: the U-Net's (each 3×3
    /// convolution at level l adds 2^l, each pooling into l adds 2^(l−1), each bilinear
    /// upsampling from l+1 reads ±1 pixel there) plus the composite's reach (a k×k kernel at scale
    /// s reads (k/2 + 1)·2^s pixels of box-averaged colour, the upsampling from s+1 2^(s+1)).
    pub fn radius(&self) -> usize {
        let r = self.convs_per_block * (CONV / 2);
        let levels = self.levels();
        let mut unet = 0;
        for l in 0..levels {
            unet += r << l;
            if l > 0 {
                unet += 1 << (l - 1);
            }
            if l + 1 < levels {
                unet += (2 << l) + (r << l);
            }
        }
        let s = self.kernel_scales;
        unet + (self.filter_size / 2 + 1) * (1 << (s - 1)) + (2 << s)
    }

    /// Sizes the pooling grid needs to stay in phase with a larger image (window origins must be
    /// multiples of this for tiled inference to equal the whole-image run).
    pub fn alignment(&self) -> usize {
        1 << (self.levels() - 1)
    }

    /// Xavier-uniform weights (gain √2 before a ReLU, 1 on the linear heads), zero biases.
    pub fn init(&self, seed: u64, device: &Device) -> MsKpNet {
        assert!(self.in_channels >= 3, "the column needs a colour input");
        assert!(self.levels() >= 1 && self.convs_per_block >= 1, "the U-Net needs ≥ 1 level and ≥ 1 convolution per block");
        assert!(
            (1..=self.levels()).contains(&self.kernel_scales),
            "kernel scales ({}) must be between 1 and the U-Net's levels ({})",
            self.kernel_scales,
            self.levels()
        );
        assert!(self.filter_size % 2 == 1, "filter size must be odd");
        let hidden = Init::XavierUniform { gain: std::f64::consts::SQRT_2 };
        let block = |cin: usize, cout: usize, tag: u64| {
            let mut widths = vec![cin];
            widths.extend(std::iter::repeat_n(cout, self.convs_per_block));
            ConvStack::new(&widths, CONV, Padding::Same, hidden, hidden, false, Activation::Relu, seed, tag, device)
        };
        let w = &self.widths;
        MsKpNet {
            down: (0..self.levels()).map(|l| block(if l == 0 { self.in_channels } else { w[l - 1] }, w[l], 0x4d53_0100 + l as u64)).collect(),
            up: (0..self.levels() - 1).map(|l| block(w[l + 1] + w[l], w[l], 0x4d53_0200 + l as u64)).collect(),
            heads: (0..self.kernel_scales)
                .map(|s| {
                    let spec = ConvSpec {
                        in_channels: w[s],
                        out_channels: self.head_channels(s),
                        kernel: 1,
                        padding: Padding::Valid,
                        init: Init::XavierUniform { gain: 1.0 },
                        weight_norm: false,
                    };
                    Conv::new(spec, seed, 0x4d53_0300 + s as u64, device)
                })
                .collect(),
            margin: self.margin,
            low_pass_swap: self.compositor == ScaleCompositor::LowPassSwap,
        }
    }
}

/// See [`MsKpConfig`].
#[derive(Module, Debug)]
pub struct MsKpNet {
    pub down: Vec<ConvStack>,
    pub up: Vec<ConvStack>,
    /// One 1×1 head per kernel scale, on the decoder's features at that level.
    pub heads: Vec<Conv>,
    pub margin: usize,
    /// [`ScaleCompositor::LowPassSwap`] (else the convex blend); set from the config.
    pub low_pass_swap: bool,
}

/// 2×2 box average (floors odd sizes, like the U-Net's pooling).
fn box_down(x: Tensor<4>) -> Tensor<4> {
    avg_pool2d(x, AvgPoolOptions::new([2, 2]).with_stride([2, 2]))
}

fn upsample_to(x: Tensor<4>, h: usize, w: usize) -> Tensor<4> {
    interpolate(x, InterpolateOptions::new(InterpolateMode::Bilinear).with_align_corners(false).with_output_size([h, w]))
}

/// Applies softmax kernels `[B, k², H, W]` to `colour` `[B, 3, H, W]` of the same size, reading
/// a mirror image past the edges (edge replication where the level is too small to mirror).
pub fn apply_kernel_reflect(colour: Tensor<4>, logits: Tensor<4>) -> Tensor<4> {
    let k = crate::kernel::filter_size(logits.dims()[1]);
    let r = k / 2;
    if r == 0 {
        return apply_kernel(colour, logits);
    }
    let [_, _, h, w] = colour.dims();
    let mode = if h > r && w > r { PadMode::Reflect } else { PadMode::Edge };
    apply_kernel(colour.pad([(r, r), (r, r)], mode), logits)
}

impl MsKpNet {
    /// The decoder features at each kernel scale, finest first: `[B, widths[s], H/2^s, W/2^s]`.
    pub fn features(&self, x: Tensor<4>) -> Vec<Tensor<4>> {
        let levels = self.down.len();
        let mut skips = Vec::with_capacity(levels);
        let mut x = x;
        for (l, block) in self.down.iter().enumerate() {
            if l > 0 {
                x = max_pool2d(x, MaxPoolOptions::new([2, 2]).with_stride([2, 2]));
            }
            x = relu(block.forward(x));
            skips.push(x.clone());
        }
        skips.pop();
        let scales = self.heads.len();
        let mut out = vec![None; scales];
        if levels - 1 < scales {
            out[levels - 1] = Some(x.clone());
        }
        for l in (0..self.up.len()).rev() {
            let skip = skips.pop().expect("one skip per level");
            let [_, _, h, w] = skip.dims();
            x = relu(self.up[l].forward(Tensor::cat(vec![upsample_to(x, h, w), skip], 1)));
            if l < scales {
                out[l] = Some(x.clone());
            }
        }
        out.into_iter().map(|f| f.expect("a decoder level per kernel scale")).collect()
    }

    /// Head outputs per scale, finest first: (kernel logits `[B, k², ·, ·]`, blend logit
    /// `[B, 1, ·, ·]` except at the coarsest scale).
    pub fn heads(&self, x: Tensor<4>) -> Vec<(Tensor<4>, Option<Tensor<4>>)> {
        let scales = self.heads.len();
        self.features(x)
            .into_iter()
            .zip(&self.heads)
            .enumerate()
            .map(|(s, (f, head))| {
                let o = head.forward(f);
                let c = o.dims()[1];
                if s + 1 < scales {
                    (o.clone().narrow(1, 0, c - 1), Some(o.narrow(1, c - 1, 1)))
                } else {
                    (o, None)
                }
            })
            .collect()
    }

    /// Filters and composites the colour `[B, 3, H, W]` with the head outputs; full size.
    pub fn composite(colour: Tensor<4>, heads: Vec<(Tensor<4>, Option<Tensor<4>>)>, low_pass_swap: bool) -> Tensor<4> {
        let mut pyramid = vec![colour];
        for _ in 1..heads.len() {
            let next = box_down(pyramid.last().unwrap().clone());
            pyramid.push(next);
        }
        let mut out: Option<Tensor<4>> = None;
        for (c, (logits, alpha)) in pyramid.into_iter().zip(heads).rev() {
            let f = apply_kernel_reflect(c, logits);
            out = Some(match (out, alpha) {
                (Some(coarse), Some(a)) => {
                    let [_, _, h, w] = f.dims();
                    // Vogels et al.'s scale compositor: α swaps only the fine level's own
                    // low-pass band for the coarse result, so the edges its kernel kept stay.
                    let a = sigmoid(a);
                    let low = if low_pass_swap { upsample_to(box_down(f.clone()), h, w) } else { f.clone() };
                    f + (upsample_to(coarse, h, w) - low) * a
                }
                (None, _) => f,
                (Some(_), None) => unreachable!("only the coarsest scale lacks a blend weight"),
            });
        }
        out.expect("at least one kernel scale")
    }

    /// `[B, C_in, H, W]` (sanitised) → `[B, 3, H−2m, W−2m]`.
    pub fn forward(&self, input: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = input.dims();
        let heads = self.heads(input.clone());
        let out = Self::composite(input.narrow(1, 0, 3), heads, self.low_pass_swap);
        center_crop(out, h - 2 * self.margin, w - 2 * self.margin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::test_util::{grad_of, max_abs, tensor, to_vec};
    use crate::{cpu_device, cpu_training_device};

    fn tiny(in_channels: usize) -> MsKpConfig {
        MsKpConfig::new(in_channels).with_widths(vec![4, 6, 6]).with_kernel_scales(3).with_filter_size(3).with_margin(1).with_compositor(ScaleCompositor::LowPassSwap)
    }

    /// The hand count of a two-level, one-scale column.
    #[test]
    fn cost_is_the_hand_count() {
        let c = MsKpConfig::new(10).with_widths(vec![4, 8]).with_kernel_scales(1).with_filter_size(3).with_convs_per_block(1);
        let full = 10 * 4 * 9 + (8 + 4) * 4 * 9 + 4 * 9 + 27;
        let half = 4 * 8 * 9;
        assert_eq!(c.macs_per_pixel(), (full as f64 + half as f64 / 4.0) as u64);
        // Default column on the G input: the budget of docs/denoiser-design.md.
        assert!(MsKpConfig::new(34).macs_per_pixel() < 60_000);
        assert!(MsKpConfig::new(34).radius() >= 64);
    }

    /// The gradient of Σ probe·column(x) with respect to the input and to a weight of every
    /// kind (encoder, decoder, kernel head, blend head) matches central finite differences of the
    /// forward pass. The forward runs in f32, so the step is 2e-3: its rounding error is
    /// ≈ 1e-6·|objective|/h ≈ 5e-4 and a step this small rarely crosses a ReLU kink or flips a
    /// max-pool choice. Bound: 2 % of the largest gradient plus 2e-3 absolute; a wrong chain
    /// rule or a missed path is O(1).
    #[test]
    fn gradients_match_finite_differences() {
        let dev = cpu_training_device();
        let cfg = tiny(5);
        let net = cfg.init(3, &dev);
        let mut rng = SplitMix64::new(17);
        let dims = [1, 5, 8, 8];
        let x: Vec<f64> = (0..dims.iter().product()).map(|_| rng.symmetric(1.0) as f64).collect();
        let o = 8 - 2 * cfg.margin;
        let probe: Vec<f64> = (0..3 * o * o).map(|_| rng.symmetric(1.0) as f64).collect();
        let objective = |net: &MsKpNet, x: &[f64]| -> f64 {
            let out = to_vec(net.valid().forward(tensor(x, dims, &cpu_device())));
            out.iter().zip(&probe).map(|(a, b)| a * b).sum()
        };
        let xt = tensor(&x, dims, &dev).require_grad();
        let grads = (net.forward(xt.clone()) * tensor(&probe, [1, 3, o, o], &dev)).sum().backward();
        let h = 2e-3;
        let gx = grad_of(&xt, &grads);
        let fd_x: Vec<f64> = (0..x.len())
            .step_by(7)
            .map(|i| {
                let (mut p, mut m) = (x.clone(), x.clone());
                p[i] += h;
                m[i] -= h;
                (objective(&net, &p) - objective(&net, &m)) / (2.0 * h)
            })
            .collect();
        let an_x: Vec<f64> = gx.iter().copied().step_by(7).collect();
        let check = |what: &str, an: &[f64], num: &[f64]| {
            let scale = max_abs(num);
            assert!(scale > 1e-3, "{what}: degenerate probe");
            let err = an.iter().zip(num).fold(0.0f64, |m, (a, n)| m.max((a - n).abs()));
            assert!(err <= 0.02 * scale + 2e-3, "{what}: max err {err} vs scale {scale}");
        };
        check("input", &an_x, &fd_x);
        // Weights: perturb one entry of a layer through its flat data and rebuild.
        type LayerOf = Box<dyn Fn(&MsKpNet) -> &Conv>;
        let layers: Vec<(&str, LayerOf)> = vec![
            ("encoder 0", Box::new(|n: &MsKpNet| &n.down[0].layers[0])),
            ("bottleneck", Box::new(|n: &MsKpNet| &n.down[2].layers[1])),
            ("decoder 0", Box::new(|n: &MsKpNet| &n.up[0].layers[0])),
            ("head 0", Box::new(|n: &MsKpNet| &n.heads[0])),
            ("head 2", Box::new(|n: &MsKpNet| &n.heads[2])),
        ];
        for (what, get) in layers {
            let w0 = to_vec(get(&net).weight.val());
            let an_all = grad_of(&get(&net).weight.val(), &grads);
            let idx: Vec<usize> = (0..w0.len()).step_by((w0.len() / 6).max(1)).collect();
            let with = |delta: f64, i: usize| {
                let mut w = w0.clone();
                w[i] += delta;
                let mut n2 = net.valid();
                let shape = get(&n2).weight.val().dims();
                let t = tensor(&w, shape, &cpu_device());
                set_weight(&mut n2, what, t);
                objective(&n2, &x)
            };
            let num: Vec<f64> = idx.iter().map(|&i| (with(h, i) - with(-h, i)) / (2.0 * h)).collect();
            let an: Vec<f64> = idx.iter().map(|&i| an_all[i]).collect();
            check(what, &an, &num);
        }
    }

    fn set_weight(n: &mut MsKpNet, what: &str, t: Tensor<4>) {
        let layer = match what {
            "encoder 0" => &mut n.down[0].layers[0],
            "bottleneck" => &mut n.down[2].layers[1],
            "decoder 0" => &mut n.up[0].layers[0],
            "head 0" => &mut n.heads[0],
            _ => &mut n.heads[2],
        };
        layer.weight = burn::module::Param::from_tensor(t);
    }

    /// Heads set to a one-hot centre kernel at full resolution and α → 0 return the input colour
    /// exactly (the identity a converged input needs); α → 1 instead gives the coarse levels, which
    /// differ from the input, so the check can fail.
    #[test]
    fn constructed_identity_returns_the_input() {
        let d = cpu_device();
        let cfg = tiny(4);
        let mut rng = SplitMix64::new(5);
        let dims = [2, 4, 12, 12];
        let x: Vec<f64> = (0..dims.iter().product()).map(|_| rng.next_f64() * 3.0).collect();
        for (alpha, expect_identity) in [(-60.0f32, true), (60.0, false)] {
            let mut net = cfg.init(1, &d);
            let taps = 9;
            let c0 = net.heads[0].weight.dims()[1];
            let mut bias = vec![-60.0f32; taps + 1];
            bias[taps / 2] = 60.0;
            bias[taps] = alpha;
            net.heads[0].weight = burn::module::Param::from_tensor(Tensor::zeros([taps + 1, c0, 1, 1], &d));
            net.heads[0].bias = burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(bias, [taps + 1]), &d));
            let out = to_vec(net.forward(tensor(&x, dims, &d)));
            let m = cfg.margin;
            let mut worst = 0.0f64;
            for b in 0..2 {
                for c in 0..3 {
                    for y in 0..12 - 2 * m {
                        for xx in 0..12 - 2 * m {
                            let o = out[((b * 3 + c) * (12 - 2 * m) + y) * (12 - 2 * m) + xx];
                            let i = x[((b * 4 + c) * 12 + y + m) * 12 + xx + m];
                            worst = worst.max((o - i).abs());
                        }
                    }
                }
            }
            if expect_identity {
                assert!(worst < 1e-5, "identity heads changed the input by {worst}");
            } else {
                assert!(worst > 0.1, "coarse levels should differ from the input ({worst})");
            }
        }
    }

    /// Odd sizes (pooling floors, upsampling returns to the skip's size) and images smaller than
    /// a coarse level's mirror padding run and give the documented shape.
    /// Vogels et al.'s compositor swaps only a level's own low-pass band: with identity kernels
    /// at every scale the output is the input even at α = 1, edges included. (The convex blend
    /// it replaced gave up(down(x)) there, a blurred copy.)
    #[test]
    fn identity_kernels_keep_the_input_at_any_blend_weight() {
        let d = cpu_device();
        let cfg = tiny(4);
        let mut rng = SplitMix64::new(6);
        let dims = [1, 4, 16, 16];
        // A step edge plus noise: what a converged frame's silhouette looks like.
        let x: Vec<f64> = (0..dims.iter().product()).map(|i| if i % 16 < 7 { 0.02 } else { 1.0 } + 0.01 * rng.next_f64()).collect();
        let mut net = cfg.init(1, &d);
        let taps = 9;
        for s in 0..cfg.kernel_scales {
            let n = cfg.head_channels(s);
            let c = net.heads[s].weight.dims()[1];
            let mut bias = vec![-60.0f32; n];
            bias[taps / 2] = 60.0;
            if n > taps {
                bias[taps] = 60.0; // α = 1
            }
            net.heads[s].weight = burn::module::Param::from_tensor(Tensor::zeros([n, c, 1, 1], &d));
            net.heads[s].bias = burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(bias, [n]), &d));
        }
        let out = to_vec(net.forward(tensor(&x, dims, &d)));
        let (m, o) = (cfg.margin, 16 - 2 * cfg.margin);
        let mut worst = 0.0f64;
        for c in 0..3 {
            for y in 0..o {
                for xx in 0..o {
                    worst = worst.max((out[(c * o + y) * o + xx] - x[(c * 16 + y + m) * 16 + xx + m]).abs());
                }
            }
        }
        assert!(worst < 1e-5, "identity kernels with α = 1 changed the input by {worst}");
    }

    #[test]
    fn any_size_runs() {
        let d = cpu_device();
        let net = tiny(3).init(2, &d);
        for (h, w) in [(13, 9), (5, 7), (4, 4)] {
            let out = net.forward(Tensor::<4>::ones([1, 3, h, w], &d));
            assert_eq!(out.dims(), [1, 3, h - 2, w - 2]);
            assert!(to_vec(out).iter().all(|v| (v - 1.0).abs() < 1e-5));
        }
    }
}
