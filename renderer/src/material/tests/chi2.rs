//! χ² goodness-of-fit tests of every BSDF's `sample` against its `pdf` (integrated over
//! cells of the sphere), and a check that the test rejects a subtly wrong pdf.

use super::*;
use crate::rng::Pcg32;
use crate::stats::{chi2_p_value, sidak};
use std::f64::consts::PI as PI64;

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
fn simpson_rec(
    f: &mut dyn FnMut(f64) -> f64,
    a: f64,
    b: f64,
    fa: f64,
    fm: f64,
    fb: f64,
    whole: f64,
    eps: f64,
    rel: f64,
    depth: u32,
) -> f64 {
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
