use super::cache::CachedImage;
use super::train::{train, GateTrainOptions};
use super::*;
use crate::rng::SplitMix64;

/// A synthetic image whose albedo's red channel says which of two experts is right: expert A
/// equals the reference where it is 1 and is twice as bright elsewhere; expert B the reverse.
fn split_image(w: usize, h: usize, seed: u64) -> CachedImage {
    let mut rng = SplitMix64::new(seed);
    let n = w * h;
    let reference: Vec<f32> = (0..3 * n).map(|_| 0.2 + 0.6 * rng.next_f64() as f32).collect();
    // Regions: vertical stripes of random width, so the cue, not the position, tells them apart.
    let mut cue = vec![0.0f32; n];
    let mut x0 = 0;
    let mut on = rng.below(2) == 1;
    while x0 < w {
        let len = 3 + rng.below(8);
        for x in x0..(x0 + len).min(w) {
            for y in 0..h {
                cue[y * w + x] = on as u8 as f32;
            }
        }
        on = !on;
        x0 += len;
    }
    let wrong = |i: usize| reference[i] * 2.0;
    let a: Vec<f32> = (0..3 * n).map(|i| if cue[i / 3] > 0.5 { reference[i] } else { wrong(i) }).collect();
    let b: Vec<f32> = (0..3 * n).map(|i| if cue[i / 3] > 0.5 { wrong(i) } else { reference[i] }).collect();
    let albedo: Vec<f32> = (0..3 * n).map(|i| if i % 3 == 0 { cue[i / 3] } else { 0.5 }).collect();
    // The noisy input is the reference (no noise), so nothing but the cue separates the experts
    // (A and B are both wrong by the same factor where they are wrong).
    let noisy: Vec<f32> = reference.iter().map(|v| v * 1.5).collect();
    CachedImage {
        spp: 8,
        width: w,
        height: h,
        experts: vec![(Expert::G, a), (Expert::P, b)],
        radiance: noisy.clone(),
        radiance_var: vec![0.01; 3 * n],
        diffuse: noisy,
        specular: vec![0.0; 3 * n],
        albedo,
        normal: vec![0.0; 3 * n],
        depth: vec![0.5; n],
        passthrough: vec![false; n],
        reference,
    }
}

/// The gate is told apart from a constant choice only by learning the cue: its weight for the
/// right expert must reach 0.9 on each region (the floor), on an image it never saw.
#[test]
fn gate_learns_a_split_marked_by_a_gbuffer_channel() {
    let train_imgs: Vec<CachedImage> = (0..6).map(|s| split_image(32, 32, s)).collect();
    let test = split_image(32, 32, 99);
    let opts = GateTrainOptions {
        experts: vec![Expert::G, Expert::P],
        widths: vec![8, 8],
        steps: 300,
        batch: 4,
        crop: 16,
        lr: 1e-2,
        seed: 3,
        val_every: 0,
        eps: 1e-2,
        logit_noise: 0.0,
    };
    let refs: Vec<&CachedImage> = train_imgs.iter().collect();
    let trained = train(&refs, &[], &opts, &mut |_, _, _| {}).expect("trains");
    let imgs = test.expert_images(&opts.experts);
    let feats = features(&test.gate_frame(), &imgs);
    let wts = run::gate_weights(&trained.net, &trained.config, &feats, 32, 32, &crate::cpu_device());
    let n = 32 * 32;
    let (mut on, mut off, mut non, mut noff) = (0.0, 0.0, 0, 0);
    for i in 0..n {
        if test.albedo[3 * i] > 0.5 {
            on += wts[i] as f64;
            non += 1;
        } else {
            off += wts[n + i] as f64;
            noff += 1;
        }
    }
    let (wa, wb) = (on / non as f64, off / noff as f64);
    assert!(wa >= 0.9 && wb >= 0.9, "mean weight of the right expert: A {wa:.3} where A is right, B {wb:.3} where B is right");
}

#[test]
fn one_hot_weights_return_the_expert_exactly_and_passthrough_keeps_noisy() {
    let n = 4;
    let a: Vec<f32> = (0..12).map(|i| i as f32 * 0.37).collect();
    let b: Vec<f32> = (0..12).map(|i| 5.0 - i as f32 * 0.11).collect();
    let noisy: Vec<f32> = (0..12).map(|i| 100.0 + i as f32).collect();
    let mut w = vec![0.0f32; 2 * n];
    w[..n].fill(1.0);
    let pt = vec![false, true, false, false];
    let out = blend(&[&a, &b], &w, &noisy, &pt);
    for i in 0..n {
        let want = if pt[i] { &noisy[3 * i..3 * i + 3] } else { &a[3 * i..3 * i + 3] };
        assert_eq!(&out[3 * i..3 * i + 3], want, "pixel {i}");
    }
}

#[test]
fn features_are_finite_on_non_finite_input() {
    let n = 2;
    let bad = vec![f32::NAN, f32::INFINITY, -1.0, 1e30, 0.0, f32::NEG_INFINITY];
    let f = GateFrame {
        width: 2,
        height: 1,
        spp: 4,
        radiance: &bad,
        radiance_var: &bad,
        diffuse: &bad,
        specular: &bad,
        albedo: &bad,
        normal: &bad,
        depth: &bad[..n],
    };
    let feats = features(&f, &[&bad, &bad]);
    assert_eq!(feats.len(), feature_channels(2) * n);
    assert!(feats.iter().all(|v| v.is_finite()), "{feats:?}");
}
