//! Light sources for next-event estimation: emissive triangles (area lights) and the
//! environment (constant colour or an importance-sampled lat-long map).
//!
//! Light selection picks one light per NEE sample with probability proportional to an estimate
//! of its power; every pdf this module returns is a solid-angle density that already includes
//! that selection probability, so the integrator's MIS weights need nothing else.

use crate::geometry::Mesh;
use crate::scene::Material;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// The environment seen by rays that leave the scene.
#[derive(Clone, Debug)]
pub enum Environment {
    /// Same radiance in every direction (black = no environment light).
    Constant(Vec3),
    /// Lat-long (equirectangular) map. Direction convention (y up): see `light::environment`.
    Map { image: Texture, rotation_deg: f32, scale: f32 },
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

/// All lights of a scene.
pub struct Lights {
    _private: (),
}

impl Lights {
    /// `scene_bounds` are the mesh bounds (used for the environment's power estimate).
    pub fn build(mesh: &Mesh, materials: &[Material], env: Environment) -> Lights {
        let _ = (mesh, materials, env);
        todo!("light helper")
    }

    /// True if there is nothing to sample (no emissive triangle of positive area, black env).
    pub fn is_empty(&self) -> bool {
        todo!("light helper")
    }

    /// Picks a light with `u_select` and a point on it with `u`, as seen from `p`.
    pub fn sample(&self, mesh: &Mesh, p: Vec3, u_select: f32, u: Vec2) -> Option<LightSample> {
        let _ = (mesh, p, u_select, u);
        todo!("light helper")
    }

    /// Density (solid angle, selection included) with which `sample` from `p` would pick point
    /// `p_light` on emissive triangle `prim` (whose geometric normal is `n_light`).
    pub fn pdf_triangle(&self, mesh: &Mesh, prim: u32, p: Vec3, p_light: Vec3, n_light: Vec3) -> f32 {
        let _ = (mesh, prim, p, p_light, n_light);
        todo!("light helper")
    }

    /// Radiance of the environment along world direction `dir` (pointing away from the scene).
    pub fn env_radiance(&self, dir: Vec3) -> Vec3 {
        let _ = dir;
        todo!("light helper")
    }

    /// Density (solid angle, selection included) with which `sample` picks environment direction `dir`.
    pub fn env_pdf(&self, dir: Vec3) -> f32 {
        let _ = dir;
        todo!("light helper")
    }
}
