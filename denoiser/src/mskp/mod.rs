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
//! measured difference is in docs/journal/denoiser.md ("The swap models").
//!
//! Edge stopping (`edge_stopping`, the `edge` preset): a softmax kernel predicted by the U-Net
//! alone leaked 5–25 % of a bright neighbour across silhouettes and around emitters even on a
//! 1024-spp input (docs/journal/denoiser.md, "Error floors"). With guide groups (colour as log(1+c),
//! normal, depth, albedo for D_G; colour and f_P for D_P) every tap's logit is lowered by
//! Σ_g w_g·‖s_g·(g(q) − g(p))‖² (for the colour only where q is brighter), with per-pixel strengths w_g = exp(·) predicted by the same
//! head: the cross-bilateral weighting of Kalantari et al. 2015 (method.md §12) inside a learned
//! kernel. The centre tap's distance is 0, so the identity stays in reach. The `edge-noise`
//! preset measures the colour's differences in units of its noise instead (guides.rs), so the
//! kernels tend to the identity as the input converges.
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

mod guides;
#[cfg(test)]
use guides::pooled_variance;
use guides::{guide_features, joint_upsample, VARIANCE_POOL};
pub use guides::{tap_distances, two_sided_share, EdgeStopping, GuideGroup, GuideLevel};

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
    /// Which edge-stopping guides the column gets; `DenoiserConfig::mskp_for` turns this into
    /// `guides` for its input variant. Files without the field have none.
    #[config(default = "EdgeStopping::Off")]
    pub edge_stopping: EdgeStopping,
    /// The guide groups this column's kernels stop at (empty: plain softmax kernels).
    #[config(default = "Vec::new()")]
    pub guides: Vec<GuideGroup>,
    /// γ of the guides' sample-count gain: at N spp every guide strength the head predicts is
    /// multiplied by (N/2)^γ ([`guide_gain`]). Files without the field have γ = 0 (no gain).
    /// Fitted after training on the validation shots (`pixguide calibrate`).
    #[config(default = 0.0)]
    pub guide_gain_exponent: f64,
}

/// The factor (N/2)^γ on every guide strength at `spp` = N samples per pixel (1 at N ≤ 2).
///
/// Why: a guide's distance compares two per-pixel sample means, and how far such a distance can
/// be trusted grows with N (a variance estimated from 2 samples is itself mostly noise; from 32 it
/// is sound). The head cannot see N: its inputs hold the variance of the mean, σ²/N, in which a
/// smooth region at 2 spp and a noisy one at 64 spp look alike. Trained on 2–32 spp, the shipped
/// edge-noise columns predict one compromise strength, too weak once the input has converged:
/// their output was blurrier than the 32- and 64-spp input on wire-fence (docs/denoiser.md,
/// "Guide strength grows with the sample count"). The exponent is one scalar per weight file,
/// fitted on the validation shots, not on the test scenes.
pub fn guide_gain(exponent: f64, spp: usize) -> f64 {
    (spp.max(2) as f64 / 2.0).powf(exponent)
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

/// Initial log-strength of every edge-stopping guide (see `MsKpConfig::init`).
const GUIDE_STRENGTH_INIT: f32 = -6.0;

impl MsKpConfig {
    fn levels(&self) -> usize {
        self.widths.len()
    }

    /// Output channels of the head at scale `s`: k² kernel logits, the blend logit α_s except at
    /// the coarsest kernel scale, then one edge-stopping strength per guide group.
    fn head_channels(&self, s: usize) -> usize {
        self.filter_size * self.filter_size + usize::from(s + 1 < self.kernel_scales) + self.guides.len()
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
                let guide_channels: u64 =
                    self.guides.iter().map(|g| g.len as u64 + 1 + if g.variance.is_some() { 2 * g.len as u64 + 3 } else { 0 }).sum();
                total += (conv_macs(w[l], self.head_channels(l), 1) + (3 + guide_channels) * taps) as f64 / area;
            }
        }
        total as u64
    }

    /// Convolution kernel weights (no biases): a lower bound on the column's parameter count,
    /// which a weight file must hold (`weights::load` checks it before building the network).
    pub fn kernel_weights(&self) -> u64 {
        let w = &self.widths;
        let c = self.convs_per_block as u64;
        let block = |cin: usize, cout: usize| conv_macs(cin, cout, CONV) + (c - 1) * conv_macs(cout, cout, CONV);
        let mut total = 0;
        for l in 0..self.levels() {
            total += block(if l == 0 { self.in_channels } else { w[l - 1] }, w[l]);
            if l + 1 < self.levels() {
                total += block(w[l + 1] + w[l], w[l]);
            }
            if l < self.kernel_scales {
                total += conv_macs(w[l], self.head_channels(l), 1);
            }
        }
        total
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
        // A pooled variance reads its 5×5 window at full size, before the pyramid.
        let pool = if self.guides.iter().any(|g| g.pooled_variance) { VARIANCE_POOL / 2 } else { 0 };
        unet + (self.filter_size / 2 + 1) * (1 << (s - 1)) + (2 << s) + pool
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
        for g in &self.guides {
            assert!(
                g.len > 0 && g.start + g.len <= self.in_channels,
                "guide channels {}..{} outside the {} inputs",
                g.start,
                g.start + g.len,
                self.in_channels
            );
            assert!(
                g.variance.is_none_or(|v| v < self.in_channels),
                "guide variance channel {:?} outside the {} inputs",
                g.variance,
                self.in_channels
            );
        }
        let hidden = Init::XavierUniform { gain: std::f64::consts::SQRT_2 };
        let block = |cin: usize, cout: usize, tag: u64| {
            let mut widths = vec![cin];
            widths.extend(std::iter::repeat_n(cout, self.convs_per_block));
            ConvStack::new(&widths, CONV, Padding::Same, hidden, hidden, false, Activation::Relu, seed, tag, device)
        };
        let w = &self.widths;
        MsKpNet {
            down: (0..self.levels())
                .map(|l| block(if l == 0 { self.in_channels } else { w[l - 1] }, w[l], 0x4d53_0100 + l as u64))
                .collect(),
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
                    let mut head = Conv::new(spec, seed, 0x4d53_0300 + s as u64, device);
                    if !self.guides.is_empty() {
                        // Guide strengths start near zero (e^−6): the column begins as plain
                        // softmax kernels and learns where a guide can be trusted. Starting at
                        // e^0 cut every tap wherever the G-buffer is noisy (behind glass, on
                        // caustics), and 2900 steps did not unlearn it (docs/denoiser.md).
                        let n = self.head_channels(s);
                        let first = n - self.guides.len();
                        let bias: Vec<f32> = (0..n)
                            .map(|i| if i >= first { self.guides[i - first].init_log_strength.unwrap_or(GUIDE_STRENGTH_INIT) } else { 0.0 })
                            .collect();
                        head.bias = burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(bias, [n]), device));
                    }
                    head
                })
                .collect(),
            margin: self.margin,
            low_pass_swap: self.compositor == ScaleCompositor::LowPassSwap,
            guides: self.guides.clone(),
            guide_gain_exponent: self.guide_gain_exponent,
            engine: None,
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
    /// Edge-stopping guide groups (from the config).
    #[module(skip)]
    pub guides: Vec<GuideGroup>,
    /// [`MsKpConfig::guide_gain_exponent`].
    #[module(skip)]
    pub guide_gain_exponent: f64,
    /// When set, [`Self::heads`] runs on the inference engine instead of burn (same weights,
    /// same result to f32 rounding; `MethodModel::use_engine`). Never set while training.
    #[module(skip)]
    pub engine: Option<crate::engine::SharedUnet>,
}

/// One scale's head outputs: kernel logits `[B, k², h, w]`, the blend logit `[B, 1, h, w]`
/// (all but the coarsest scale) and the guide strengths' logs `[B, G, h, w]` (G guide groups).
pub struct HeadOutput {
    pub logits: Tensor<4>,
    pub alpha: Option<Tensor<4>>,
    pub guide_strength: Option<Tensor<4>>,
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
    apply_kernel(pad_reflect(colour, r), logits)
}

/// Reflect padding by `r` (edge replication where the level is too small to mirror), as the
/// colour gets before filtering.
fn pad_reflect(x: Tensor<4>, r: usize) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    let mode = if h > r && w > r { PadMode::Reflect } else { PadMode::Edge };
    x.pad([(r, r), (r, r)], mode)
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

    /// Multiply-accumulates of [`Self::heads`] on one `h × w` input (pooling floors odd sizes).
    pub fn conv_macs(&self, h: usize, w: usize) -> u64 {
        let px = |l: usize| ((h >> l) * (w >> l)) as u64;
        let conv = |layer: &Conv| {
            let [o, i, k, _] = layer.weight.dims();
            (o * i * k * k) as u64
        };
        let stacks = self.down.iter().enumerate().chain(self.up.iter().enumerate());
        let convs: u64 = stacks.map(|(l, s)| px(l) * s.layers.iter().map(conv).sum::<u64>()).sum();
        convs + self.heads.iter().enumerate().map(|(s, hd)| px(s) * conv(hd)).sum::<u64>()
    }

    /// Head outputs per scale, finest first.
    pub fn heads(&self, x: Tensor<4>) -> Vec<HeadOutput> {
        let scales = self.heads.len();
        let guides = self.guides.len();
        let outputs: Vec<Tensor<4>> = match &self.engine {
            Some(e) => {
                let device = x.device();
                e.head_tensors(x, &device)
            }
            None => self.features(x).into_iter().zip(&self.heads).map(|(f, head)| head.forward(f)).collect(),
        };
        outputs
            .into_iter()
            .enumerate()
            .map(|(s, o)| {
                let c = o.dims()[1] - guides;
                let guide_strength = (guides > 0).then(|| o.clone().narrow(1, c, guides));
                if s + 1 < scales {
                    HeadOutput { logits: o.clone().narrow(1, 0, c - 1), alpha: Some(o.narrow(1, c - 1, 1)), guide_strength }
                } else {
                    HeadOutput { logits: o.narrow(1, 0, c), alpha: None, guide_strength }
                }
            })
            .collect()
    }

    /// Filters and composites the colour `[B, 3, H, W]` with the head outputs; full size.
    /// `guides` are the guide groups' features at full size (empty without edge stopping);
    /// `gain` multiplies every guide strength ([`guide_gain`]).
    pub fn composite(colour: Tensor<4>, guides: Vec<GuideLevel>, heads: Vec<HeadOutput>, low_pass_swap: bool, gain: f64) -> Tensor<4> {
        let mut pyramid = vec![(colour, guides)];
        for _ in 1..heads.len() {
            let (c, g) = pyramid.last().unwrap();
            let next = (box_down(c.clone()), g.iter().map(GuideLevel::down).collect());
            pyramid.push(next);
        }
        let mut out: Option<Tensor<4>> = None;
        // The coarser level's guides, for the joint-bilateral upsampling into this one.
        let mut coarse_guides: Option<Vec<GuideLevel>> = None;
        let scales = heads.len();
        for (i, ((c, g), head)) in pyramid.into_iter().zip(heads).rev().enumerate() {
            let t = std::time::Instant::now();
            let [b, _, ch, cw] = c.dims();
            let taps = head.logits.dims()[1] as u64;
            let macs = (b * ch * cw) as u64 * taps * (3 + g.iter().map(GuideLevel::macs_per_tap).sum::<u64>());
            let mut logits = head.logits;
            // Bounded so that exp stays finite; e^±12 spans any useful strength.
            let strength =
                head.guide_strength
                    .map(|s| if gain == 1.0 { s.clamp(-12.0, 12.0).exp() } else { s.clamp(-12.0, 12.0).exp().mul_scalar(gain) });
            if let Some(strength) = &strength {
                let k = crate::kernel::filter_size(logits.dims()[1]);
                for (i, g) in g.iter().enumerate() {
                    logits = logits - tap_distances(g, k) * strength.clone().narrow(1, i, 1);
                }
            }
            let f = apply_kernel_reflect(c, logits);
            let own = f.clone();
            let up = |x: Tensor<4>, h: usize, w: usize| match (&strength, &coarse_guides) {
                (Some(s), Some(cg)) => joint_upsample(x, own.clone(), cg, &g, s.clone(), h, w),
                _ => upsample_to(x, h, w),
            };
            out = Some(match (out, head.alpha) {
                (Some(coarse), Some(a)) => {
                    let [_, _, h, w] = f.dims();
                    // Vogels et al.'s scale compositor: α swaps only the fine level's own
                    // low-pass band for the coarse result, so the edges its kernel kept stay.
                    let a = sigmoid(a);
                    let low = if low_pass_swap { up(box_down(f.clone()), h, w) } else { f.clone() };
                    f + (up(coarse, h, w) - low) * a
                }
                (None, _) => f,
                (Some(_), None) => unreachable!("only the coarsest scale lacks a blend weight"),
            });
            coarse_guides = Some(g);
            if crate::engine::profile::active() {
                // burn flex runs eagerly, so the time around the ops is theirs.
                let s = scales - 1 - i;
                crate::engine::profile::record(&format!("kernel application s{s}"), t.elapsed().as_secs_f64(), macs as f64);
            }
        }
        out.expect("at least one kernel scale")
    }

    /// `[B, C_in, H, W]` (sanitised) at `spp` samples per pixel → `[B, 3, H−2m, W−2m]`.
    pub fn forward(&self, input: Tensor<4>, spp: usize) -> Tensor<4> {
        let [b, _, h, w] = input.dims();
        let conv_macs = (b as u64 * self.conv_macs(h, w)) as f64;
        let heads = crate::engine::profile::timed(|| "convolutions".into(), conv_macs, || self.heads(input.clone()));
        let guides = crate::engine::profile::timed(|| "guide features".into(), 0.0, || guide_features(&input, &self.guides, spp));
        let out = Self::composite(input.narrow(1, 0, 3), guides, heads, self.low_pass_swap, guide_gain(self.guide_gain_exponent, spp));
        center_crop(out, h - 2 * self.margin, w - 2 * self.margin)
    }
}

#[cfg(test)]
mod tests;
