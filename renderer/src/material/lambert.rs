//! Lambertian reflector (reflection only; the integrator flips the frame so that wo.z > 0).

use super::{BsdfSample, Lobe, LobeKind};
use crate::math::INV_PI;
use crate::sampling::square_to_cosine_hemisphere;
use glam::{Vec2, Vec3};

pub const LOBE: Lobe = Lobe { kind: LobeKind::Diffuse, transmission: false, roughness: 1.0 };

pub fn sample(albedo: Vec3, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
    if !(wo.z > 0.0) {
        return None;
    }
    let wi = square_to_cosine_hemisphere(u);
    if !(wi.z > 0.0) {
        return None;
    }
    let pdf = wi.z * INV_PI;
    Some(BsdfSample { wi, weight: albedo, f_cos: albedo * pdf, pdf, lobe: LOBE, eta: 1.0 })
}

pub fn eval(albedo: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
    if wo.z > 0.0 && wi.z > 0.0 {
        albedo * (wi.z * INV_PI)
    } else {
        Vec3::ZERO
    }
}

pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z > 0.0 && wi.z > 0.0 {
        wi.z * INV_PI
    } else {
        0.0
    }
}
