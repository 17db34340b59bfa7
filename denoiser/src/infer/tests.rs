//! Tests of whole-image inference: tiled and staged results against the model's forward on the
//! whole padded image, records against planes, timings, context, hostile input and errors.

use super::tiles::{clean, denoise_tiled};
use super::timing::timed_forward;
use super::window::{align_up, reflect, window};
use super::*;
use crate::ensemble::EnsembleConfig;
use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::kpcn::KpcnConfig;
use crate::mskp::MsKpConfig;
use crate::pathnet::PathNetConfig;
use crate::preprocess::DESCRIPTOR_CHANNELS;
use crate::rng::SplitMix64;

fn tiny() -> DenoiserConfig {
    DenoiserConfig::new(
        KpcnConfig::new(34).with_depth(2).with_width(8).with_conv_kernel(3).with_filter_size(3),
        // Three U-Net levels so pooling alignment matters.
        PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 8, 8]).with_convs_per_block(1).with_out_hidden(8),
        EnsembleConfig::new().with_depth(2).with_width(6).with_conv_kernel(3),
    )
    .with_seed(5)
}

fn random_image(w: usize, h: usize, s: usize, seed: u64) -> PreparedImage {
    let mut rng = SplitMix64::new(seed);
    let mut r = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.next_f64() as f32).collect() };
    let n = w * h;
    PreparedImage {
        width: w,
        height: h,
        spp: s,
        diffuse: r(COLOUR_BLOCK * n),
        specular: r(COLOUR_BLOCK * n),
        g_block: r(G_BLOCK * n),
        path_weight: r(n),
        descriptors: Some(r(s * DESCRIPTOR_CHANNELS * n)),
        records: None,
        passthrough: (0..n).map(|i| i % 11 == 0).collect(),
    }
}

#[test]
fn reflect_mirrors_without_repeating_the_edge() {
    let v: Vec<usize> = (-3..8).map(|i| reflect(i, 4)).collect();
    assert_eq!(v, [3, 2, 1, 0, 1, 2, 3, 2, 1, 0, 1]);
    assert_eq!(reflect(-5, 1), 0);
}

/// Small tiles (many windows, shifted edge windows, a partial last tile) give the same image
/// as one window covering the whole padded image, for every method. Tolerance 1e-4 relative
/// (+1e-5 absolute): the same arithmetic on differently sized tensors may be blocked
/// differently by the matmul kernels, which changes f32 rounding (~1e-6 per op); a missing
/// context pixel or a pooling grid out of phase changes values at the 1e-2 level.
#[test]
fn tiled_equals_untiled() {
    let d = crate::cpu_device();
    // Larger than two windows in each direction (window = tile + 2·(margin + E radius), and
    // U-Net windows ≈ tile + 2·15 here), so there are interior, shifted-edge and partial
    // blocks in both passes.
    let (w, h) = (125, 111);
    let img = random_image(w, h, 2, 1);
    let noisy: Vec<f32> = (0..3 * w * h).map(|i| i as f32 * 1e-3).collect();
    for m in Method::ALL {
        let cfg = tiny();
        let model = MethodModel::init(&cfg, m, &d);
        let whole = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 1000, batch: 1 }, &d).unwrap();
        assert_eq!(whole.timings.windows, 1);
        let tiled = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 8, batch: 3 }, &d).unwrap();
        assert!(tiled.timings.windows > 10 && 2 * tiled.timings.window < w.min(h) + 20, "{:?}", tiled.timings);
        let close = |a: &[f32], b: &[f32], what: &str| {
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert!((x - y).abs() <= 1e-5 + 1e-4 * y.abs(), "{m} {what} [{i}]: tiled {x} vs whole {y}");
            }
        };
        close(&tiled.radiance, &whole.radiance, "radiance");
        if let (Some(a), Some(b)) = (&tiled.weights_g, &whole.weights_g) {
            close(&a.diffuse, &b.diffuse, "W_G diffuse");
            close(&a.specular, &b.specular, "W_G specular");
        }
        assert_eq!(whole.weights_g.is_some(), m == Method::Guided);
        // Passthrough pixels keep the noisy value.
        assert_eq!(&tiled.radiance[33..36], &noisy[33..36]);
    }
}

/// Inference from the renderer's records (normalised in place, `prepare_for_inference`) gives
/// bit for bit what it gives from the normalised planes (`prepare`), tiled or not, for
/// every method; records with more samples than the image use their first `spp`.
#[test]
fn records_equal_planes() {
    let d = crate::cpu_device();
    let (w, h, s) = (70, 53, 3);
    let mut rec = film::descriptors::Descriptors::new(w as u32, h as u32, s as u32 + 1);
    let mut rng = SplitMix64::new(8);
    for v in rec.data.iter_mut() {
        *v = (rng.next_f64() * 20.0 - 5.0) as f32;
    }
    let mut planes = random_image(w, h, s, 3);
    let all: Vec<usize> = (0..w * h).collect();
    planes.descriptors = Some(crate::preprocess::normalised_columns(&rec, s, &all));
    let mut records = planes.clone();
    records.descriptors = None;
    records.records = Some(crate::preprocess::NormalisedRecords::new(rec));
    let noisy = vec![0.5f32; 3 * w * h];
    let cfg = tiny();
    for m in [Method::P, Method::Both, Method::Guided] {
        let model = MethodModel::init(&cfg, m, &d);
        for tile in [1000, 16] {
            let o = InferOptions { tile, batch: 2 };
            let a = denoise(&model, &cfg, &planes, &noisy, &o, &d).unwrap();
            let b = denoise(&model, &cfg, &records, &noisy, &o, &d).unwrap();
            assert_eq!(a.radiance, b.radiance, "{m}, tile {tile}");
        }
    }
}

/// The per-network timed forward computes exactly what `MethodModel::forward` computes, for
/// every method, and books time only to the networks the method has.
#[test]
fn timed_forward_matches_forward() {
    let d = crate::cpu_device();
    let cfg = tiny();
    let img = random_image(30, 26, 2, 9);
    for m in Method::ALL {
        let model = MethodModel::init(&cfg, m, &d);
        let mut t = Timings::default();
        let a = to_vec(timed_forward(&model, PreparedImage::to_tensors(&[&img], &d), None, &mut t).radiance);
        let b = to_vec(model.forward(PreparedImage::to_tensors(&[&img], &d)).radiance);
        assert_eq!(a, b, "{m}");
        assert_eq!(t.d_g_s > 0.0, matches!(m, Method::G | Method::Guided), "{m} {t:?}");
        assert_eq!(t.d_p_s > 0.0, m != Method::G, "{m} {t:?}");
        assert_eq!(t.path_s > 0.0, m != Method::G, "{m} {t:?}");
        assert!(t.path_s <= t.d_p_s, "{m} {t:?}");
        assert!(t.e_s > 0.0, "{m} {t:?}");
    }
}

/// The context bound is tight enough to matter: with too little context the tiled result
/// differs from the whole-image one (so the test above can fail).
#[test]
fn context_is_needed() {
    let d = crate::cpu_device();
    let cfg = tiny();
    let model = MethodModel::init(&cfg, Method::Guided, &d);
    let (w, h) = (40, 40);
    let mut img = random_image(w, h, 2, 2);
    img.passthrough.clear();
    let noisy = vec![0.0; 3 * w * h];
    let whole = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 1000, batch: 1 }, &d).unwrap();
    // Same tiling but a window that only covers the KPCN margin: emulate by a config whose
    // PathNet radius is understated is not possible from outside, so compare against a
    // crop-and-run of one inner block with margin-only context.
    let m = cfg.margin();
    let (x0, y0, b) = (16, 16, 8);
    let win = window(&img, m, x0, y0, b + 2 * m, b + 2 * m, true);
    let out = model.forward(PreparedImage::to_tensors(&[&win], &d));
    let rad = to_vec(out.radiance);
    let mut max_diff = 0.0f32;
    for y in 0..b {
        for x in 0..b {
            let i = (y0 + y) * w + x0 + x;
            max_diff = max_diff.max((rad[y * b + x] - whole.radiance[3 * i]).abs());
        }
    }
    assert!(max_diff > 1e-3, "margin-only context matched ({max_diff}); the U-Net/E context would be unnecessary");
}

/// NaN/Inf/1e6 radiance features, zero albedo, a black frame and 1 spp: the output is finite
/// and non-negative, and W_G lies in [0, 1].
#[test]
fn finite_on_hostile_input() {
    let d = crate::cpu_device();
    let cfg = tiny();
    let model = MethodModel::init(&cfg, Method::Guided, &d);
    let (w, h) = (20, 13);
    let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e6, 0.0, -1e6];
    let mut hostile = random_image(w, h, 1, 3);
    for (i, v) in hostile.diffuse.iter_mut().enumerate() {
        *v = specials[i % specials.len()];
    }
    for (i, v) in hostile.specular.iter_mut().enumerate() {
        *v = specials[(i + 1) % specials.len()];
    }
    // Zero albedo: the G block's albedo planes (channels 14..24).
    let n = w * h;
    hostile.g_block[14 * n..].iter_mut().for_each(|v| *v = 0.0);
    if let Some(ds) = hostile.descriptors.as_mut() {
        ds.iter_mut().enumerate().for_each(|(i, v)| *v = specials[i % specials.len()]);
    }
    let mut black = random_image(w, h, 1, 4);
    for v in black.diffuse.iter_mut().chain(black.specular.iter_mut()).chain(black.g_block.iter_mut()) {
        *v = 0.0;
    }
    let noisy: Vec<f32> = (0..3 * n).map(|i| specials[i % specials.len()]).collect();
    for img in [hostile, black] {
        let out = denoise(&model, &cfg, &img, &noisy, &InferOptions { tile: 8, batch: 2 }, &d).unwrap();
        assert!(out.radiance.iter().all(|x| x.is_finite() && *x >= 0.0));
        let wg = out.weights_g.unwrap();
        assert!(wg.diffuse.iter().chain(&wg.specular).all(|x| (0.0..=1.0).contains(x)));
    }
}

/// The automatic tile depends on the backbone only, not on spp (windows hold per-pixel
/// inputs only): 256 for KPCN columns, 1024 for U-Net columns, whose receptive radius is far
/// larger. The tiled pass's context is the column's radius plus E's, without the
/// path-manifold U-Net's.
#[test]
fn windows_carry_the_receptive_radius() {
    let c = DenoiserConfig::kpcn_cpu();
    assert_eq!(context(&c, Method::G), 7);
    assert_eq!(context(&c, Method::Guided), 7 + 5);
    assert_eq!(pathnet_radius(&c), 29);
    assert_eq!(window_side(&c, Method::Guided, 256), 280);
    assert_eq!(unet_window_side(&c, Method::Guided, 256), 320);
    assert_eq!(auto_tile(&c), 256);
    let ms = DenoiserConfig::cpu_default();
    assert_eq!(auto_tile(&ms), 1024);
    let r = ms.column_radius();
    assert_eq!(context(&ms, Method::G), r);
    assert_eq!(window_side(&ms, Method::G, 1024) % 16, 0);
    assert!(window_side(&ms, Method::G, 1024) >= 1024 + 2 * r + 15);
    assert_eq!(alignment(&ms, Method::P), 16);
}

/// The staged path (P-buffers for the whole image in chunks, U-Net windows, then tiled
/// KPCN/E) gives what `MethodModel::forward` gives on the whole mirror-padded image, for
/// every method, at 1, 3 and 8 spp, with one window or 8-px tiles, and with chunks that end
/// mid-row (50 sample-pixels) or hold the whole image. Tolerance 1e-4 relative + 1e-5
/// absolute, as in `tiled_equals_untiled`: only the blocking of the arithmetic differs
/// (chunked 1×1 convolutions, windowed U-Net), which changes f32 rounding at ~1e-6 per op.
/// The check can fail: mirror-padding the mean embedding one pixel off (all else unchanged)
/// makes it fail (p, 1 spp, one window: 1.2611 vs 1.2609 at the first pixel it reaches).
/// With U-Net columns the image is larger than a window, so tiles of 16 and 24 px cut it
/// into several windows that carry the columns' receptive radius and keep their pooling
/// grids in phase.
#[test]
#[ignore = "slow tier: over a minute on 2 cores (five configurations × methods × spp × tilings); run with --include-ignored"]
fn staged_equals_model_forward() {
    let mskp = tiny().with_mskp(Some(MsKpConfig::new(34).with_widths(vec![6, 8]).with_kernel_scales(2).with_filter_size(3).with_margin(2)));
    // The shipped compositor, at three kernel scales so that two of them swap a low band.
    let swap =
        MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
    let swap = tiny().with_mskp(Some(swap.with_compositor(crate::mskp::ScaleCompositor::LowPassSwap)));
    // Edge-stopping kernels and joint-bilateral upsampling read guides at every level.
    let edge =
        MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
    let edge = tiny().with_mskp(Some(edge.with_edge_stopping(crate::mskp::EdgeStopping::FeaturesAndColour)));
    // The noise-normalised colour guides, one with a pooled variance that reads past the kernel.
    let noise =
        MsKpConfig::new(34).with_widths(vec![4, 4, 4]).with_convs_per_block(1).with_kernel_scales(3).with_filter_size(3).with_margin(2);
    let noise = tiny().with_mskp(Some(noise.with_edge_stopping(crate::mskp::EdgeStopping::FeaturesAndNoisyColour)));
    for (cfg, (w, h), tiles) in [
        (tiny(), (37, 29), [8, 13]),
        (mskp, (80, 72), [16, 24]),
        (swap, (120, 104), [16, 24]),
        (edge, (120, 104), [16, 24]),
        (noise, (120, 104), [16, 24]),
    ] {
        staged_equals_model_forward_for(&cfg, w, h, tiles);
    }
}

fn staged_equals_model_forward_for(cfg: &DenoiserConfig, w: usize, h: usize, tiles: [usize; 2]) {
    let d = crate::cpu_device();
    let cfg = cfg.clone();
    let m = cfg.margin();
    if cfg.mskp.is_some() {
        assert!(window_side(&cfg, Method::Guided, tiles[1]) < w + 2 * m, "the U-Net case must cut the image into several windows");
    }
    for method in Method::ALL {
        let model = MethodModel::init(&cfg, method, &d);
        let a = alignment(&cfg, method);
        let (pw, ph) = (align_up(w + 2 * m, a), align_up(h + 2 * m, a));
        for spp in [1, 3, 8] {
            let img = random_image(w, h, spp, 40 + spp as u64);
            let noisy = vec![0.25f32; 3 * w * h];
            // Reference: the model on the whole padded image, output cropped to the frame.
            let padded = window(&img, m, 0, 0, pw, ph, true);
            let reference = to_vec(model.forward(PreparedImage::to_tensors(&[&padded], &d)).radiance);
            let (ow, oh) = (pw - 2 * m, ph - 2 * m);
            for tile in [1000, tiles[0], tiles[1]] {
                let out = denoise_tiled(&model, &cfg, &img, &noisy, &InferOptions { tile, batch: 2 }, &d).unwrap();
                for y in 0..h {
                    for x in 0..w {
                        let i = y * w + x;
                        for ch in 0..3 {
                            let want = if img.passthrough[i] { noisy[3 * i + ch] } else { clean(reference[(ch * oh + y) * ow + x]) };
                            let got = out.radiance[3 * i + ch];
                            assert!(
                                (got - want).abs() <= 1e-5 + 1e-4 * want.abs(),
                                "{method} spp {spp} tile {tile} ({x},{y},{ch}): {got} vs {want}"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn clear_errors() {
    let d = crate::cpu_device();
    let cfg = tiny();
    let model = MethodModel::init(&cfg, Method::P, &d);
    let mut img = random_image(9, 9, 1, 5);
    img.descriptors = None;
    let e = denoise(&model, &cfg, &img, &vec![0.0; 243], &InferOptions::default(), &d).unwrap_err();
    assert!(e.to_string().contains("descriptors"), "{e}");
    let e = denoise(&model, &cfg, &img, &[0.0; 5], &InferOptions::default(), &d).unwrap_err();
    assert!(e.to_string().contains("expected 243"), "{e}");
    // A G model needs no descriptors, and a 1×1 image works (mirroring a single pixel).
    let g = MethodModel::init(&cfg, Method::G, &d);
    let one = random_image(1, 1, 1, 6);
    let out = denoise(&g, &cfg, &one, &[0.5; 3], &InferOptions::default(), &d).unwrap();
    assert_eq!(out.radiance.len(), 3);
}
