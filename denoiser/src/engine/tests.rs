//! The engine against burn: single convolutions on random data, and the shipped g column's whole
//! forward on rendered frames, at every instruction set this CPU has and the portable code.
//!
//! Tolerance (issue "Tests"): per value |a − b| ≤ 1e-4·(|b| + 1e-2). Both sides compute in f32
//! and differ only in the order of their sums (burn: im2col then a blocked matrix product; the
//! engine: input channel, then tap, with fused multiply-adds), ~1e-6 relative per layer over a
//! dozen layers; a wrong tap, channel, border or upsampling weight is O(1e-1).

use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Tensor, TensorData};

use super::*;
use crate::cpu_device;
use crate::infer::{denoise, InferOptions};
use crate::method::Method;
use crate::preprocess::prepare_for_inference;
use crate::rng::SplitMix64;
use crate::weights;

fn close(a: &[f32], b: &[f32], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        assert!(x.is_finite(), "{what} [{i}]: engine gives {x}");
        assert!((x - y).abs() <= 1e-4 * (y.abs() + 1e-2), "{what} [{i}]: engine {x} vs burn {y}");
    }
}

fn random(n: usize, rng: &mut SplitMix64) -> Vec<f32> {
    (0..n).map(|_| rng.symmetric(1.0)).collect()
}

/// One 3×3 (and 1×1) convolution with two concatenated inputs, odd sizes (runs that end inside
/// a vector, a row shorter than one run), output channels not a multiple of 8: the engine equals
/// burn's conv2d plus ReLU.
#[test]
fn convolution_equals_burn() {
    let d = cpu_device();
    let mut rng = SplitMix64::new(7);
    for (h, w, ca, cb, cout, k) in [(13, 37, 5, 3, 11, 3), (5, 3, 2, 0, 8, 3), (9, 70, 16, 8, 31, 1), (33, 17, 24, 24, 24, 3)] {
        let cin = ca + cb;
        let (xa, xb) = (random(ca * h * w, &mut rng), random(cb * h * w, &mut rng));
        let wt = random(cout * cin * k * k, &mut rng);
        let bias = random(cout, &mut rng);
        let x: Vec<f32> = xa.iter().chain(&xb).copied().collect();
        let expect = conv2d(
            Tensor::<4>::from_data(TensorData::new(x, [1, cin, h, w]), &d),
            Tensor::from_data(TensorData::new(wt.clone(), [cout, cin, k, k]), &d),
            Some(Tensor::from_data(TensorData::new(bias.clone(), [cout]), &d)),
            ConvOptions::new([1, 1], [k / 2, k / 2], [1, 1], 1),
        );
        let expect: Vec<f32> = burn::tensor::activation::relu(expect).into_data().try_to_vec::<f32>().unwrap();
        let cw = ConvWeights::new(&wt, &bias, cout, cin, k);
        let (pa, pb) = (Planes::from_planar(&xa, ca, h, w), Planes::from_planar(&xb, cb, h, w));
        for isa in Isa::available() {
            let inputs: Vec<&Planes> = if cb > 0 { vec![&pa, &pb] } else { vec![&pa] };
            let out = conv(isa, &inputs, &cw, true);
            // Each value sums n = cin·k² products of random values in [−1, 1], which can cancel
            // to near 0; two summation orders then differ by up to ~n·ε·|partial sums|, so the
            // bound is absolute in n (1e-6·n ≈ 17·n·ε) plus 1e-4 relative. A wrong tap or
            // channel is off by O(0.1–1).
            let what = format!("{} {h}×{w} {cin}→{cout} k{k}", isa.name());
            for (i, (a, b)) in out.to_planar(0, cout).iter().zip(&expect).enumerate() {
                assert!((a - b).abs() <= 1e-6 * (cin * k * k) as f32 + 1e-4 * b.abs(), "{what} [{i}]: engine {a} vs burn {b}");
            }
            // The border stays zero: it is the next layer's padding.
            let top = &out.data[..out.stride];
            assert!(top.iter().all(|&v| v == 0.0), "{}: border written", isa.name());
        }
    }
}

/// Pooling and upsampling equal burn's to the bit, on odd sizes (pooling floors them; the
/// upsampling back to an odd size is not an exact 2×).
#[test]
fn pooling_and_upsampling_equal_burn() {
    use burn::tensor::module::{interpolate, max_pool2d};
    use burn::tensor::ops::{InterpolateMode, InterpolateOptions, MaxPoolOptions};
    let d = cpu_device();
    let mut rng = SplitMix64::new(3);
    let (c, h, w) = (3, 11, 7);
    let v = random(c * h * w, &mut rng);
    let t = Tensor::<4>::from_data(TensorData::new(v.clone(), [1, c, h, w]), &d);
    let p = Planes::from_planar(&v, c, h, w);
    let pooled: Vec<f32> = max_pool2d(t.clone(), MaxPoolOptions::new([2, 2]).with_stride([2, 2])).into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(p.max_pool().to_planar(0, c), pooled);
    let up = interpolate(t, InterpolateOptions::new(InterpolateMode::Bilinear).with_align_corners(false).with_output_size([23, 15]));
    let up: Vec<f32> = up.into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(p.upsample_to(23, 15).to_planar(0, c), up);
}

fn rendered(scene: &str, w: u32, h: u32, spp: u32) -> film::Frame {
    use renderer::film::BufferRequest;
    use renderer::integrator::{self, RenderOptions};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut s = renderer::scene::Scene::load(&root.join(scene)).expect("shipped scene");
    (s.camera.width, s.camera.height) = (w, h);
    let mut opts = RenderOptions::from_scene(&s, BufferRequest { split: true, gbuffers: true, descriptors: false });
    opts.spp = spp;
    integrator::render(&s, &opts, &|_| {}).expect("render").0
}

/// The shipped g model denoises rendered frames of odd sizes at 2, 8 and 32 spp the same with
/// its convolutions on the engine as on burn, at every instruction set and with the portable
/// code; with small tiles (many windows) as with one; with 1 thread as with 2 (bit for bit).
#[test]
fn shipped_g_equals_burn() {
    let d = cpu_device();
    let loaded = weights::load(&weights::default_path(Method::G), &d).expect("shipped g weights");
    for (scene, w, h, spp) in [
        ("scenes/glossy-room/scene.toml", 61, 47, 2),
        ("scenes/cornell-box/scene.toml", 45, 39, 8),
        ("scenes/glossy-room/scene.toml", 33, 53, 32),
    ] {
        let mut frame = rendered(scene, w, h, spp);
        let noisy = frame.radiance.mean.clone();
        let prepared = prepare_for_inference(&mut frame).unwrap();
        let run = |model: &MethodModel, tile: usize| {
            denoise(model, &loaded.config, &prepared, &noisy, &InferOptions { tile, batch: 1 }, &d).unwrap().radiance
        };
        let burn = run(&loaded.model, 0);
        for isa in Isa::available() {
            let mut model = loaded.model.clone();
            use_engine(&mut model, Some(isa));
            let what = format!("{scene} {w}×{h} {spp} spp, {}", isa.name());
            let whole = run(&model, 0);
            close(&whole, &burn, &what);
            if isa == Isa::detect() {
                let tiled = run(&model, 16);
                close(&tiled, &whole, &format!("{what}, tiled"));
                let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(|| run(&model, 0));
                let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap().install(|| run(&model, 0));
                assert_eq!(one, two, "{what}: the thread count changed the image");
            }
        }
    }
}

/// NaN, ±Inf and huge inputs give finite head outputs (the column sanitises its input before
/// the engine sees it; this checks the engine adds no overflow of its own at the input limit).
#[test]
fn hostile_inputs_give_finite_outputs() {
    let d = cpu_device();
    let loaded = weights::load(&weights::default_path(Method::G), &d).expect("shipped g weights");
    let col = loaded.model.diffuse.d_g.as_ref().unwrap();
    let mut model = loaded.model.clone();
    use_engine(&mut model, Some(Isa::detect()));
    let col_e = model.diffuse.d_g.as_ref().unwrap();
    let (c, h, w) = (34, 37, 41);
    let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, 0.0, 0.5];
    let v: Vec<f32> = (0..c * h * w).map(|i| specials[(i * 7 + i / 13) % specials.len()]).collect();
    let x = Tensor::<4>::from_data(TensorData::new(v, [1, c, h, w]), &d);
    let a: Vec<f32> = col_e.forward(x.clone(), 4).into_data().try_to_vec::<f32>().unwrap();
    assert!(a.iter().all(|v| v.is_finite()), "non-finite engine output");
    let b: Vec<f32> = col.forward(x, 4).into_data().try_to_vec::<f32>().unwrap();
    close(&a, &b, "hostile input");
}
