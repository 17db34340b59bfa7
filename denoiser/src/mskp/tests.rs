use super::*;
use crate::rng::SplitMix64;
use crate::test_util::{grad_of, max_abs, tensor, to_vec};
use crate::{cpu_device, cpu_training_device};

fn tiny(in_channels: usize) -> MsKpConfig {
    MsKpConfig::new(in_channels)
        .with_widths(vec![4, 6, 6])
        .with_kernel_scales(3)
        .with_filter_size(3)
        .with_margin(1)
        .with_compositor(ScaleCompositor::LowPassSwap)
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
        let noisy = vec![
            GuideGroup::new(0, 3, 1.0, false).with_variance(4).with_init_log_strength(-1.0),
            GuideGroup::new(0, 3, 1.0, false).with_pooled_variance(4),
        ];
        gradients_match_finite_differences_for(tiny(5).with_compositor(compositor).with_guides(noisy));
        // The fading two-sided test at GRADIENT_SPP blends both subtractions (share 1/3).
        let fading = vec![GuideGroup::new(0, 3, 1.0, false).with_variance(4).with_init_log_strength(-1.0).two_sided_fading()];
        gradients_match_finite_differences_for(tiny(5).with_compositor(compositor).with_guides(fading));
    }
}

/// Samples per pixel of the gradient checks' inputs: a fading two-sided guide is then half-way
/// between its two forms, so both are on the gradient path.
const GRADIENT_SPP: usize = 4;

fn gradients_match_finite_differences_for(cfg: MsKpConfig) {
    let dev = cpu_training_device();
    let net = cfg.init(3, &dev);
    let mut rng = SplitMix64::new(17);
    let dims = [1, 5, 8, 8];
    let x: Vec<f64> = (0..dims.iter().product()).map(|_| rng.symmetric(1.0) as f64).collect();
    let o = 8 - 2 * cfg.margin;
    let probe: Vec<f64> = (0..3 * o * o).map(|_| rng.symmetric(1.0) as f64).collect();
    let objective = |net: &MsKpNet, x: &[f64]| -> f64 {
        let out = to_vec(net.valid().forward(tensor(x, dims, &cpu_device()), GRADIENT_SPP));
        out.iter().zip(&probe).map(|(a, b)| a * b).sum()
    };
    let xt = tensor(&x, dims, &dev).require_grad();
    let grads = (net.forward(xt.clone(), GRADIENT_SPP) * tensor(&probe, [1, 3, o, o], &dev)).sum().backward();
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
        let out = to_vec(net.forward(tensor(&x, dims, &d), 4));
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
    set_constant_heads(&mut net, &cfg, identity_kernels_full_blend(&cfg, None));
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
        .map(|i| {
            if i / 256 == 3 {
                f64::from(u8::from(side(i)))
            } else if side(i) {
                0.02
            } else {
                1.0
            }
        })
        .collect();
    for (strength, expect_sharp) in [(12.0f32, true), (-12.0, false)] {
        let mut net = cfg.init(1, &d);
        set_constant_heads(&mut net, &cfg, box_kernels_no_blend(&cfg, Some(strength)));
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
    let x: Vec<f64> = (0..4 * 256)
        .map(|i| {
            if i / 256 == 3 {
                f64::from(u8::from(i % 256 == dark))
            } else if i % 256 == dark {
                0.02
            } else {
                1.0
            }
        })
        .collect();
    let mut net = cfg.init(1, &d);
    set_constant_heads(&mut net, &cfg, identity_kernels_full_blend(&cfg, Some(12.0)));
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
        let x: Vec<f64> = (0..4 * 256)
            .map(|i| {
                if i / 256 == 3 {
                    variance
                } else if side(i) {
                    0.02
                } else {
                    1.0
                }
            })
            .collect();
        let mut net = cfg.init(1, &d);
        set_constant_heads(&mut net, &cfg, box_kernels_no_blend(&cfg, None));
        let worst = largest_change(&net, &cfg, &x, 16);
        if expect_sharp {
            assert!(worst < 1e-5, "a 98σ step was blurred by {worst}");
        } else {
            assert!(worst > 0.1, "a step well inside the noise should be smoothed ({worst})");
        }
    }
}

/// A dim scene at 2 spp: a sixth of the pixels caught the light in one of their two samples
/// (mean m, population variance of the mean m²/2, what the renderer reports), the rest in none
/// (0, variance 0). Box kernels at strength e^0 with the two-sided test see no difference
/// the noise cannot explain (m² = 2·(0 + m²/2)): they stay box kernels and keep the image's
/// mean brightness (to float rounding). The
/// one-sided form of Rousselle et al. gives a black pixel's lit neighbour twice the distance it
/// gives the lit pixel's black one, so black pixels keep black and lit ones take the black in:
/// the same image lost 15 % of its brightness (veach-ajar at 2 spp lost 46 % with the
/// 2026-11-24 weights).
#[test]
fn two_sided_noise_test_keeps_the_brightness_of_a_sparse_2spp_image() {
    // A lit pixel saw one bright sample of two: mean m, variance of the mean m²/2.
    let mean_change = |group| sparse_image_mean_change(7, 2, 0.5, group);
    let one_sided = mean_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3));
    let two_sided = mean_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided());
    let fading = mean_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided_fading());
    assert!(two_sided.abs() < 1e-5, "two-sided test changed the mean brightness by {two_sided}");
    assert!(fading.abs() < 1e-5, "the fading test is two-sided at 2 spp, but changed the mean brightness by {fading}");
    assert!(one_sided < -0.05, "the one-sided form should darken a sparse image ({one_sided})");
}

/// The same sparse image at 4 spp (a lit pixel saw one bright sample of four: mean m, variance
/// of the mean 3m²/4), the way most of veach-ajar still looks at 4 spp. The fading test keeps a
/// third of the two-sided subtraction there, so black pixels refuse their lit neighbours and the
/// image darkens; doubting black centres keeps the two-sided test where it matters and the mean.
#[test]
fn doubting_black_centres_keeps_the_brightness_of_a_sparse_4spp_image() {
    let mean_change = |group| sparse_image_mean_change(11, 4, 0.75, group);
    let fading = mean_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided_fading());
    let doubting = mean_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided_fading_doubting_black());
    assert!(doubting.abs() < 1e-5, "doubting black centres changed the mean brightness by {doubting}");
    assert!(fading < -0.05, "the fading test should darken a sparse 4-spp image ({fading})");
}

/// A firefly at 64 spp: one sample of 64 hit a bright caustic, so the pixel's mean is up by
/// Δ = S/64 and its variance of the mean is about Δ². Its neighbours (0.5, variance 10⁻⁶) must
/// not take it in: the one-sided test explains only what the neighbour's own noise adds
/// (2·10⁻⁶), so at strength e^3 they keep their value; the two-sided test calls the same
/// difference noise (Δ² < 2(v_p + v_q)) and lets it in: the price of the two-sided test, paid on
/// glass-still-life's caustics at 32–64 spp (docs/journal/denoiser.md, "The two-sided noise test").
/// The fading test keeps 1/63 of the two-sided subtraction at 64 spp, and the firefly out.
#[test]
fn one_sided_own_variance_guide_keeps_a_firefly_out_of_its_neighbours() {
    let side = 16;
    let n = side * side;
    let fly = 7 * side + 8;
    let delta = 0.4;
    let x: Vec<f64> = (0..4 * n)
        .map(|i| match (i / n, i % n == fly) {
            (3, true) => delta * delta * 63.0 / 64.0,
            (3, false) => 1e-6,
            (_, true) => 0.5 + delta,
            (_, false) => 0.5,
        })
        .collect();
    let neighbours_change = |group: GuideGroup| {
        let (out, cfg) = box_kernels_with_guide(&x, side, 64, group, 3.0);
        let o = side - 2 * cfg.margin;
        (0..3 * o * o)
            .filter(|i| (i % (o * o) / o + cfg.margin) * side + i % o + cfg.margin != fly)
            .map(|i| (out[i] - 0.5).abs())
            .fold(0.0, f64::max)
    };
    let one_sided = neighbours_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3));
    let two_sided = neighbours_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided());
    let fading = neighbours_change(GuideGroup::new(0, 3, 1.0, false).with_variance(3).two_sided_fading());
    assert!(one_sided < 1e-3, "the one-sided test let the firefly into its neighbours ({one_sided})");
    assert!(fading < 1e-3, "the fading test at 64 spp let the firefly into its neighbours ({fading})");
    assert!(two_sided > 0.02, "the two-sided test should let the firefly in ({two_sided})");
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
        .map(|i| {
            if i / 256 == 3 {
                f64::from(u8::from(side(i)))
            } else if side(i) {
                0.02
            } else {
                1.0
            }
        })
        .collect();
    for (strength, expect_sharp) in [(12.0f32, true), (-12.0, false)] {
        let mut net = cfg.init(1, &d);
        set_constant_heads(&mut net, &cfg, identity_kernels_full_blend(&cfg, Some(strength)));
        let worst = largest_change(&net, &cfg, &x, 16);
        if expect_sharp {
            assert!(worst < 1e-4, "joint-bilateral upsampling moved the edge by {worst}");
        } else {
            assert!(worst > 0.1, "bilinear upsampling should blur the edge ({worst})");
        }
    }
}

/// Head biases for 3×3 kernels: box kernels (all logits 0) with α = 0 (no coarse levels), and
/// the last guide's log-strength when given (else 0).
fn box_kernels_no_blend(cfg: &MsKpConfig, strength: Option<f32>) -> impl Fn(usize, usize) -> Vec<f32> + '_ {
    move |s, n| {
        let mut bias = vec![0.0f32; n];
        if s + 1 < cfg.kernel_scales {
            bias[9] = -60.0; // α = 0
        }
        if let Some(w) = strength {
            bias[n - 1] = w;
        }
        bias
    }
}

/// Head biases for 3×3 kernels: one-hot centre kernels with α = 1 (only the coarsest level
/// survives, upsampled), and the last guide's log-strength when given (else −60).
fn identity_kernels_full_blend(cfg: &MsKpConfig, strength: Option<f32>) -> impl Fn(usize, usize) -> Vec<f32> + '_ {
    move |s, n| {
        let mut bias = vec![-60.0f32; n];
        bias[4] = 60.0; // identity kernel
        if s + 1 < cfg.kernel_scales {
            bias[9] = 60.0; // α = 1
        }
        if let Some(w) = strength {
            bias[n - 1] = w;
        }
        bias
    }
}

/// A 32² image where one pixel in six (drawn from `seed`) is lit at m = 3 with variance of the
/// mean `lit_variance`·m², the rest black with variance 0, filtered by 3×3 box kernels stopped by
/// `group` (strength 1) at `spp`: the relative change of the mean against plain box kernels on
/// the kept window (which read one pixel beyond it).
fn sparse_image_mean_change(seed: u64, spp: usize, lit_variance: f64, group: GuideGroup) -> f64 {
    let side = 32;
    let n = side * side;
    let mut rng = SplitMix64::new(seed);
    let lit: Vec<bool> = (0..n).map(|_| rng.below(6) == 0).collect();
    let m = 3.0;
    let x: Vec<f64> = (0..4 * n)
        .map(|i| match (i / n, lit[i % n]) {
            (_, false) => 0.0,
            (3, true) => lit_variance * m * m,
            (_, true) => m,
        })
        .collect();
    let (out, cfg) = box_kernels_with_guide(&x, side, spp, group, 0.0);
    let o = side - 2 * cfg.margin;
    let boxed = |i: usize| {
        let (y, xx) = (i / o + cfg.margin, i % o + cfg.margin);
        let taps = (0..9).filter(|t| lit[(y + t / 3 - 1) * side + xx + t % 3 - 1]).count();
        taps as f64 * m / 9.0
    };
    let before = (0..o * o).map(boxed).sum::<f64>() / (o * o) as f64;
    let after = out[..o * o].iter().sum::<f64>() / (o * o) as f64;
    after / before - 1.0
}

/// The convex-blend column with the single guide `group`, box kernels without blend at
/// log-strength `strength`, run on one `side`² image `x` (4 channels): its output and config.
fn box_kernels_with_guide(x: &[f64], side: usize, spp: usize, group: GuideGroup, strength: f32) -> (Vec<f64>, MsKpConfig) {
    let d = cpu_device();
    let cfg = tiny(4).with_compositor(ScaleCompositor::ConvexBlend).with_guides(vec![group]);
    let mut net = cfg.init(1, &d);
    set_constant_heads(&mut net, &cfg, box_kernels_no_blend(&cfg, Some(strength)));
    (to_vec(net.forward(tensor(x, [1, 4, side, side], &d), spp)), cfg)
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
    let out = to_vec(net.forward(tensor(x, [1, c_in, side, side], &cpu_device()), 4));
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
    let guided = tiny(4)
        .with_compositor(ScaleCompositor::ConvexBlend)
        .with_guides(vec![GuideGroup::new(0, 3, 1.0, true).brighter_only(), GuideGroup::new(3, 1, 1.0, false)]);
    for (cfg, c) in [(tiny(3), 3), (guided, 4)] {
        let net = cfg.init(2, &d);
        for (h, w) in [(13, 9), (5, 7), (4, 4)] {
            let out = net.forward(Tensor::<4>::ones([1, c, h, w], &d), 4);
            assert_eq!(out.dims(), [1, 3, h - 2, w - 2]);
            assert!(to_vec(out).iter().all(|v| (v - 1.0).abs() < 1e-5));
        }
    }
}

/// The guide gain (N/2)^γ: a step the weak strength e^−3 blurs at 64 spp comes back sharp with
/// γ = 1 (32× the strength), while at 2 spp the column is exactly the one without a gain.
#[test]
fn guide_gain_sharpens_a_converged_step_and_leaves_2spp_alone() {
    assert_eq!(guide_gain(0.5, 32), 4.0);
    assert_eq!(guide_gain(1.0, 2), 1.0);
    assert_eq!(guide_gain(1.0, 1), 1.0);
    let d = cpu_device();
    let side = |i: usize| (i % 16) < 7;
    // A 0.98 step at variance 0.1: about 3.8 noise units per channel after the subtraction.
    let x: Vec<f64> = (0..4 * 256)
        .map(|i| {
            if i / 256 == 3 {
                0.1
            } else if side(i) {
                0.02
            } else {
                1.0
            }
        })
        .collect();
    let run = |gamma: f64, spp: usize| {
        let cfg = tiny(4).with_guides(vec![GuideGroup::new(0, 3, 1.0, false).with_variance(3)]).with_guide_gain_exponent(gamma);
        let mut net = cfg.init(1, &d);
        set_constant_heads(&mut net, &cfg, box_kernels_no_blend(&cfg, Some(-3.0)));
        let out = to_vec(net.forward(tensor(&x, [1, 4, 16, 16], &d), spp));
        let (m, o) = (cfg.margin, 16 - 2 * cfg.margin);
        let worst = (0..3 * o * o).map(|k| (out[k] - x[((k / (o * o)) * 16 + (k / o) % o + m) * 16 + k % o + m]).abs()).fold(0.0, f64::max);
        (out, worst)
    };
    let (plain64, blurred) = run(0.0, 64);
    let (_, sharp) = run(1.0, 64);
    assert!(blurred > 0.05, "without a gain the weak strength should blur the step ({blurred})");
    assert!(sharp < 1e-3, "32× the strength should keep the step ({sharp}; {blurred} without)");
    assert_eq!(run(1.0, 2).0, run(0.0, 2).0);
    assert_ne!(plain64, run(1.0, 64).0);
}
