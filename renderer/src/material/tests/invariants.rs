//! Properties every BSDF keeps: `sample`'s weight and pdf agree with `eval` and `pdf`,
//! degenerate inputs give finite answers, sampled lobes carry the right bitmasks, and the
//! Fresnel terms match their reference values.

use super::*;
use crate::rng::Pcg32;

// ---------------------------------------------------------------------------------------------
// Consistency of sample() with eval() and pdf().

fn all_configs() -> Vec<Config> {
    CHI2_GROUPS.iter().flat_map(|g| chi2_configs(g)).collect()
}

#[test]
fn sample_weight_matches_eval_over_pdf() {
    // 1e-3 relative: everything is f32; eval/pdf recompute the half vector from wi, which moves
    // it by a few ulps, and D varies on the scale of alpha ≥ 2e-3, so ~1e-4 is typical.
    let mut checked = 0;
    for cfg in all_configs() {
        // Near index matching the transmission half vector wi·η' + wo has length ~|η−1|, so its
        // f32 rounding (~6e-8/|η−1| rad) is magnified by D's relative slope ~4/α: the error is
        // ~2.4e-7/(|η−1|·α) (2.4e-3 at η = 1.05, α = 0.002); allow twice that on top of 1e-3.
        let tol = match cfg.bsdf {
            Bsdf::Dielectric { eta, alpha, .. } => 1e-3f32 + 5e-7 / ((eta - 1.0).abs() * alpha),
            _ => 1e-3,
        };
        let mut rng = Pcg32::new(77, 3);
        for _ in 0..2000 {
            let Some(s) = cfg.bsdf.sample(cfg.wo, rng.next_f32(), rng.next_2d()) else { continue };
            if is_delta_sample(&s) {
                continue;
            }
            let e = cfg.bsdf.eval(cfg.wo, s.wi);
            let p = cfg.bsdf.pdf(cfg.wo, s.wi);
            let close = |a: f32, b: f32| (a - b).abs() <= tol * a.abs().max(b.abs()) + 1e-6;
            assert!(close(p, s.pdf), "{}: pdf() {p} vs sample pdf {} at wi {:?}", cfg.name, s.pdf, s.wi);
            for c in 0..3 {
                assert!(close(s.weight[c], e[c] / p), "{}: weight {:?} vs eval/pdf {:?} at wi {:?}", cfg.name, s.weight, e / p, s.wi);
                assert!(close(s.f_cos[c], e[c]), "{}: f_cos {:?} vs eval {:?}", cfg.name, s.f_cos, e);
            }
            checked += 1;
        }
    }
    assert!(checked > 100_000, "too few non-delta samples checked: {checked}");
}

// ---------------------------------------------------------------------------------------------
// Degenerate inputs.

#[test]
fn hard_cases_stay_finite() {
    let mut bsdfs = vec![Bsdf::Lambert { albedo: Vec3::ZERO }, Bsdf::Lambert { albedo: Vec3::ONE }];
    for alpha in [0.0, 1e-4, MIN_ALPHA, 0.5, 1.0] {
        bsdfs.push(conductor(alpha));
        bsdfs.push(Bsdf::Conductor { eta: Vec3::ONE, k: Vec3::ZERO, alpha, specular_tint: Vec3::ZERO, dist: Default::default() });
        for eta in [1.0, 1.00005, 1.0002, 1.5, 0.6] {
            bsdfs.push(Bsdf::Dielectric { eta, alpha, tint: Vec3::ONE, dist: Default::default() });
        }
        for eta in [1.0, 1.5] {
            bsdfs.push(Bsdf::Plastic { albedo: Vec3::ZERO, eta, alpha, dist: Default::default(), nonlinear: true });
            bsdfs.push(Bsdf::Plastic { albedo: Vec3::ONE, eta, alpha, dist: Default::default(), nonlinear: true });
        }
    }
    let wos = [
        Vec3::Z,
        -Vec3::Z,
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        Vec3::new(0.0, 1.0, -1e-7).normalize(),
        Vec3::new(1.0, 0.0, 0.0),
        wo_at(0.5),
        wo_at(-0.5),
    ];
    let us = [0.0, 0.5, 0.999_999_9];
    let mut rng = Pcg32::new(9, 9);
    for bsdf in &bsdfs {
        let a = bsdf.albedo();
        assert!(a.is_finite() && a.min_element() >= 0.0 && a.max_element() <= 1.0, "{bsdf:?}: albedo {a}");
        for &wo in &wos {
            let mut draws: Vec<(f32, Vec2)> = Vec::new();
            for &x in &us {
                for &y in &us {
                    for &z in &us {
                        draws.push((x, Vec2::new(y, z)));
                    }
                }
            }
            draws.extend((0..200).map(|_| (rng.next_f32(), rng.next_2d())));
            for (ul, u) in draws {
                if let Some(s) = bsdf.sample(wo, ul, u) {
                    assert!(s.pdf > 0.0 && s.pdf.is_finite(), "{bsdf:?} wo={wo}: pdf {}", s.pdf);
                    assert!(s.weight.is_finite() && s.weight.min_element() >= 0.0, "{bsdf:?} wo={wo}: weight {}", s.weight);
                    assert!(s.f_cos.is_finite() && s.f_cos.min_element() >= 0.0, "{bsdf:?} wo={wo}: f_cos {}", s.f_cos);
                    assert!((s.wi.length() - 1.0).abs() < 1e-3, "{bsdf:?} wo={wo}: |wi| = {}", s.wi.length());
                    assert!(s.eta.is_finite() && s.eta > 0.0);
                    let e = bsdf.eval(wo, s.wi);
                    assert!(e.is_finite() && bsdf.pdf(wo, s.wi).is_finite());
                }
                let wi = crate::sampling::square_to_uniform_sphere(u);
                for w in [wi, Vec3::Z, -Vec3::Z, wo, -wo, Vec3::new(-wo.x, -wo.y, wo.z)] {
                    let sp = bsdf.eval_split(wo, w);
                    let p = bsdf.pdf(wo, w);
                    assert!(sp.diffuse.is_finite() && sp.other.is_finite() && sp.total().min_element() >= 0.0, "{bsdf:?}: eval {sp:?}");
                    assert!(p.is_finite() && p >= 0.0, "{bsdf:?}: pdf {p}");
                }
            }
        }
    }
    // Reflection-only BSDFs give nothing below the surface.
    for bsdf in bsdfs.iter().filter(|b| !b.is_transmissive()) {
        assert!(bsdf.sample(wo_at(-0.5), 0.3, Vec2::splat(0.3)).is_none());
        assert_eq!(bsdf.eval(wo_at(0.5), wo_at(-0.5)), Vec3::ZERO);
        assert_eq!(bsdf.pdf(wo_at(0.5), wo_at(-0.5)), 0.0);
    }
    // IOR 1 passes straight through with the tint as weight.
    let clear = Bsdf::Dielectric { eta: 1.0, alpha: 0.4, tint: Vec3::new(0.9, 0.8, 0.7), dist: Default::default() };
    let s = clear.sample(wo_at(0.3), 0.5, Vec2::splat(0.5)).unwrap();
    assert_eq!(s.wi, -wo_at(0.3));
    assert_eq!(s.weight, Vec3::new(0.9, 0.8, 0.7));
    assert!(clear.is_delta());
}

// ---------------------------------------------------------------------------------------------
// Lobe bitmasks (method.md §1.1).

#[test]
fn lobe_bitmasks_match_method() {
    let cases: Vec<(Bsdf, Vec3, Vec<u32>)> = vec![
        (Bsdf::Lambert { albedo: Vec3::ONE }, wo_at(0.5), vec![5]),
        (conductor(0.0), wo_at(0.5), vec![17]),
        (conductor(0.2), wo_at(0.5), vec![9]),
        (Bsdf::Dielectric { eta: 1.5, alpha: 0.0, tint: Vec3::ONE, dist: Default::default() }, wo_at(0.5), vec![17, 18]),
        (Bsdf::Dielectric { eta: 1.5, alpha: 0.2, tint: Vec3::ONE, dist: Default::default() }, wo_at(-0.5), vec![9, 10]),
        (Bsdf::Dielectric { eta: 1.0, alpha: 0.2, tint: Vec3::ONE, dist: Default::default() }, wo_at(0.5), vec![18]),
        (
            Bsdf::Plastic { albedo: Vec3::splat(0.5), eta: 1.5, alpha: 0.0, dist: Default::default(), nonlinear: true },
            wo_at(0.2),
            vec![5, 17],
        ),
        (
            Bsdf::Plastic { albedo: Vec3::splat(0.5), eta: 1.5, alpha: 0.2, dist: Default::default(), nonlinear: true },
            wo_at(0.2),
            vec![5, 9],
        ),
    ];
    let mut rng = Pcg32::new(1, 2);
    for (bsdf, wo, expect) in cases {
        let mut seen: Vec<u32> = Vec::new();
        for _ in 0..5000 {
            if let Some(s) = bsdf.sample(wo, rng.next_f32(), rng.next_2d()) {
                let roughness_ok = match s.lobe.kind {
                    LobeKind::Diffuse => s.lobe.roughness == 1.0,
                    LobeKind::Specular => s.lobe.roughness == 0.0,
                    LobeKind::Glossy => s.lobe.roughness == bsdf.roughness(),
                };
                assert!(roughness_ok, "{bsdf:?}: lobe {:?}", s.lobe);
                assert_eq!(s.lobe.transmission, s.wi.z * wo.z < 0.0, "{bsdf:?}: lobe {:?} wi {}", s.lobe, s.wi);
                if !seen.contains(&s.lobe.bitmask()) {
                    seen.push(s.lobe.bitmask());
                }
            }
        }
        seen.sort();
        assert_eq!(seen, expect, "{bsdf:?}");
    }
    assert_eq!(Lobe { kind: LobeKind::Specular, transmission: true, roughness: 0.0 }.bitmask(), 18);
}

// ---------------------------------------------------------------------------------------------
// Fresnel cross-checks.

#[test]
fn fresnel_reference_values() {
    // Normal incidence ((η−1)/(η+1))², TIR beyond the critical angle from inside.
    assert!((fresnel::dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
    assert!((fresnel::dielectric(-1.0, 1.5) - 0.04).abs() < 1e-6);
    assert_eq!(fresnel::dielectric(-0.5, 1.5), 1.0);
    // A conductor with k = 0 is a dielectric; at normal incidence the closed form holds.
    for c in [0.01f32, 0.2, 0.5, 0.9, 1.0] {
        let fc = fresnel::conductor(c, Vec3::splat(1.7), Vec3::ZERO).x;
        assert!((fc - fresnel::dielectric(c, 1.7)).abs() < 1e-5, "cos {c}: {fc}");
    }
    let f0 = fresnel::conductor(1.0, GOLD_ETA, GOLD_K);
    let expect = ((GOLD_ETA - 1.0).powf(2.0) + GOLD_K * GOLD_K) / ((GOLD_ETA + 1.0).powf(2.0) + GOLD_K * GOLD_K);
    assert!((f0 - expect).abs().max_element() < 1e-5, "{f0} vs {expect}");
    assert!((conductor(0.3).albedo() - expect).abs().max_element() < 1e-5);
}
