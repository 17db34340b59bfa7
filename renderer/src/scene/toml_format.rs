//! Our native scene format (TOML). The full reference with defaults and units is
//! `docs/scene-format.md`; a minimal scene:
//!
//! ```toml
//! [camera]
//! position = [0, 1, 3.5]
//! target = [0, 1, 0]
//! fov = 40
//! resolution = [256, 256]
//!
//! [materials.white]
//! type = "diffuse"
//! albedo = [0.8, 0.8, 0.8]
//!
//! [materials.lamp]
//! type = "diffuse"
//! albedo = [0, 0, 0]
//! emission = [10, 10, 10]
//!
//! [[shapes]]
//! type = "sphere"
//! material = "white"
//!
//! [[shapes]]
//! type = "quad"
//! material = "lamp"
//! translate = [0, 3, 0]
//! rotate = [90, 0, 0]
//! ```
//!
//! Every table denies unknown keys, so a misspelt key is an error rather than a silent default.

use super::builder::{check_resolution, warn, Builder};
use super::obj::MaterialChoice;
use super::{gltf_format, image_io, obj, primitives, procedural};
use super::{ColorParam, Material, MaterialKind, RenderSettings, SceneDescription};
use crate::camera::Camera;
use crate::light::Environment;
use crate::{Error, Result};
use glam::{Mat3, Mat4, Vec3};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Default tessellation of spheres and disks (segments around the axis).
pub const DEFAULT_SEGMENTS: u32 = 64;
/// Largest accepted tessellation (a sphere of 4096 segments already has 16.7 M triangles).
pub const MAX_SEGMENTS: u32 = 4096;

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub camera: Option<CameraDef>,
    #[serde(default)]
    pub render: RenderDef,
    #[serde(default)]
    pub materials: BTreeMap<String, MaterialDef>,
    #[serde(default)]
    pub shapes: Vec<ShapeDef>,
    pub environment: Option<EnvironmentDef>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct CameraDef {
    pub position: [f32; 3],
    pub target: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    /// Vertical field of view in degrees.
    #[serde(default = "default_fov")]
    pub fov: f32,
    #[serde(default = "default_resolution")]
    pub resolution: [u32; 2],
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f32 {
    40.0
}
fn default_resolution() -> [u32; 2] {
    [512, 512]
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields, default)]
pub struct RenderDef {
    pub spp: u32,
    pub max_bounces: u32,
    pub seed: u64,
    pub russian_roulette: bool,
}

impl Default for RenderDef {
    fn default() -> Self {
        let d = RenderSettings::default();
        RenderDef { spp: d.spp, max_bounces: d.max_bounces, seed: d.seed, russian_roulette: d.russian_roulette }
    }
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum MaterialType {
    Diffuse,
    Conductor,
    Dielectric,
    Plastic,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct MaterialDef {
    #[serde(rename = "type")]
    pub kind: MaterialType,
    pub albedo: Option<[f32; 3]>,
    pub albedo_texture: Option<String>,
    pub roughness: Option<f32>,
    pub ior: Option<f32>,
    /// Named conductor: one of [`CONDUCTOR_PRESETS`].
    pub preset: Option<String>,
    pub eta: Option<[f32; 3]>,
    pub k: Option<[f32; 3]>,
    pub specular_tint: Option<[f32; 3]>,
    /// Image whose texels multiply `specular_tint` over the surface (patinated, engraved or
    /// inlaid metals); texels must lie in [0, 1] like the tint itself.
    pub specular_tint_texture: Option<String>,
    pub tint: Option<[f32; 3]>,
    pub emission: Option<[f32; 3]>,
    pub strength: Option<f32>,
    pub two_sided_emission: Option<bool>,
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ShapeType {
    Obj,
    Gltf,
    Quad,
    Cube,
    Sphere,
    Disk,
    Lathe,
    Heightfield,
    Grid,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct ShapeDef {
    #[serde(rename = "type")]
    pub kind: ShapeType,
    pub file: Option<String>,
    pub material: Option<String>,
    /// File material name → scene material name (obj, gltf).
    pub materials_override: Option<BTreeMap<String, String>>,
    pub radius: Option<f32>,
    pub segments: Option<u32>,
    pub translate: Option<[f32; 3]>,
    pub rotate: Option<Rotate>,
    pub scale: Option<Scale>,
    /// Row-major 4×4 matrix (rows as written), applied before scale, rotate and translate.
    pub matrix: Option<[[f32; 4]; 4]>,
    /// Procedural shapes (`procedural.rs`): lathe.
    pub profile: Option<Vec<[f32; 2]>>,
    /// heightfield
    pub resolution: Option<[u32; 2]>,
    pub amplitude: Option<f32>,
    pub frequency: Option<f32>,
    pub octaves: Option<u32>,
    pub seed: Option<u32>,
    /// grid
    pub element: Option<String>,
    pub count: Option<[u32; 3]>,
    pub spacing: Option<[f32; 3]>,
    pub element_scale: Option<Scale>,
}

/// Euler angles in degrees `[x, y, z]` (applied about X, then Y, then Z, fixed axes), or an
/// axis and an angle in degrees.
#[derive(Deserialize, Debug)]
#[serde(untagged, expecting = "Euler degrees [x, y, z] or { axis = [x, y, z], angle = degrees }")]
pub enum Rotate {
    Euler([f32; 3]),
    AxisAngle(AxisAngle),
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct AxisAngle {
    pub axis: [f32; 3],
    pub angle: f32,
}

#[derive(Deserialize, Debug)]
#[serde(untagged, expecting = "a number (uniform scale) or [x, y, z]")]
pub enum Scale {
    Uniform(f32),
    Xyz([f32; 3]),
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum EnvironmentType {
    Constant,
    Map,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentDef {
    #[serde(rename = "type")]
    pub kind: Option<EnvironmentType>,
    pub color: Option<[f32; 3]>,
    pub map: Option<String>,
    pub rotation: Option<f32>,
    pub scale: Option<f32>,
}

/// RGB complex IOR (η, k) of named conductors, integrated from measured spectra to linear sRGB
/// (the table Tungsten, Mitsuba and Nori use), digits kept as published.
#[allow(clippy::excessive_precision)]
pub const CONDUCTOR_PRESETS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("Ag", [0.1552646489, 0.1167232965, 0.1383806959], [4.8283433224, 3.1222459278, 2.1469504455]),
    ("Al", [1.6574599595, 0.8803689579, 0.5212287346], [9.2238691996, 6.2695232477, 4.8370012281]),
    ("Au", [0.1431189557, 0.3749570432, 1.4424785571], [3.9831604247, 2.3857207478, 1.6032152899]),
    ("Cr", [4.3696828663, 2.9167024892, 1.6547005413], [5.2064337956, 4.2313645277, 3.7549467933]),
    ("Cu", [0.2004376970, 0.9240334304, 1.1022119527], [3.9129485033, 2.4528477015, 2.1421879552]),
];

/// Loads a TOML scene file.
pub fn load(path: &Path) -> Result<SceneDescription> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let file: SceneFile = toml::from_str(&text).map_err(|e| toml_error(path, &text, &e))?;
    build(path, file)
}

/// A TOML error as "line L, column C" plus the offending line, so the key is visible even when
/// the parser's message names only a type.
fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> Error {
    let message = e.message().trim().to_string();
    match e.span() {
        Some(span) => {
            let start = span.start.min(text.len());
            let before = &text[..floor_char_boundary(text, start)];
            let line = before.matches('\n').count() + 1;
            let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            let line_text = text.lines().nth(line - 1).unwrap_or("").trim();
            Error::scene(path, format!("line {line}, column {col}"), format!("{message} (in `{line_text}`)"))
        }
        None => Error::scene(path, "toml", message),
    }
}

fn floor_char_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// Field checks that name the file and the field.
struct Check<'a> {
    file: &'a Path,
}

impl Check<'_> {
    fn err(&self, field: &str, message: impl Into<String>) -> Error {
        Error::scene(self.file, field, message)
    }
    fn finite(&self, field: &str, v: f32) -> Result<f32> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(field, format!("{v} is not a finite number")))
        }
    }
    fn nonneg(&self, field: &str, v: f32) -> Result<f32> {
        if self.finite(field, v)? < 0.0 {
            return Err(self.err(field, format!("{v} must not be negative")));
        }
        Ok(v)
    }
    fn positive(&self, field: &str, v: f32) -> Result<f32> {
        if self.finite(field, v)? <= 0.0 {
            return Err(self.err(field, format!("{v} must be positive")));
        }
        Ok(v)
    }
    fn vec3(&self, field: &str, v: [f32; 3]) -> Result<Vec3> {
        let v = Vec3::from(v);
        if !v.is_finite() {
            return Err(self.err(field, format!("{v} is not finite")));
        }
        Ok(v)
    }
    fn nonneg3(&self, field: &str, v: [f32; 3]) -> Result<Vec3> {
        let v = self.vec3(field, v)?;
        if v.min_element() < 0.0 {
            return Err(self.err(field, format!("{v} has a negative component")));
        }
        Ok(v)
    }
    /// A reflectance: above 1 a surface would create energy.
    fn unit3(&self, field: &str, v: [f32; 3]) -> Result<Vec3> {
        let v = self.nonneg3(field, v)?;
        if v.max_element() > 1.0 {
            return Err(self.err(field, format!("{v} exceeds 1 (a surface cannot reflect more than it receives)")));
        }
        Ok(v)
    }
}

fn build(path: &Path, file: SceneFile) -> Result<SceneDescription> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let check = Check { file: path };
    let mut b = Builder::new(path);

    let r = &file.render;
    if r.spp == 0 {
        return Err(check.err("render.spp", "must be at least 1"));
    }
    let settings = RenderSettings { spp: r.spp, max_bounces: r.max_bounces, seed: r.seed, russian_roulette: r.russian_roulette };

    let mut by_name: HashMap<String, u32> = HashMap::new();
    for (name, def) in &file.materials {
        let m = material(&check, &mut b, dir, name, def)?;
        by_name.insert(name.clone(), b.add_material(m));
    }
    let names = || file.materials.keys().map(String::as_str).collect::<Vec<_>>().join(", ");
    let lookup = |field: &str, name: &str| -> Result<u32> {
        by_name.get(name).copied().ok_or_else(|| check.err(field, format!("unknown material '{name}' (defined: {})", names())))
    };

    for (i, s) in file.shapes.iter().enumerate() {
        let f = |key: &str| format!("shapes[{i}].{key}");
        let transform = shape_transform(&check, i, s)?;
        let is_file = matches!(s.kind, ShapeType::Obj | ShapeType::Gltf);
        if !is_file {
            if s.file.is_some() {
                return Err(check.err(&f("file"), "only obj and gltf shapes read a file"));
            }
            if s.materials_override.is_some() {
                return Err(check.err(&f("materials_override"), "only obj and gltf shapes have file materials"));
            }
        }
        if !matches!(s.kind, ShapeType::Sphere | ShapeType::Disk) && s.radius.is_some() {
            return Err(check.err(&f("radius"), "only spheres and disks have a radius"));
        }
        if !matches!(s.kind, ShapeType::Sphere | ShapeType::Disk | ShapeType::Lathe | ShapeType::Grid) && s.segments.is_some() {
            return Err(check.err(&f("segments"), "only spheres, disks, lathes and grids have segments"));
        }
        procedural_keys_belong(&check, i, s)?;
        let radius = match s.radius {
            Some(r) => check.positive(&f("radius"), r)?,
            None => 1.0,
        };
        let segments = s.segments.unwrap_or(DEFAULT_SEGMENTS);
        if !(3..=MAX_SEGMENTS).contains(&segments) {
            return Err(check.err(&f("segments"), format!("{segments} is outside 3..={MAX_SEGMENTS}")));
        }
        let material = match &s.material {
            Some(name) => Some(lookup(&f("material"), name)?),
            None => None,
        };
        if is_file {
            let Some(rel) = &s.file else {
                return Err(check.err(&f("file"), "missing (obj and gltf shapes need a file)"));
            };
            let mut overrides = HashMap::new();
            if let Some(map) = &s.materials_override {
                if material.is_some() {
                    return Err(check.err(&f("materials_override"), "has no effect together with `material`"));
                }
                for (file_name, scene_name) in map {
                    overrides.insert(file_name.clone(), lookup(&format!("shapes[{i}].materials_override.{file_name}"), scene_name)?);
                }
            }
            let choice = MaterialChoice { all: material, by_name: &overrides };
            let p = dir.join(rel);
            if s.kind == ShapeType::Obj {
                obj::load(&mut b, &p, &transform, &choice, &f("file"))?;
            } else {
                gltf_format::load(&mut b, &p, &transform, &choice, &f("file"))?;
            }
        } else {
            let material = material.ok_or_else(|| check.err(&f("material"), "missing (built-in shapes need a material)"))?;
            let mesh = match s.kind {
                ShapeType::Quad => primitives::quad(),
                ShapeType::Cube => primitives::cube(),
                ShapeType::Sphere => primitives::sphere(radius, segments),
                ShapeType::Disk => primitives::disk(radius, segments),
                _ => procedural_mesh(&check, i, s, segments)?,
            };
            b.add_mesh(&mesh.transformed(&transform), material, &format!("shapes[{i}]"))?;
        }
    }

    let environment = match &file.environment {
        None => Environment::Constant(Vec3::ZERO),
        Some(e) => environment(&check, dir, e)?,
    };

    let camera = match &file.camera {
        Some(c) => camera(&check, c)?,
        None => {
            warn(path, "no [camera]; using one that frames the scene bounds");
            let [w, h] = default_resolution();
            b.framing_camera(w, h)?
        }
    };
    b.finish(camera, settings, environment)
}

fn camera(check: &Check, c: &CameraDef) -> Result<Camera> {
    let position = check.vec3("camera.position", c.position)?;
    let target = check.vec3("camera.target", c.target)?;
    let up = check.vec3("camera.up", c.up)?;
    let fov = check.finite("camera.fov", c.fov)?;
    if !(fov > 0.0 && fov < 180.0) {
        return Err(check.err("camera.fov", format!("{fov} is outside (0, 180) degrees")));
    }
    let [w, h] = c.resolution;
    check_resolution(check.file, "camera.resolution", w, h)?;
    if (target - position).length() == 0.0 {
        return Err(check.err("camera.target", "equals camera.position"));
    }
    Camera::look_at(position, target, up, fov, w, h).ok_or_else(|| check.err("camera.up", "is zero or parallel to the viewing direction"))
}

fn material(check: &Check, b: &mut Builder, dir: &Path, name: &str, d: &MaterialDef) -> Result<Material> {
    let f = |key: &str| format!("materials.{name}.{key}");
    use MaterialType::*;
    // Keys that make sense for this type; anything else is a mistake worth reporting.
    let given: [(&str, bool, &[MaterialType]); 10] = [
        ("albedo", d.albedo.is_some(), &[Diffuse, Plastic]),
        ("albedo_texture", d.albedo_texture.is_some(), &[Diffuse, Plastic]),
        ("roughness", d.roughness.is_some(), &[Conductor, Dielectric, Plastic]),
        ("ior", d.ior.is_some(), &[Dielectric, Plastic]),
        ("preset", d.preset.is_some(), &[Conductor]),
        ("eta", d.eta.is_some(), &[Conductor]),
        ("k", d.k.is_some(), &[Conductor]),
        ("specular_tint", d.specular_tint.is_some(), &[Conductor]),
        ("specular_tint_texture", d.specular_tint_texture.is_some(), &[Conductor]),
        ("tint", d.tint.is_some(), &[Dielectric]),
    ];
    for (key, present, types) in given {
        if present && !types.contains(&d.kind) {
            return Err(check.err(&f(key), format!("is not a parameter of type \"{}\"", format!("{:?}", d.kind).to_lowercase())));
        }
    }
    let roughness = match d.roughness {
        Some(r) => check.nonneg(&f("roughness"), r)?,
        None => 0.0,
    };
    let ior = match d.ior {
        Some(v) => check.positive(&f("ior"), v)?,
        None => 1.5,
    };
    let mut albedo = || -> Result<ColorParam> {
        let scale = match d.albedo {
            Some(a) => Some(check.unit3(&f("albedo"), a)?),
            None => None,
        };
        Ok(match &d.albedo_texture {
            Some(rel) => ColorParam::texture(b.albedo_texture(&dir.join(rel), &f("albedo_texture"))?, scale.unwrap_or(Vec3::ONE)),
            None => ColorParam::Const(scale.unwrap_or(Vec3::splat(0.5))),
        })
    };
    let kind = match d.kind {
        Diffuse => MaterialKind::Lambert { albedo: albedo()? },
        Plastic => MaterialKind::Plastic { albedo: albedo()?, ior, roughness, dist: Default::default(), nonlinear: true },
        Dielectric => {
            let tint = match d.tint {
                Some(t) => check.unit3(&f("tint"), t)?,
                None => Vec3::ONE,
            };
            MaterialKind::Dielectric { ior, roughness, tint, dist: Default::default() }
        }
        Conductor => {
            let (eta, k) = match (&d.preset, d.eta, d.k) {
                (Some(p), None, None) => {
                    let (_, eta, k) = CONDUCTOR_PRESETS.iter().find(|(n, _, _)| n.eq_ignore_ascii_case(p)).ok_or_else(|| {
                        let known: Vec<_> = CONDUCTOR_PRESETS.iter().map(|(n, _, _)| *n).collect();
                        check.err(&f("preset"), format!("unknown conductor '{p}' (known: {})", known.join(", ")))
                    })?;
                    (Vec3::from(*eta), Vec3::from(*k))
                }
                (None, Some(eta), Some(k)) => {
                    let eta = check.nonneg3(&f("eta"), eta)?;
                    if eta.min_element() <= 0.0 {
                        return Err(check.err(&f("eta"), format!("{eta} must be positive")));
                    }
                    (eta, check.nonneg3(&f("k"), k)?)
                }
                (Some(_), _, _) => return Err(check.err(&f("preset"), "give either `preset` or `eta` and `k`, not both")),
                (None, Some(_), None) => return Err(check.err(&f("k"), "missing (explicit `eta` needs `k`)")),
                (None, None, Some(_)) => return Err(check.err(&f("eta"), "missing (explicit `k` needs `eta`)")),
                (None, None, None) => return Err(check.err(&f("preset"), "missing (a conductor needs `preset` or `eta` and `k`)")),
            };
            let tint = match d.specular_tint {
                Some(t) => check.unit3(&f("specular_tint"), t)?,
                None => Vec3::ONE,
            };
            let specular_tint = match &d.specular_tint_texture {
                Some(rel) => {
                    let field = f("specular_tint_texture");
                    let index = b.albedo_texture(&dir.join(rel), &field)?;
                    // A tint above 1 would make the metal reflect more than arrives.
                    if let Some(t) = b.textures[index as usize].texels.iter().find(|t| t.max_element() > 1.0) {
                        return Err(check.err(&field, format!("{} has a texel {t} above 1; a reflectance tint lies in [0, 1]", rel)));
                    }
                    ColorParam::texture(index, tint)
                }
                None => ColorParam::Const(tint),
            };
            MaterialKind::Conductor { eta, k, roughness, specular_tint, dist: Default::default() }
        }
    };
    let emission = match d.emission {
        Some(e) => check.nonneg3(&f("emission"), e)?,
        None => Vec3::ZERO,
    };
    let strength = match d.strength {
        Some(s) => check.nonneg(&f("strength"), s)?,
        None => 1.0,
    };
    if d.strength.is_some() && d.emission.is_none() {
        return Err(check.err(&f("strength"), "scales `emission`, which is missing"));
    }
    let emission = emission * strength;
    if !emission.is_finite() {
        return Err(check.err(&f("strength"), "emission × strength overflows"));
    }
    Ok(Material { name: name.to_string(), kind, emission, two_sided_emission: d.two_sided_emission.unwrap_or(false), one_sided: false })
}

/// Rejects a procedural key on a shape type that does not read it (a typo must not pass silently).
fn procedural_keys_belong(check: &Check, i: usize, s: &ShapeDef) -> Result<()> {
    use ShapeType::*;
    let keys: [(&str, bool, ShapeType); 10] = [
        ("profile", s.profile.is_some(), Lathe),
        ("resolution", s.resolution.is_some(), Heightfield),
        ("amplitude", s.amplitude.is_some(), Heightfield),
        ("frequency", s.frequency.is_some(), Heightfield),
        ("octaves", s.octaves.is_some(), Heightfield),
        ("seed", s.seed.is_some(), Heightfield),
        ("element", s.element.is_some(), Grid),
        ("count", s.count.is_some(), Grid),
        ("spacing", s.spacing.is_some(), Grid),
        ("element_scale", s.element_scale.is_some(), Grid),
    ];
    for (key, present, owner) in keys {
        if present && s.kind != owner {
            return Err(check.err(&format!("shapes[{i}].{key}"), format!("only {} shapes have it", format!("{owner:?}").to_lowercase())));
        }
    }
    Ok(())
}

/// The mesh of a lathe, heightfield or grid shape (docs/scene-format.md, "Procedural shapes").
fn procedural_mesh(check: &Check, i: usize, s: &ShapeDef, segments: u32) -> Result<primitives::TriMesh> {
    let f = |key: &str| format!("shapes[{i}].{key}");
    let mesh = match s.kind {
        ShapeType::Lathe => {
            let profile = s.profile.as_ref().ok_or_else(|| check.err(&f("profile"), "missing (a lathe needs [[r, y], ...] points)"))?;
            procedural::lathe(profile, segments).map_err(|m| check.err(&f("profile"), m))?
        }
        ShapeType::Heightfield => {
            let p = procedural::HeightfieldParams {
                resolution: s.resolution.unwrap_or([64, 64]),
                amplitude: s.amplitude.unwrap_or(0.1),
                frequency: s.frequency.unwrap_or(4.0),
                octaves: s.octaves.unwrap_or(4),
                seed: s.seed.unwrap_or(0),
            };
            procedural::heightfield(&p).map_err(|m| check.err(&format!("shapes[{i}]"), m))?
        }
        _ => {
            let element = match s.element.as_deref().unwrap_or("cube") {
                "cube" => procedural::GridElement::Cube,
                "sphere" => procedural::GridElement::Sphere,
                other => return Err(check.err(&f("element"), format!("unknown element '{other}' (expected \"cube\" or \"sphere\")"))),
            };
            let count = s.count.ok_or_else(|| check.err(&f("count"), "missing (a grid needs [nx, ny, nz])"))?;
            let spacing = check.vec3(&f("spacing"), s.spacing.unwrap_or([2.5, 2.5, 2.5]))?;
            let element_scale = match &s.element_scale {
                None => Vec3::ONE,
                Some(Scale::Uniform(u)) => Vec3::splat(*u),
                Some(Scale::Xyz(v)) => Vec3::from(*v),
            };
            procedural::grid(element, count, spacing, element_scale, segments).map_err(|m| check.err(&format!("shapes[{i}]"), m))?
        }
    };
    Ok(mesh)
}

/// T · R · S · M of a shape (M = `matrix`, applied first).
fn shape_transform(check: &Check, i: usize, s: &ShapeDef) -> Result<Mat4> {
    let f = |key: &str| format!("shapes[{i}].{key}");
    let mut m = Mat4::IDENTITY;
    if let Some(rows) = &s.matrix {
        let flat: Vec<f32> = rows.iter().flatten().copied().collect();
        if flat.iter().any(|v| !v.is_finite()) {
            return Err(check.err(&f("matrix"), "has a non-finite entry"));
        }
        if rows[3] != [0.0, 0.0, 0.0, 1.0] {
            return Err(check.err(&f("matrix"), "last row must be [0, 0, 0, 1] (projective transforms are not supported)"));
        }
        m = Mat4::from_cols_array_2d(rows).transpose();
    }
    if let Some(scale) = &s.scale {
        let v = match scale {
            Scale::Uniform(u) => Vec3::splat(*u),
            Scale::Xyz(v) => Vec3::from(*v),
        };
        let v = check.vec3(&f("scale"), v.to_array())?;
        if v.min_element() == 0.0 || v.x * v.y * v.z == 0.0 {
            return Err(check.err(&f("scale"), format!("{v} has a zero component (flattens the shape)")));
        }
        m = Mat4::from_scale(v) * m;
    }
    if let Some(rot) = &s.rotate {
        let r = match rot {
            Rotate::Euler(e) => {
                let e = check.vec3(&f("rotate"), *e)?;
                Mat3::from_rotation_z(e.z.to_radians()) * Mat3::from_rotation_y(e.y.to_radians()) * Mat3::from_rotation_x(e.x.to_radians())
            }
            Rotate::AxisAngle(aa) => {
                let axis = check.vec3(&f("rotate.axis"), aa.axis)?.normalize_or_zero();
                if axis == Vec3::ZERO {
                    return Err(check.err(&f("rotate.axis"), "is zero"));
                }
                Mat3::from_axis_angle(axis, check.finite(&f("rotate.angle"), aa.angle)?.to_radians())
            }
        };
        m = Mat4::from_mat3(r) * m;
    }
    if let Some(t) = s.translate {
        m = Mat4::from_translation(check.vec3(&f("translate"), t)?) * m;
    }
    let det = Mat3::from_mat4(m).determinant();
    if !det.is_finite() || det == 0.0 {
        let key = if s.matrix.is_some() { "matrix" } else { "scale" };
        return Err(check.err(&f(key), "the transform is singular or overflows"));
    }
    Ok(m)
}

fn environment(check: &Check, dir: &Path, e: &EnvironmentDef) -> Result<Environment> {
    let kind = e.kind.unwrap_or(if e.map.is_some() { EnvironmentType::Map } else { EnvironmentType::Constant });
    let scale = match e.scale {
        Some(s) => check.nonneg("environment.scale", s)?,
        None => 1.0,
    };
    match kind {
        EnvironmentType::Constant => {
            if e.map.is_some() {
                return Err(check.err("environment.map", "given with type = \"constant\""));
            }
            if e.rotation.is_some() {
                return Err(check.err("environment.rotation", "only a map can be rotated"));
            }
            let color = check.nonneg3(
                "environment.color",
                e.color.ok_or_else(|| check.err("environment.color", "missing (a constant environment needs a colour)"))?,
            )?;
            let c = color * scale;
            if !c.is_finite() {
                return Err(check.err("environment.scale", "color × scale overflows"));
            }
            Ok(Environment::Constant(c))
        }
        EnvironmentType::Map => {
            if e.color.is_some() {
                return Err(check.err("environment.color", "given with a map (use `scale` to brighten a map)"));
            }
            let rel = e.map.as_ref().ok_or_else(|| check.err("environment.map", "missing (type = \"map\" needs a file)"))?;
            let rotation_deg = match e.rotation {
                Some(r) => check.finite("environment.rotation", r)?,
                None => 0.0,
            };
            let image = image_io::load_image(&dir.join(rel), check.file, "environment.map")?;
            Ok(Environment::Map { image, rotation_deg, scale })
        }
    }
}
