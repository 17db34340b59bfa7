//! BSDF tests: chi-square goodness of fit of `sample` against `pdf`, sample/eval/pdf consistency,
//! energy bounds, degenerate inputs and lobe bitmasks.

use super::*;
use crate::rng::Pcg32;
use crate::stats::{chi2_p_value, sidak};
use std::f64::consts::PI as PI64;

// ---------------------------------------------------------------------------------------------
// Test configurations.

const GOLD_ETA: Vec3 = Vec3::new(0.143, 0.374, 1.442);
const GOLD_K: Vec3 = Vec3::new(3.983, 2.385, 1.603);

/// wo with cos θ = `c` (negative: inside/below), at an azimuth away from any cell boundary.
fn wo_at(c: f32) -> Vec3 {
    let s = (1.0 - c * c).max(0.0).sqrt();
    let phi = 0.7f32;
    Vec3::new(s * phi.cos(), s * phi.sin(), c)
}

/// Incidence cosines: near grazing, intermediate, near normal.
const WO_COS: [f32; 3] = [0.05, 0.5, 0.93];

struct Config {
    name: String,
    bsdf: Bsdf,
    wo: Vec3,
}

fn conductor(alpha: f32) -> Bsdf {
    Bsdf::Conductor { eta: GOLD_ETA, k: GOLD_K, alpha, specular_tint: Vec3::ONE, dist: Default::default() }
}

fn chi2_configs(group: &str) -> Vec<Config> {
    let mut v = Vec::new();
    let mut push = |name: String, bsdf: Bsdf, signs: &[f32]| {
        for &c in &WO_COS {
            for &s in signs {
                v.push(Config { name: format!("{name} cos_o={}", c * s), bsdf, wo: wo_at(c * s) });
            }
        }
    };
    match group {
        "lambert" => push("lambert".into(), Bsdf::Lambert { albedo: Vec3::new(0.8, 0.5, 0.2) }, &[1.0]),
        "conductor" => {
            for alpha in [0.002, 0.05, 0.3, 1.0] {
                push(format!("conductor a={alpha}"), conductor(alpha), &[1.0]);
            }
            for alpha in [0.05, 0.3, 1.0] {
                let bsdf = Bsdf::Conductor { eta: GOLD_ETA, k: GOLD_K, alpha, specular_tint: Vec3::ONE, dist: Distribution::Beckmann };
                push(format!("beckmann conductor a={alpha}"), bsdf, &[1.0]);
            }
        }
        "dielectric_out" | "dielectric_in" => {
            let sign = if group == "dielectric_out" { 1.0 } else { -1.0 };
            for alpha in [0.002, 0.1, 0.5, 1.0] {
                // 1.05 stands for "nearly index-matched": at 1.01 the transmitted lobe is so
                // narrow that integrating the pdf over the cells alone takes minutes.
                for eta in [1.05, 1.33, 1.5, 2.4] {
                    let bsdf = Bsdf::Dielectric { eta, alpha, tint: Vec3::new(1.0, 0.9, 0.8), dist: Default::default() };
                    push(format!("dielectric a={alpha} eta={eta}"), bsdf, &[sign]);
                }
            }
        }
        "plastic" => {
            for alpha in [0.0, 0.1, 0.6, 1.0] {
                let bsdf = Bsdf::Plastic { albedo: Vec3::new(0.7, 0.4, 0.1), eta: 1.5, alpha, dist: Default::default(), nonlinear: true };
                push(format!("plastic a={alpha}"), bsdf, &[1.0]);
            }
        }
        _ => unreachable!(),
    }
    v
}

const CHI2_GROUPS: [&str; 5] = ["lambert", "conductor", "dielectric_out", "dielectric_in", "plastic"];

/// Every chi-square configuration run by the tests below, for the Šidák correction.
fn chi2_total_configs() -> usize {
    CHI2_GROUPS.iter().map(|g| chi2_configs(g).len()).sum()
}

fn is_delta_sample(s: &BsdfSample) -> bool {
    s.lobe.kind == LobeKind::Specular
}

// ---------------------------------------------------------------------------------------------
// Chi-square test.

const THETA_RES: usize = 10;
const PHI_RES: usize = 20;
const CHI2_SAMPLES: usize = 200_000;

fn dir64(c: f64, phi: f64) -> Vec3 {
    let s = (1.0 - c * c).max(0.0).sqrt();
    Vec3::new((s * phi.cos()) as f32, (s * phi.sin()) as f32, c as f32)
}

fn phi_of(w: Vec3) -> f64 {
    let p = (w.y as f64).atan2(w.x as f64);
    if p < 0.0 {
        p + 2.0 * PI64
    } else {
        p
    }
}

#[allow(clippy::too_many_arguments)]
fn simpson_rec(f: &mut dyn FnMut(f64) -> f64, a: f64, b: f64, fa: f64, fm: f64, fb: f64, whole: f64, eps: f64, rel: f64, depth: u32) -> f64 {
    let m = 0.5 * (a + b);
    let (lm, rm) = (0.5 * (a + m), 0.5 * (m + b));
    let (flm, frm) = (f(lm), f(rm));
    let left = (m - a) / 6.0 * (fa + 4.0 * flm + fm);
    let right = (b - m) / 6.0 * (fm + 4.0 * frm + fb);
    let delta = left + right - whole;
    // The relative criterion stops refinement at f32 noise level of the pdf (~1e-7 relative),
    // which an absolute tolerance alone would chase down to the depth limit everywhere.
    if depth == 0 || delta.abs() <= 15.0 * eps || delta.abs() <= rel * (left + right).abs() {
        return left + right + delta / 15.0;
    }
    simpson_rec(f, a, m, fa, flm, fm, left, 0.5 * eps, rel, depth - 1) + simpson_rec(f, m, b, fm, frm, fb, right, 0.5 * eps, rel, depth - 1)
}

/// Adaptive Simpson over [a, b], split first at `breaks` (the lobe peaks: a peak a few 1e-3 wide
/// can fall between the initial nodes, but never goes unseen when it sits on a panel end) and
/// then into 4 panels per piece.
fn integrate(f: &mut dyn FnMut(f64) -> f64, a: f64, b: f64, breaks: &[f64], eps: f64, rel: f64) -> f64 {
    let mut pts = vec![a, b];
    pts.extend(breaks.iter().copied().filter(|&x| x > a && x < b));
    pts.sort_by(|x, y| x.partial_cmp(y).unwrap());
    let mut nodes = Vec::new();
    for w in pts.windows(2) {
        for k in 0..4 {
            nodes.push(w[0] + (w[1] - w[0]) * k as f64 / 4.0);
        }
    }
    nodes.push(b);
    let panels = (nodes.len() - 1) as f64;
    let mut sum = 0.0;
    for w in nodes.windows(2) {
        let (x0, x1) = (w[0], w[1]);
        if x1 <= x0 {
            continue;
        }
        let (f0, fm, f1) = (f(x0), f(0.5 * (x0 + x1)), f(x1));
        let whole = (x1 - x0) / 6.0 * (f0 + 4.0 * fm + f1);
        // Depth 16 resolves 1/(4·2^16) of a panel (~1e-6 rad), far below the narrowest lobe.
        sum += simpson_rec(f, x0, x1, f0, fm, f1, whole, eps / panels, rel, 16);
    }
    sum
}

/// Directions where a lobe may peak sharply: mirror reflection, refraction (both ways), -wo.
fn peak_directions(wo: Vec3, bsdf: &Bsdf) -> Vec<Vec3> {
    let mut v = vec![Vec3::new(-wo.x, -wo.y, wo.z), -wo];
    if let Bsdf::Dielectric { eta, .. } = *bsdf {
        if let Some((t, _)) = fresnel::refract(wo, Vec3::Z, eta) {
            v.push(t);
        }
    }
    v
}

/// Expected cell probabilities: ∫∫ pdf dcosθ dφ over each cell.
fn integrate_pdf(bsdf: &Bsdf, wo: Vec3) -> Vec<f64> {
    let peaks = peak_directions(wo, bsdf);
    let cos_breaks: Vec<f64> = peaks.iter().map(|p| p.z as f64).collect();
    let phi_breaks: Vec<f64> = peaks.iter().map(|&p| phi_of(p)).collect();
    let mut out = vec![0.0; THETA_RES * PHI_RES];
    for i in 0..THETA_RES {
        let c0 = -1.0 + 2.0 * i as f64 / THETA_RES as f64;
        let c1 = -1.0 + 2.0 * (i + 1) as f64 / THETA_RES as f64;
        for j in 0..PHI_RES {
            let p0 = 2.0 * PI64 * j as f64 / PHI_RES as f64;
            let p1 = 2.0 * PI64 * (j + 1) as f64 / PHI_RES as f64;
            // Absolute errors: 1e-7 per cell is 0.02 expected counts at 2e5 samples; the inner
            // tolerance is tighter so the outer rule does not chase the inner one's noise.
            let mut outer = |c: f64| {
                let mut inner = |phi: f64| bsdf.pdf(wo, dir64(c, phi)) as f64;
                integrate(&mut inner, p0, p1, &phi_breaks, 1e-9, 1e-4)
            };
            // Relative 1e-4 (inner) / 1e-5 (outer) keep a 1e5-count cell within ~10 counts of exact,
            // well inside its Poisson spread of ~300.
            out[i * PHI_RES + j] = integrate(&mut outer, c0, c1, &cos_breaks, 1e-7, 1e-5);
        }
    }
    out
}

/// Runs the chi-square test for one configuration; returns (p-value, description).
fn chi2_run(cfg: &Config, seed: u64) -> (f64, String) {
    let mut rng = Pcg32::new(seed, 0x5eed);
    let mut observed = vec![0.0f64; THETA_RES * PHI_RES + 1];
    let other = THETA_RES * PHI_RES;
    for _ in 0..CHI2_SAMPLES {
        let u_lobe = rng.next_f32();
        let u = rng.next_2d();
        match cfg.bsdf.sample(cfg.wo, u_lobe, u) {
            Some(s) if !is_delta_sample(&s) => {
                let c = ((s.wi.z as f64).clamp(-1.0, 1.0) + 1.0) * 0.5;
                let i = ((c * THETA_RES as f64) as usize).min(THETA_RES - 1);
                let j = ((phi_of(s.wi) / (2.0 * PI64) * PHI_RES as f64) as usize).min(PHI_RES - 1);
                observed[i * PHI_RES + j] += 1.0;
            }
            _ => observed[other] += 1.0,
        }
    }
    let n = CHI2_SAMPLES as f64;
    let mut expected: Vec<f64> = integrate_pdf(&cfg.bsdf, cfg.wo).into_iter().map(|p| p * n).collect();
    // Delta lobes and rejected samples share one extra cell whose expectation is the pdf mass
    // missing from the sphere, so a wrong delta probability or lost samples are caught too.
    let total: f64 = expected.iter().sum();
    expected.push((n - total).max(0.0));

    // Pool cells with expected count < 5 (the chi-square approximation needs ≥ 5 per cell).
    let mut order: Vec<usize> = (0..expected.len()).collect();
    order.sort_by(|&a, &b| expected[a].partial_cmp(&expected[b]).unwrap());
    let (mut stat, mut dof, mut pool_e, mut pool_o) = (0.0, 0usize, 0.0, 0.0);
    let mut worst = (0.0, 0usize);
    for &k in &order {
        if expected[k] < 5.0 {
            pool_e += expected[k];
            pool_o += observed[k];
        } else {
            let d = (observed[k] - expected[k]).powi(2) / expected[k];
            if d > worst.0 {
                worst = (d, k);
            }
            stat += d;
            dof += 1;
        }
    }
    if pool_o > 0.0 || pool_e > 0.0 {
        // A sample where the integrated pdf is ~0 is an outright failure (pdf too small there).
        stat += (pool_o - pool_e).powi(2) / pool_e.max(1e-3);
        dof += 1;
    }
    let p = if dof > 1 { chi2_p_value(stat, dof - 1) } else { 1.0 };
    let k = worst.1;
    let desc = format!(
        "{}: chi2 = {stat:.1}, dof = {}, p = {p:.3e}; pooled obs/exp {pool_o}/{pool_e:.2}; worst cell {k} obs {} exp {:.1}",
        cfg.name,
        dof.saturating_sub(1),
        observed[k],
        expected[k]
    );
    (p, desc)
}

fn chi2_group(group: &str) {
    // Šidák: per-configuration level so the whole family of tests rejects a correct sampler
    // with probability 0.01.
    let alpha = sidak(0.01, chi2_total_configs());
    let mut failures = Vec::new();
    for (idx, cfg) in chi2_configs(group).iter().enumerate() {
        let t0 = std::time::Instant::now();
        let (p, desc) = chi2_run(cfg, 1000 + idx as u64);
        // CHI2_VERBOSE=1 with --nocapture prints every configuration's statistic and timing.
        if std::env::var_os("CHI2_VERBOSE").is_some() {
            eprintln!("{desc} [{:.2}s]", t0.elapsed().as_secs_f64());
        }
        if p < alpha {
            failures.push(desc);
        }
    }
    assert!(failures.is_empty(), "chi-square rejections at per-test level {alpha:.2e}:\n{}", failures.join("\n"));
}

#[test]
fn chi2_lambert() {
    chi2_group("lambert");
}

#[test]
fn chi2_conductor() {
    chi2_group("conductor");
}

#[test]
fn chi2_dielectric_from_outside() {
    chi2_group("dielectric_out");
}

#[test]
fn chi2_dielectric_from_inside() {
    chi2_group("dielectric_in");
}

#[test]
fn chi2_plastic() {
    chi2_group("plastic");
}

/// The chi-square machinery must reject a sampler whose pdf is subtly wrong: Lambert samples
/// checked against a pdf ∝ cos^1.15 θ (a 15 % change in the exponent).
#[test]
fn chi2_rejects_a_wrong_pdf() {
    let wo = wo_at(0.5);
    let mut rng = Pcg32::new(5, 9);
    let lambert = Bsdf::Lambert { albedo: Vec3::ONE };
    let mut observed = vec![0.0f64; THETA_RES * PHI_RES];
    for _ in 0..CHI2_SAMPLES {
        let s = lambert.sample(wo, rng.next_f32(), rng.next_2d()).unwrap();
        let i = (((s.wi.z as f64 + 1.0) * 0.5 * THETA_RES as f64) as usize).min(THETA_RES - 1);
        let j = ((phi_of(s.wi) / (2.0 * PI64) * PHI_RES as f64) as usize).min(PHI_RES - 1);
        observed[i * PHI_RES + j] += 1.0;
    }
    let k = 1.15f64;
    // ∫ cos^k over the hemisphere = 2π/(k+1); per cell ∝ (c1^{k+1} − c0^{k+1}).
    let mut stat = 0.0;
    let mut dof = 0;
    for i in THETA_RES / 2..THETA_RES {
        let c0 = -1.0 + 2.0 * i as f64 / THETA_RES as f64;
        let c1 = c0 + 2.0 / THETA_RES as f64;
        let e = CHI2_SAMPLES as f64 * (c1.powf(k + 1.0) - c0.powf(k + 1.0)) / PHI_RES as f64;
        for j in 0..PHI_RES {
            let o = observed[i * PHI_RES + j];
            stat += (o - e).powi(2) / e;
            dof += 1;
        }
    }
    let p = chi2_p_value(stat, dof - 1);
    assert!(p < 1e-6, "wrong pdf not detected: chi2 = {stat}, p = {p}");
}

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
// Energy.

/// Mean and standard error of the per-channel-max weight; transmitted weights are divided by
/// `s.eta²` when `undo_eta` is set (the radiance scaling is not an energy gain: it cancels on
/// leaving the object).
fn energy(bsdf: &Bsdf, wo: Vec3, n: usize, undo_eta: bool, seed: u64) -> (f64, f64) {
    let mut rng = Pcg32::new(seed, 11);
    let (mut s1, mut s2) = (0.0f64, 0.0f64);
    for _ in 0..n {
        let w = match bsdf.sample(wo, rng.next_f32(), rng.next_2d()) {
            Some(s) => {
                let scale = if undo_eta && s.lobe.transmission { 1.0 / (s.eta * s.eta) } else { 1.0 };
                (s.weight * scale).max_element() as f64
            }
            None => 0.0,
        };
        s1 += w;
        s2 += w * w;
    }
    let mean = s1 / n as f64;
    let var = (s2 / n as f64 - mean * mean).max(0.0);
    (mean, (var / n as f64).sqrt())
}

fn white_bsdfs() -> Vec<(String, Bsdf)> {
    let mut v: Vec<(String, Bsdf)> = vec![("lambert".into(), Bsdf::Lambert { albedo: Vec3::ONE })];
    for alpha in [0.0, 0.002, 0.05, 0.3, 1.0] {
        // Silver-like and a k = 0 "conductor" (a dielectric-like Fresnel) bracket the range.
        v.push((format!("conductor a={alpha}"), Bsdf::Conductor { eta: Vec3::splat(0.15), k: Vec3::splat(3.6), alpha, specular_tint: Vec3::ONE, dist: Default::default() }));
        v.push((format!("gold a={alpha}"), conductor(alpha)));
        for eta in [1.01, 1.33, 1.5, 2.4] {
            v.push((format!("dielectric a={alpha} eta={eta}"), Bsdf::Dielectric { eta, alpha, tint: Vec3::ONE, dist: Default::default() }));
        }
    }
    for alpha in [0.0, 0.05, 0.1, 0.3, 0.6, 1.0] {
        for eta in [1.0, 1.2, 1.5, 2.0, 3.0] {
            v.push((format!("plastic a={alpha} eta={eta}"), Bsdf::Plastic { albedo: Vec3::ONE, eta, alpha, dist: Default::default(), nonlinear: true }));
        }
    }
    v
}

#[test]
fn energy_never_exceeds_one() {
    // 4 standard errors: the per-test false-alarm rate is ~3e-5, fine over ~500 estimates.
    // The 2e-3 slack covers the rough-plastic coat table (interpolated directional albedo).
    let n = 20_000;
    let mut bad = Vec::new();
    for (name, bsdf) in white_bsdfs() {
        let sides: &[f32] = if bsdf.is_transmissive() { &[1.0, -1.0] } else { &[1.0] };
        for &c in &[0.001, 0.05, 0.3, 0.7, 1.0] {
            for &side in sides {
                let wo = wo_at(c * side);
                let (mean, se) = energy(&bsdf, wo, n, true, 3);
                if mean > 1.0 + 4.0 * se + 2e-3 {
                    bad.push(format!("{name} cos_o={}: {mean:.5} ± {se:.5}", c * side));
                }
            }
        }
    }
    assert!(bad.is_empty(), "energy > 1:\n{}", bad.join("\n"));
}

#[test]
fn energy_of_known_cases() {
    let n = 100_000;
    // White Lambert: every weight is exactly the albedo, so the estimate is 1 up to rounding.
    let (m, _) = energy(&Bsdf::Lambert { albedo: Vec3::ONE }, wo_at(0.6), n, false, 1);
    assert!((m - 1.0).abs() < 1e-5, "white Lambert energy {m}");
    let (m, _) = energy(&Bsdf::Lambert { albedo: Vec3::splat(0.5) }, wo_at(0.6), n, false, 1);
    assert!((m - 0.5).abs() < 1e-5, "grey Lambert energy {m}");

    // Smooth glass, eta 1.5, normal incidence: F = ((η−1)/(η+1))² = 0.04. In radiance units the
    // transmitted weight is (1/1.5)² so the mean is F + (1−F)/η² = 0.46667 from outside and
    // F + (1−F)η² = 2.2 from inside; with the η² factor undone it is 1 on both sides.
    let glass = Bsdf::Dielectric { eta: 1.5, alpha: 0.0, tint: Vec3::ONE, dist: Default::default() };
    let f = 0.04f64;
    for (wo, expect) in [(Vec3::Z, f + (1.0 - f) / 2.25), (-Vec3::Z, f + (1.0 - f) * 2.25)] {
        let (m, se) = energy(&glass, wo, n, false, 2);
        // The mean is binomial over the two lobes; 4 standard errors + f32 rounding.
        assert!((m - expect).abs() < 4.0 * se + 1e-4, "smooth glass wo={wo}: {m} ± {se}, expected {expect}");
        let (m, _) = energy(&glass, wo, n, true, 2);
        assert!((m - 1.0).abs() < 1e-4, "smooth glass wo={wo}, η² undone: {m}");
    }

    // White plastic is lossless by construction (coat + base with ρ = 1 sum to 1); for the rough
    // coat only the tabulated directional albedo (~1e-3) separates it from 1.
    for alpha in [0.0, 0.3, 1.0] {
        for c in [0.1, 0.5, 1.0] {
            let plastic = Bsdf::Plastic { albedo: Vec3::ONE, eta: 1.5, alpha, dist: Default::default(), nonlinear: true };
            let (m, se) = energy(&plastic, wo_at(c), n, false, 4);
            assert!((m - 1.0).abs() < 4.0 * se + 3e-3, "white plastic a={alpha} cos_o={c}: {m} ± {se}");
        }
    }

    // Rough glass keeps almost all energy at moderate roughness: single-scattering GGX loses
    // only what G2 < G1 discards (< 2 % at alpha 0.1 near normal incidence).
    let rough = Bsdf::Dielectric { eta: 1.5, alpha: 0.1, tint: Vec3::ONE, dist: Default::default() };
    for wo in [wo_at(0.9), wo_at(-0.9)] {
        let (m, se) = energy(&rough, wo, n, true, 5);
        assert!(m > 0.98 - 4.0 * se && m <= 1.0 + 4.0 * se, "rough glass wo={wo}: {m} ± {se}");
    }
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
        (Bsdf::Plastic { albedo: Vec3::splat(0.5), eta: 1.5, alpha: 0.0, dist: Default::default(), nonlinear: true }, wo_at(0.2), vec![5, 17]),
        (Bsdf::Plastic { albedo: Vec3::splat(0.5), eta: 1.5, alpha: 0.2, dist: Default::default(), nonlinear: true }, wo_at(0.2), vec![5, 9]),
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

