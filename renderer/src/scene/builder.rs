//! Assembly of a [`SceneDescription`] shared by the loaders: validated meshes appended to one
//! soup, materials and textures collected with stable indices, and the final checks (non-empty
//! scene, sane camera, a warning when nothing emits light).

use super::image_io;
use super::primitives::TriMesh;
use super::{ColorParam, Material, MaterialKind, RenderSettings, SceneDescription};
use crate::camera::Camera;
use crate::geometry::Mesh;
use crate::light::Environment;
use crate::texture::Texture;
use crate::{Error, Result};
use glam::Vec3;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Largest accepted image side and pixel count of a render (shared with the EXR reader).
pub use ::film::{MAX_RESOLUTION_PIXELS, MAX_RESOLUTION_SIDE};

/// Vertical field of view (degrees) of a camera made up to frame the scene.
pub const FRAMING_FOV_DEG: f32 = 40.0;

thread_local! {
    /// The substitutions of a strict load on this thread (`Scene::load_strict`); `None` when
    /// loading normally, where they are printed as warnings.
    static REFUSED: std::cell::RefCell<Option<Vec<String>>> = const { std::cell::RefCell::new(None) };
}

/// A feature the loader does not model and replaces by something close: printed as a warning, or
/// collected during a strict load, which then fails with all of them.
pub(crate) fn warn(file: &Path, message: impl std::fmt::Display) {
    let message = format!("{}: {message}", file.display());
    let collected = REFUSED.with(|r| r.borrow_mut().as_mut().map(|v| v.push(message.clone())).is_some());
    if !collected {
        eprintln!("warning: {message}");
    }
}

/// Runs `load` collecting its substitutions instead of printing them; returns them with the result.
pub(crate) fn collecting_substitutions<T>(load: impl FnOnce() -> T) -> (T, Vec<String>) {
    REFUSED.with(|r| *r.borrow_mut() = Some(Vec::new()));
    let out = load();
    let refused = REFUSED.with(|r| r.borrow_mut().take()).unwrap_or_default();
    (out, refused)
}

pub(crate) struct Builder {
    /// The scene file, named by every error.
    pub file: PathBuf,
    pub mesh: Mesh,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    texture_cache: HashMap<PathBuf, u32>,
    default_material: Option<u32>,
}

impl Builder {
    pub fn new(file: &Path) -> Builder {
        Builder {
            file: file.to_path_buf(),
            mesh: Mesh::default(),
            materials: Vec::new(),
            textures: Vec::new(),
            texture_cache: HashMap::new(),
            default_material: None,
        }
    }

    pub fn add_material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }

    /// A grey Lambertian used where a file names no material (or an unknown one).
    pub fn default_material(&mut self) -> u32 {
        if let Some(i) = self.default_material {
            return i;
        }
        let i = self.add_material(Material {
            name: "default".into(),
            kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::splat(0.5)) },
            emission: Vec3::ZERO,
            two_sided_emission: false,
            one_sided: false,
        });
        self.default_material = Some(i);
        i
    }

    pub fn add_texture(&mut self, t: Texture) -> u32 {
        self.textures.push(t);
        (self.textures.len() - 1) as u32
    }

    /// Loads (once per path) an albedo texture referenced by `field`.
    pub fn albedo_texture(&mut self, path: &Path, field: &str) -> Result<u32> {
        if let Some(&i) = self.texture_cache.get(path) {
            return Ok(i);
        }
        let t = image_io::load_image(path, &self.file, field)?;
        let i = self.add_texture(t);
        self.texture_cache.insert(path.to_path_buf(), i);
        Ok(i)
    }

    /// Appends a world-space mesh. Non-finite data is an error naming `field`; degenerate
    /// triangles are kept (the BVH skips them).
    pub fn add_mesh(&mut self, m: &TriMesh, material: u32, field: &str) -> Result<()> {
        let n = m.positions.len();
        if let Some(i) = m.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::scene(
                &self.file,
                field,
                format!("vertex {i} position {} is not finite (after the transform)", m.positions[i]),
            ));
        }
        if let Some(i) = m.normals.iter().position(|p| !p.is_finite()) {
            return Err(Error::scene(&self.file, field, format!("vertex {i} normal is not finite")));
        }
        if let Some(i) = m.uvs.iter().position(|p| !p.is_finite()) {
            return Err(Error::scene(&self.file, field, format!("vertex {i} texture coordinate is not finite")));
        }
        if let Some(t) = m.triangles.iter().find(|t| t.iter().any(|&v| v as usize >= n)) {
            return Err(Error::scene(&self.file, field, format!("triangle {t:?} indexes past the {n} vertices")));
        }
        if self.mesh.positions.len() + n > u32::MAX as usize {
            return Err(Error::scene(&self.file, field, "more than 2^32 vertices in the scene"));
        }
        let normals: &[Vec3] = if m.normals.len() == n { &m.normals } else { &[] };
        let uvs = if m.uvs.len() == n { &m.uvs[..] } else { &[] };
        self.mesh.append(&m.positions, normals, uvs, &m.triangles, material);
        Ok(())
    }

    /// A camera looking at the centre of the mesh bounds along −Z from far enough to see them all.
    pub fn framing_camera(&self, width: u32, height: u32) -> Result<Camera> {
        let (lo, hi) = self.mesh.bounds();
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-3);
        let aspect = width as f32 / height.max(1) as f32;
        // Fit the bounding sphere into the narrower of the two fields of view.
        let half_v = (FRAMING_FOV_DEG.to_radians() * 0.5).tan();
        let half = half_v.min(half_v * aspect).atan();
        let dist = radius / half.sin() * 1.05;
        Camera::look_at(centre + Vec3::Z * dist, centre, Vec3::Y, FRAMING_FOV_DEG, width, height)
            .ok_or_else(|| Error::scene(&self.file, "camera", "cannot frame the scene bounds"))
    }

    pub fn finish(self, camera: Camera, settings: RenderSettings, environment: Environment) -> Result<SceneDescription> {
        if self.mesh.triangles.is_empty() {
            return Err(Error::scene(&self.file, "shapes", "the scene has no triangles"));
        }
        let emitters = self.mesh.material.iter().any(|&m| self.materials[m as usize].is_emissive());
        let env_black = match &environment {
            Environment::Constant(c) => c.max_element() <= 0.0,
            Environment::Map { scale, image, .. } => *scale <= 0.0 || image.texels.iter().all(|t| t.max_element() <= 0.0),
        };
        if !emitters && env_black {
            warn(&self.file, "no emissive material on any triangle and a black environment: the render will be black");
        }
        Ok(SceneDescription { camera, settings, mesh: self.mesh, materials: self.materials, textures: self.textures, environment })
    }
}

/// Checks a render resolution against the limits documented in docs/scene-format.md.
pub fn check_resolution(file: &Path, field: &str, w: u32, h: u32) -> Result<()> {
    if w == 0 || h == 0 {
        return Err(Error::scene(file, field, format!("resolution {w}×{h} has a zero side")));
    }
    if w > MAX_RESOLUTION_SIDE || h > MAX_RESOLUTION_SIDE {
        return Err(Error::scene(file, field, format!("resolution {w}×{h} exceeds {MAX_RESOLUTION_SIDE} per side")));
    }
    if w as u64 * h as u64 > MAX_RESOLUTION_PIXELS {
        return Err(Error::scene(file, field, format!("resolution {w}×{h} exceeds 2^26 pixels")));
    }
    Ok(())
}
