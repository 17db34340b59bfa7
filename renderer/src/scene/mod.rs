//! Scenes: what a render needs (camera, settings, geometry, materials, lights), loaded from our
//! TOML format, from glTF/GLB, or from Mitsuba XML.

use crate::camera::Camera;
use crate::geometry::{Accel, Hit, Mesh};
use crate::light::{Environment, Lights};
use crate::material::{Bsdf, Distribution, MIN_ALPHA};
use crate::math::Ray;
use crate::texture::Texture;
use crate::{Error, Result};
use glam::{Affine2, Vec2, Vec3};
use std::path::{Path, PathBuf};

mod builder;
pub mod gltf_format;
pub mod image_io;
pub mod mitsuba;
pub mod obj;
pub mod primitives;
pub mod procedural;
pub mod toml_format;

pub use builder::{MAX_RESOLUTION_PIXELS, MAX_RESOLUTION_SIDE};

/// A colour that is constant or varies over a surface with its texture coordinates. Every
/// colour parameter of a material (albedo, a conductor's tint) is one of these, and
/// `ColorParam::eval` is the one place they are looked up.
#[derive(Clone, Debug)]
pub enum ColorParam {
    Const(Vec3),
    /// `textures[index]` times `scale`, bilinear and repeating, looked up at `to_uv(uv)`.
    Texture { index: u32, scale: Vec3, to_uv: Affine2 },
    /// Mitsuba's `checkerboard`: with (s, t) = `to_uv(uv)`, `color0` where the fractional parts
    /// of s and t are on the same side of ½ (both ≤ ½ or both > ½), else `color1`; so
    /// uv (0, 0) is `color0` and one period of the pattern spans one unit of s and t.
    Checkerboard { color0: Vec3, color1: Vec3, to_uv: Affine2 },
}

impl ColorParam {
    /// An image texture times `scale`, with the texture coordinates as they are.
    pub fn texture(index: u32, scale: Vec3) -> ColorParam {
        ColorParam::Texture { index, scale, to_uv: Affine2::IDENTITY }
    }

    /// The colour at texture coordinate `uv`.
    pub fn eval(&self, uv: Vec2, textures: &[Texture]) -> Vec3 {
        match self {
            ColorParam::Const(v) => *v,
            ColorParam::Texture { index, scale, to_uv } => textures[*index as usize].sample_bilinear(to_uv.transform_point2(uv)) * *scale,
            ColorParam::Checkerboard { color0, color1, to_uv } => {
                let p = to_uv.transform_point2(uv);
                if (p.x - p.x.floor() > 0.5) == (p.y - p.y.floor() > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
        }
    }

    /// Whether the colour varies over a surface.
    pub fn is_textured(&self) -> bool {
        !matches!(self, ColorParam::Const(_))
    }
}

/// The BSDF of a material, before texture lookups.
#[derive(Clone, Debug)]
pub enum MaterialKind {
    Lambert { albedo: ColorParam },
    Conductor { eta: Vec3, k: Vec3, roughness: f32, specular_tint: ColorParam, dist: Distribution },
    Dielectric { ior: f32, roughness: f32, tint: Vec3, dist: Distribution },
    /// `nonlinear`: see `Bsdf::Plastic` (true in our formats; Mitsuba's `nonlinear`, default false).
    Plastic { albedo: ColorParam, ior: f32, roughness: f32, dist: Distribution, nonlinear: bool },
}

/// A named material. `roughness` values above are GGX alpha. Non-zero `emission` makes every
/// triangle with this material an area light, emitting on the side of its geometric normal
/// (both sides if `two_sided_emission`).
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub kind: MaterialKind,
    pub emission: Vec3,
    pub two_sided_emission: bool,
    /// Reflect only on the front side (the winding normal's side), black from behind, as
    /// Mitsuba's BSDFs are unless wrapped in `twosided`. False (both sides alike) in our formats;
    /// transmissive BSDFs ignore it.
    pub one_sided: bool,
}

impl Material {
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// Emitted radiance leaving the surface with geometric normal `ng` in direction `w`.
    pub fn emitted(&self, ng: Vec3, w: Vec3) -> Vec3 {
        if self.two_sided_emission || ng.dot(w) > 0.0 {
            self.emission
        } else {
            Vec3::ZERO
        }
    }

    /// The BSDF at texture coordinate `uv`.
    pub fn bsdf(&self, uv: Vec2, textures: &[Texture]) -> Bsdf {
        let color = |c: &ColorParam| c.eval(uv, textures);
        let alpha = |r: f32| if r < MIN_ALPHA { 0.0 } else { r.min(1.0) };
        match &self.kind {
            MaterialKind::Lambert { albedo } => Bsdf::Lambert { albedo: color(albedo).clamp(Vec3::ZERO, Vec3::ONE) },
            MaterialKind::Conductor { eta, k, roughness, specular_tint, dist } => {
                Bsdf::Conductor { eta: *eta, k: *k, alpha: alpha(*roughness), specular_tint: color(specular_tint).min(Vec3::ONE), dist: *dist }
            }
            MaterialKind::Dielectric { ior, roughness, tint, dist } => Bsdf::Dielectric { eta: *ior, alpha: alpha(*roughness), tint: *tint, dist: *dist },
            MaterialKind::Plastic { albedo, ior, roughness, dist, nonlinear } => Bsdf::Plastic {
                albedo: color(albedo).clamp(Vec3::ZERO, Vec3::ONE),
                eta: *ior,
                alpha: alpha(*roughness),
                dist: *dist,
                nonlinear: *nonlinear,
            },
        }
    }
}

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
        Ok(Scene { source, camera, settings, mesh, materials, textures, accel, lights, radius })
    }

    /// Loads a scene file, choosing the loader by extension (.toml, .gltf/.glb, .xml).
    pub fn load(path: &Path) -> Result<Scene> {
        let desc = load_description(path)?;
        Scene::new(path, desc)
    }

    /// Surface geometry of a hit returned by `accel.intersect(ray, ..)`.
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> SurfaceHit {
        let i = hit.prim as usize;
        let [a, b, c] = self.mesh.triangles[i];
        let (a, b, c) = (a as usize, b as usize, c as usize);
        let (b1, b2) = (hit.bary.x, hit.bary.y);
        let b0 = 1.0 - b1 - b2;
        let m = &self.mesh;
        // Barycentric interpolation is more precise than ray.at(t) far from the origin.
        let p = m.positions[a] * b0 + m.positions[b] * b1 + m.positions[c] * b2;
        let p = if p.is_finite() { p } else { ray.at(hit.t) };
        let ng = m.geometric_normal(i);
        let ns = if m.normals.is_empty() {
            ng
        } else {
            let n = m.normals[a] * b0 + m.normals[b] * b1 + m.normals[c] * b2;
            let n = n.normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() { ng } else { n }
        };
        let uv = if m.uvs.is_empty() { Vec2::ZERO } else { m.uvs[a] * b0 + m.uvs[b] * b1 + m.uvs[c] * b2 };
        SurfaceHit { p, ng, ns, uv, prim: hit.prim, material: m.material[i] }
    }
}

/// Dispatches on the file extension to a loader: `.toml` (our format, docs/scene-format.md),
/// `.gltf`/`.glb`, `.xml` (Mitsuba, `mitsuba.rs`).
pub fn load_description(path: &Path) -> Result<SceneDescription> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("toml") => toml_format::load(path),
        Some("gltf") | Some("glb") => gltf_format::load_scene(path),
        Some("xml") => mitsuba::load(path),
        _ => Err(Error::scene(path, "file", "unknown scene format (expected .toml, .gltf, .glb or Mitsuba .xml)")),
    }
}
