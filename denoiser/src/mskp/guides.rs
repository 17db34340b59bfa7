//! Edge-stopping guides of the multi-scale column (docs/method.md §12): which input channels a
//! kernel stops at ([`GuideGroup`]), the distance between a tap and the centre (plain, brighter
//! only, or in units of the noise), and the joint-bilateral upsampling of the coarse levels.

use burn::tensor::activation::softmax;
use burn::tensor::module::{avg_pool2d, interpolate, unfold4d};
use burn::tensor::ops::{AvgPoolOptions, InterpolateMode, InterpolateOptions, PadMode, UnfoldOptions};
use burn::tensor::{Device, Tensor};

use super::{box_down, pad_reflect};

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
    /// As `FeaturesAndNoisyColour`, both colour guides with the two-sided test of
    /// [`GuideGroup::two_sided`]: the `edge-noise` preset of 2026-11-25, evening. Sparse 2-spp
    /// images keep their brightness; the price is paid at 32–64 spp, where a firefly or a thin
    /// feature's difference is about its own variance and passes (docs/denoiser.md, "The
    /// two-sided noise test").
    FeaturesAndTwoSidedNoisyColour,
    /// As `FeaturesAndTwoSidedNoisyColour`, with the two-sided share fading as 1/(N − 1) at N
    /// spp ([`GuideGroup::two_sided_fades`]): two-sided at 2 spp, where a zero variance says
    /// nothing, and nearly Rousselle's one-sided test at 32–64 spp, where it is sound. The
    /// `edge-noise` preset of 2026-11-26, morning.
    FeaturesAndFadingTwoSidedNoisyColour,
    /// As `FeaturesAndFadingTwoSidedNoisyColour`, in the diffuse branch two-sided at any sample
    /// count wherever the centre pixel is black ([`GuideGroup::doubt_black`]): the `edge-noise`
    /// preset since 2026-11-26, afternoon.
    FeaturesAndFadingNoisyColourDoubtingBlack,
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
///
/// A `two_sided` group subtracts 2(v_p + v_q) instead (see [`TWO_SIDED_NOISE_FACTOR`]), what the noise of both pixels adds: the
/// distance is then symmetric in p and q, a two-sample test of equal means. Rousselle's
/// one-sided form was made for a pixel whose variance estimate is sound; at 2 spp a pixel whose
/// samples both found no light reports v = 0, and its distance to a lit neighbour came out twice
/// the neighbour's distance to it. Zero pixels then refused the lit ones while the lit ones took
/// the zeros in: veach-ajar at 2 spp came out at 0.54 of the reference's brightness (median over
/// pixels; docs/journal/denoiser.md, "Two-sided noise test").
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
    /// Subtract 2(v_p + v_q) (symmetric) instead of v_p + min(v_p, v_q). Files without the field
    /// have the one-sided form.
    #[serde(default)]
    pub two_sided: bool,
    /// With `two_sided`: at N spp subtract w·2(v_p + v_q) + (1 − w)·(v_p + min(v_p, v_q)), w =
    /// 1/(N − 1) (1 at N ≤ 2). A pixel whose N samples all found no light reports v = 0; at 2
    /// spp that is an accident of two samples (the two-sided test lets it take its lit
    /// neighbours in), at 64 spp it is a fact (a diffuse wall beside a glinting wire has no
    /// specular light, and the two-sided test had let the wire's highlight spill onto it:
    /// wire-fence at 64 spp 0.0035 one-sided, 0.0088 two-sided, noisy 0.0038). How sure a
    /// variance estimate of N samples is grows with N; the share of the test that doubts it falls
    /// as 1/(N − 1), the gap between the unbiased and the population variance that the renderer
    /// reports. Files without the field keep the full two-sided test.
    #[serde(default)]
    pub two_sided_fades: bool,
    /// With `two_sided_fades`: the full two-sided test wherever the centre pixel is black (every
    /// sample found no light), at any sample count. N black samples say nothing about the
    /// pixel's variance: on veach-ajar at 4 spp most pixels still see no light, and the fading
    /// share (1/3) let them refuse their lit neighbours (docs/denoiser.md). A wall beside a
    /// glinting wire at 64 spp is lit, so it keeps the fading, nearly one-sided test. Files
    /// without the field fade everywhere.
    #[serde(default)]
    pub doubt_black: bool,
}

impl GuideGroup {
    pub fn new(start: usize, len: usize, scale: f64, log: bool) -> Self {
        GuideGroup {
            start,
            len,
            scale,
            log,
            brighter_only: false,
            variance: None,
            init_log_strength: None,
            pooled_variance: false,
            two_sided: false,
            two_sided_fades: false,
            doubt_black: false,
        }
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

    /// The symmetric test of [`GuideGroup::two_sided`].
    pub fn two_sided(self) -> Self {
        GuideGroup { two_sided: true, ..self }
    }

    /// The two-sided test with its share fading with the sample count
    /// ([`GuideGroup::two_sided_fades`]).
    pub fn two_sided_fading(self) -> Self {
        GuideGroup { two_sided: true, two_sided_fades: true, ..self }
    }

    /// The fading test, two-sided wherever the centre is black ([`GuideGroup::doubt_black`]).
    pub fn two_sided_fading_doubting_black(self) -> Self {
        GuideGroup { doubt_black: true, ..self.two_sided_fading() }
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
    /// Share of the two-sided test in the subtraction (0: one-sided; [`GuideGroup::two_sided_fades`]).
    two_sided_share: f32,
    /// [`GuideGroup::doubt_black`].
    doubt_black: bool,
}

impl GuideLevel {
    /// Multiply-accumulates of one tap's distance, as `MsKpConfig::macs_per_pixel` counts them.
    pub(super) fn macs_per_tap(&self) -> u64 {
        let c = self.x.dims()[1] as u64;
        c + 1 + if self.var.is_some() { 2 * c + 3 } else { 0 }
    }

    /// The next coarser level: 2×2 box means, whose variance is a quarter of the mean variance
    /// (independent pixels).
    pub(super) fn down(&self) -> Self {
        GuideLevel {
            x: box_down(self.x.clone()),
            var: self.var.clone().map(|v| box_down(v).div_scalar(4.0)),
            brighter_only: self.brighter_only,
            two_sided_share: self.two_sided_share,
            doubt_black: self.doubt_black,
        }
    }
}

/// Keeps a noise-normalised distance finite where both variances are 0 (a pixel whose samples
/// all agree); in the colour's units squared, far below any visible difference.
const NOISE_EPS: f32 = 1e-4;

/// How many times v_p + v_q a two-sided test lets pass free. The renderer reports the
/// population variance of the mean, which at N spp is (N − 1)/N of the unbiased estimate: half
/// at 2 spp, where the test matters most (a pixel with one lit sample of two is then exactly
/// consistent with a black neighbour). With the pixel's own variance (factor 1) the shipped
/// one-sided weights still left veach-ajar at 0.67 of its brightness at 2 spp, at 2 at 0.81
/// (docs/journal/denoiser.md, "Two-sided noise test"). At high spp a difference must exceed 1.4 σ
/// instead of 1 σ before it costs anything; the learned strength scales what is beyond.
const TWO_SIDED_NOISE_FACTOR: f32 = 2.0;

/// Guide distances between taps q `[B, C, T, N]` (variances `[B, 1, T, N]`) and centres p
/// `[B, C, 1, N]` (`[B, 1, 1, N]`) → `[B, T, N]`.
fn guide_distance(q: Tensor<4>, p: Tensor<4>, var: Option<(Tensor<4>, Tensor<4>)>, g: &GuideLevel) -> Tensor<3> {
    let diff = q - p.clone();
    let diff = if g.brighter_only { diff.clamp_min(0.0) } else { diff };
    let d2 = diff.square();
    match var {
        None => d2.sum_dim(1).squeeze_dim(1),
        Some((vq, vp)) => {
            // v_p + v_q: what both tests subtract (scaled) and the unit of the distance.
            let both = vq.clone() + vp.clone();
            let two_sided = || both.clone().mul_scalar(TWO_SIDED_NOISE_FACTOR);
            // v_p + min(v_p, v_q), min written so that autodiff sees one expression.
            let one_sided = || vp.clone() + (both.clone() - (vq.clone() - vp.clone()).abs()).mul_scalar(0.5);
            let w = g.two_sided_share;
            let explained = if w >= 1.0 {
                two_sided()
            } else if g.doubt_black {
                // Share 1 where the centre is black (a coarse level's centre only if all of its
                // fine pixels are: box means of non-negative values), w elsewhere.
                let black = p.clone().abs().sum_dim(1).lower_equal_elem(0.0).float();
                let share = black.mul_scalar(1.0 - w).add_scalar(w);
                two_sided() * share.clone() + one_sided() * share.neg().add_scalar(1.0)
            } else if w <= 0.0 {
                one_sided()
            } else {
                two_sided().mul_scalar(w) + one_sided().mul_scalar(1.0 - w)
            };
            let excess = (d2 - explained).clamp_min(0.0);
            (excess / both.add_scalar(NOISE_EPS)).sum_dim(1).squeeze_dim(1)
        }
    }
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
    guide_distance(windows(&g.x), g.x.clone().reshape([b, c, 1, h * w]), var, g).reshape([b, k * k, h, w])
}

/// Side of the window whose mean variance a pixel's own may not fall below (see
/// [`pooled_variance`]).
pub(super) const VARIANCE_POOL: usize = 5;

/// max(v, mean of v over the 5×5 window): at 2 spp most pixels of a dim scene saw no light in
/// either sample and report variance 0, and a distance normalised by that called every lit
/// neighbour an edge, so black holes stayed black (veach-ajar 2 spp: 0.205 → 0.144 with the same
/// weights). The window's mean is what the pixel's variance would be had its samples been as
/// lucky as its neighbours'; the max keeps a firefly's own large variance. Next to a thin,
/// noisy feature (wires at 64 spp) the pooled variance is too large and lets the feature leak,
/// so the preset gives the network both distances, each with its own strength.
pub(super) fn pooled_variance(v: Tensor<4>) -> Tensor<4> {
    let r = VARIANCE_POOL / 2;
    let mean = avg_pool2d(pad_reflect(v.clone(), r), AvgPoolOptions::new([VARIANCE_POOL, VARIANCE_POOL]).with_stride([1, 1]));
    v.max_pair(mean)
}

/// Share of the two-sided test at `spp` samples per pixel ([`GuideGroup::two_sided_fades`]).
pub fn two_sided_share(g: &GuideGroup, spp: usize) -> f32 {
    match (g.two_sided, g.two_sided_fades) {
        (false, _) => 0.0,
        (true, false) => 1.0,
        (true, true) => 1.0 / (spp.max(2) - 1) as f32,
    }
}

/// The guide groups' features at full size, scaled (and log-compressed where asked), with their
/// variances for noise-normalised groups (scaled alike, clamped at 0), in the group order, for an
/// input of `spp` samples per pixel.
pub(super) fn guide_features(input: &Tensor<4>, guides: &[GuideGroup], spp: usize) -> Vec<GuideLevel> {
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
            GuideLevel {
                x: x.mul_scalar(g.scale),
                var,
                brighter_only: g.brighter_only,
                two_sided_share: two_sided_share(g, spp),
                doubt_black: g.two_sided && g.doubt_black,
            }
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
/// every silhouette into the convex blend (docs/journal/denoiser.md, "Error floors").
///
/// A tenth tap holds `fallback` (the fine level's own filtered value) at a small fixed weight:
/// a small feature (a 3×3 shadow, a thin edge) has no coarse pixel of its own, so every coarse tap
/// is cut and the softmax would otherwise hand the pixel to the least different one, however far
/// (a shadow filled with the sunlit wall around it, docs/denoiser.md).
pub(super) fn joint_upsample(
    coarse: Tensor<4>,
    fallback: Tensor<4>,
    coarse_guides: &[GuideLevel],
    fine_guides: &[GuideLevel],
    strength: Tensor<4>,
    fh: usize,
    fw: usize,
) -> Tensor<4> {
    let [b, c, h, w] = coarse.dims();
    let n = fh * fw;
    let mut logits = fit_to(bilinear_tap_logits(h, w, &coarse.device()), fh, fw).reshape([1, 9, n]).repeat_dim(0, b);
    for (i, (cg, fg)) in coarse_guides.iter().zip(fine_guides).enumerate() {
        let gc = fg.x.dims()[1];
        let var =
            cg.var.as_ref().zip(fg.var.as_ref()).map(|(cv, fv)| (coarse_windows(cv.clone(), fh, fw), fv.clone().reshape([b, 1, 1, n])));
        let d = guide_distance(coarse_windows(cg.x.clone(), fh, fw), fg.x.clone().reshape([b, gc, 1, n]), var, fg);
        logits = logits - d * strength.clone().narrow(1, i, 1).reshape([b, 1, n]);
    }
    let own = Tensor::<3>::full([b, 1, n], UPSAMPLE_FALLBACK_LOG_WEIGHT, &coarse.device());
    let wts = softmax(Tensor::cat(vec![logits, own], 1), 1).reshape([b, 1, 10, n]);
    let taps = Tensor::cat(vec![coarse_windows(coarse, fh, fw), fallback.reshape([b, c, 1, n])], 2);
    (taps * wts).sum_dim(2).reshape([b, c, fh, fw])
}
