//! Losses (method.md §3, §4.3, §7.3). All return a one-element tensor.

use burn::tensor::{Int, Tensor, TensorData};

use crate::layers::center_crop;
use crate::rng::SplitMix64;

/// How a branch or joint loss weighs its patches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LossScale {
    /// The paper's L1, averaged over the batch: a 2-spp patch, whose noisy input is 4× further
    /// from the reference than a 32-spp one's, counts about 4× as much.
    #[default]
    Absolute,
    /// Each patch's L1 (both branches) divided by its noisy input's L1 against the same target
    /// ([`l1_relative_to_input`]): the loss is the share of the input's error the column leaves,
    /// so a 32-spp patch counts as much as a 2-spp one and an output worse than its input costs
    /// more than 1 at any sample count.
    RelativeToInput,
    /// Each patch's L1 divided by the square root of its noisy input's L1: halfway, in powers,
    /// between [`LossScale::Absolute`] and [`LossScale::RelativeToInput`]. A 32-spp patch counts
    /// about half as much as a 2-spp one (the absolute L1: a quarter), so the low sample counts
    /// keep more of the gradient than under the fully relative loss.
    RelativeToSqrtInput,
    /// Not an L1: the squared error of each pixel weighed by 1/(its output² + 0.01), the output
    /// without gradient ([`rel_l2`]; the relMSE loss of Noise2Noise, Lehtinen et al. 2018). Its
    /// optimum is the conditional mean of the target, where L1's is the median: on a sparse
    /// input, whose lit pixels are rare, the median is darker than the mean.
    RelativeL2,
}

impl LossScale {
    pub const ALL: [LossScale; 4] =
        [LossScale::Absolute, LossScale::RelativeToInput, LossScale::RelativeToSqrtInput, LossScale::RelativeL2];

    pub fn name(self) -> &'static str {
        match self {
            LossScale::Absolute => "absolute",
            LossScale::RelativeToInput => "relative-to-input",
            LossScale::RelativeToSqrtInput => "relative-to-sqrt-input",
            LossScale::RelativeL2 => "relative-l2",
        }
    }

    /// The power of the input's error that divides a patch's L1, or `None` for the losses that
    /// do not look at the input.
    pub fn input_power(self) -> Option<f32> {
        match self {
            LossScale::Absolute | LossScale::RelativeL2 => None,
            LossScale::RelativeToInput => Some(1.0),
            LossScale::RelativeToSqrtInput => Some(0.5),
        }
    }
}

crate::names::named!(LossScale, "loss scale");

/// ε of [`l1_relative_to_input`]'s denominator, in branch units (demodulated diffuse, log
/// specular): a black patch whose input is already exact divides by this, not by 0.
pub const RELATIVE_L1_EPS: f32 = 1e-3;

/// Per patch of `[B, 3, H, W]` pairs: Σ_pairs mean of `f(x, y)` over the patch, shape `[B]`.
fn per_patch(pairs: &[(Tensor<4>, Tensor<4>)], f: impl Fn(Tensor<4>, Tensor<4>) -> Tensor<4>) -> Tensor<1> {
    let mut total: Option<Tensor<1>> = None;
    for (x, y) in pairs {
        let [b, ..] = x.dims();
        let d = f(x.clone(), y.clone()).reshape([b as i32, -1]).mean_dim(1).reshape([b]);
        total = Some(match total {
            Some(t) => t + d,
            None => d,
        });
    }
    total.expect("at least one pair")
}

/// Per patch: Σ_pairs mean|x − y|, shape `[B]`.
fn l1_per_patch(pairs: &[(Tensor<4>, Tensor<4>)]) -> Tensor<1> {
    per_patch(pairs, |x, y| (x - y).abs())
}

/// mean over patches b of Σ_k mean|out_k − t_k| / (Σ_k mean|in_k − t_k| + [`RELATIVE_L1_EPS`])^power,
/// k over the branches, with `(out_k, in_k, t_k)` triples of `[B, 3, H, W]` (the noisy input is
/// cropped to the target). The denominator carries no gradient: it is data.
pub fn l1_relative_to_input(branches: &[(Tensor<4>, Tensor<4>, Tensor<4>)], power: f32) -> Tensor<1> {
    relative_to_input(branches, power, 0.0)
}

/// [`l1_relative_to_input`] with `l2_weight` × each patch's [`rel_l2`] (both branches summed)
/// added to its L1 before the division: the relative L2 term then weighs every sample count
/// alike too, instead of being ruled by the 2-spp patches, whose squared errors are the largest.
pub fn relative_to_input(branches: &[(Tensor<4>, Tensor<4>, Tensor<4>)], power: f32, l2_weight: f32) -> Tensor<1> {
    let out: Vec<_> = branches.iter().map(|(o, _, t)| (o.clone(), t.clone())).collect();
    let noisy: Vec<_> = branches
        .iter()
        .map(|(_, i, t)| {
            let [_, _, h, w] = t.dims();
            (center_crop(i.clone(), h, w).detach(), t.clone())
        })
        .collect();
    let denominator = l1_per_patch(&noisy).add_scalar(RELATIVE_L1_EPS);
    let denominator = if power == 1.0 { denominator } else { denominator.powf_scalar(power) };
    let mut numerator = l1_per_patch(&out);
    if l2_weight > 0.0 {
        numerator = numerator + rel_l2_per_patch(&out).mul_scalar(l2_weight);
    }
    (numerator / denominator).mean()
}

/// Per patch: Σ_pairs [`rel_l2`] of the patch, shape `[B]`.
fn rel_l2_per_patch(pairs: &[(Tensor<4>, Tensor<4>)]) -> Tensor<1> {
    per_patch(pairs, rel_l2_elements)
}

/// ε of [`rel_l2`]'s denominator, in branch units: Noise2Noise's 0.01.
pub const REL_L2_EPS: f32 = 0.01;

/// mean over elements of (x − y)² / (x̂² + [`REL_L2_EPS`]), x̂ = x without gradient.
pub fn rel_l2(x: Tensor<4>, y: Tensor<4>) -> Tensor<1> {
    rel_l2_elements(x, y).mean()
}

/// (x − y)² / (x̂² + [`REL_L2_EPS`]) element by element, x̂ = x without gradient.
fn rel_l2_elements(x: Tensor<4>, y: Tensor<4>) -> Tensor<4> {
    let d = x.clone() - y;
    let x_hat = x.detach();
    d.clone() * d / (x_hat.clone() * x_hat).add_scalar(REL_L2_EPS)
}

/// Mean absolute error over all elements.
pub fn l1<const D: usize>(x: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    (x - y).abs().mean()
}

/// The evaluation's tone map (a) of method.md §7.3, on `[B, 3, H, W]` radiance, with a 1e-3
/// offset under the 1/2.2 power so that its gradient stays finite at black:
/// τ(c) = (max(c, 0)/(1 + lum(c)/1.5) + 1e-3)^(1/2.2).
pub fn tonemap_eval(c: Tensor<4>) -> Tensor<4> {
    let c = c.clamp_min(0.0);
    let lum = c.clone().narrow(1, 0, 1).mul_scalar(0.2126)
        + c.clone().narrow(1, 1, 1).mul_scalar(0.7152)
        + c.clone().narrow(1, 2, 1).mul_scalar(0.0722);
    (c / lum.div_scalar(1.5).add_scalar(1.0)).add_scalar(1e-3).powf_scalar(1.0 / 2.2)
}

/// L1 after [`tonemap_eval`]: the distance the test relMSE sees, so a dark pixel's relative
/// error counts as much as a bright one's (plain L1 on radiance lets a shadow next to a lit
/// face take its neighbour's light at almost no cost).
pub fn l1_tonemapped(x: Tensor<4>, y: Tensor<4>) -> Tensor<1> {
    l1(tonemap_eval(x), tonemap_eval(y))
}

/// Validation relMSE on linear HDR radiance: ½·mean[(x−y)² / (y² + 0.01)].
pub fn rel_mse_val<const D: usize>(x: Tensor<D>, y: Tensor<D>) -> Tensor<1> {
    let den = y.clone().square().add_scalar(0.01);
    ((x - y).square() / den).mean().mul_scalar(0.5)
}

/// The test relMSE of `pixguide eval` ([`crate::metrics::rel_mse`] with tone map (a), ε 1e-4)
/// on `[B, 3, H, W]` radiance, for validation: no gradient flows, so the tone map is the exact
/// one (no offset), clipped to [0, 1] as the metric does. Checkpoints chosen by the linear
/// [`rel_mse_val`] kept fireflies that the test metric punishes (docs/training.md).
pub fn rel_mse_test(x: Tensor<4>, y: Tensor<4>) -> Tensor<1> {
    let tm = |c: Tensor<4>| {
        let c = c.clamp_min(0.0);
        let lum = c.clone().narrow(1, 0, 1).mul_scalar(0.2126)
            + c.clone().narrow(1, 1, 1).mul_scalar(0.7152)
            + c.clone().narrow(1, 2, 1).mul_scalar(0.0722);
        (c / lum.div_scalar(1.5).add_scalar(1.0)).powf_scalar(1.0 / 2.2).clamp(0.0, 1.0)
    };
    let (x, y) = (tm(x), tm(y));
    let den = y.clone().square().add_scalar(1e-4);
    ((x - y).square() / den).mean()
}

/// Pseudo-label tone map of the disentangling loss: τ(x) = (max(x,0)/(1+max(x,0)))^(1/2.2).
pub fn tonemap_label<const D: usize>(t: Tensor<D>) -> Tensor<D> {
    let t = t.clamp_min(0.0);
    (t.clone() / t.add_scalar(1.0)).powf_scalar(1.0 / 2.2)
}

/// One term of the disentangling loss for a fixed pairing: with rows `p` `[.., N, C]` and labels
/// `r` `[.., N, L]`, d_P = ½‖p_i − p_π(i)‖², d_R = ½‖r_i − r_π(i)‖², result ½·mean (d_P − d_R)².
/// `perm` (length N) permutes dimension `D − 2`.
pub fn disentangle_term<const D: usize>(p: Tensor<D>, r: Tensor<D>, perm: &[usize]) -> Tensor<1> {
    let dev = p.device();
    let n = perm.len();
    let idx: Vec<i64> = perm.iter().map(|&i| i as i64).collect();
    let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [n]), &dev);
    let half_sq_dist = |x: Tensor<D>| {
        let y = x.clone().select(D - 2, idx.clone());
        (x - y).square().sum_dim(D - 1).mul_scalar(0.5)
    };
    let diff = half_sq_dist(p) - half_sq_dist(r);
    diff.square().mean().mul_scalar(0.5)
}

/// Path-disentangling ("FMSE") loss, method.md §4.3.
///
/// `samples` `[B, S, C, H, W]` are the per-sample P-buffers, `target` `[B, 3, h, w]` the branch
/// reference (T_diff or T_spec, h ≤ H); the samples are centre-cropped to the target. Labels are
/// τ(target), shared by all samples of a pixel. Returns the term over one random permutation of
/// the S·h·w entries of each patch (the same permutation for every patch) plus the term over one
/// random permutation of all B·S·h·w entries. Fresh permutations come from `rng` each call.
pub fn path_disentangling_loss(samples: Tensor<5>, target: Tensor<4>, rng: &mut SplitMix64) -> Tensor<1> {
    let [b, s, c, _, _] = samples.dims();
    let [bt, l, h, w] = target.dims();
    assert_eq!(b, bt, "P-buffer batch {b} ≠ target batch {bt}");
    let n = s * h * w;
    // Rows = (sample, y, x) within a patch, columns = channels.
    let p = center_crop(samples, h, w).permute([0, 1, 3, 4, 2]).reshape([b, n, c]);
    let r = tonemap_label(target).permute([0, 2, 3, 1]).reshape([b, 1, h * w, l]).expand([b, s, h * w, l]).reshape([b, n, l]);
    let within = disentangle_term(p.clone(), r.clone(), &rng.permutation(n));
    let across = disentangle_term(p.reshape([1, b * n, c]), r.reshape([1, b * n, l]), &rng.permutation(b * n));
    within + across
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu_device;
    use crate::test_util::{tensor, to_vec};

    fn scalar(t: Tensor<1>) -> f64 {
        to_vec(t)[0]
    }

    /// The tone-mapped L1 is the metric's distance: the same absolute error costs more on a
    /// shadow than on a lit face (here ≈ 5×: a 0.02 → 0.04 error against 1.0 → 1.02), and its
    /// gradient stays finite at black.
    #[test]
    fn tonemapped_l1_weighs_dark_errors_and_has_finite_gradients() {
        let d = crate::cpu_training_device();
        let img = |v: f64| tensor(&[v; 3], [1, 3, 1, 1], &d);
        let dark = scalar(l1_tonemapped(img(0.04), img(0.02)));
        let bright = scalar(l1_tonemapped(img(1.02), img(1.0)));
        assert!(dark > 4.0 * bright, "dark {dark} vs bright {bright}");
        // Hand value of τ at c = 1 (grey): 1/(1 + 1/1.5) = 0.6, (0.6 + 1e-3)^(1/2.2).
        let t = to_vec(tonemap_eval(img(1.0)))[0];
        assert!((t - 0.601f64.powf(1.0 / 2.2)).abs() < 1e-5, "{t}");
        let x = img(0.0).require_grad();
        let g = l1_tonemapped(x.clone(), img(0.5)).backward();
        let grad = crate::test_util::grad_of(&x, &g);
        assert!(grad.iter().all(|v| v.is_finite() && *v != 0.0), "{grad:?}");
    }

    /// The relative loss is each patch's share of its input's error: an output equal to the
    /// input scores 1 (to ε), and two patches whose inputs are 10× apart but whose outputs
    /// each halve their input's error count alike (0.5; an absolute L1 would give the noisier
    /// patch 10× the weight). The input is cropped to the target's size first (here 4×4 → 2×2,
    /// with a different border so that a missing crop would change the value).
    #[test]
    fn relative_loss_weighs_every_patch_by_its_input_error() {
        let d = crate::cpu_training_device();
        let (b, c, h, w) = (2usize, 3usize, 2usize, 2usize);
        let target = tensor(&vec![1.0; b * c * h * w], [b, c, h, w], &d);
        // Patch 0: input off by 1.0, patch 1: by 0.1 (inside the crop); the border is off by 9.
        let noisy: Vec<f64> = (0..b * c * 16)
            .map(|i| {
                let (patch, y, x) = (i / (c * 16), (i % 16) / 4, i % 4);
                let inside = (1..3).contains(&y) && (1..3).contains(&x);
                if !inside {
                    10.0
                } else if patch == 0 {
                    2.0
                } else {
                    1.1
                }
            })
            .collect();
        let noisy = tensor(&noisy, [b, c, 4, 4], &d);
        let same = center_crop(noisy.clone(), h, w);
        let identity = scalar(l1_relative_to_input(&[(same, noisy.clone(), target.clone())], 1.0));
        // Σ_b e_b/(e_b + ε)/2 with e = 1.0 and 0.1.
        let want = (1.0 / (1.0 + 1e-3) + 0.1 / (0.1 + 1e-3)) / 2.0;
        assert!((identity - want).abs() < 1e-5, "identity scores {identity}, want {want}");
        let halved = tensor(&(0..b * c * h * w).map(|i| if i < c * h * w { 1.5 } else { 1.05 }).collect::<Vec<_>>(), [b, c, h, w], &d);
        let rel = scalar(l1_relative_to_input(&[(halved.clone(), noisy.clone(), target.clone())], 1.0));
        let want = (0.5 / (1.0 + 1e-3) + 0.05 / (0.1 + 1e-3)) / 2.0;
        assert!((rel - want).abs() < 1e-5 && (rel - 0.5).abs() < 0.01, "halved scores {rel}, want {want}");
        // Under the square root the noisier patch counts √10 ≈ 3.2× as much, not 1× or 10×.
        let sqrt = scalar(l1_relative_to_input(&[(halved, noisy, target)], 0.5));
        let want = (0.5 / (1.0f64 + 1e-3).sqrt() + 0.05 / (0.1f64 + 1e-3).sqrt()) / 2.0;
        assert!((sqrt - want).abs() < 1e-5, "halved under the square root scores {sqrt}, want {want}");
    }

    /// The relative L2 term inside the relative loss: each patch's L1 plus w × its rel_l2,
    /// divided by its input's L1, so the term of a patch whose input is 10× closer counts 10×
    /// as much as it would outside the division. Checked against the two parts computed apart.
    #[test]
    fn relative_l2_term_is_divided_by_the_input_error() {
        let d = crate::cpu_training_device();
        let (b, c, h, w) = (2usize, 3usize, 2usize, 2usize);
        let target = tensor(&vec![1.0; b * c * h * w], [b, c, h, w], &d);
        let noisy = tensor(&(0..b * c * h * w).map(|i| if i < c * h * w { 2.0 } else { 1.1 }).collect::<Vec<_>>(), [b, c, h, w], &d);
        let out = tensor(&(0..b * c * h * w).map(|i| if i < c * h * w { 1.5 } else { 1.05 }).collect::<Vec<_>>(), [b, c, h, w], &d);
        let mixed = scalar(relative_to_input(&[(out.clone(), noisy.clone(), target.clone())], 1.0, 4.0));
        // Patch 0: L1 0.5, rel_l2 0.25/(2.25 + 0.01), input 1.0; patch 1: 0.05, 0.0025/(1.1025 + 0.01), 0.1.
        let part = |l1: f64, r: f64, e: f64| (l1 + 4.0 * r) / (e + 1e-3);
        let want = (part(0.5, 0.25 / 2.26, 1.0) + part(0.05, 0.0025 / 1.1125, 0.1)) / 2.0;
        assert!((mixed - want).abs() < 1e-5 * want, "mixed {mixed}, want {want}");
        let plain = scalar(relative_to_input(&[(out, noisy, target)], 1.0, 0.0));
        assert!((plain - (part(0.5, 0.0, 1.0) + part(0.05, 0.0, 0.1)) / 2.0).abs() < 1e-5, "plain {plain}");
    }

    /// rel_l2's value is (x − y)²/(x² + 0.01) averaged, and its gradient is that of the squared
    /// error over a constant denominator: 2(x − y)/(x² + 0.01)/n, so a prediction of 0.25 for
    /// targets 0, 0, 0 and 1 (their mean) has gradient 0 in sum, where L1's sum is 2/n ≠ 0
    /// (its optimum is the median, 0).
    #[test]
    fn rel_l2_optimum_is_the_mean() {
        let d = crate::cpu_training_device();
        let y = tensor(&[0.0, 0.0, 0.0, 1.0], [1, 1, 2, 2], &d);
        let x = tensor(&[0.25; 4], [1, 1, 2, 2], &d).require_grad();
        let value = scalar(rel_l2(x.clone(), y.clone()));
        let want = (3.0 * 0.0625 + 0.5625) / 4.0 / (0.0625 + 0.01);
        assert!((value - want).abs() < 1e-5 * want, "rel_l2 {value}, want {want}");
        let g = rel_l2(x.clone(), y.clone()).backward();
        let grad = crate::test_util::grad_of(&x, &g);
        let sum: f64 = grad.iter().sum();
        assert!(sum.abs() < 1e-5, "gradient sum at the mean {sum} ({grad:?})");
        let g1 = l1(x.clone(), y).backward();
        let sum1: f64 = crate::test_util::grad_of(&x, &g1).iter().sum();
        assert!((sum1 - 0.5).abs() < 1e-6, "L1 gradient sum at the mean {sum1}");
    }

    /// Validation scores what `pixguide eval` scores: the tensor version equals the CPU metric
    /// (tone map (a), ε 1e-4) on an image with black, negative, bright and ordinary pixels, to
    /// f32 rounding (1e-5 relative).
    #[test]
    fn validation_metric_is_the_test_metric() {
        let d = cpu_device();
        let (w, h) = (4usize, 3usize);
        let mut rng = crate::rng::SplitMix64::new(5);
        let y: Vec<f32> = (0..3 * w * h).map(|i| if i % 7 == 0 { 0.0 } else { 2.0 + 2.0 * rng.symmetric(1.0) }).collect();
        let x: Vec<f32> =
            y.iter().enumerate().map(|(i, v)| if i % 5 == 0 { -0.3 } else { v * (1.0 + 0.5 * rng.symmetric(1.0)) + 0.01 }).collect();
        let planar = |v: &[f32]| -> Vec<f64> { (0..3).flat_map(|c| (0..w * h).map(move |p| v[3 * p + c] as f64)).collect() };
        let t = |v: &[f32]| tensor(&planar(v), [1, 3, h, w], &d);
        let got = scalar(rel_mse_test(t(&x), t(&y)));
        let want = crate::metrics::rel_mse(&x, &y, w, h, crate::metrics::ToneMap::Paper, 0);
        assert!((got - want).abs() < 1e-5 * want, "tensor {got} vs metric {want}");
    }

    #[test]
    fn l1_and_rel_mse_values() {
        let d = cpu_device();
        let x = tensor(&[1.0, 2.0, 0.0, -1.0], [4], &d);
        let y = tensor(&[0.0, 2.0, 1.0, 1.0], [4], &d);
        assert!((scalar(l1(x.clone(), y.clone())) - 1.0).abs() < 1e-6);
        let expect = 0.5 * (1.0 / 0.01 + 0.0 + 1.0 / 1.01 + 4.0 / 1.01) / 4.0;
        assert!((scalar(rel_mse_val(x, y)) - expect).abs() < 1e-4 * expect);
    }

    /// Zero exactly when embedding distances equal label distances: P-buffers that carry the
    /// tone-mapped reference (plus constant channels) for every sample. Scaling them breaks the
    /// equality and the loss becomes positive, so the test can fail.
    #[test]
    fn disentangling_loss_vanishes_on_matching_distances() {
        let d = cpu_device();
        let (b, s, h, w, c) = (2, 3, 4, 5, 12);
        let mut rng = SplitMix64::new(4);
        let t: Vec<f64> = (0..b * 3 * h * w).map(|_| rng.next_f64() * 4.0).collect();
        let target = tensor(&t, [b, 3, h, w], &d);
        let labels = to_vec(tonemap_label(target.clone()));
        let mut p = vec![0.25; b * s * c * (h + 2) * (w + 2)];
        for n in 0..b {
            for si in 0..s {
                for ch in 0..3 {
                    for y in 0..h {
                        for x in 0..w {
                            p[(((n * s + si) * c + ch) * (h + 2) + y + 1) * (w + 2) + x + 1] = labels[((n * 3 + ch) * h + y) * w + x];
                        }
                    }
                }
            }
        }
        let samples = tensor(&p, [b, s, c, h + 2, w + 2], &d);
        let zero = scalar(path_disentangling_loss(samples.clone(), target.clone(), &mut rng));
        // Equal f32 inputs give bit-identical distances; allow a whisker for summation order.
        assert!(zero.abs() < 1e-10, "loss {zero}");
        let off = scalar(path_disentangling_loss(samples.mul_scalar(2.0), target, &mut rng));
        assert!(off > 1e-4, "scaled embedding should be penalised, got {off}");
    }

    /// Against a hand evaluation for a fixed permutation.
    #[test]
    fn disentangle_term_matches_hand_computation() {
        let d = cpu_device();
        let p = tensor(&[0.0, 0.0, 1.0, 0.0, 0.0, 2.0], [3, 2], &d);
        let r = tensor(&[0.0, 0.0, 0.0, 0.5, 0.0, 0.0], [3, 2], &d);
        // π = (1, 2, 0): d_P = ½·(1, 5, 4), d_R = ½·(0.25, 0.25, 0).
        let dp = [0.5, 2.5, 2.0];
        let dr = [0.125, 0.125, 0.0];
        let expect: f64 = 0.5 * dp.iter().zip(&dr).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / 3.0;
        let got = scalar(disentangle_term(p, r, &[1, 2, 0]));
        assert!((got - expect).abs() < 1e-6, "{got} vs {expect}");
    }
}
