//! Dielectrics (glass): smooth (delta reflection + delta refraction chosen by Fresnel) and rough
//! GGX or Beckmann (Walter et al. 2007 with visible-normal sampling).
//!
//! The frame is not flipped: wo.z > 0 means outside, `eta` = interior/exterior. Transmitted
//! radiance is scaled by (η_o/η_i)², η_o on wo's side and η_i on wi's side (the side the path
//! continues into), so a path entering and leaving a closed object gets the two factors cancelled.
//! `BsdfSample::eta` reports η_o/η_i for transmission.

use super::fresnel;
use super::microfacet::{Distribution, Microfacet};
use super::{BsdfSample, Lobe, LobeKind, MIN_ALPHA};
use glam::{Vec2, Vec3};

/// |η − 1| below this is treated as an index-matched interface: the ray passes straight through.
/// Refraction formulas stay finite there, but the rough half-vector `wi·η + wo` degenerates.
pub const PASS_THROUGH_EPS: f32 = 1e-4;

#[derive(Clone, Copy, Debug)]
pub struct Dielectric {
    pub eta: f32,
    pub alpha: f32,
    pub tint: Vec3,
    pub dist: Distribution,
}

const SPEC_R: Lobe = Lobe { kind: LobeKind::Specular, transmission: false, roughness: 0.0 };
const SPEC_T: Lobe = Lobe { kind: LobeKind::Specular, transmission: true, roughness: 0.0 };

impl Dielectric {
    pub fn pass_through(&self) -> bool {
        !((self.eta - 1.0).abs() >= PASS_THROUGH_EPS)
    }

    fn smooth(&self) -> bool {
        !(self.alpha >= MIN_ALPHA)
    }

    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if self.pass_through() {
            let t = self.tint;
            return Some(BsdfSample { wi: -wo, weight: t, f_cos: t, pdf: 1.0, lobe: SPEC_T, eta: 1.0 });
        }
        if self.smooth() {
            self.sample_smooth(wo, u_lobe)
        } else {
            self.sample_rough(wo, u_lobe, u)
        }
    }

    fn sample_smooth(&self, wo: Vec3, u_lobe: f32) -> Option<BsdfSample> {
        let f = fresnel::dielectric(wo.z, self.eta);
        if u_lobe < f {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample { wi, weight: self.tint, f_cos: self.tint * f, pdf: f, lobe: SPEC_R, eta: 1.0 });
        }
        let (wi, etap) = fresnel::refract(wo, Vec3::Z, self.eta)?;
        let t = 1.0 - f;
        if !(t > 0.0) {
            return None;
        }
        let weight = self.tint / (etap * etap);
        Some(BsdfSample { wi, weight, f_cos: weight * t, pdf: t, lobe: SPEC_T, eta: 1.0 / etap })
    }

    fn sample_rough(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let ggx = Microfacet::new(self.alpha, self.dist);
        let m = ggx.sample_visible(wo, u);
        let cos_om = wo.dot(m);
        if !(cos_om * wo.z > 0.0) {
            return None;
        }
        let f = fresnel::dielectric(cos_om, self.eta);
        let pdf_m = ggx.pdf_visible(wo, m);
        let g1o = ggx.g1(wo);
        let d = ggx.d(m);
        if u_lobe < f {
            let wi = crate::math::reflect(wo, m);
            if !(wi.z * wo.z > 0.0) {
                return None;
            }
            let g2 = ggx.g2(wo, wi);
            let pdf = pdf_m / (4.0 * cos_om.abs()) * f;
            let f_cos = self.tint * (d * g2 * f / (4.0 * wo.z.abs()));
            // f·cos/pdf = G2/G1(wo) exactly; computed directly so it stays bounded at grazing.
            let weight = self.tint * (g2 / g1o);
            let lobe = Lobe { kind: LobeKind::Glossy, transmission: false, roughness: self.alpha };
            return Some(BsdfSample { wi, weight, f_cos, pdf, lobe, eta: 1.0 });
        }
        let (wi, etap) = fresnel::refract(wo, m, self.eta)?;
        if !(wi.z * wo.z < 0.0) {
            return None;
        }
        let t = 1.0 - f;
        let cos_im = wi.dot(m);
        let denom = cos_im + cos_om / etap;
        let jac = cos_im.abs() / (denom * denom);
        let g2 = ggx.g2(wo, wi);
        let pdf = pdf_m * jac * t;
        let f_cos = self.tint * (d * g2 * t * (cos_im * cos_om).abs() / (denom * denom * wo.z.abs()) / (etap * etap));
        let weight = self.tint * (g2 / g1o / (etap * etap));
        let lobe = Lobe { kind: LobeKind::Glossy, transmission: true, roughness: self.alpha };
        Some(BsdfSample { wi, weight, f_cos, pdf, lobe, eta: 1.0 / etap })
    }

    /// The generalised half vector of (wo, wi), oriented up, with the relative IOR etap = η on
    /// wi's side / η on wo's side; `None` when degenerate or when a facet would be back-facing.
    fn half_vector(&self, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32)> {
        if wo.z == 0.0 || wi.z == 0.0 {
            return None;
        }
        let reflect = wo.z * wi.z > 0.0;
        let etap = if reflect {
            1.0
        } else if wo.z > 0.0 {
            self.eta
        } else {
            1.0 / self.eta
        };
        let mut m = (wi * etap + wo).normalize_or_zero();
        if m.z < 0.0 {
            m = -m;
        }
        if !(m.z > 0.0) {
            return None;
        }
        if !(m.dot(wi) * wi.z > 0.0) || !(m.dot(wo) * wo.z > 0.0) {
            return None;
        }
        Some((m, etap))
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if self.pass_through() || self.smooth() {
            return Vec3::ZERO;
        }
        let Some((m, etap)) = self.half_vector(wo, wi) else { return Vec3::ZERO };
        let ggx = Microfacet::new(self.alpha, self.dist);
        let cos_om = wo.dot(m);
        let f = fresnel::dielectric(cos_om, self.eta);
        let dg = ggx.d(m) * ggx.g2(wo, wi);
        if wo.z * wi.z > 0.0 {
            return self.tint * (dg * f / (4.0 * wo.z.abs()));
        }
        let cos_im = wi.dot(m);
        let denom = cos_im + cos_om / etap;
        if denom == 0.0 {
            return Vec3::ZERO;
        }
        self.tint * (dg * (1.0 - f) * (cos_im * cos_om).abs() / (denom * denom * wo.z.abs()) / (etap * etap))
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.pass_through() || self.smooth() {
            return 0.0;
        }
        let Some((m, etap)) = self.half_vector(wo, wi) else { return 0.0 };
        let ggx = Microfacet::new(self.alpha, self.dist);
        let cos_om = wo.dot(m);
        let f = fresnel::dielectric(cos_om, self.eta);
        let pdf_m = ggx.pdf_visible(wo, m);
        if wo.z * wi.z > 0.0 {
            return pdf_m / (4.0 * cos_om.abs()) * f;
        }
        let cos_im = wi.dot(m);
        let denom = cos_im + cos_om / etap;
        if denom == 0.0 {
            return 0.0;
        }
        pdf_m * cos_im.abs() / (denom * denom) * (1.0 - f)
    }
}
