//! Isotropic microfacet distributions, GGX (Trowbridge–Reitz) and Beckmann (Mitsuba's
//! `distribution="beckmann"`): D, Smith Λ/G1, the height-correlated G2, and visible-normal
//! sampling — for GGX with the spherical-cap construction of Dupuy & Benyoub 2023 ("Sampling
//! Visible GGX Normals with Spherical Caps"), for Beckmann by numerically inverting the
//! visible-slope CDF (Heitz & d'Eon 2014, in the robust form of Jakob's and pbrt-v3's
//! `BeckmannSample11`). Microfacet normals `m` always lie in the upper hemisphere (m.z > 0).

use crate::math::PI;
use glam::{Vec2, Vec3};

/// Which microfacet normal distribution a rough lobe uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Distribution {
    #[default]
    Ggx,
    Beckmann,
}

#[derive(Clone, Copy, Debug)]
pub struct Microfacet {
    pub alpha: f32,
    pub dist: Distribution,
}

impl Microfacet {
    pub fn new(alpha: f32, dist: Distribution) -> Self {
        Microfacet { alpha, dist }
    }

    /// Normal distribution D(m), normalised so that ∫ D(m) m.z dm = 1.
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        if self.dist == Distribution::Beckmann {
            let a2 = self.alpha * self.alpha;
            let z2 = m.z * m.z;
            let tan2 = (m.x * m.x + m.y * m.y) / z2;
            let v = (-tan2 / a2).exp() / (PI * a2 * z2 * z2);
            return if v.is_finite() { v } else { 0.0 };
        }
        let a2 = self.alpha * self.alpha;
        // Written as 1/(π α² t²) with t = (x²+y²)/α² + z², which stays accurate for tiny α where
        // the textbook cos⁴θ(α² + tan²θ)² form cancels.
        let t = (m.x * m.x + m.y * m.y) / a2 + m.z * m.z;
        1.0 / (PI * a2 * t * t)
    }

    /// Smith Λ(w); symmetric in w.z, infinite at the horizon.
    pub fn lambda(&self, w: Vec3) -> f32 {
        let z2 = w.z * w.z;
        if z2 == 0.0 {
            return f32::INFINITY;
        }
        let x = self.alpha * self.alpha * (w.x * w.x + w.y * w.y).max(0.0) / z2;
        if !x.is_finite() {
            return f32::INFINITY;
        }
        if self.dist == Distribution::Beckmann {
            // Λ = (e^(−a²)/(a√π) − erfc(a))/2 with a = 1/(α tan θ) = 1/√x.
            if x == 0.0 {
                return 0.0;
            }
            let a = 1.0 / (x as f64).sqrt();
            if a > 6.0 {
                return 0.0;
            }
            let l = 0.5 * ((-a * a).exp() / (a * std::f64::consts::PI.sqrt()) - erfc(a));
            return l.max(0.0) as f32;
        }
        // (√(1+x) − 1)/2 rewritten without the cancellation for small x.
        x / (2.0 * ((1.0 + x).sqrt() + 1.0))
    }

    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking-shadowing.
    pub fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// Sample a normal visible from `wo` (from `-wo` if `wo` is below the surface, so the same
    /// upper-hemisphere normals serve both sides of a dielectric).
    pub fn sample_visible(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let w = if wo.z < 0.0 { -wo } else { wo };
        let a = self.alpha;
        if self.dist == Distribution::Beckmann {
            return beckmann_sample_visible(w, a, u);
        }
        let wh = Vec3::new(w.x * a, w.y * a, w.z).normalize_or_zero();
        if wh == Vec3::ZERO {
            return Vec3::Z;
        }
        // Visible normals of the hemisphere configuration are uniform on the spherical cap
        // z ∈ (−wh.z, 1] offset by wh.
        let phi = 2.0 * PI * u.x;
        let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
        let s = (1.0 - z * z).max(0.0).sqrt();
        let h = Vec3::new(s * phi.cos(), s * phi.sin(), z) + wh;
        let m = Vec3::new(h.x * a, h.y * a, h.z.max(0.0));
        let len = m.length();
        if !(len > 0.0) || !len.is_finite() {
            return Vec3::Z;
        }
        m / len
    }

    /// Density of `sample_visible(wo, ·)` producing `m`: G1(wo)·max(0, wo·m)·D(m)/|wo.z|
    /// (with `wo` flipped to the upper side as in sampling).
    pub fn pdf_visible(&self, wo: Vec3, m: Vec3) -> f32 {
        let cos = wo.z.abs();
        if cos == 0.0 {
            return 0.0;
        }
        let dot = if wo.z < 0.0 { -wo.dot(m) } else { wo.dot(m) };
        if dot <= 0.0 {
            return 0.0;
        }
        self.g1(wo) * dot * self.d(m) / cos
    }
}

/// erfc(x) with relative error below 1.2e-7 (Numerical Recipes' Chebyshev fit `erfcc`).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let p = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07 + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * p.exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

pub fn erf(x: f64) -> f64 {
    1.0 - erfc(x)
}

/// Inverse of `erf` on (−1, 1): Giles' single-precision approximation, polished by one Newton
/// step against `erf` (|erf(erfinv(y)) − y| ≲ 1e-7).
pub fn erfinv(y: f64) -> f64 {
    let y = y.clamp(-0.999_999, 0.999_999);
    let mut w = -((1.0 - y) * (1.0 + y)).ln();
    let p = if w < 5.0 {
        w -= 2.5;
        [
            3.432_739_39e-7,
            -3.523_387_7e-6,
            -4.391_506_54e-6,
            2.185_808_7e-4,
            -1.253_725_03e-3,
            -4.177_681_64e-3,
            0.246_640_727,
            1.501_409_41,
        ]
        .iter()
        .fold(2.810_226_36e-8, |p, c| c + p * w)
    } else {
        w = w.sqrt() - 3.0;
        [1.009_505_58e-4, 1.349_343_22e-3, -3.673_428_44e-3, 5.739_507_73e-3, -7.622_461_3e-3, 9.438_870_47e-3, 1.001_674_06, 2.832_976_82]
            .iter()
            .fold(-2.002_142_57e-4, |p, c| c + p * w)
    };
    let x = p * y;
    let d = 2.0 / std::f64::consts::PI.sqrt() * (-x * x).exp();
    if d > 0.0 {
        x - (erf(x) - y) / d
    } else {
        x
    }
}

/// A Beckmann normal visible from `w` (w.z ≥ 0): sample the visible slopes of the unit-roughness
/// distribution seen from the stretched direction, then rotate and unstretch them.
fn beckmann_sample_visible(w: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    let ws = Vec3::new(w.x * alpha, w.y * alpha, w.z).normalize_or_zero();
    if ws == Vec3::ZERO {
        return Vec3::Z;
    }
    let (sx, sy) = beckmann_sample_11(ws.z as f64, u.x as f64, u.y as f64);
    let r = (ws.x * ws.x + ws.y * ws.y).sqrt();
    let (cos_phi, sin_phi) = if r > 0.0 { ((ws.x / r) as f64, (ws.y / r) as f64) } else { (1.0, 0.0) };
    let (x, y) = (cos_phi * sx - sin_phi * sy, sin_phi * sx + cos_phi * sy);
    let m = Vec3::new((-x * alpha as f64) as f32, (-y * alpha as f64) as f32, 1.0).normalize_or_zero();
    if m == Vec3::ZERO || !m.is_finite() {
        Vec3::Z
    } else {
        m
    }
}

/// Visible slopes (x along the view's azimuth, y across it) of the α = 1 Beckmann distribution
/// seen at incidence cosine `cos_i`: x by inverting its CDF in the erf domain (bracketed Newton),
/// y from the Gaussian marginal.
fn beckmann_sample_11(cos_i: f64, u1: f64, u2: f64) -> (f64, f64) {
    let inv_sqrt_pi = 1.0 / std::f64::consts::PI.sqrt();
    if cos_i > 0.999_999 {
        // Normal incidence: the slopes are an isotropic Gaussian.
        let r = (-(1.0 - u1).max(1e-300).ln()).sqrt();
        let phi = 2.0 * std::f64::consts::PI * u2;
        return (r * phi.cos(), r * phi.sin());
    }
    let sin_i = (1.0 - cos_i * cos_i).max(0.0).sqrt();
    let tan_i = sin_i / cos_i;
    let cot_i = 1.0 / tan_i;
    // The CDF of the slope x, as a function of b = erf(x): (1 + b + tan·e^(−x²)/√π)/norm on
    // b ∈ [−1, erf(cot)].
    let (mut a, mut c) = (-1.0f64, erf(cot_i));
    let sample = u1.clamp(1e-9, 1.0 - 1e-9);
    let theta = cos_i.acos();
    let fit = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
    let mut b = c - (1.0 + c) * (1.0 - sample).powf(fit);
    let norm = 1.0 / (1.0 + c + inv_sqrt_pi * tan_i * (-cot_i * cot_i).exp());
    for _ in 0..20 {
        if !(b >= a && b <= c) {
            b = 0.5 * (a + c);
        }
        let x = erfinv(b);
        let value = norm * (1.0 + b + inv_sqrt_pi * tan_i * (-x * x).exp()) - sample;
        // erf is good to ~1e-7, so the CDF cannot be solved much more precisely than this.
        if value.abs() < 1e-6 {
            break;
        }
        let derivative = norm * (1.0 - x * tan_i);
        if value > 0.0 {
            c = b;
        } else {
            a = b;
        }
        b -= value / derivative;
    }
    (erfinv(b), erfinv(2.0 * u2.clamp(1e-9, 1.0 - 1e-9) - 1.0))
}
