//! Light sampling tests: histogram (chi-square) checks of the environment sampler against
//! `env_pdf`, Monte Carlo integrals against closed forms, pdf consistency, selection by power,
//! and degenerate inputs.

use super::*;
use crate::material::{ColorParam, MaterialKind};
use crate::math::PI;
use crate::rng::Pcg32;

fn material(emission: Vec3, two_sided: bool) -> Material {
    Material {
        name: "m".into(),
        kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::splat(0.5)) },
        emission,
        two_sided_emission: two_sided,
        one_sided: false,
    }
}

/// Axis-aligned square `[x0, x0+s] × [z0, z0+s]` at height `y`, wound so its normal is −Y.
fn add_square(mesh: &mut Mesh, x0: f32, z0: f32, y: f32, s: f32, mat: u32) {
    let p = [Vec3::new(x0, y, z0), Vec3::new(x0 + s, y, z0), Vec3::new(x0 + s, y, z0 + s), Vec3::new(x0, y, z0 + s)];
    mesh.append(&p, &[], &[], &[[0, 1, 2], [0, 2, 3]], mat);
}

/// 16 × 8 map with a smooth ramp and one "sun" texel at (5, 2) ~1000× brighter.
fn sun_map() -> Texture {
    let (w, h) = (16u32, 8u32);
    let mut texels = Vec::new();
    for y in 0..h {
        for x in 0..w {
            texels.push(Vec3::new(0.1 + 0.05 * x as f32, 0.2 + 0.02 * y as f32, 0.3));
        }
    }
    texels[(2 * w + 5) as usize] = Vec3::new(400.0, 300.0, 200.0);
    Texture { width: w, height: h, texels }
}

/// 3 columns of the 16-column map: bins aligned with texel columns stay aligned after rotation.
const SUN_ROTATION: f32 = 3.0 * 360.0 / 16.0;

/// Mean and standard error of the mean.
fn mean_and_stderr(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// World direction of lat-long coordinates, written out from the environment.rs docs
/// independently of the implementation.
fn documented_dir(u: f32, v: f32, rotation_deg: f32) -> Vec3 {
    let (theta, phi) = (PI * v, 2.0 * PI * u);
    let d = Vec3::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos());
    let a = rotation_deg.to_radians();
    Vec3::new(d.x * a.cos() + d.z * a.sin(), d.y, -d.x * a.sin() + d.z * a.cos())
}

fn world_uv(d: Vec3) -> (f32, f32) {
    let mut u = d.x.atan2(-d.z) / (2.0 * PI);
    if u < 0.0 {
        u += 1.0;
    }
    (u.min(0.999_999), d.y.clamp(-1.0, 1.0).acos() / PI)
}

/// Upper bound of the chi-square statistic at significance `alpha` ≈ 1e-4 (z = 3.72), through the
/// Wilson–Hilferty normal approximation, accurate to a few percent for dof ≥ 10.
fn chi2_critical(dof: f64) -> f64 {
    let z = 3.72;
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

#[test]
fn env_map_sampling_matches_env_pdf_chi_square() {
    let env = Environment::Map { image: sun_map(), rotation_deg: SUN_ROTATION, scale: 2.0 };
    let lights = Lights::build(&Mesh::default(), &[], env);
    assert!(!lights.is_empty());
    let (bw, bh) = (16usize, 8usize);
    let n = 200_000;
    let mut counts = vec![0u64; bw * bh];
    let mut rng = Pcg32::new(11, 3);
    for _ in 0..n {
        let s = lights.sample(Vec3::ZERO, rng.next_f32(), rng.next_2d()).expect("env sample");
        assert!(s.prim.is_none() && s.dist == f32::INFINITY);
        // The integrator's MIS needs the reported density to be the one env_pdf gives, exactly.
        assert_eq!(s.pdf, lights.env_pdf(s.wi));
        assert_eq!(s.radiance, lights.env_radiance(s.wi));
        let (u, v) = world_uv(s.wi);
        counts[((v * bh as f32) as usize).min(bh - 1) * bw + ((u * bw as f32) as usize).min(bw - 1)] += 1;
    }
    // Expected counts: integrate env_pdf over each world-space bin with an 8×8 midpoint rule in
    // (φ, θ). Bins align with texels, so env_pdf · sin θ is constant inside a bin and the rule is
    // exact up to rounding; any error in the Jacobian, rotation or normalisation shows up here.
    let k = 8;
    let mut expected = vec![0.0f64; bw * bh];
    for by in 0..bh {
        for bx in 0..bw {
            let mut acc = 0.0f64;
            for j in 0..k {
                for i in 0..k {
                    let u = (bx as f32 + (i as f32 + 0.5) / k as f32) / bw as f32;
                    let v = (by as f32 + (j as f32 + 0.5) / k as f32) / bh as f32;
                    let d = documented_dir(u, v, 0.0);
                    acc += lights.env_pdf(d) as f64 * (PI * v).sin() as f64;
                }
            }
            let cell = (2.0 * PI as f64 / bw as f64) * (PI as f64 / bh as f64) / (k * k) as f64;
            expected[by * bw + bx] = acc * cell * n as f64;
        }
    }
    let total: f64 = expected.iter().sum();
    assert!((total / n as f64 - 1.0).abs() < 1e-3, "env_pdf integrates to {}", total / n as f64);
    // Pool bins with small expectation (the chi-square approximation needs ≥ 5 per bin).
    let (mut chi2, mut dof, mut pool_e, mut pool_o) = (0.0f64, 0usize, 0.0f64, 0.0f64);
    for (e, &o) in expected.iter().zip(&counts) {
        if *e < 5.0 {
            pool_e += e;
            pool_o += o as f64;
        } else {
            chi2 += (o as f64 - e) * (o as f64 - e) / e;
            dof += 1;
        }
    }
    if pool_e > 0.0 {
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e;
        dof += 1;
    }
    let crit = chi2_critical((dof - 1) as f64);
    eprintln!("env chi-square: {chi2:.1} over {} dof (critical {crit:.1})", dof - 1);
    assert!(chi2 < crit, "chi2 = {chi2:.1} over {} dof, critical {crit:.1}", dof - 1);
    // The sun texel sits where the documented mapping says: map column 5 shifted by the rotation.
    let sun_dir = documented_dir(5.5 / 16.0, 2.5 / 8.0, SUN_ROTATION);
    let (su, sv) = world_uv(sun_dir);
    let sun_bin = (sv * bh as f32) as usize * bw + (su * bw as f32) as usize;
    let max_bin = (0..counts.len()).max_by_key(|&i| counts[i]).unwrap();
    assert_eq!(max_bin, sun_bin);
}

#[test]
fn env_map_lookup_follows_documented_mapping() {
    let image = sun_map();
    let lights = Lights::build(&Mesh::default(), &[], Environment::Map { image: image.clone(), rotation_deg: SUN_ROTATION, scale: 2.0 });
    for (x, y) in [(5u32, 2u32), (0, 0), (15, 7), (9, 4)] {
        // At a texel centre the bilinear lookup returns the texel itself.
        let d = documented_dir((x as f32 + 0.5) / 16.0, (y as f32 + 0.5) / 8.0, SUN_ROTATION);
        let want = image.texels[(y * 16 + x) as usize] * 2.0;
        let got = lights.env_radiance(d);
        assert!((got - want).abs().max_element() <= 1e-3 * want.max_element(), "texel ({x},{y}): {got} vs {want}");
    }
    // Hand-checked: texel (2, 0) of a 4 × 2 map spans map azimuths from +Z (u = ½) to −X
    // (u = ¾) in the upper hemisphere; a +90° turn takes +Z to +X and −X to +Z, so the texel
    // centre (u = ⅝, θ = 45°) lands halfway between world +X and +Z. Unrotated, that world
    // direction would read texel (1, 0), which is black.
    let mut img = Texture { width: 4, height: 2, texels: vec![Vec3::ZERO; 8] };
    img.texels[2] = Vec3::ONE;
    let l = Lights::build(&Mesh::default(), &[], Environment::Map { image: img, rotation_deg: 90.0, scale: 1.0 });
    let horizontal = Vec3::new(1.0, 0.0, 1.0).normalize();
    let d = (horizontal + Vec3::Y).normalize();
    assert!((l.env_radiance(d) - Vec3::ONE).abs().max_element() < 1e-3, "{}", l.env_radiance(d));
    let opposite = Vec3::new(-horizontal.x, 1.0, -horizontal.z).normalize();
    assert_eq!(l.env_radiance(opposite), Vec3::ZERO);
}

#[test]
fn env_pdf_covers_every_direction_with_radiance() {
    // Bilinear lookup spreads the sun into neighbouring texels; the filtered distribution must
    // give those directions a positive density or light sampling would miss energy.
    let lights = Lights::build(&Mesh::default(), &[], Environment::Map { image: sun_map(), rotation_deg: 10.0, scale: 1.0 });
    let mut rng = Pcg32::new(5, 9);
    for _ in 0..20_000 {
        let d = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        if lights.env_radiance(d).max_element() > 0.0 {
            assert!(lights.env_pdf(d) > 0.0, "no density toward {d}");
        }
    }
}

#[test]
fn constant_env_integrals_match_closed_form() {
    let c = Vec3::new(0.5, 1.0, 2.0);
    let lights = Lights::build(&Mesh::default(), &[], Environment::Constant(c));
    let mut rng = Pcg32::new(1, 1);
    let n = 100_000;
    let (mut sphere, mut cosw) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for _ in 0..n {
        let s = lights.sample(Vec3::ZERO, rng.next_f32(), rng.next_2d()).unwrap();
        sphere.push((s.radiance.y / s.pdf) as f64);
        cosw.push((s.radiance.y * s.wi.y.max(0.0) / s.pdf) as f64);
    }
    // ∫ L dω over the sphere = 4π·c; every sample equals it, so only rounding (1e-5) is allowed.
    let (m, _) = mean_and_stderr(&sphere);
    assert!((m - 4.0 * PI as f64 * c.y as f64).abs() < 1e-5 * m);
    // Irradiance on a +Y plane = π·c; 4 standard errors (false alarm < 1e-4).
    let (m, se) = mean_and_stderr(&cosw);
    assert!((m - PI as f64 * c.y as f64).abs() < 4.0 * se, "{m} vs {} (se {se})", PI * c.y);
}

#[test]
fn env_map_integral_matches_quadrature() {
    let lights = Lights::build(&Mesh::default(), &[], Environment::Map { image: sun_map(), rotation_deg: 33.0, scale: 1.5 });
    // Reference ∫ L dω by a 2048×1024 midpoint rule over (φ, θ): the integrand is bilinear per
    // texel, so the rule's error is ~1e-5 relative, far below the MC tolerance.
    let (qw, qh) = (2048, 1024);
    let mut reference = Vec3::ZERO.as_dvec3();
    for j in 0..qh {
        let v = (j as f32 + 0.5) / qh as f32;
        for i in 0..qw {
            let u = (i as f32 + 0.5) / qw as f32;
            let d = documented_dir(u, v, 0.0);
            reference += (lights.env_radiance(d) * (PI * v).sin()).as_dvec3();
        }
    }
    reference *= (2.0 * PI as f64 / qw as f64) * (PI as f64 / qh as f64);
    let mut rng = Pcg32::new(2, 7);
    let n = 200_000;
    let mut est: [Vec<f64>; 3] = Default::default();
    for _ in 0..n {
        let s = lights.sample(Vec3::ZERO, rng.next_f32(), rng.next_2d()).unwrap();
        let f = s.radiance / s.pdf;
        for c in 0..3 {
            est[c].push(f[c] as f64);
        }
    }
    for c in 0..3 {
        let (m, se) = mean_and_stderr(&est[c]);
        eprintln!("env integral channel {c}: MC {m:.5} ± {se:.5}, quadrature {:.5}", reference[c]);
        // 4 standard errors for the MC noise plus 1e-3 relative for the quadrature and f32 sums.
        assert!((m - reference[c]).abs() < 4.0 * se + 1e-3 * reference[c], "channel {c}: {m} vs {} (se {se})", reference[c]);
    }
}

/// Irradiance at `p` (normal `n`) from a uniform polygon of radiance 1 (Lambert's formula).
fn polygon_irradiance(p: Vec3, n: Vec3, verts: &[Vec3]) -> f64 {
    let mut sum = 0.0f64;
    for i in 0..verts.len() {
        let a = (verts[i] - p).as_dvec3().normalize();
        let b = (verts[(i + 1) % verts.len()] - p).as_dvec3().normalize();
        let angle = a.dot(b).clamp(-1.0, 1.0).acos();
        sum += angle * a.cross(b).normalize().dot(n.as_dvec3());
    }
    0.5 * sum.abs()
}

#[test]
fn square_light_plus_env_irradiance_matches_lambert_formula() {
    let mut mesh = Mesh::default();
    let le = Vec3::new(2.0, 3.0, 4.0);
    let c = Vec3::splat(0.25);
    add_square(&mut mesh, -0.3, -0.2, 1.0, 1.0, 0);
    let lights = Lights::build(&mesh, &[material(le, false)], Environment::Constant(c));
    let p = Vec3::new(0.1, 0.0, 0.05);
    let n = Vec3::Y;
    let verts = [Vec3::new(-0.3, 1.0, -0.2), Vec3::new(0.7, 1.0, -0.2), Vec3::new(0.7, 1.0, 0.8), Vec3::new(-0.3, 1.0, 0.8)];
    // Lights are sampled without visibility, so the estimator's mean is the sum of both
    // unoccluded integrals: the square's irradiance plus π·c from the upper hemisphere.
    let want = le.y as f64 * polygon_irradiance(p, n, &verts) + PI as f64 * c.y as f64;
    let mut rng = Pcg32::new(3, 4);
    let samples: Vec<f64> = (0..200_000)
        .map(|_| match lights.sample(p, rng.next_f32(), rng.next_2d()) {
            Some(s) => (s.radiance.y * s.wi.dot(n).max(0.0) / s.pdf) as f64,
            None => 0.0,
        })
        .collect();
    let (m, se) = mean_and_stderr(&samples);
    eprintln!("square + env irradiance: MC {m:.5} ± {se:.5}, Lambert formula {want:.5}");
    // 4 standard errors: a correct estimator fails with probability < 1e-4.
    assert!((m - want).abs() < 4.0 * se, "{m} vs {want} (se {se})");
    assert!(se < 0.01 * want, "estimator too noisy to mean anything: se {se}");
}

#[test]
fn pdf_triangle_and_env_pdf_equal_sample_pdf() {
    let mut mesh = Mesh::default();
    add_square(&mut mesh, -1.0, -1.0, 2.0, 1.5, 0);
    add_square(&mut mesh, 0.8, 0.2, 1.0, 0.4, 1);
    let mats = [material(Vec3::splat(5.0), false), material(Vec3::new(1.0, 8.0, 2.0), true)];
    let lights = Lights::build(&mesh, &mats, Environment::Map { image: sun_map(), rotation_deg: -40.0, scale: 1.0 });
    let mut rng = Pcg32::new(8, 8);
    let (mut tri, mut env) = (0, 0);
    for k in 0..20_000 {
        let p = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() * 0.5, rng.next_f32() - 0.5) * 2.0;
        let Some(s) = lights.sample(p, rng.next_f32(), rng.next_2d()) else { continue };
        assert!(s.pdf > 0.0 && s.pdf.is_finite() && s.radiance.is_finite(), "sample {k}: {s:?}");
        match s.prim {
            Some(prim) => {
                tri += 1;
                let ng = mesh.geometric_normal(prim as usize);
                let q = lights.pdf_triangle(prim, p, p + s.wi * s.dist, ng);
                // p + wi·dist rebuilds the light point to ~1e-6 relative; 1e-4 still catches any
                // missing factor (selection, area, cosine, distance²).
                assert!((q - s.pdf).abs() <= 1e-4 * s.pdf, "sample {k}: pdf_triangle {q} vs {}", s.pdf);
                assert_eq!(s.radiance, mats[mesh.material[prim as usize] as usize].emitted(ng, -s.wi));
            }
            None => {
                env += 1;
                assert_eq!(s.pdf, lights.env_pdf(s.wi));
            }
        }
    }
    assert!(tri > 1000 && env > 1000, "both kinds must be exercised: {tri} / {env}");
    // Non-light triangles have no light density.
    let mut m2 = mesh.clone();
    add_square(&mut m2, 5.0, 5.0, 0.0, 1.0, 2);
    let mut mats2 = mats.to_vec();
    mats2.push(material(Vec3::ZERO, false));
    let l2 = Lights::build(&m2, &mats2, Environment::Constant(Vec3::ZERO));
    assert_eq!(l2.pdf_triangle(4, Vec3::ZERO, Vec3::new(5.5, 0.0, 5.5), Vec3::NEG_Y), 0.0);
}

/// Fraction of `n` samples from `p` whose light satisfies `pred`.
fn frequency(lights: &Lights, p: Vec3, n: usize, pred: impl Fn(&LightSample) -> bool) -> f64 {
    let mut rng = Pcg32::new(21, 2);
    let mut hits = 0usize;
    for _ in 0..n {
        let s = lights.sample(p, rng.next_f32(), rng.next_2d()).expect("a sample facing the lights");
        hits += pred(&s) as usize;
    }
    hits as f64 / n as f64
}

/// 4 binomial standard deviations of a frequency with probability `q` over `n` trials.
fn binomial_4sigma(q: f64, n: usize) -> f64 {
    4.0 * (q * (1.0 - q) / n as f64).sqrt()
}

#[test]
fn selection_is_proportional_to_power() {
    // Two unit-area squares, emission 1 and 3 (grey): selection 1/4 and 3/4.
    let mut mesh = Mesh::default();
    add_square(&mut mesh, -2.0, 0.0, 1.0, 1.0, 0);
    add_square(&mut mesh, 1.0, 0.0, 1.0, 1.0, 1);
    let mats = [material(Vec3::ONE, false), material(Vec3::splat(3.0), false)];
    let lights = Lights::build(&mesh, &mats, Environment::Constant(Vec3::ZERO));
    let n = 40_000;
    let f = frequency(&lights, Vec3::ZERO, n, |s| s.prim.unwrap() >= 2);
    assert!((f - 0.75).abs() < binomial_4sigma(0.75, n), "bright light picked {f}");

    // Environment against a square of equal estimated power: the square (area 1, emission 2π)
    // has 2π²; the mesh bounds' half diagonal is √2/2, so a unit env has 4π·π·½ = 2π².
    let mut m1 = Mesh::default();
    add_square(&mut m1, 0.0, 0.0, 0.0, 1.0, 0);
    let l1 = Lights::build(&m1, &[material(Vec3::splat(2.0 * PI), false)], Environment::Constant(Vec3::ONE));
    let f = frequency(&l1, Vec3::new(0.5, -1.0, 0.5), n, |s| s.prim.is_none());
    assert!((f - 0.5).abs() < binomial_4sigma(0.5, n), "env picked {f}");
}

#[test]
fn dim_and_bright_kinds_keep_a_floor_share() {
    let mut mesh = Mesh::default();
    add_square(&mut mesh, 0.0, 0.0, 1.0, 1.0, 0);
    let p = Vec3::new(0.5, 0.0, 0.5);
    let n = 40_000;
    let q = MIN_KIND_SHARE as f64;
    // A nearly black sky next to a bright lamp, then a blinding sky next to a dim lamp.
    let dim_env = Lights::build(&mesh, &[material(Vec3::splat(100.0), false)], Environment::Constant(Vec3::splat(1e-9)));
    let f = frequency(&dim_env, p, n, |s| s.prim.is_none());
    assert!((f - q).abs() < binomial_4sigma(q, n), "dim env picked {f}");
    let bright_env = Lights::build(&mesh, &[material(Vec3::splat(1e-6), false)], Environment::Constant(Vec3::splat(1e5)));
    let f = frequency(&bright_env, p, n, |s| s.prim.is_some());
    assert!((f - q).abs() < binomial_4sigma(q, n), "dim lamp picked {f}");
}

#[test]
fn zero_area_lights_are_never_sampled() {
    let degenerate = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
    let mut mesh = Mesh::default();
    mesh.append(&degenerate, &[], &[], &[[0, 1, 2]], 0);
    let mats = [material(Vec3::ONE, true)];
    let lights = Lights::build(&mesh, &mats, Environment::Constant(Vec3::ZERO));
    assert!(lights.is_empty());
    assert!(lights.sample(Vec3::Y, 0.3, Vec2::splat(0.5)).is_none());
    assert_eq!(lights.pdf_triangle(0, Vec3::Y, Vec3::X, Vec3::Y), 0.0);

    add_square(&mut mesh, 0.0, 0.0, 1.0, 1.0, 0);
    let lights = Lights::build(&mesh, &mats, Environment::Constant(Vec3::ZERO));
    assert!(!lights.is_empty());
    let mut rng = Pcg32::new(4, 4);
    for _ in 0..10_000 {
        let s = lights.sample(Vec3::new(0.5, 0.0, 0.5), rng.next_f32(), rng.next_2d()).unwrap();
        assert_ne!(s.prim, Some(0));
    }
}

#[test]
fn huge_emission_stays_finite() {
    let mut mesh = Mesh::default();
    add_square(&mut mesh, 0.0, 0.0, 1.0, 1e-3, 0);
    let lights = Lights::build(&mesh, &[material(Vec3::splat(1e6), false)], Environment::Constant(Vec3::ONE));
    let mut rng = Pcg32::new(6, 1);
    let mut seen = 0;
    for _ in 0..10_000 {
        let p = Vec3::new(rng.next_f32(), -rng.next_f32(), rng.next_f32()) * 1e3;
        if let Some(s) = lights.sample(p, rng.next_f32(), rng.next_2d()) {
            let ratio = s.radiance / s.pdf;
            assert!(s.pdf > 0.0 && s.pdf.is_finite() && ratio.is_finite() && s.wi.is_finite(), "{s:?}");
            seen += s.prim.is_some() as usize;
        }
    }
    assert!(seen > 1000);
}

#[test]
fn grazing_and_coincident_points_give_none_or_finite() {
    let mut mesh = Mesh::default();
    add_square(&mut mesh, 0.0, 0.0, 1.0, 1.0, 0);
    for two_sided in [false, true] {
        let lights = Lights::build(&mesh, &[material(Vec3::ONE, two_sided)], Environment::Constant(Vec3::ZERO));
        let mut rng = Pcg32::new(7, two_sided as u64);
        // Points in the light's plane: inside the square, on an edge, at a corner, outside.
        for p in [Vec3::new(0.5, 1.0, 0.5), Vec3::new(1.0, 1.0, 0.3), Vec3::new(0.0, 1.0, 0.0), Vec3::new(3.0, 1.0, 0.5)] {
            for _ in 0..2000 {
                if let Some(s) = lights.sample(p, rng.next_f32(), rng.next_2d()) {
                    assert!(s.pdf > 0.0 && s.pdf.is_finite() && (s.radiance / s.pdf).is_finite(), "{s:?}");
                }
            }
            let q = lights.pdf_triangle(0, p, Vec3::new(0.7, 1.0, 0.2), Vec3::NEG_Y);
            assert!(q.is_finite() && q >= 0.0);
        }
        // The shading point on the light point itself.
        let q = lights.pdf_triangle(0, Vec3::new(0.7, 1.0, 0.2), Vec3::new(0.7, 1.0, 0.2), Vec3::NEG_Y);
        assert_eq!(q, 0.0);
        // Above the light, i.e. behind its emitting side (it faces −Y).
        let above = Vec3::new(0.5, 2.0, 0.5);
        let s = lights.sample(above, 0.5, Vec2::new(0.3, 0.6));
        assert_eq!(s.is_some(), two_sided);
        let q = lights.pdf_triangle(0, above, Vec3::new(0.7, 1.0, 0.2), Vec3::NEG_Y);
        assert_eq!(q > 0.0, two_sided);
    }
}

#[test]
fn black_and_broken_environments_are_not_selectable() {
    let black = Lights::build(&Mesh::default(), &[], Environment::Constant(Vec3::ZERO));
    assert!(black.is_empty());
    assert!(black.sample(Vec3::ZERO, 0.5, Vec2::splat(0.5)).is_none());
    assert_eq!(black.env_pdf(Vec3::Y), 0.0);
    assert_eq!(black.env_radiance(Vec3::Y), Vec3::ZERO);

    // With a lamp present, a black env must never take a sample away from it.
    let mut mesh = Mesh::default();
    add_square(&mut mesh, 0.0, 0.0, 1.0, 1.0, 0);
    let l = Lights::build(&mesh, &[material(Vec3::ONE, false)], Environment::Constant(Vec3::ZERO));
    assert_eq!(frequency(&l, Vec3::new(0.5, 0.0, 0.5), 5000, |s| s.prim.is_none()), 0.0);
    assert_eq!(l.env_pdf(Vec3::NEG_Y), 0.0);

    // NaN, infinite and negative texels count as black; nothing non-finite comes out.
    let mut img = sun_map();
    img.texels[0] = Vec3::NAN;
    img.texels[1] = Vec3::splat(f32::INFINITY);
    img.texels[2] = Vec3::splat(-5.0);
    img.texels[17] = Vec3::new(f32::MAX, f32::MAX, f32::MAX);
    let l = Lights::build(&Mesh::default(), &[], Environment::Map { image: img, rotation_deg: f32::NAN, scale: 4.0 });
    let mut rng = Pcg32::new(9, 9);
    for _ in 0..20_000 {
        let d = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        assert!(l.env_radiance(d).is_finite() && l.env_pdf(d).is_finite());
        if let Some(s) = l.sample(Vec3::ZERO, rng.next_f32(), rng.next_2d()) {
            assert!(s.pdf > 0.0 && s.pdf.is_finite() && s.radiance.is_finite());
        }
    }
    assert!(l.env_radiance(Vec3::ZERO).is_finite() && l.env_pdf(Vec3::NAN) == 0.0);

    // Maps that carry no light at all.
    let all_nan = Texture { width: 4, height: 2, texels: vec![Vec3::NAN; 8] };
    let wrong_size = Texture { width: 4, height: 2, texels: vec![Vec3::ONE; 3] };
    let empty = Texture { width: 0, height: 0, texels: vec![] };
    for (image, scale) in [(all_nan, 1.0), (wrong_size, 1.0), (empty, 1.0), (sun_map(), -1.0), (sun_map(), f32::NAN)] {
        let l = Lights::build(&Mesh::default(), &[], Environment::Map { image, rotation_deg: 0.0, scale });
        assert!(l.is_empty());
        assert_eq!(l.env_radiance(Vec3::Y), Vec3::ZERO);
    }
}

#[test]
fn non_finite_random_numbers_never_leak() {
    let mut mesh = Mesh::default();
    add_square(&mut mesh, 0.0, 0.0, 1.0, 1.0, 0);
    let mats = [material(Vec3::ONE, false)];
    for env in [Environment::Constant(Vec3::ONE), Environment::Map { image: sun_map(), rotation_deg: 5.0, scale: 1.0 }] {
        let lights = Lights::build(&mesh, &mats, env);
        for us in [f32::NAN, -1.0, 1.0, 2.0, f32::INFINITY] {
            for u in [Vec2::splat(f32::NAN), Vec2::splat(-0.5), Vec2::ONE, Vec2::new(f32::INFINITY, 0.5)] {
                if let Some(s) = lights.sample(Vec3::new(0.5, 0.0, 0.5), us, u) {
                    assert!(s.wi.is_finite() && s.radiance.is_finite() && s.pdf.is_finite() && s.pdf > 0.0, "{us} {u}: {s:?}");
                }
            }
        }
    }
}
