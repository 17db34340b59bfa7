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

/// A frame of `w × h` with every buffer the gate reads, from a seeded stream.
fn frame(w: usize, h: usize, seed: u64) -> film::Frame {
    let mut rng = SplitMix64::new(seed);
    let n = w * h;
    let mut buf = |c: usize, scale: f32| {
        let mut b = film::PixelBuffer::new(c, n);
        for v in b.mean.iter_mut() {
            *v = rng.next_f64() as f32 * scale;
        }
        for v in b.var.iter_mut() {
            *v = rng.next_f64() as f32 * 0.01;
        }
        b
    };
    film::Frame {
        width: w as u32,
        height: h as u32,
        spp: 4,
        radiance: buf(3, 2.0),
        diffuse: Some(buf(3, 1.0)),
        specular: Some(buf(3, 1.0)),
        albedo: Some(buf(3, 1.0)),
        normal: Some(buf(3, 1.0)),
        depth: Some(buf(1, 1.0)),
        depth_scale: 1.0,
        descriptors: None,
        nonfinite_samples: 0,
    }
}

/// The inference path (features, E in windows, blend) with E's head forced to the first expert
/// returns that expert's output exactly, except where a pixel keeps its noisy value by design.
/// An odd size larger than one window checks the windows' seams too.
#[test]
fn gate_forced_to_one_expert_returns_it_exactly() {
    use burn::module::Param;
    use burn::tensor::{Tensor, TensorData};
    let (w, h) = (301, 263);
    let f = frame(w, h, 5);
    let n = w * h;
    let mut rng = SplitMix64::new(8);
    let experts: Vec<Vec<f32>> = (0..3).map(|_| (0..3 * n).map(|_| rng.next_f64() as f32 * 3.0).collect()).collect();
    let passthrough: Vec<bool> = (0..n).map(|i| i % 97 == 0).collect();
    let device = crate::cpu_device();
    let config = GateConfig::new(feature_channels(3), 3).with_widths(vec![4, 4, 4]);
    let mut net = config.init(1, &device);
    // softmax(1000, 0, 0): exp(−1000) is 0 in f32, so the weights are exactly (1, 0, 0).
    net.head.bias = Param::from_tensor(Tensor::<1>::from_data(TensorData::new(vec![1000.0f32, 0.0, 0.0], [3]), &device));
    let header = file::GateHeader {
        experts: vec![Expert::Oidn, Expert::G, Expert::P],
        expert_ids: vec![String::new(); 3],
        widths: vec![4, 4, 4],
        provenance: Default::default(),
    };
    let gate = file::Gate { net, config, header };
    let outputs = run::ExpertOutputs { images: experts.clone(), passthrough: passthrough.clone(), seconds: vec![0.0; 3], prepare_s: 0.0 };
    let (out, weights) = run::apply(&gate, &f, &outputs, &device).expect("gate runs");
    assert!(weights[..n].iter().all(|&v| v == 1.0), "W of the forced expert must be exactly 1");
    for i in 0..n {
        let want = if passthrough[i] { &f.radiance.mean[3 * i..3 * i + 3] } else { &experts[0][3 * i..3 * i + 3] };
        assert_eq!(&out[3 * i..3 * i + 3], want, "pixel {i}");
    }
}

/// Windows are an implementation detail: E's weights on an image larger than one window equal
/// E's weights computed on the whole padded image at once, to f32 rounding.
#[test]
fn windowed_weights_equal_whole_image_weights() {
    let (w, h) = (300, 70);
    let f = frame(w, h, 9);
    let n = w * h;
    let mut rng = SplitMix64::new(4);
    let experts: Vec<Vec<f32>> = (0..2).map(|_| (0..3 * n).map(|_| rng.next_f64() as f32).collect()).collect();
    let device = crate::cpu_device();
    let config = GateConfig::new(feature_channels(2), 2).with_widths(vec![4, 6, 6]);
    let mut net = config.init(2, &device);
    // A non-zero head, so the weights depend on the features.
    net.head = crate::layers::Conv::new(
        crate::layers::ConvSpec {
            in_channels: 4,
            out_channels: 2,
            kernel: 1,
            padding: crate::layers::Padding::Same,
            init: crate::layers::Init::XavierUniform { gain: 1.0 },
            weight_norm: false,
        },
        3,
        7,
        &device,
    );
    let refs: Vec<&[f32]> = experts.iter().map(|v| &v[..]).collect();
    let gf = run::gate_frame(&f).unwrap();
    let feats = features(&gf, &refs);
    let windowed = run::gate_weights(&net, &config, &feats, w, h, &device);
    let whole = whole_image_weights(&net, &config, &feats, w, h, &device);
    let worst = windowed.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "windowed and whole-image weights differ by {worst}");
    assert!(windowed.iter().any(|&v| (v - 0.5).abs() > 0.01), "weights should vary");
}

/// E on the whole image mirror-padded by the windows' context, for the test above.
fn whole_image_weights(net: &GateNet, config: &GateConfig, feats: &[f32], w: usize, h: usize, device: &burn::tensor::Device) -> Vec<f32> {
    use burn::tensor::{Tensor, TensorData};
    let c = config.in_channels;
    let m = 32usize;
    let a = config.alignment();
    let (pw, ph) = ((w + 2 * m).div_ceil(a) * a, (h + 2 * m).div_ceil(a) * a);
    let refl = |i: isize, n: usize| -> usize {
        let p = 2 * (n as isize - 1);
        let r = i.rem_euclid(p);
        (if r < n as isize { r } else { p - r }) as usize
    };
    let mut buf = vec![0.0f32; c * pw * ph];
    for ch in 0..c {
        for y in 0..ph {
            for x in 0..pw {
                buf[(ch * ph + y) * pw + x] = feats[ch * w * h + refl(y as isize - m as isize, h) * w + refl(x as isize - m as isize, w)];
            }
        }
    }
    let out: Vec<f32> = net
        .weights(Tensor::<4>::from_data(TensorData::new(buf, [1, c, ph, pw]), device))
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .unwrap();
    let k = config.experts;
    let mut res = vec![0.0f32; k * w * h];
    for e in 0..k {
        for y in 0..h {
            for x in 0..w {
                res[e * w * h + y * w + x] = out[(e * ph + y + m) * pw + x + m];
            }
        }
    }
    res
}
