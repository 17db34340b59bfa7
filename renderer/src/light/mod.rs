//! Light sources for next-event estimation: emissive triangles (area lights) and the
//! environment (constant colour or an importance-sampled lat-long map).
//!
//! Light selection picks one light per NEE sample with probability proportional to an estimate
//! of its power; every pdf this module returns is a solid-angle density that already includes
//! that selection probability, so the integrator's MIS weights need nothing else.
//!
//! Power estimates: a triangle emits `area · luminance · π` per emitting side; the environment
//! `4π · πR² · mean luminance` with R half the mesh bounding-box diagonal (pbrt's estimate of
//! the flux an infinite light sends through the scene). When both kinds exist, each kind keeps at
//! least [`MIN_KIND_SHARE`] of the selection probability: the estimates can be off by orders of
//! magnitude (an enclosed room under a bright sky, a lamp far outside the bounds), and a light
//! that is never picked leaves only BSDF sampling to find it.

mod area;
mod distribution;
pub mod environment;
#[cfg(test)]
mod tests;

use crate::geometry::Mesh;
use crate::material::Material;
use crate::texture::Texture;
pub(crate) use area::{connect_parts, TriangleLight};
use distribution::Distribution1D;
use environment::EnvLight;
use glam::{Vec2, Vec3};

/// The environment seen by rays that leave the scene.
#[derive(Clone, Debug)]
pub enum Environment {
    /// Same radiance in every direction (black = no environment light).
    Constant(Vec3),
    /// Lat-long (equirectangular) map. Direction convention (y up): see `light::environment`.
    Map { image: Texture, rotation_deg: f32, scale: f32 },
}

/// The environment as the lights hold it: sanitised, with the map's `scale` applied (what a
/// scene exporter writes out; `light::environment` documents the map's convention).
pub enum EnvironmentView<'a> {
    Black,
    Constant(Vec3),
    /// `texels` row-major from the zenith row; `d_world = R_y(α) · d_map` with cos α, sin α.
    Map {
        width: usize,
        height: usize,
        texels: &'a [Vec3],
        cos_rot: f32,
        sin_rot: f32,
    },
}

/// A sampled point on a light, as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point to the light.
    pub wi: Vec3,
    /// Distance to the light point (f32::INFINITY for the environment).
    pub dist: f32,
    /// Emitted radiance arriving along `-wi` (before any MIS or pdf division).
    pub radiance: Vec3,
    /// Solid-angle density of this sample, selection probability included. > 0.
    pub pdf: f32,
    /// The triangle sampled, or `None` for the environment.
    pub prim: Option<u32>,
}

/// Smallest selection probability of the environment, and of all triangles together, when both
/// exist.
pub const MIN_KIND_SHARE: f32 = 0.1;

/// All lights of a scene.
pub struct Lights {
    triangles: Vec<TriangleLight>,
    /// Light index of each mesh triangle, `u32::MAX` for triangles that are not lights.
    prim_to_light: Vec<u32>,
    env: EnvLight,
    /// Over `triangles` followed by the environment (if it is not black). `None` = no lights.
    select: Option<Distribution1D>,
    /// `select`'s `pmf` of each of its cells, which every light sample and MIS weight needs.
    select_pmf: Vec<f32>,
}

impl Lights {
    /// Collects the emissive triangles of positive area and the environment; the mesh bounds
    /// set the scale of the environment's power estimate.
    pub fn build(mesh: &Mesh, materials: &[Material], env: Environment) -> Lights {
        let mut triangles = Vec::new();
        let mut prim_to_light = vec![u32::MAX; mesh.triangles.len()];
        for (i, &m) in mesh.material.iter().enumerate().take(mesh.triangles.len()) {
            let Some(mat) = materials.get(m as usize) else { continue };
            if !mat.is_emissive() {
                continue;
            }
            let area = mesh.area(i);
            let normal = mesh.geometric_normal(i);
            let light = TriangleLight {
                prim: i as u32,
                area,
                emission: mat.emission,
                two_sided: mat.two_sided_emission,
                normal,
                vertices: mesh.triangle(i),
                max_emission: mat.emission.max_element(),
            };
            let power = light.power();
            // Zero-area triangles can never be sampled; non-finite emission has no meaningful pdf.
            if !(area > 0.0) || normal == Vec3::ZERO || !(power > 0.0) || !power.is_finite() {
                continue;
            }
            prim_to_light[i] = triangles.len() as u32;
            triangles.push(light);
        }
        let env = EnvLight::new(env);
        let (lo, hi) = mesh.bounds();
        let r = 0.5 * (hi - lo).length();
        let r = if r.is_finite() && r > 0.0 { r } else { 1.0 };

        let tri_power: Vec<f64> = triangles.iter().map(|t| t.power()).collect();
        let tri_total: f64 = tri_power.iter().sum();
        let env_power = if env.is_black() { 0.0 } else { env.power(r) };
        let env_share = match (tri_total > 0.0, !env.is_black()) {
            (_, false) => 0.0,
            (false, true) => 1.0,
            (true, true) => {
                let s = env_power / (env_power + tri_total);
                let s = if s.is_finite() { s } else { 0.5 };
                s.clamp(MIN_KIND_SHARE as f64, 1.0 - MIN_KIND_SHARE as f64)
            }
        };
        let mut weights: Vec<f64> =
            if tri_total > 0.0 { tri_power.iter().map(|p| p / tri_total * (1.0 - env_share)).collect() } else { Vec::new() };
        if !env.is_black() {
            weights.push(env_share);
        }
        let select = Distribution1D::new(weights);
        let select_pmf = select.as_ref().map_or(Vec::new(), |s| (0..=triangles.len()).map(|i| s.pmf(i)).collect());
        Lights { triangles, prim_to_light, env, select, select_pmf }
    }

    /// True if there is nothing to sample (no emissive triangle of positive area, black env).
    pub fn is_empty(&self) -> bool {
        self.select.is_none()
    }

    /// Selection probability of the environment.
    fn env_pmf(&self) -> f32 {
        match &self.select {
            Some(_) if !self.env.is_black() => self.select_pmf[self.triangles.len()],
            _ => 0.0,
        }
    }

    /// Picks a light with `u_select` and a point on it with `u`, as seen from `p`.
    pub fn sample(&self, p: Vec3, u_select: f32, u: Vec2) -> Option<LightSample> {
        let i = self.select.as_ref()?.sample_index(u_select);
        let pmf = self.select_pmf[i];
        if !(pmf > 0.0) {
            return None;
        }
        if i == self.triangles.len() {
            let (wi, pdf, radiance) = self.env.sample(u)?;
            let pdf = pmf * pdf;
            // A direction between texels can filter to black: not worth a shadow ray.
            let useful = pdf > 0.0 && pdf.is_finite() && radiance.max_element() > 0.0 && wi.is_finite();
            return useful.then_some(LightSample { wi, dist: f32::INFINITY, radiance, pdf, prim: None });
        }
        let light = &self.triangles[i];
        let [p0, p1, p2] = light.vertices;
        let b = crate::sampling::square_to_triangle(u);
        let p_light = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
        let (wi, dist, pdf) = light.connect(p, p_light, light.normal, pmf)?;
        Some(LightSample { wi, dist, radiance: light.emission, pdf, prim: Some(light.prim) })
    }

    /// True when only emissive triangles can be picked by `sample` (the environment is black or
    /// there are no lights): what the wavefront integrator (`integrator::wave`) handles.
    pub(crate) fn triangles_only(&self) -> bool {
        self.env.is_black()
    }

    /// The light selection of `sample` for a scene whose lights are all triangles: the light
    /// picked with `u_select` and its selection probability, or `None` where `sample` returns
    /// `None` before looking at the light.
    #[inline]
    pub(crate) fn select_triangle(&self, u_select: f32) -> Option<(&TriangleLight, f32)> {
        let i = self.select.as_ref()?.sample_index(u_select);
        let pmf = self.select_pmf[i];
        if !(pmf > 0.0) {
            return None;
        }
        self.triangles.get(i).map(|t| (t, pmf))
    }

    /// Density (solid angle, selection included) with which `sample` from `p` would pick point
    /// `p_light` on emissive triangle `prim` (whose geometric normal is `n_light`).
    pub fn pdf_triangle(&self, prim: u32, p: Vec3, p_light: Vec3, n_light: Vec3) -> f32 {
        let Some(&li) = self.prim_to_light.get(prim as usize) else { return 0.0 };
        let (Some(light), Some(&pmf)) = (self.triangles.get(li as usize), self.select_pmf.get(li as usize)) else { return 0.0 };
        light.connect(p, p_light, n_light, pmf).map_or(0.0, |(_, _, pdf)| pdf)
    }

    /// The environment light, as rendered.
    pub fn environment(&self) -> EnvironmentView<'_> {
        self.env.view()
    }

    /// Radiance of the environment along world direction `dir` (pointing away from the scene).
    pub fn env_radiance(&self, dir: Vec3) -> Vec3 {
        self.env.radiance(dir)
    }

    /// `env_radiance(dir)` and, if `want_pdf`, `env_pdf(dir)` (else 0), for the price of one.
    pub fn env_radiance_pdf(&self, dir: Vec3, want_pdf: bool) -> (Vec3, f32) {
        let pmf = self.env_pmf();
        let (radiance, pdf) = self.env.radiance_pdf(dir, want_pdf && pmf > 0.0);
        (radiance, if pmf > 0.0 { pmf * pdf } else { 0.0 })
    }

    /// Density (solid angle, selection included) with which `sample` picks environment direction `dir`.
    pub fn env_pdf(&self, dir: Vec3) -> f32 {
        let pmf = self.env_pmf();
        if pmf > 0.0 {
            pmf * self.env.pdf(dir)
        } else {
            0.0
        }
    }
}
