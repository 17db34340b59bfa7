//! Isotropic GGX (Trowbridge–Reitz) microfacet distribution: D, Smith Λ/G1, the
//! height-correlated G2, and visible-normal sampling with the spherical-cap construction of
//! Dupuy & Benyoub 2023 ("Sampling Visible GGX Normals with Spherical Caps").
//! Microfacet normals `m` always lie in the upper hemisphere (m.z > 0).

use crate::math::PI;
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Ggx {
    pub alpha: f32,
}

impl Ggx {
    pub fn new(alpha: f32) -> Self {
        Ggx { alpha }
    }

    /// Normal distribution D(m), normalised so that ∫ D(m) m.z dm = 1.
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
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
