//! Scenes: what a render needs (camera, settings, geometry, materials, lights), loaded from our
//! TOML format, from glTF/GLB, or from Mitsuba XML.

use crate::camera::Camera;
use crate::geometry::{Accel, Hit, Mesh};
use crate::light::{Environment, Lights};
use crate::math::Ray;
use crate::texture::Texture;
use crate::{Error, Result};
use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};

mod builder;
pub mod gltf_format;
pub mod image_io;
pub mod mitsuba;
mod mitsuba_export;
pub mod obj;
pub mod primitives;
pub mod procedural;
pub mod toml_format;

pub use builder::{MAX_RESOLUTION_PIXELS, MAX_RESOLUTION_SIDE};
pub use mitsuba_export::export_mitsuba;
// Materials live in `crate::material` (the light structures use them too); scenes hold them.
pub use crate::material::{ColorParam, Material, MaterialKind};

/// Render settings stored with a scene; the command line may override them.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub spp: u32,
    /// Maximum number of scattering events; a path has at most `max_bounces + 1` vertices.
    pub max_bounces: u32,
    pub seed: u64,
    /// Russian roulette after the third bounce (off by default: it adds noise the denoiser's
    /// training data does not have).
    pub russian_roulette: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings { spp: 16, max_bounces: 5, seed: 0, russian_roulette: false }
    }
}

/// Everything a loader produces, before acceleration structures are built.
pub struct SceneDescription {
    pub camera: Camera,
    pub settings: RenderSettings,
    pub mesh: Mesh,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub environment: Environment,
}

/// A scene ready to render.
pub struct Scene {
    pub source: PathBuf,
    pub camera: Camera,
    pub settings: RenderSettings,
    pub mesh: Mesh,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub accel: Accel,
    pub lights: Lights,
    /// Largest extent of the mesh bounds (depth normalisation, method.md §1.1).
    pub radius: f32,
    /// `mesh.geometric_normal(i)` of every triangle, computed once: every hit needs it, and
    /// recomputing it (cross product, square root, vertex-normal vote) was 5% of render time.
    geometric_normals: Vec<Vec3>,
}

/// Geometry at a ray hit.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub p: Vec3,
    /// Unit geometric normal (see `Mesh::geometric_normal`).
    pub ng: Vec3,
    /// Unit interpolated shading normal (equal to `ng` without vertex normals).
    pub ns: Vec3,
    pub uv: Vec2,
    pub prim: u32,
    pub material: u32,
    /// Largest vertex coordinate of the triangle, in absolute value: the scale of `p`'s
    /// rounding error, for `geometry::offset_ray_origin`.
    pub extent: f32,
}

impl Scene {
    /// Builds the BVH and the light structures. Fails on an empty or non-finite mesh.
    pub fn new(source: impl Into<PathBuf>, desc: SceneDescription) -> Result<Scene> {
        let source = source.into();
        let SceneDescription { camera, settings, mesh, materials, textures, environment } = desc;
        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::scene(&source, format!("vertex {i}"), "position is not finite"));
        }
        if let Some((i, _)) = mesh.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&v| v as usize >= mesh.positions.len())) {
            return Err(Error::scene(&source, format!("triangle {i}"), "vertex index out of range"));
        }
        if let Some(&m) = mesh.material.iter().find(|&&m| m as usize >= materials.len()) {
            return Err(Error::scene(&source, "material", format!("material index {m} out of range")));
        }
        let (lo, hi) = mesh.bounds();
        let radius = (hi - lo).max_element().max(1e-6);
        let accel = Accel::build(&mesh);
        let lights = Lights::build(&mesh, &materials, environment);
        let geometric_normals = (0..mesh.triangles.len()).map(|i| mesh.geometric_normal(i)).collect();
        Ok(Scene { source, camera, settings, mesh, materials, textures, accel, lights, radius, geometric_normals })
    }

    /// Loads a scene file, choosing the loader by extension (.toml, .gltf/.glb, .xml).
    pub fn load(path: &Path) -> Result<Scene> {
        let desc = load_description(path)?;
        Scene::new(path, desc)
    }

    /// As [`Scene::load`], but a feature the loader would replace by an approximation (each
    /// named by its file, line and substitution) is an error instead of a warning.
    pub fn load_strict(path: &Path) -> Result<Scene> {
        let (desc, refused) = builder::collecting_substitutions(|| load_description(path));
        let desc = desc?;
        if !refused.is_empty() {
            let list = refused.iter().map(|m| format!("\n  {m}")).collect::<String>();
            return Err(Error::scene(path, "strict", format!("{} substitution(s) refused:{list}", refused.len())));
        }
        Scene::new(path, desc)
    }

    /// Surface geometry of a hit returned by `accel.intersect(ray, ..)`.
    #[inline]
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> SurfaceHit {
        self.surface_inline(ray, hit)
    }

    /// `surface`, always inlined (the wavefront's hit stage).
    #[inline(always)]
    pub(crate) fn surface_inline(&self, ray: &Ray, hit: &Hit) -> SurfaceHit {
        let i = hit.prim as usize;
        let [a, b, c] = self.mesh.triangles[i];
        let (a, b, c) = (a as usize, b as usize, c as usize);
        let (b1, b2) = (hit.bary.x, hit.bary.y);
        let b0 = 1.0 - b1 - b2;
        let m = &self.mesh;
        // Barycentric interpolation is more precise than ray.at(t) far from the origin.
        let (pa, pb, pc) = (m.positions[a], m.positions[b], m.positions[c]);
        let p = pa * b0 + pb * b1 + pc * b2;
        let p = if p.is_finite() { p } else { ray.at(hit.t) };
        let extent = pa.abs().max(pb.abs()).max(pc.abs()).max_element();
        let ng = self.geometric_normals[i];
        let ns = if m.normals.is_empty() {
            ng
        } else {
            let n = m.normals[a] * b0 + m.normals[b] * b1 + m.normals[c] * b2;
            let n = n.normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                ng
            } else {
                n
            }
        };
        let uv = if m.uvs.is_empty() { Vec2::ZERO } else { m.uvs[a] * b0 + m.uvs[b] * b1 + m.uvs[c] * b2 };
        SurfaceHit { p, ng, ns, uv, prim: hit.prim, material: m.material[i], extent }
    }
}

/// Dispatches on the file extension to a loader: `.toml` (our format, docs/scene-format.md),
/// `.gltf`/`.glb`, `.xml` (Mitsuba, `mitsuba/`).
pub fn load_description(path: &Path) -> Result<SceneDescription> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("toml") => toml_format::load(path),
        Some("gltf") | Some("glb") => gltf_format::load_scene(path),
        Some("xml") => mitsuba::load(path),
        _ => Err(Error::scene(path, "file", "unknown scene format (expected .toml, .gltf, .glb or Mitsuba .xml)")),
    }
}
