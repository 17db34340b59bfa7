//! The denoiser's inputs: diffuse/specular split, G-buffers, variance buffers and per-sample
//! path descriptors (docs/formats.md).

mod common;

use common::*;
use glam::{Mat4, Vec2, Vec3};
use renderer::film::descriptors::{field, FIELDS};
use renderer::film::BufferRequest;
use renderer::light::Environment;
use renderer::scene::primitives::{quad, sphere};
use renderer::scene::{ColorParam, MaterialKind};
use renderer::texture::Texture;
use std::f32::consts::FRAC_PI_2;

/// Cornell-like scene with diffuse, glossy plastic, rough metal and glass, so every lobe
/// type contributes to the split.
fn mixed_scene(w: u32, h: u32) -> renderer::scene::Scene {
    let cam = camera(Vec3::new(0.0, 0.6, 3.0), Vec3::new(0.0, 0.4, 0.0), 45.0, w, h);
    scene(
        vec![
            (quad(), Mat4::from_rotation_x(-FRAC_PI_2) * Mat4::from_scale(Vec3::splat(3.0)), lambert(0.6)),
            (
                sphere(0.35, 24),
                Mat4::from_translation(Vec3::new(-0.6, 0.35, 0.0)),
                with_kind(MaterialKind::Plastic {
                    albedo: ColorParam::Const(Vec3::new(0.1, 0.4, 0.8)),
                    ior: 1.5,
                    roughness: 0.05,
                    dist: Default::default(),
                    nonlinear: true,
                }),
            ),
            (
                sphere(0.35, 24),
                Mat4::from_translation(Vec3::new(0.0, 0.35, 0.0)),
                with_kind(MaterialKind::Conductor {
                    eta: Vec3::new(0.2, 0.9, 1.1),
                    k: Vec3::new(3.9, 2.4, 2.2),
                    roughness: 0.15,
                    specular_tint: ColorParam::Const(Vec3::ONE),
                    dist: Default::default(),
                }),
            ),
            (
                sphere(0.35, 24),
                Mat4::from_translation(Vec3::new(0.6, 0.35, 0.0)),
                with_kind(MaterialKind::Dielectric { ior: 1.5, roughness: 0.0, tint: Vec3::ONE, dist: Default::default() }),
            ),
            (
                quad(),
                Mat4::from_translation(Vec3::new(0.0, 2.0, 0.0)) * Mat4::from_rotation_x(FRAC_PI_2) * Mat4::from_scale(Vec3::splat(0.5)),
                emitter(Vec3::splat(10.0)),
            ),
        ],
        Environment::Constant(Vec3::splat(0.3)),
        cam,
        vec![],
    )
}

#[test]
fn diffuse_plus_specular_is_radiance() {
    let s = mixed_scene(32, 24);
    let f = render(&s, 8, 3, 5, BufferRequest::ALL);
    let (d, sp) = (f.diffuse.as_ref().unwrap(), f.specular.as_ref().unwrap());
    let mut both = [0usize; 2];
    for i in 0..f.radiance.mean.len() {
        let (r, sum) = (f.radiance.mean[i], d.mean[i] + sp.mean[i]);
        // Per sample diffuse + specular = radiance up to float rounding of the split
        // (a few ulps of the larger term); the mean keeps that relative size.
        assert!((r - sum).abs() <= 1e-5 * r.abs().max(1.0), "pixel value {i}: {r} vs {sum}");
        both[0] += (d.mean[i] > 0.0) as usize;
        both[1] += (sp.mean[i] > 0.0) as usize;
    }
    assert!(both[0] > 100 && both[1] > 100, "both parts must be non-trivial: {both:?}");
}

#[test]
fn albedo_of_a_textured_plane_equals_the_texture() {
    // A quad filling the view exactly, head-on: pixel centre (x+½)/W, (y+½)/H ↦ uv. The mean of
    // a bilinear texture over a pixel footprint equals its value at the centre when the
    // footprint stays inside one bilinear cell; we test those pixels.
    let tex =
        Texture { width: 4, height: 4, texels: (0..16).map(|i| Vec3::new((i % 4) as f32 / 3.0, (i / 4) as f32 / 3.0, 0.5)).collect() };
    let d = 2.0f32;
    let fov = 2.0 * (1.0 / d).atan().to_degrees();
    let cam = camera(Vec3::new(0.0, 0.0, d), Vec3::ZERO, fov, 64, 64);
    let mat = with_kind(MaterialKind::Lambert { albedo: ColorParam::texture(0, Vec3::ONE) });
    let s = scene(vec![(quad(), Mat4::IDENTITY, mat)], Environment::Constant(Vec3::ONE), cam, vec![tex.clone()]);
    let f = render(&s, 16, 5, 1, BufferRequest { split: false, gbuffers: true, descriptors: false });
    let a = f.albedo.as_ref().unwrap();
    let mut tested = 0;
    for y in 0..64u32 {
        for x in 0..64u32 {
            // texel centres sit at pixel boundaries 8, 24, 40, 56: avoid pixels touching them
            if [7, 8, 23, 24, 39, 40, 55, 56].contains(&x) || [7, 8, 23, 24, 39, 40, 55, 56].contains(&y) {
                continue;
            }
            let uv = Vec2::new((x as f32 + 0.5) / 64.0, (y as f32 + 0.5) / 64.0);
            let want = tex.sample_bilinear(uv);
            let i = (y * 64 + x) as usize;
            for c in 0..3 {
                let got = a.mean[i * 3 + c];
                // Across a pixel the bilinear texture changes by at most 1/16 per channel (adjacent
                // texels differ by ≤ 1 and a texel spans 16 px), so one jittered sample has a
                // standard deviation ≤ (1/16)/√12 around the centre value and the 16-sample mean
                // ≤ that / 4 ≈ 0.0045. 5 of those plus f32 rounding (the estimated variance
                // from 16 samples is itself too noisy to build a 5σ bound on).
                let tol = 5.0 * (1.0 / 16.0) / (12f32.sqrt() * 4.0) + 1e-4;
                assert!((got - want[c]).abs() <= tol, "pixel ({x},{y}) channel {c}: {got} vs {} (tol {tol})", want[c]);
            }
            tested += 1;
        }
    }
    assert!(tested > 2000);
}

#[test]
fn normals_are_unit_and_depth_matches_a_head_on_plane() {
    let d = 3.0f32;
    let fov = 40.0f32;
    let (w, h) = (48u32, 32u32);
    let cam = camera(Vec3::new(0.0, 0.0, d), Vec3::ZERO, fov, w, h);
    let s = scene(vec![(quad(), Mat4::from_scale(Vec3::splat(10.0)), lambert(0.5))], Environment::Constant(Vec3::ONE), cam.clone(), vec![]);
    let f = render(&s, 1, 9, 1, BufferRequest { split: false, gbuffers: true, descriptors: false });
    let (n, z) = (f.normal.as_ref().unwrap(), f.depth.as_ref().unwrap());
    let t = (fov.to_radians() / 2.0).tan();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let nv = Vec3::new(n.mean[i * 3], n.mean[i * 3 + 1], n.mean[i * 3 + 2]);
            assert!((nv.length() - 1.0).abs() < 1e-4, "normal at ({x},{y}) has length {}", nv.length());
            // Facing the camera head-on: camera-space normal is +Z.
            assert!(nv.z > 0.999);
            // Path length along the jittered ray lies between the distances through the nearest
            // and the farthest point of the pixel footprint on the plane.
            let corner = |cx: f32, cy: f32| {
                let sx = (2.0 * cx / w as f32 - 1.0) * t * w as f32 / h as f32;
                let sy = (1.0 - 2.0 * cy / h as f32) * t;
                d * (1.0 + sx * sx + sy * sy).sqrt()
            };
            let ds = [
                corner(x as f32, y as f32),
                corner(x as f32 + 1.0, y as f32),
                corner(x as f32, y as f32 + 1.0),
                corner(x as f32 + 1.0, y as f32 + 1.0),
            ];
            let (lo, hi) = (ds.iter().cloned().fold(f32::MAX, f32::min), ds.iter().cloned().fold(0.0, f32::max));
            let dist = z.mean[i] * f.depth_scale;
            let (lo, hi) = (lo.min(d), hi); // the footprint may contain the foot of the perpendicular
            assert!(dist >= lo * (1.0 - 1e-5) && dist <= hi * (1.0 + 1e-5), "depth at ({x},{y}): {dist} not in [{lo}, {hi}]");
        }
    }
}

#[test]
fn gbuffers_look_through_a_mirror() {
    // Camera looks down −Z at a mirror tilted 45° that reflects the view up (+Y) onto a red
    // sphere: the G-buffers must show the sphere, not the mirror.
    let cam = camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 10.0, 16, 16);
    let mirror = with_kind(MaterialKind::Conductor {
        eta: Vec3::new(0.155, 0.117, 0.138),
        k: Vec3::new(4.83, 3.12, 2.15),
        roughness: 0.0,
        specular_tint: ColorParam::Const(Vec3::ONE),
        dist: Default::default(),
    });
    let red = with_kind(MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::new(0.8, 0.1, 0.1)) });
    let s = scene(
        vec![
            (quad(), Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_4) * Mat4::from_scale(Vec3::splat(1.5)), mirror),
            (sphere(1.0, 64), Mat4::from_translation(Vec3::new(0.0, 3.0, 0.0)), red),
        ],
        Environment::Constant(Vec3::splat(0.5)),
        cam,
        vec![],
    );
    let f = render(&s, 4, 11, 5, BufferRequest { split: false, gbuffers: true, descriptors: false });
    let i = (8 * 16 + 8) as usize;
    let a = &f.albedo.as_ref().unwrap().mean[i * 3..i * 3 + 3];
    assert!((a[0] - 0.8).abs() < 1e-4 && (a[1] - 0.1).abs() < 1e-4, "albedo through the mirror: {a:?}");
    let n = &f.normal.as_ref().unwrap().mean[i * 3..i * 3 + 3];
    // The sphere's bottom faces −Y in world space = camera-space −Y.
    assert!(n[1] < -0.98, "normal through the mirror: {n:?}");
    // Camera → mirror (4) → sphere bottom (2); pixel footprint changes it by < 1 %.
    let dist = f.depth.as_ref().unwrap().mean[i] * f.depth_scale;
    assert!((dist - 6.0).abs() < 0.06, "path length through the mirror {dist}");
}

#[test]
fn variance_buffer_matches_the_spread_of_independent_renders() {
    // 32 renders with different seeds: the spread of each pixel's mean estimates the variance
    // of the mean; the variance buffer of each render estimates the same thing. Summed over
    // 384 pixels the relative standard deviation of the empirical side is ≈ sqrt(2/31)/sqrt(384)
    // ≈ 1.3 % (more with correlated pixels); a 10 % band is > 5σ yet catches an S vs S−1
    // mix-up at 4 spp (25 %) or a missing 1/S (300 %).
    let cam = camera(Vec3::new(0.0, 1.0, 3.0), Vec3::ZERO, 40.0, 24, 16);
    let s = scene(
        vec![
            (quad(), Mat4::from_rotation_x(-FRAC_PI_2) * Mat4::from_scale(Vec3::splat(5.0)), lambert(0.7)),
            (sphere(0.5, 24), Mat4::IDENTITY, lambert(0.5)),
        ],
        Environment::Constant(Vec3::ONE),
        cam,
        vec![],
    );
    let runs: Vec<_> =
        (0..32).map(|k| render(&s, 4, 1000 + k, 3, BufferRequest { split: true, gbuffers: true, descriptors: false })).collect();
    let check = |get: &dyn Fn(&renderer::film::Frame) -> &renderer::film::PixelBuffer, name: &str| {
        let n = get(&runs[0]).mean.len();
        let (mut emp, mut buf) = (0.0f64, 0.0f64);
        for i in 0..n {
            let xs: Vec<f64> = runs.iter().map(|f| get(f).mean[i] as f64).collect();
            let m = xs.iter().sum::<f64>() / 32.0;
            emp += xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / 31.0;
            buf += runs.iter().map(|f| get(f).var[i] as f64).sum::<f64>() / 32.0;
        }
        assert!(emp > 0.0);
        let ratio = buf / emp;
        assert!((ratio - 1.0).abs() < 0.10, "{name}: variance buffer / empirical variance = {ratio}");
    };
    check(&|f| &f.radiance, "radiance");
    check(&|f| f.diffuse.as_ref().unwrap(), "diffuse");
    check(&|f| f.normal.as_ref().unwrap(), "normal");
    check(&|f| f.depth.as_ref().unwrap(), "depth");
}

/// Diffuse floor under a light whose own BSDF is black, black environment: every BSDF-sampled
/// path is camera → floor → (light | nothing), which we can check by hand.
fn floor_and_light() -> renderer::scene::Scene {
    let cam = camera(Vec3::new(0.0, 0.9, 1.5), Vec3::ZERO, 30.0, 12, 12);
    scene(
        vec![
            (quad(), Mat4::from_rotation_x(-FRAC_PI_2) * Mat4::from_scale(Vec3::splat(4.0)), lambert(0.6)),
            (
                quad(),
                Mat4::from_translation(Vec3::new(0.0, 1.0, 0.0)) * Mat4::from_rotation_x(FRAC_PI_2),
                emitter(Vec3::new(4.0, 3.0, 2.0)),
            ),
        ],
        Environment::Constant(Vec3::ZERO),
        cam,
        vec![],
    )
}

#[test]
fn descriptors_of_one_diffuse_bounce_match_hand_computation() {
    let s = floor_and_light();
    let f = render(&s, 16, 21, 5, BufferRequest::ALL);
    let d = f.descriptors.as_ref().unwrap();
    let (mut to_light, mut escaped) = (0, 0);
    for i in 0..f.pixels() {
        for k in 0..d.spp as usize {
            let r = d.sample(i, k);
            assert_eq!(r.len(), FIELDS);
            // Vertex 0 is the floor: Lambert reflection (1|4 = 5), roughness 1.
            assert_eq!(r[field::BOUNCE_TYPE], 5.0);
            assert_eq!(r[field::ROUGHNESS], 1.0);
            // For Lambert, f·cos / pdf = albedo exactly: throughput / path weight = 0.6.
            let t0 = &r[field::THROUGHPUT..field::THROUGHPUT + 3];
            let pw = r[field::PATH_WEIGHT];
            assert!(pw > 0.0);
            for t in t0 {
                assert!((t / pw - 0.6).abs() < 1e-4, "throughput/pdf {} ", t / pw);
            }
            let li = &r[field::LIGHT_INTENSITY..field::LIGHT_INTENSITY + 3];
            if li[0] > 0.0 {
                to_light += 1;
                assert_eq!(li, &[4.0, 3.0, 2.0]);
                let rw = &r[field::RADIANCE_NO_WEIGHT..field::RADIANCE_NO_WEIGHT + 3];
                for c in 0..3 {
                    assert!((rw[c] - t0[c] * li[c]).abs() <= 1e-5 * rw[c].abs().max(1e-3));
                }
                // The light's black BSDF ends the path: nothing recorded at vertex 1 and beyond.
                assert!(r[field::BOUNCE_TYPE + 1..field::BOUNCE_TYPE + 6].iter().all(|&b| b == 0.0));
            } else {
                escaped += 1;
                assert!(r[field::RADIANCE_NO_WEIGHT..field::RADIANCE_NO_WEIGHT + 3].iter().all(|&v| v == 0.0));
            }
        }
    }
    assert!(to_light > 100 && escaped > 100, "both kinds of paths must occur: {to_light} / {escaped}");
}

#[test]
fn descriptor_bsdf_estimator_reproduces_the_radiance() {
    // With paths that end at their first emitter, (radiance without weight) / (path weight) is
    // the plain BSDF-sampling estimator, unbiased for the same radiance the NEE+MIS estimator
    // computes. Compare image means within 4 combined standard errors.
    let s = floor_and_light();
    let f = render(&s, 64, 22, 5, BufferRequest::ALL);
    let d = f.descriptors.as_ref().unwrap();
    let n = f.pixels() as f64;
    let (mut bsdf_sum, mut bsdf_sq, mut count) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..f.pixels() {
        for k in 0..d.spp as usize {
            let r = d.sample(i, k);
            let v = (r[0] + r[1] + r[2]) as f64 / 3.0 / r[field::PATH_WEIGHT] as f64;
            bsdf_sum += v;
            bsdf_sq += v * v;
            count += 1.0;
        }
    }
    let bsdf_mean = bsdf_sum / count;
    let bsdf_se = ((bsdf_sq / count - bsdf_mean * bsdf_mean) / count).sqrt();
    let nee_mean = f.radiance.mean.iter().map(|&v| v as f64).sum::<f64>() / (3.0 * n);
    let nee_se = (f.radiance.var.iter().map(|&v| v as f64).sum::<f64>() * 3.0).sqrt() / (3.0 * n);
    let tol = 4.0 * (bsdf_se * bsdf_se + nee_se * nee_se).sqrt();
    assert!((bsdf_mean - nee_mean).abs() < tol, "BSDF estimator {bsdf_mean} vs NEE {nee_mean} (tol {tol})");
}

/// Recording descriptors changes the tiling (full-width bands that write straight into the
/// frame) but not the image; and each pixel's records land at that pixel: a crop's descriptors
/// equal the full frame's at the same pixels. Sizes are not multiples of the 16-px tile.
#[test]
fn descriptor_bands_keep_the_image_and_put_records_at_their_pixels() {
    let s = mixed_scene(37, 29);
    let plain = render(&s, 3, 11, 5, BufferRequest { split: true, gbuffers: true, descriptors: false });
    let full = render(&s, 3, 11, 5, BufferRequest::ALL);
    assert_eq!(plain.radiance.mean, full.radiance.mean);
    assert_eq!(plain.diffuse.as_ref().unwrap().mean, full.diffuse.as_ref().unwrap().mean);
    let d = full.descriptors.as_ref().unwrap();
    assert!(d.data.iter().any(|&v| v != 0.0));
    let (x0, y0, w, h) = (5u32, 17u32, 30u32, 12u32);
    let opts = renderer::integrator::RenderOptions {
        spp: 3,
        seed: 11,
        max_bounces: 5,
        russian_roulette: false,
        request: BufferRequest::ALL,
        crop: Some((x0, y0, w, h)),
        first_sample: 0,
    };
    let (crop, _) = renderer::integrator::render(&s, &opts, &|_| {}).unwrap();
    let c = crop.descriptors.as_ref().unwrap();
    let per_pixel = 3 * FIELDS;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let i = y * w as usize + x;
            let j = (y + y0 as usize) * 37 + x + x0 as usize;
            assert_eq!(
                c.data[i * per_pixel..(i + 1) * per_pixel],
                d.data[j * per_pixel..(j + 1) * per_pixel],
                "pixel ({x}, {y}) of the crop"
            );
        }
    }
}
