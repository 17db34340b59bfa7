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
//! Edge stopping (`edge_stopping`, the `edge` preset): a softmax kernel predicted by the U-Net
//! alone leaked 5–25 % of a bright neighbour across silhouettes and around emitters even on a
//! 1024-spp input (docs/denoiser.md, "Error floors"). With guide groups (colour as log(1+c),
//! normal, depth, albedo for D_G; colour and f_P for D_P) every tap's logit is lowered by
//! Σ_g w_g·‖s_g·(g(q) − g(p))‖² (for the colour only where q is brighter), with per-pixel strengths w_g = exp(·) predicted by the same
//! head: the cross-bilateral weighting of Kalantari et al. 2015 (method.md §12) inside a learned
//! kernel. The centre tap's distance is 0, so the identity stays in reach.
//!
//! Borders: each level is reflect-padded before filtering, so the kernels never read zeros and the
//! image edge is not darkened (the KPCN's ⚠ of docs/method.md §3). The network output is cropped
//! by `margin` per side like the KPCN's, so training and tiled inference treat both columns alike.

use burn::config::Config;
use burn::module::Module;
use burn::tensor::activation::{relu, sigmoid, softmax};
use burn::tensor::module::{avg_pool2d, interpolate, max_pool2d, unfold4d};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions, MaxPoolOptions, PadMode, UnfoldOptions};
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
    /// Which edge-stopping guides the column gets; `DenoiserConfig::mskp_for` turns this into
    /// `guides` for its input variant. Files without the field have none.
    #[config(default = "EdgeStopping::Off")]
    pub edge_stopping: EdgeStopping,
    /// The guide groups this column's kernels stop at (empty: plain softmax kernels).
    #[config(default = "Vec::new()")]
    pub guides: Vec<GuideGroup>,
}

/// The edge-stopping guides of a preset (per variant: `DenoiserConfig::mskp_for`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum EdgeStopping {
    /// Plain softmax kernels.
    Off,
    /// The column's auxiliary features: normal, depth and albedo (D_G), f_P (D_P).
    Features,
    /// Those plus the colour, brighter taps only.
    FeaturesAndColour,
    /// The features plus the colour, its differences measured in units of their own noise
    /// (Rousselle et al. 2012): a difference the per-pixel variance explains costs nothing, so
    /// noisy pixels still average, and as the variance falls with more samples every real
    /// difference stops the kernel, which tends to the identity on a converged input.
    FeaturesAndNoisyColour,
}

/// Input channels `start..start + len` used as an edge-stopping guide, multiplied by `scale`
/// (after log(1 + max(c, 0)) when `log`) before distances are taken. A `brighter_only` guide
/// counts only how much a tap exceeds the centre, Σ max(g(q) − g(p), 0)²: on the noisy colour a
/// symmetric distance would keep every firefly (its neighbours all look far from it), while this
/// one only stops light from flowing in from brighter taps, fireflies included.
///
/// A guide with a `variance` channel (the per-pixel variance of the mean of channels
/// `start..start + len`, in their units) is noise-normalised: a tap's distance is
/// Σ_c max((g_c(q) − g_c(p))² − (v_p + min(v_p, v_q)), 0) / (ε + v_p + v_q), the non-local-means
/// distance of Rousselle et al. 2012 (docs/method.md §12): the subtraction removes what the noise
/// alone adds to a squared difference, the division puts it in units of that noise. Its strength
/// starts at `init_log_strength` (e^`GUIDE_STRENGTH_INIT` when `None`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GuideGroup {
    pub start: usize,
    pub len: usize,
    pub scale: f64,
    pub log: bool,
    #[serde(default)]
    pub brighter_only: bool,
    #[serde(default)]
    pub variance: Option<usize>,
    #[serde(default)]
    pub init_log_strength: Option<f32>,
    /// Normalise by [`pooled_variance`] instead of the pixel's own variance.
    #[serde(default)]
    pub pooled_variance: bool,
}

impl GuideGroup {
    pub fn new(start: usize, len: usize, scale: f64, log: bool) -> Self {
        GuideGroup { start, len, scale, log, brighter_only: false, variance: None, init_log_strength: None, pooled_variance: false }
    }

    pub fn brighter_only(self) -> Self {
        GuideGroup { brighter_only: true, ..self }
    }

    /// Noise-normalised distances, with the variance of the mean in input channel `channel`.
    pub fn with_variance(self, channel: usize) -> Self {
        GuideGroup { variance: Some(channel), ..self }
    }

    /// Noise-normalised by the variance pooled over a window ([`pooled_variance`]).
    pub fn with_pooled_variance(self, channel: usize) -> Self {
        GuideGroup { variance: Some(channel), pooled_variance: true, ..self }
    }

    pub fn with_init_log_strength(self, s: f32) -> Self {
        GuideGroup { init_log_strength: Some(s), ..self }
    }
}

/// A guide group's features at one pyramid level, with the variance of their mean for a
/// noise-normalised group.
#[derive(Clone, Debug)]
pub struct GuideLevel {
    x: Tensor<4>,
    var: Option<Tensor<4>>,
    brighter_only: bool,
}

impl GuideLevel {
    /// The next coarser level: 2×2 box means, whose variance is a quarter of the mean variance
    /// (independent pixels).
    fn down(&self) -> Self {
        GuideLevel { x: box_down(self.x.clone()), var: self.var.clone().map(|v| box_down(v).div_scalar(4.0)), brighter_only: self.brighter_only }
    }
}

/// Keeps a noise-normalised distance finite where both variances are 0 (a pixel whose samples
/// all agree); in the colour's units squared, far below any visible difference.
const NOISE_EPS: f32 = 1e-4;

/// Guide distances between taps q `[B, C, T, N]` (variances `[B, 1, T, N]`) and centres p
/// `[B, C, 1, N]` (`[B, 1, 1, N]`) → `[B, T, N]`.
fn guide_distance(q: Tensor<4>, p: Tensor<4>, var: Option<(Tensor<4>, Tensor<4>)>, brighter_only: bool) -> Tensor<3> {
    let diff = q - p;
    let diff = if brighter_only { diff.clamp_min(0.0) } else { diff };
    let d2 = diff.square();
    match var {
        None => d2.sum_dim(1).squeeze_dim(1),
        Some((vq, vp)) => {
            let min = (vq.clone() + vp.clone() - (vq.clone() - vp.clone()).abs()).mul_scalar(0.5);
            let excess = (d2 - (vp.clone() + min)).clamp_min(0.0);
            (excess / (vq + vp).add_scalar(NOISE_EPS)).sum_dim(1).squeeze_dim(1)
        }
    }
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
                let guide_channels: u64 = self.guides.iter().map(|g| g.len as u64 + 1 + if g.variance.is_some() { 2 * g.len as u64 + 3 } else { 0 }).sum();
                total += (conv_macs(w[l], self.head_channels(l), 1) + (3 + guide_channels) * taps) as f64 / area;
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
            assert!(g.len > 0 && g.start + g.len <= self.in_channels, "guide channels {}..{} outside the {} inputs", g.start, g.start + g.len, self.in_channels);
            assert!(g.variance.is_none_or(|v| v < self.in_channels), "guide variance channel {:?} outside the {} inputs", g.variance, self.in_channels);
        }
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
                    let mut head = Conv::new(spec, seed, 0x4d53_0300 + s as u64, device);
                    if !self.guides.is_empty() {
                        // Guide strengths start near zero (e^−6): the column begins as plain
                        // softmax kernels and learns where a guide can be trusted. Starting at
                        // e^0 cut every tap wherever the G-buffer is noisy (behind glass, on
                        // caustics), and 2900 steps did not unlearn it (docs/denoiser.md).
                        let n = self.head_channels(s);
                        let first = n - self.guides.len();
                        let bias: Vec<f32> = (0..n).map(|i| if i >= first { self.guides[i - first].init_log_strength.unwrap_or(GUIDE_STRENGTH_INIT) } else { 0.0 }).collect();
                        head.bias = burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(bias, [n]), device));
                    }
                    head
                })
                .collect(),
            margin: self.margin,
            low_pass_swap: self.compositor == ScaleCompositor::LowPassSwap,
            guides: self.guides.clone(),
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

/// The guide distance (Σ_c (g_c(q) − g_c(p))², only the positive differences if
/// `brighter_only`, noise-normalised with a variance: [`GuideGroup`]) for every tap q of the k×k
/// window around each pixel p: `[B, C, H, W]` → `[B, k², H, W]`, taps in the kernel map's order.
pub fn tap_distances(g: &GuideLevel, k: usize) -> Tensor<4> {
    let [b, c, h, w] = g.x.dims();
    let windows = |x: &Tensor<4>| {
        let c = x.dims()[1];
        unfold4d(pad_reflect(x.clone(), k / 2), [k, k], UnfoldOptions::new([1, 1], [0, 0], [1, 1])).reshape([b, c, k * k, h * w])
    };
    let var = g.var.as_ref().map(|v| (windows(v), v.clone().reshape([b, 1, 1, h * w])));
    guide_distance(windows(&g.x), g.x.clone().reshape([b, c, 1, h * w]), var, g.brighter_only).reshape([b, k * k, h, w])
}

/// Side of the window whose mean variance a pixel's own may not fall below (see
/// [`pooled_variance`]).
const VARIANCE_POOL: usize = 5;

/// max(v, mean of v over the 5×5 window): at 2 spp most pixels of a dim scene saw no light in
/// either sample and report variance 0, and a distance normalised by that called every lit
/// neighbour an edge, so black holes stayed black (veach-ajar 2 spp: 0.205 → 0.144 with the same
/// weights). The window's mean is what the pixel's variance would be had its samples been as
/// lucky as its neighbours'; the max keeps a firefly's own large variance. Next to a thin,
/// noisy feature (wires at 64 spp) the pooled variance is too large and lets the feature leak,
/// so the preset gives the network both distances, each with its own strength.
fn pooled_variance(v: Tensor<4>) -> Tensor<4> {
    let r = VARIANCE_POOL / 2;
    let mean = avg_pool2d(pad_reflect(v.clone(), r), AvgPoolOptions::new([VARIANCE_POOL, VARIANCE_POOL]).with_stride([1, 1]));
    v.max_pair(mean)
}

/// The guide groups' features at full size, scaled (and log-compressed where asked), with their
/// variances for noise-normalised groups (scaled alike, clamped at 0), in the group order.
fn guide_features(input: &Tensor<4>, guides: &[GuideGroup]) -> Vec<GuideLevel> {
    guides
        .iter()
        .map(|g| {
            let x = input.clone().narrow(1, g.start, g.len);
            let x = if g.log { x.clamp_min(0.0).log1p() } else { x };
            let var = g.variance.map(|v| {
                let v = input.clone().narrow(1, v, 1).clamp_min(0.0);
                let v = if g.pooled_variance { pooled_variance(v) } else { v };
                v.mul_scalar(g.scale * g.scale)
            });
            GuideLevel { x: x.mul_scalar(g.scale), var, brighter_only: g.brighter_only }
        })
        .collect()
}

/// Log of the bilinear (align-corners-false) weights of the 3×3 coarse neighbours of each pixel
/// of a 2h×2w grid, `[1, 9, 2h, 2w]`, taps in unfold order; −1e4 where a weight is 0.
fn bilinear_tap_logits(h: usize, w: usize, device: &Device) -> Tensor<4> {
    // A fine pixel in the upper (left) half of its parent takes ¼ of the coarse row (column)
    // above (left), ¾ of its own and none of the one below (right); mirrored for the other half.
    let one_d = |sub: usize| if sub == 0 { [0.25f32, 0.75, 0.0] } else { [0.0, 0.75, 0.25] };
    let (fh, fw) = (2 * h, 2 * w);
    let mut v = vec![0f32; 9 * fh * fw];
    for y in 0..fh {
        for x in 0..fw {
            let (wy, wx) = (one_d(y % 2), one_d(x % 2));
            for i in 0..3 {
                for j in 0..3 {
                    let wt = wy[i] * wx[j];
                    v[((i * 3 + j) * fh + y) * fw + x] = if wt > 0.0 { wt.ln() } else { -1e4 };
                }
            }
        }
    }
    Tensor::<1>::from_data(burn::tensor::TensorData::new(v, [9 * fh * fw]), device).reshape([1, 9, fh, fw])
}

/// Edge-pads (or crops) the bottom/right of `x` to `h`×`w`.
fn fit_to(x: Tensor<4>, h: usize, w: usize) -> Tensor<4> {
    let [_, _, xh, xw] = x.dims();
    let x = x.narrow(2, 0, xh.min(h)).narrow(3, 0, xw.min(w));
    let (py, px) = (h.saturating_sub(xh), w.saturating_sub(xw));
    if py > 0 || px > 0 {
        x.pad([(0, py), (0, px)], PadMode::Edge)
    } else {
        x
    }
}

/// The 3×3 windows of `x` `[B, C, h, w]` (reflect-padded), repeated onto the 2×2 fine pixels of
/// each coarse one and edge-padded to `[B, C, 9, fh·fw]` (fh ∈ {2h, 2h + 1}: pooling floors).
fn coarse_windows(x: Tensor<4>, fh: usize, fw: usize) -> Tensor<4> {
    let [b, c, h, w] = x.dims();
    let cols = unfold4d(pad_reflect(x, 1), [3, 3], UnfoldOptions::new([1, 1], [0, 0], [1, 1])).reshape([b, c * 9, h, w]);
    let rep = interpolate(cols, InterpolateOptions::new(InterpolateMode::Nearest).with_output_size([2 * h, 2 * w]));
    fit_to(rep, fh, fw).reshape([b, c, 9, fh * fw])
}

/// Log-weight of the fine level's own value among the coarse taps of [`joint_upsample`]: e^−6
/// ≈ 0.25 % beside unpenalised bilinear weights (which sum to 1), all of it where every coarse
/// tap is cut.
const UPSAMPLE_FALLBACK_LOG_WEIGHT: f32 = -6.0;

/// Joint-bilateral 2× upsampling (Kopf et al. 2007) of `coarse` `[B, 3, h, w]` to `fh`×`fw`:
/// each fine pixel p averages its 3×3 coarse neighbours q with the bilinear weights times
/// exp(−Σ_g s_g(p)·‖g(q) − g(p)‖²), renormalised, where g(q) are the coarse level's guides and
/// g(p) this level's. Plain bilinear upsampling carried a quarter of a bright coarse pixel across
/// every silhouette into the convex blend (docs/denoiser.md, "Error floors").
///
/// A tenth tap holds `fallback` (the fine level's own filtered value) at a small fixed weight:
/// a small feature (a 3×3 shadow, a thin edge) has no coarse pixel of its own, so every coarse tap
/// is cut and the softmax would otherwise hand the pixel to the least different one, however far
/// (a shadow filled with the sunlit wall around it, docs/denoiser.md).
fn joint_upsample(coarse: Tensor<4>, fallback: Tensor<4>, coarse_guides: &[GuideLevel], fine_guides: &[GuideLevel], strength: Tensor<4>, fh: usize, fw: usize) -> Tensor<4> {
    let [b, c, h, w] = coarse.dims();
    let n = fh * fw;
    let mut logits = fit_to(bilinear_tap_logits(h, w, &coarse.device()), fh, fw).reshape([1, 9, n]).repeat_dim(0, b);
    for (i, (cg, fg)) in coarse_guides.iter().zip(fine_guides).enumerate() {
        let gc = fg.x.dims()[1];
        let var = cg.var.as_ref().zip(fg.var.as_ref()).map(|(cv, fv)| (coarse_windows(cv.clone(), fh, fw), fv.clone().reshape([b, 1, 1, n])));
        let d = guide_distance(coarse_windows(cg.x.clone(), fh, fw), fg.x.clone().reshape([b, gc, 1, n]), var, fg.brighter_only);
        logits = logits - d * strength.clone().narrow(1, i, 1).reshape([b, 1, n]);
    }
    let own = Tensor::<3>::full([b, 1, n], UPSAMPLE_FALLBACK_LOG_WEIGHT, &coarse.device());
    let wts = softmax(Tensor::cat(vec![logits, own], 1), 1).reshape([b, 1, 10, n]);
    let taps = Tensor::cat(vec![coarse_windows(coarse, fh, fw), fallback.reshape([b, c, 1, n])], 2);
    (taps * wts).sum_dim(2).reshape([b, c, fh, fw])
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

    /// Head outputs per scale, finest first.
    pub fn heads(&self, x: Tensor<4>) -> Vec<HeadOutput> {
        let scales = self.heads.len();
        let guides = self.guides.len();
        self.features(x)
            .into_iter()
            .zip(&self.heads)
            .enumerate()
            .map(|(s, (f, head))| {
                let o = head.forward(f);
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
    /// `guides` are the guide groups' features at full size (empty without edge stopping).
    pub fn composite(colour: Tensor<4>, guides: Vec<GuideLevel>, heads: Vec<HeadOutput>, low_pass_swap: bool) -> Tensor<4> {
        let mut pyramid = vec![(colour, guides)];
        for _ in 1..heads.len() {
            let (c, g) = pyramid.last().unwrap();
            let next = (box_down(c.clone()), g.iter().map(GuideLevel::down).collect());
            pyramid.push(next);
        }
        let mut out: Option<Tensor<4>> = None;
        // The coarser level's guides, for the joint-bilateral upsampling into this one.
        let mut coarse_guides: Option<Vec<GuideLevel>> = None;
        for ((c, g), head) in pyramid.into_iter().zip(heads).rev() {
            let mut logits = head.logits;
            // Bounded so that exp stays finite; e^±12 spans any useful strength.
            let strength = head.guide_strength.map(|s| s.clamp(-12.0, 12.0).exp());
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
        }
        out.expect("at least one kernel scale")
    }

    /// `[B, C_in, H, W]` (sanitised) → `[B, 3, H−2m, W−2m]`.
    pub fn forward(&self, input: Tensor<4>) -> Tensor<4> {
        let [_, _, h, w] = input.dims();
        let heads = self.heads(input.clone());
        let guides = guide_features(&input, &self.guides);
        let out = Self::composite(input.narrow(1, 0, 3), guides, heads, self.low_pass_swap);
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
        gradients_match_finite_differences_for(tiny(5));
    }

    /// The same check with edge-stopping guides (the strengths and the tap distances are on the
    /// gradient path of the kernel logits).
    #[test]
    fn edge_stopping_gradients_match_finite_differences() {
        for compositor in [ScaleCompositor::LowPassSwap, ScaleCompositor::ConvexBlend] {
            let guides = vec![GuideGroup::new(0, 3, 1.0, false).brighter_only(), GuideGroup::new(3, 2, 2.0, false)];
            gradients_match_finite_differences_for(tiny(5).with_compositor(compositor).with_guides(guides));
            // Noise-normalised: the variance channel (4) is on the gradient path too.
            let noisy = vec![GuideGroup::new(0, 3, 1.0, false).with_variance(4).with_init_log_strength(-1.0), GuideGroup::new(0, 3, 1.0, false).with_pooled_variance(4)];
            gradients_match_finite_differences_for(tiny(5).with_compositor(compositor).with_guides(noisy));
        }
    }

    fn gradients_match_finite_differences_for(cfg: MsKpConfig) {
        let dev = cpu_training_device();
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
        set_constant_heads(&mut net, &cfg, |_, n| {
            let mut bias = vec![-60.0f32; n];
            bias[taps / 2] = 60.0;
            if n > taps {
                bias[taps] = 60.0; // α = 1
            }
            bias
        });
        let worst = largest_change(&net, &cfg, &x, 16);
        assert!(worst < 1e-5, "identity kernels with α = 1 changed the input by {worst}");
    }

    /// Box kernels (all logits 0) and no coarse levels (α → 0) blur a step edge; with a guide
    /// channel that steps where the colour does and a strong edge-stopping strength, every tap
    /// across the step is cut and the output is the input on both sides. The strength's sign
    /// flips the outcome, so the test can fail.
    #[test]
    fn edge_stopping_keeps_a_guided_step_edge() {
        let d = cpu_device();
        let cfg = tiny(4).with_guides(vec![GuideGroup::new(3, 1, 1.0, false)]);
        let dims = [1, 4, 16, 16];
        let side = |i: usize| (i % 16) < 7;
        let x: Vec<f64> = (0..dims.iter().product())
            .map(|i| if i / 256 == 3 { f64::from(u8::from(side(i))) } else if side(i) { 0.02 } else { 1.0 })
            .collect();
        for (strength, expect_sharp) in [(12.0f32, true), (-12.0, false)] {
            let mut net = cfg.init(1, &d);
            set_constant_heads(&mut net, &cfg, |s, n| {
                let mut bias = vec![0.0f32; n];
                if s + 1 < cfg.kernel_scales {
                    bias[9] = -60.0; // α = 0
                }
                bias[n - 1] = strength;
                bias
            });
            let worst = largest_change(&net, &cfg, &x, 16);
            if expect_sharp {
                assert!(worst < 1e-5, "edge-stopped box kernels moved the edge by {worst}");
            } else {
                assert!(worst > 0.1, "plain box kernels should blur the edge ({worst})");
            }
        }
    }

    /// At 2 spp a dark pixel whose two samples both missed the light reports variance 0. The
    /// pooled variance gives it its neighbours' (5×5 mean: 24/25 of theirs), while a pixel with
    /// more variance than its window keeps its own.
    #[test]
    fn pooled_variance_lends_a_zero_variance_pixel_its_neighbours_noise() {
        let d = cpu_device();
        let mut v = vec![1.0f64; 81];
        v[40] = 0.0; // centre of 9×9
        v[0] = 50.0; // a firefly's corner
        let pooled = to_vec(pooled_variance(tensor(&v, [1, 1, 9, 9], &d)));
        assert!((pooled[40] - 24.0 / 25.0).abs() < 1e-6, "{}", pooled[40]);
        assert_eq!(pooled[0], 50.0);
        assert!(pooled.iter().zip(&v).all(|(p, v)| p >= v));
    }

    /// A feature smaller than a coarse pixel (one dark pixel, marked by the guide) has no coarse
    /// tap of its own: with α = 1 and identity kernels, every coarse tap of its upsampling is cut,
    /// and it must come back as itself (the fine level's own value) rather than as the least
    /// different coarse pixel (0.755, its block's mean). Everything else is constant, so the
    /// whole output must equal the input.
    #[test]
    fn a_feature_smaller_than_a_coarse_pixel_survives_the_convex_blend() {
        let d = cpu_device();
        let cfg = tiny(4).with_compositor(ScaleCompositor::ConvexBlend).with_guides(vec![GuideGroup::new(3, 1, 1.0, false)]);
        let dark = 7 * 16 + 9;
        let x: Vec<f64> = (0..4 * 256).map(|i| if i / 256 == 3 { f64::from(u8::from(i % 256 == dark)) } else if i % 256 == dark { 0.02 } else { 1.0 }).collect();
        let mut net = cfg.init(1, &d);
        set_constant_heads(&mut net, &cfg, |s, n| {
            let mut bias = vec![-60.0f32; n];
            bias[4] = 60.0; // identity kernel
            if s + 1 < cfg.kernel_scales {
                bias[9] = 60.0; // α = 1
            }
            bias[n - 1] = 12.0;
            bias
        });
        let worst = largest_change(&net, &cfg, &x, 16);
        assert!(worst < 1e-4, "the dark pixel changed by {worst}");
    }

    /// A noise-normalised colour guide at a fixed strength (e^0) keeps a step of 0.98 where the
    /// variance of the mean is 1e-4 (σ = 0.01: a 98σ step) and blurs the same step where it is
    /// 10 (σ ≈ 3.2: the noise explains it), so the same network is sharp on a converged input
    /// and smooths a noisy one. Either assertion fails if the variance is ignored.
    #[test]
    fn noise_normalised_colour_guide_stops_only_at_steps_the_noise_cannot_explain() {
        let d = cpu_device();
        let cfg = tiny(4).with_guides(vec![GuideGroup::new(0, 3, 1.0, false).with_variance(3)]);
        let side = |i: usize| (i % 16) < 7;
        for (variance, expect_sharp) in [(1e-4, true), (10.0, false)] {
            let x: Vec<f64> = (0..4 * 256).map(|i| if i / 256 == 3 { variance } else if side(i) { 0.02 } else { 1.0 }).collect();
            let mut net = cfg.init(1, &d);
            set_constant_heads(&mut net, &cfg, |s, n| {
                let mut bias = vec![0.0f32; n];
                if s + 1 < cfg.kernel_scales {
                    bias[9] = -60.0; // α = 0
                }
                bias
            });
            let worst = largest_change(&net, &cfg, &x, 16);
            if expect_sharp {
                assert!(worst < 1e-5, "a 98σ step was blurred by {worst}");
            } else {
                assert!(worst > 0.1, "a step well inside the noise should be smoothed ({worst})");
            }
        }
    }

    /// The convex blend at α = 1 with identity kernels returns the coarse levels, upsampled. A
    /// step edge on the coarsest grid with a guide that steps with it comes back exactly when the
    /// upsampling is joint-bilateral (each fine pixel takes only coarse pixels on its side), and
    /// blurred when the strengths are off (plain bilinear weights), so the test can fail.
    #[test]
    fn joint_bilateral_upsampling_keeps_a_guided_edge_through_the_convex_blend() {
        let d = cpu_device();
        let cfg = tiny(4).with_compositor(ScaleCompositor::ConvexBlend).with_guides(vec![GuideGroup::new(3, 1, 1.0, false)]);
        let dims = [1, 4, 16, 16];
        let side = |i: usize| (i % 16) < 8;
        let x: Vec<f64> = (0..dims.iter().product())
            .map(|i| if i / 256 == 3 { f64::from(u8::from(side(i))) } else if side(i) { 0.02 } else { 1.0 })
            .collect();
        for (strength, expect_sharp) in [(12.0f32, true), (-12.0, false)] {
            let mut net = cfg.init(1, &d);
            set_constant_heads(&mut net, &cfg, |s, n| {
                let mut bias = vec![-60.0f32; n];
                bias[4] = 60.0; // identity kernel
                if s + 1 < cfg.kernel_scales {
                    bias[9] = 60.0; // α = 1
                }
                bias[n - 1] = strength;
                bias
            });
            let worst = largest_change(&net, &cfg, &x, 16);
            if expect_sharp {
                assert!(worst < 1e-4, "joint-bilateral upsampling moved the edge by {worst}");
            } else {
                assert!(worst > 0.1, "bilinear upsampling should blur the edge ({worst})");
            }
        }
    }

    /// Sets every head to a constant output: zero weights and `bias(scale, channels)`.
    fn set_constant_heads(net: &mut MsKpNet, cfg: &MsKpConfig, bias: impl Fn(usize, usize) -> Vec<f32>) {
        let d = cpu_device();
        for s in 0..cfg.kernel_scales {
            let n = cfg.head_channels(s);
            let c = net.heads[s].weight.dims()[1];
            net.heads[s].weight = burn::module::Param::from_tensor(Tensor::zeros([n, c, 1, 1], &d));
            net.heads[s].bias = burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(bias(s, n), [n]), &d));
        }
    }

    /// The largest difference between the column's output and its colour input (one image,
    /// `side`², cropped by the margin).
    fn largest_change(net: &MsKpNet, cfg: &MsKpConfig, x: &[f64], side: usize) -> f64 {
        let c_in = x.len() / (side * side);
        let out = to_vec(net.forward(tensor(x, [1, c_in, side, side], &cpu_device())));
        let (m, o) = (cfg.margin, side - 2 * cfg.margin);
        let mut worst = 0.0f64;
        for c in 0..3 {
            for y in 0..o {
                for xx in 0..o {
                    worst = worst.max((out[(c * o + y) * o + xx] - x[(c * side + y + m) * side + xx + m]).abs());
                }
            }
        }
        worst
    }

    #[test]
    fn any_size_runs() {
        let d = cpu_device();
        let guided = tiny(4).with_compositor(ScaleCompositor::ConvexBlend).with_guides(vec![GuideGroup::new(0, 3, 1.0, true).brighter_only(), GuideGroup::new(3, 1, 1.0, false)]);
        for (cfg, c) in [(tiny(3), 3), (guided, 4)] {
            let net = cfg.init(2, &d);
            for (h, w) in [(13, 9), (5, 7), (4, 4)] {
                let out = net.forward(Tensor::<4>::ones([1, c, h, w], &d));
                assert_eq!(out.dims(), [1, 3, h - 2, w - 2]);
                assert!(to_vec(out).iter().all(|v| (v - 1.0).abs() < 1e-5));
            }
        }
    }
}
