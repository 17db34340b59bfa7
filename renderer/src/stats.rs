//! Special functions and p-values of the renderer's statistical tests: the χ² goodness-of-fit
//! tests of BSDF sampling (renderer/src/material/tests/) and the Welch t-tests of the Mitsuba
//! cross-check (renderer/tests/mitsuba_crosscheck.rs). Rendering uses none of it; it is public
//! so that unit and integration tests share one copy.

use std::f64::consts::PI;

/// ln Γ(x) for x > 0 (Lanczos, g = 7, 9 terms; ~1e-15 relative).
pub fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection formula keeps the series in its accurate range.
        return (PI / (PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + 7.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Q(a, x) = Γ(a, x)/Γ(a): series for x < a + 1, Lentz continued fraction otherwise.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_pre = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        let (mut ap, mut sum, mut del) = (a, 1.0 / a, 1.0 / a);
        for _ in 0..10_000 {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if del.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_pre.exp()).clamp(0.0, 1.0)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_pre.exp() * h).clamp(0.0, 1.0)
    }
}

/// Upper-tail probability of a chi-square statistic with `dof` degrees of freedom.
pub fn chi2_p_value(stat: f64, dof: usize) -> f64 {
    gamma_q(dof as f64 / 2.0, stat / 2.0)
}

/// Regularised incomplete beta I_x(a, b) (continued fraction, Numerical Recipes' betacf).
pub fn inc_beta(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front = (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    let cf = |a: f64, b: f64, x: f64| {
        let tiny = 1e-300;
        let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
        let mut c = 1.0;
        let mut d = 1.0 - qab * x / qap;
        d = if d.abs() < tiny { tiny } else { d };
        d = 1.0 / d;
        let mut h = d;
        for m in 1..500 {
            let m = m as f64;
            let m2 = 2.0 * m;
            let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
            d = 1.0 + aa * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = 1.0 + aa / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            h *= d * c;
            let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
            d = 1.0 + aa * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = 1.0 + aa / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-15 {
                break;
            }
        }
        h
    };
    if x < (a + 1.0) / (a + b + 2.0) {
        front * cf(a, b, x) / a
    } else {
        1.0 - front * cf(b, a, 1.0 - x) / b
    }
}

/// Two-sided p-value of Student's t with `dof` degrees of freedom: P(|T| ≥ |t|).
pub fn t_two_sided_p(t: f64, dof: f64) -> f64 {
    if !t.is_finite() {
        return 0.0;
    }
    inc_beta(dof / 2.0, 0.5, dof / (dof + t * t))
}

/// The smallest |t| (for `dof`) whose two-sided p-value is below `p`, by bisection.
pub fn t_threshold(p: f64, dof: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1e3f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t_two_sided_p(mid, dof) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Šidák's per-test significance for a family of `n` tests at family-wise `alpha`.
pub fn sidak(alpha: f64, n: usize) -> f64 {
    // 1 − (1 − α)^(1/n) without cancellation.
    -((-alpha).ln_1p() / n as f64).exp_m1()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_p_values_match_tables() {
        // Critical values from standard chi-square tables (5 significant digits), and the closed
        // form exp(−x/2) for 2 dof; 1e-4 is the precision of the tabulated values.
        let cases = [
            (3.8415, 1, 0.05),
            (6.6349, 1, 0.01),
            (23.209, 10, 0.01),
            (18.307, 10, 0.05),
            (76.154, 50, 0.01),
            (4.0, 2, (-2.0f64).exp()),
            (0.5, 7, 0.99948),
            (135.81, 100, 0.01),
        ];
        for (x, dof, p) in cases {
            let got = chi2_p_value(x, dof);
            assert!((got - p).abs() < 1e-4, "chi2 Q({x}, {dof}) = {got}, table {p}");
        }
    }

    #[test]
    fn statistics_helpers_are_right() {
        // Standard normal limit and known t quantiles.
        assert!((t_two_sided_p(1.959964, 1e7) - 0.05).abs() < 1e-5);
        assert!((t_two_sided_p(2.228139, 10.0) - 0.05).abs() < 1e-5);
        assert!((t_two_sided_p(12.7062, 1.0) - 0.05).abs() < 1e-4);
        assert!((t_threshold(0.01, 30.0) - 2.749996).abs() < 1e-4);
        assert!((t_threshold(1e-6, 1e7) - 4.891638).abs() < 1e-3);
        assert!((sidak(0.05, 1) - 0.05).abs() < 1e-12);
        assert!((sidak(0.01, 100) - (1.0 - 0.99f64.powf(0.01))).abs() < 1e-15);
    }
}
