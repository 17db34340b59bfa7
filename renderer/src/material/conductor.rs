//! Conductors: a delta mirror when smooth, GGX or Beckmann with visible-normal sampling when rough.
//! Reflection only (wo.z > 0 after the integrator's flip).

use super::fresnel;
use super::microfacet::{Distribution, Microfacet};
use super::{BsdfSample, Lobe, LobeKind, MIN_ALPHA};
use glam::{Vec2, Vec3};

#[derive(Clone, Copy, Debug)]
pub struct Conductor {
    pub eta: Vec3,
    pub k: Vec3,
    pub alpha: f32,
    pub tint: Vec3,
    pub dist: Distribution,
}

impl Conductor {
    fn fresnel(&self, cos: f32) -> Vec3 {
        fresnel::conductor(cos, self.eta, self.k) * self.tint
    }

    fn smooth(&self) -> bool {
        !(self.alpha >= MIN_ALPHA)
    }

    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if !(wo.z > 0.0) {
            return None;
        }
        if self.smooth() {
            let f = self.fresnel(wo.z);
            let lobe = Lobe { kind: LobeKind::Specular, transmission: false, roughness: 0.0 };
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(BsdfSample { wi, weight: f, f_cos: f, pdf: 1.0, lobe, eta: 1.0 });
        }
        let ggx = Microfacet::new(self.alpha, self.dist);
        let m = ggx.sample_visible(wo, u);
        let cos_om = wo.dot(m);
        if !(cos_om > 0.0) {
            return None;
        }
        let wi = crate::math::reflect(wo, m);
        if !(wi.z > 0.0) {
            return None;
        }
        let f = self.fresnel(cos_om);
        let pdf = ggx.pdf_visible(wo, m) / (4.0 * cos_om);
        // f·cos/pdf simplifies to F·G2/G1(wo): no D and no 1/cos, so it stays bounded at grazing.
        let weight = f * (ggx.g2(wo, wi) / ggx.g1(wo));
        let f_cos = f * (ggx.d(m) * ggx.g2(wo, wi) / (4.0 * wo.z));
        let lobe = Lobe { kind: LobeKind::Glossy, transmission: false, roughness: self.alpha };
        Some(BsdfSample { wi, weight, f_cos, pdf, lobe, eta: 1.0 })
    }

    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if self.smooth() || !(wo.z > 0.0) || !(wi.z > 0.0) {
            return Vec3::ZERO;
        }
        let m = (wo + wi).normalize_or_zero();
        if !(m.z > 0.0) {
            return Vec3::ZERO;
        }
        let ggx = Microfacet::new(self.alpha, self.dist);
        self.fresnel(wo.dot(m)) * (ggx.d(m) * ggx.g2(wo, wi) / (4.0 * wo.z))
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.smooth() || !(wo.z > 0.0) || !(wi.z > 0.0) {
            return 0.0;
        }
        let m = (wo + wi).normalize_or_zero();
        let cos_om = wo.dot(m);
        if !(m.z > 0.0) || !(cos_om > 0.0) {
            return 0.0;
        }
        Microfacet::new(self.alpha, self.dist).pdf_visible(wo, m) / (4.0 * cos_om)
    }

    /// Normal-incidence reflectance × tint, clamped to [0, 1].
    pub fn albedo(&self) -> Vec3 {
        self.fresnel(1.0).clamp(Vec3::ZERO, Vec3::ONE)
    }
}
