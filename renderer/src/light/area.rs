//! Emissive triangles: uniform area sampling converted to a solid-angle density.

use crate::math::{is_finite3, luminance, PI};
use glam::Vec3;

/// Below this |cos θ| at the light the area-to-solid-angle Jacobian explodes; such samples carry
/// (almost) no energy, so both `sample` and `pdf_triangle` treat them as impossible, which keeps
/// the MIS weights of the two strategies consistent.
const MIN_COS_LIGHT: f32 = 1e-6;

/// One emissive triangle of positive area.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriangleLight {
    pub prim: u32,
    pub area: f32,
    pub emission: Vec3,
    pub two_sided: bool,
    /// The triangle's `Mesh::geometric_normal`, kept here because every light sample needs it.
    pub normal: Vec3,
    /// The triangle's vertices, kept here for the same reason.
    pub vertices: [Vec3; 3],
    /// `emission.max_element()`, which every connection checks against its pdf.
    pub max_emission: f32,
}

impl TriangleLight {
    /// Emitted flux: area · luminance · π per emitting side.
    pub fn power(&self) -> f64 {
        let sides = if self.two_sided { 2.0 } else { 1.0 };
        self.area as f64 * luminance(self.emission.max(Vec3::ZERO)) as f64 * PI as f64 * sides
    }

    /// Direction, distance and solid-angle pdf (times `select_pmf`) of light point `p_light`
    /// with geometric normal `n_light` seen from `p`. `None` when the connection is useless:
    /// coincident points, grazing angles, the non-emitting side, or a ratio radiance/pdf that
    /// would overflow.
    #[inline]
    pub fn connect(&self, p: Vec3, p_light: Vec3, n_light: Vec3, select_pmf: f32) -> Option<(Vec3, f32, f32)> {
        let d = p_light - p;
        let dist2 = d.length_squared();
        // Closer than ~16 ulps of the coordinates is rounding noise, not a real distance.
        let scale = p.abs().max_element().max(p_light.abs().max_element());
        let min_dist2 = (1e-6 * scale).powi(2).max(1e-24);
        if !(dist2 > min_dist2) || !dist2.is_finite() {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos = n_light.dot(-wi);
        if !self.two_sided && !(cos > 0.0) {
            return None;
        }
        if !(cos.abs() >= MIN_COS_LIGHT) {
            return None;
        }
        let pdf = select_pmf * (dist2 / (self.area * cos.abs()));
        let ratio = self.max_emission / pdf;
        if !(pdf > 0.0) || !pdf.is_finite() || !ratio.is_finite() || !is_finite3(wi) {
            return None;
        }
        Some((wi, dist, pdf))
    }
}

/// `TriangleLight::connect` (the same operations) on the light's fields, with the verdict as a flag instead of an
/// `Option` (so a loop over many connections has no early exit and can be vectorised); when the
/// flag is false the other values are meaningless.
#[inline(always)]
pub(crate) fn connect_parts(
    p: Vec3,
    p_light: Vec3,
    n_light: Vec3,
    select_pmf: f32,
    area: f32,
    two_sided: bool,
    max_emission: f32,
) -> (bool, Vec3, f32, f32) {
    let d = p_light - p;
    let dist2 = d.length_squared();
    // Closer than ~16 ulps of the coordinates is rounding noise, not a real distance.
    let scale = p.abs().max_element().max(p_light.abs().max_element());
    let min_dist2 = (1e-6 * scale).powi(2).max(1e-24);
    let dist = dist2.sqrt();
    let wi = d / dist;
    let cos = n_light.dot(-wi);
    let pdf = select_pmf * (dist2 / (area * cos.abs()));
    let ratio = max_emission / pdf;
    let ok = (dist2 > min_dist2)
        & dist2.is_finite()
        & (two_sided | (cos > 0.0))
        & (cos.abs() >= MIN_COS_LIGHT)
        & (pdf > 0.0)
        & pdf.is_finite()
        & ratio.is_finite()
        & is_finite3(wi);
    (ok, wi, dist, pdf)
}
