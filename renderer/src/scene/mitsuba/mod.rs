//! Mitsuba 0.5/0.6 XML scenes: the subset of the format that the scenes of Bitterli's
//! rendering resources (the collection the paper trained on) use. docs/scene-format.md,
//! "Mitsuba XML", lists what is read and how it is approximated.
//!
//! Everything the loader does not understand is an error naming the file, the line and the
//! element (`scene.xml: line 12 <bsdf type="hair">: unsupported BSDF type`), never a silent
//! default: a scene that renders differently from what its author made would poison a test.
//! The few things that are read but approximated (a textured dielectric or plastic specular
//! reflectance becomes its mean, anisotropic roughness becomes isotropic) print a warning.
//! renderer/tests/mitsuba_crosscheck.rs renders scenes in both renderers and compares them.
//! Texture lookups (`bitmap`, `checkerboard`) follow Mitsuba 3, which agrees with 0.6 on uv ≥ 0.

use super::builder::{check_resolution, warn, Builder};
use super::obj::MaterialChoice;
use super::primitives::{self, TriMesh};
use super::{obj, ColorParam, Material, MaterialKind, RenderSettings, SceneDescription};
use crate::camera::{Camera, FovAxis};
use crate::light::Environment;
use crate::material::Distribution;
use crate::texture::srgb_to_linear;
use crate::{Error, Result};
use glam::{Affine2, Mat3, Mat4, Vec2, Vec3};
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Mitsuba's default film size (768 × 576).
const DEFAULT_FILM: (u32, u32) = (768, 576);

/// Named dielectrics of Mitsuba's IOR table (the ones scenes use), at 589 nm.
const IOR_NAMES: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// Loads a Mitsuba XML scene.
pub fn load(path: &Path) -> Result<SceneDescription> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let doc = Document::parse(&text).map_err(|e| {
        let p = e.pos();
        Error::scene(path, format!("line {}, column {}", p.row, p.col), format!("malformed XML: {e}"))
    })?;
    let root = doc.root_element();
    let mut l = Loader {
        file: path.to_path_buf(),
        dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
        doc: &doc,
        defaults: HashMap::new(),
        bsdfs: HashMap::new(),
        textures: HashMap::new(),
        b: Builder::new(path),
    };
    if root.tag_name().name() != "scene" {
        return Err(l.err(root, "the root element must be <scene>"));
    }
    l.run(root)
}

/// A BSDF read from the XML, before it becomes a scene material (emitters copy it).
#[derive(Clone)]
struct BsdfDef {
    name: String,
    kind: MaterialKind,
    /// Wrapped in `twosided`: shaded alike from both sides (else black from behind).
    two_sided: bool,
}

/// A colour parameter: a constant or a texture node (resolved when the material is built),
/// with the name of the BSDF parameter that holds it (errors name it).
enum Spectrum<'a, 'i> {
    Const(Vec3),
    Texture { node: Node<'a, 'i>, param: String },
}

/// A texture as read from the XML, before its image is loaded.
enum TextureDef {
    Bitmap { file: PathBuf, to_uv: Affine2 },
    Checkerboard { color0: Vec3, color1: Vec3, to_uv: Affine2 },
}

struct Loader<'a, 'i> {
    file: PathBuf,
    dir: PathBuf,
    doc: &'a Document<'i>,
    /// `<default name value>` parameters, substituted for `$name` in attribute values.
    defaults: HashMap<String, String>,
    bsdfs: HashMap<String, BsdfDef>,
    textures: HashMap<String, Node<'a, 'i>>,
    b: Builder,
}

impl<'a, 'i> Loader<'a, 'i> {
    fn line(&self, n: Node<'a, 'i>) -> u32 {
        self.doc.text_pos_at(n.range().start).row
    }

    fn describe(&self, n: Node<'a, 'i>) -> String {
        match n.attribute("type").or_else(|| n.attribute("name")) {
            Some(t) if n.has_attribute("type") => format!("line {} <{} type=\"{t}\">", self.line(n), n.tag_name().name()),
            Some(t) => format!("line {} <{} name=\"{t}\">", self.line(n), n.tag_name().name()),
            None => format!("line {} <{}>", self.line(n), n.tag_name().name()),
        }
    }

    fn err(&self, n: Node<'a, 'i>, message: impl Into<String>) -> Error {
        Error::scene(&self.file, self.describe(n), message)
    }

    fn warn(&self, n: Node<'a, 'i>, message: impl std::fmt::Display) {
        warn(&self.file, format!("{}: {message}", self.describe(n)));
    }

    /// An attribute with `$name` defaults substituted.
    fn attr(&self, n: Node<'a, 'i>, key: &str) -> Result<Option<String>> {
        let Some(v) = n.attribute(key) else { return Ok(None) };
        if !v.contains('$') {
            return Ok(Some(v.to_string()));
        }
        let mut out = String::new();
        let mut rest = v;
        while let Some(i) = rest.find('$') {
            out.push_str(&rest[..i]);
            let after = &rest[i + 1..];
            let len = after.find(|c: char| !(c.is_alphanumeric() || c == '_')).unwrap_or(after.len());
            let name = &after[..len];
            let value = self.defaults.get(name).ok_or_else(|| self.err(n, format!("attribute {key}=\"{v}\" uses ${name}, which has no <default>")))?;
            out.push_str(value);
            rest = &after[len..];
        }
        out.push_str(rest);
        Ok(Some(out))
    }

    fn required(&self, n: Node<'a, 'i>, key: &str) -> Result<String> {
        self.attr(n, key)?.ok_or_else(|| self.err(n, format!("missing attribute `{key}`")))
    }

    fn elements(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
        n.children().filter(|c| c.is_element())
    }

    fn float(&self, n: Node<'a, 'i>) -> Result<f32> {
        let v = self.required(n, "value")?;
        let x: f32 = v.trim().parse().map_err(|_| self.err(n, format!("value \"{v}\" is not a number")))?;
        if !x.is_finite() {
            return Err(self.err(n, format!("value \"{v}\" is not finite")));
        }
        Ok(x)
    }

    fn integer(&self, n: Node<'a, 'i>) -> Result<i64> {
        let v = self.required(n, "value")?;
        v.trim().parse().map_err(|_| self.err(n, format!("value \"{v}\" is not an integer")))
    }

    fn boolean(&self, n: Node<'a, 'i>) -> Result<bool> {
        match self.required(n, "value")?.trim() {
            "true" => Ok(true),
            "false" => Ok(false),
            v => Err(self.err(n, format!("value \"{v}\" is not true or false"))),
        }
    }

    /// Numbers separated by commas and/or whitespace.
    fn numbers(&self, n: Node<'a, 'i>, v: &str) -> Result<Vec<f32>> {
        v.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<f32>().ok().filter(|x| x.is_finite()).ok_or_else(|| self.err(n, format!("\"{s}\" in \"{v}\" is not a finite number"))))
            .collect()
    }

    /// `<rgb>`, `<srgb>` or a constant `<spectrum>` (one value, or three for RGB).
    fn color(&self, n: Node<'a, 'i>) -> Result<Vec3> {
        let v = self.required(n, "value")?;
        let tag = n.tag_name().name();
        if tag == "spectrum" && v.contains(':') {
            return Err(self.err(n, "sampled spectra (wavelength:value pairs) are not supported; give an <rgb>"));
        }
        let c = if tag == "srgb" && v.trim_start().starts_with('#') {
            let hex = v.trim().trim_start_matches('#');
            let byte = |i: usize| u8::from_str_radix(hex.get(i..i + 2).unwrap_or("zz"), 16).ok();
            match (hex.len(), byte(0), byte(2), byte(4)) {
                (6, Some(r), Some(g), Some(b)) => Vec3::new(r as f32, g as f32, b as f32) / 255.0,
                _ => return Err(self.err(n, format!("\"{v}\" is not a #rrggbb colour"))),
            }
        } else {
            match self.numbers(n, &v)?.as_slice() {
                [x] => Vec3::splat(*x),
                [r, g, b] => Vec3::new(*r, *g, *b),
                _ => return Err(self.err(n, format!("\"{v}\" is neither one value nor three"))),
            }
        };
        let c = if tag == "srgb" { Vec3::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z)) } else { c };
        if c.min_element() < 0.0 {
            return Err(self.err(n, format!("colour {c} has a negative component")));
        }
        Ok(c)
    }

    /// `<point>`/`<vector>`: x, y, z attributes (missing = 0) or a `value` list.
    fn point(&self, n: Node<'a, 'i>) -> Result<Vec3> {
        if let Some(v) = self.attr(n, "value")? {
            return match self.numbers(n, &v)?.as_slice() {
                [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                _ => Err(self.err(n, format!("\"{v}\" is not three numbers"))),
            };
        }
        let mut p = Vec3::ZERO;
        for (i, k) in ["x", "y", "z"].iter().enumerate() {
            if let Some(v) = self.attr(n, k)? {
                p[i] = self.numbers(n, &v)?.first().copied().ok_or_else(|| self.err(n, format!("{k} is empty")))?;
            }
        }
        Ok(p)
    }

    /// A `<transform>`: its operations in document order, each applied after the previous ones.
    fn transform(&self, n: Node<'a, 'i>) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for op in Self::elements(n) {
            let xyz = |default: f32| -> Result<Vec3> {
                let mut v = Vec3::splat(default);
                if let Some(s) = self.attr(op, "value")? {
                    let nums = self.numbers(op, &s)?;
                    return match nums.as_slice() {
                        [x] => Ok(Vec3::splat(*x)),
                        [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                        _ => Err(self.err(op, format!("\"{s}\" is neither one value nor three"))),
                    };
                }
                for (i, k) in ["x", "y", "z"].iter().enumerate() {
                    if let Some(s) = self.attr(op, k)? {
                        v[i] = s.trim().parse::<f32>().ok().filter(|x| x.is_finite()).ok_or_else(|| self.err(op, format!("{k}=\"{s}\" is not a number")))?;
                    }
                }
                Ok(v)
            };
            let step = match op.tag_name().name() {
                "matrix" => {
                    let v = self.required(op, "value")?;
                    let a = self.numbers(op, &v)?;
                    if a.len() != 16 {
                        return Err(self.err(op, format!("a matrix needs 16 numbers, got {}", a.len())));
                    }
                    if a[12..] != [0.0, 0.0, 0.0, 1.0] {
                        return Err(self.err(op, "the last row must be 0 0 0 1 (projective transforms are not supported)"));
                    }
                    // Row-major in the file; glam is column-major.
                    Mat4::from_cols_array(&a.try_into().unwrap()).transpose()
                }
                "translate" => Mat4::from_translation(xyz(0.0)?),
                "scale" => Mat4::from_scale(xyz(1.0)?),
                "rotate" => {
                    let axis = xyz(0.0)?;
                    let angle = self.attr(op, "angle")?.ok_or_else(|| self.err(op, "missing attribute `angle`"))?;
                    let angle: f32 = angle.trim().parse().ok().filter(|a: &f32| a.is_finite()).ok_or_else(|| self.err(op, format!("angle \"{angle}\" is not a number")))?;
                    let axis = axis.try_normalize().ok_or_else(|| self.err(op, "the rotation axis is zero"))?;
                    Mat4::from_axis_angle(axis, angle.to_radians())
                }
                "lookat" | "lookAt" => {
                    let vec = |k: &str| -> Result<Vec3> {
                        let s = self.attr(op, k)?.ok_or_else(|| self.err(op, format!("missing attribute `{k}`")))?;
                        match self.numbers(op, &s)?.as_slice() {
                            [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
                            _ => Err(self.err(op, format!("{k}=\"{s}\" is not three numbers"))),
                        }
                    };
                    let (origin, target) = (vec("origin")?, vec("target")?);
                    let up = if op.has_attribute("up") { vec("up")? } else { Vec3::Y };
                    let dir = (target - origin).try_normalize().ok_or_else(|| self.err(op, "origin equals target"))?;
                    let left = up.cross(dir).try_normalize().ok_or_else(|| self.err(op, "up is zero or parallel to the view"))?;
                    let new_up = dir.cross(left);
                    Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0))
                }
                other => return Err(self.err(op, format!("unsupported transform operation <{other}>"))),
            };
            m = step * m;
        }
        if !m.is_finite() {
            return Err(self.err(n, "the transform is not finite"));
        }
        Ok(m)
    }

    fn run(&mut self, root: Node<'a, 'i>) -> Result<SceneDescription> {
        let mut settings = RenderSettings::default();
        let mut camera_node = None;
        let mut environment = Environment::Constant(Vec3::ZERO);
        for n in Self::elements(root) {
            match n.tag_name().name() {
                "default" => {
                    let name = self.required(n, "name")?;
                    let value = self.required(n, "value")?;
                    self.defaults.entry(name).or_insert(value);
                }
                "integrator" => self.integrator(n, &mut settings)?,
                "sensor" => {
                    if camera_node.is_some() {
                        return Err(self.err(n, "a second <sensor> (only one camera is supported)"));
                    }
                    camera_node = Some(n);
                }
                "bsdf" => {
                    let id = self.attr(n, "id")?.ok_or_else(|| self.err(n, "a top-level <bsdf> needs an id"))?;
                    let def = self.bsdf(n, &id)?;
                    self.bsdfs.insert(id, def);
                }
                "texture" => {
                    let id = self.attr(n, "id")?.ok_or_else(|| self.err(n, "a top-level <texture> needs an id"))?;
                    self.textures.insert(id, n);
                }
                "shape" => self.shape(n)?,
                "emitter" => environment = self.environment(n)?,
                other => return Err(self.err(n, format!("unsupported element <{other}> in <scene>"))),
            }
        }
        let camera = match camera_node {
            Some(n) => self.sensor(n, &mut settings)?,
            None => {
                warn(&self.file, "no <sensor>; using a camera that frames the scene bounds");
                self.b.framing_camera(DEFAULT_FILM.0, DEFAULT_FILM.1)?
            }
        };
        let b = std::mem::replace(&mut self.b, Builder::new(&self.file));
        b.finish(camera, settings, environment)
    }

    fn integrator(&self, n: Node<'a, 'i>, settings: &mut RenderSettings) -> Result<()> {
        let t = self.required(n, "type")?;
        if !matches!(t.as_str(), "path" | "volpath" | "volpath_simple") {
            return Err(self.err(n, format!("unsupported integrator \"{t}\" (path tracers only)")));
        }
        for c in Self::elements(n) {
            if matches!(c.attribute("name"), Some("maxDepth" | "max_depth")) {
                // Mitsuba's maxDepth counts path segments (2 = direct light only, one scattering
                // event); −1 means unlimited, for which our default stands.
                let d = self.integer(c)?;
                if d >= 1 {
                    settings.max_bounces = (d - 1).min(64) as u32;
                }
            }
            // Other integrator parameters (rrDepth, strictNormals, hideEmitters, ...) tune the
            // sampling of Mitsuba's integrator, not the scene; ours has its own settings.
        }
        Ok(())
    }

    fn sensor(&self, n: Node<'a, 'i>, settings: &mut RenderSettings) -> Result<Camera> {
        let t = self.required(n, "type")?;
        if t != "perspective" {
            return Err(self.err(n, format!("unsupported sensor type \"{t}\" (only perspective)")));
        }
        let (mut fov, mut axis, mut to_world) = (None, FovAxis::X, Mat4::IDENTITY);
        let (mut w, mut h) = DEFAULT_FILM;
        for c in Self::elements(n) {
            let name = c.attribute("name").unwrap_or("");
            match (c.tag_name().name(), name) {
                ("float", "fov") => fov = Some(self.float(c)?),
                ("string", "fovAxis" | "fov_axis") => {
                    let v = self.required(c, "value")?;
                    axis = FovAxis::parse(&v).ok_or_else(|| self.err(c, format!("unknown fov axis \"{v}\" (x, y, diagonal, smaller, larger)")))?;
                }
                ("transform", "toWorld" | "to_world") => to_world = self.transform(c)?,
                // Clip planes and focus distance change nothing for a pinhole camera without clipping.
                ("float", "nearClip" | "farClip" | "focusDistance" | "shutterOpen" | "shutterClose" | "near_clip" | "far_clip" | "focus_distance" | "shutter_open" | "shutter_close") => {}
                ("sampler", _) => {
                    for s in Self::elements(c) {
                        if matches!(s.attribute("name"), Some("sampleCount" | "sample_count")) {
                            let spp = self.integer(s)?;
                            if spp < 1 || spp > u32::MAX as i64 {
                                return Err(self.err(s, format!("sampleCount {spp} must be at least 1")));
                            }
                            settings.spp = spp as u32;
                        }
                    }
                }
                ("film", _) => {
                    for s in Self::elements(c) {
                        match (s.tag_name().name(), s.attribute("name").unwrap_or("")) {
                            ("integer", "width") => w = self.dim(s)?,
                            ("integer", "height") => h = self.dim(s)?,
                            ("integer", "cropOffsetX" | "cropOffsetY" | "cropWidth" | "cropHeight" | "crop_offset_x" | "crop_offset_y" | "crop_width" | "crop_height") => {
                                return Err(self.err(s, "film crop windows are not supported"));
                            }
                            // Output format, tone mapping and the reconstruction filter: how
                            // Mitsuba stores the image, not what the scene looks like.
                            _ => {}
                        }
                    }
                }
                _ => return Err(self.err(c, "unsupported sensor parameter")),
            }
        }
        check_resolution(&self.file, &self.describe(n), w, h)?;
        let fov = fov.ok_or_else(|| self.err(n, "missing <float name=\"fov\"> (focalLength is not supported)"))?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(self.err(n, format!("fov {fov} is outside (0, 180) degrees")));
        }
        // Mitsuba cameras look along +Z with +Y up; +X is the image's left.
        let position = to_world.transform_point3(Vec3::ZERO);
        let forward = to_world.transform_vector3(Vec3::Z).normalize_or_zero();
        let up = to_world.transform_vector3(Vec3::Y).normalize_or_zero();
        let left = to_world.transform_vector3(Vec3::X);
        if left.dot(up.cross(forward)) < 0.0 {
            self.warn(n, "the camera transform mirrors the image; rendering it unmirrored");
        }
        // The camera keeps the axis, so that a new image size (`--size`) keeps the angle along
        // it, as Mitsuba does when the film alone changes.
        Camera::look_at_axis(position, position + forward, up, fov, axis, w, h).ok_or_else(|| self.err(n, "degenerate camera transform (zero or parallel view and up)"))
    }

    fn dim(&self, n: Node<'a, 'i>) -> Result<u32> {
        let v = self.integer(n)?;
        u32::try_from(v).map_err(|_| self.err(n, format!("{v} is not a valid image size")))
    }

    /// A colour parameter: constant, an inline texture, or a `<ref>` to a texture.
    fn spectrum(&self, n: Node<'a, 'i>) -> Result<Spectrum<'a, 'i>> {
        let param = n.attribute("name").unwrap_or("(unnamed)").to_string();
        match n.tag_name().name() {
            "rgb" | "srgb" | "spectrum" => Ok(Spectrum::Const(self.color(n)?)),
            "float" => Ok(Spectrum::Const(Vec3::splat(self.float(n)?.max(0.0)))),
            "texture" => Ok(Spectrum::Texture { node: n, param }),
            "ref" => {
                let id = self.required(n, "id")?;
                let node = *self.textures.get(&id).ok_or_else(|| self.err(n, format!("no <texture id=\"{id}\"> defined before this")))?;
                Ok(Spectrum::Texture { node, param })
            }
            other => Err(self.err(n, format!("<{other}> is not a colour"))),
        }
    }

    /// Where a texture is in the file and which BSDF parameter uses it, for errors:
    /// `line 79 <texture type="bitmap"> (specularReflectance)`.
    fn texture_field(&self, t: Node<'a, 'i>, param: &str) -> String {
        format!("{} ({param})", self.describe(t))
    }

    /// Reads a `bitmap` or `checkerboard` texture. Texture coordinates are mapped by Mitsuba
    /// 3's `to_uv` transform or Mitsuba 0.6's `uscale`/`vscale`/`uoffset`/`voffset`
    /// (uv · scale + offset).
    fn texture_def(&self, t: Node<'a, 'i>, param: &str) -> Result<TextureDef> {
        let field = self.texture_field(t, param);
        let fail = |n: Node<'a, 'i>, msg: String| {
            let at = if n == t { field.clone() } else { format!("{} in {field}", self.describe(n)) };
            Error::scene(&self.file, at, msg)
        };
        let ty = self.attr(t, "type")?.ok_or_else(|| fail(t, "missing attribute `type`".into()))?;
        if !matches!(ty.as_str(), "bitmap" | "checkerboard") {
            return Err(fail(t, format!("unsupported texture type \"{ty}\" (bitmap, checkerboard)")));
        }
        let (mut scale, mut offset, mut to_uv, mut old_style) = (Vec2::ONE, Vec2::ZERO, None, false);
        let (mut file, mut color0, mut color1) = (None, Vec3::splat(0.4), Vec3::splat(0.2));
        for c in Self::elements(t) {
            let name = c.attribute("name").unwrap_or("");
            match (ty.as_str(), c.tag_name().name(), name) {
                (_, "float", "uscale" | "vscale" | "uoffset" | "voffset") => {
                    let v = self.float(c)?;
                    old_style = true;
                    match name {
                        "uscale" => scale.x = v,
                        "vscale" => scale.y = v,
                        "uoffset" => offset.x = v,
                        _ => offset.y = v,
                    }
                }
                (_, "transform", "to_uv" | "toUV") => {
                    // The 2-D affine part: x and y rows, x and y columns and the translation.
                    let m = self.transform(c)?;
                    to_uv = Some(Affine2::from_cols(m.x_axis.truncate().truncate(), m.y_axis.truncate().truncate(), m.w_axis.truncate().truncate()));
                }
                ("bitmap", "string", "filename") => file = Some(self.required(c, "value")?),
                // Filtering: ours is bilinear (no MIP maps).
                ("bitmap", "string", "filterType" | "filter_type") | ("bitmap", "float", "maxAnisotropy") | ("bitmap", "boolean", "cache") => {}
                ("bitmap", "string", "wrapMode" | "wrapModeU" | "wrapModeV" | "wrap_mode") => {
                    let v = self.required(c, "value")?;
                    if v != "repeat" {
                        self.warn(c, format!("{param}: wrap mode \"{v}\" becomes repeat"));
                    }
                }
                ("bitmap", "float", "gamma") => {
                    let g = self.float(c)?;
                    if g != -1.0 && (g - 2.2).abs() > 1e-3 {
                        return Err(fail(c, format!("gamma {g} is not supported (8-bit images are read as sRGB, float images as linear)")));
                    }
                }
                ("bitmap", "boolean", "raw") => {
                    if self.boolean(c)? {
                        return Err(fail(c, "raw=true is not supported (8-bit images are always read as sRGB)".into()));
                    }
                }
                ("checkerboard", _, "color0" | "color1") => {
                    let v = match c.tag_name().name() {
                        "float" => Vec3::splat(self.float(c)?.max(0.0)),
                        "rgb" | "srgb" | "spectrum" => self.color(c)?,
                        other => return Err(fail(c, format!("{name} must be a constant colour, not <{other}>"))),
                    };
                    if name == "color0" {
                        color0 = v
                    } else {
                        color1 = v
                    }
                }
                _ => return Err(fail(c, format!("unsupported {ty} parameter"))),
            }
        }
        let to_uv = match (to_uv, old_style) {
            (Some(_), true) => return Err(fail(t, "give either to_uv or uscale/vscale/uoffset/voffset, not both".into())),
            (Some(m), false) => m,
            (None, _) => Affine2::from_scale_angle_translation(scale, 0.0, offset),
        };
        if !to_uv.is_finite() {
            return Err(fail(t, "the texture coordinate transform is not finite".into()));
        }
        Ok(match ty.as_str() {
            "bitmap" => {
                let file = file.ok_or_else(|| fail(t, "a bitmap needs <string name=\"filename\">".into()))?;
                TextureDef::Bitmap { file: self.dir.join(file), to_uv }
            }
            _ => TextureDef::Checkerboard { color0, color1, to_uv },
        })
    }

    /// A colour parameter that may vary over the surface (diffuse reflectance, a conductor's
    /// specular reflectance): constants and checkerboards as they are, bitmaps loaded as
    /// textures, all values capped at 1 (a reflectance).
    fn color_param(&mut self, s: Spectrum<'a, 'i>) -> Result<ColorParam> {
        match s {
            Spectrum::Const(c) => Ok(ColorParam::Const(c.min(Vec3::ONE))),
            Spectrum::Texture { node, param } => match self.texture_def(node, &param)? {
                TextureDef::Bitmap { file, to_uv } => {
                    let field = self.texture_field(node, &param);
                    let index = self.b.albedo_texture(&file, &field)?;
                    Ok(ColorParam::Texture { index, scale: Vec3::ONE, to_uv })
                }
                TextureDef::Checkerboard { color0, color1, to_uv } => {
                    Ok(ColorParam::Checkerboard { color0: color0.min(Vec3::ONE), color1: color1.min(Vec3::ONE), to_uv })
                }
            },
        }
    }

    /// A constant colour or a texture's mean, for parameters that cannot vary over a surface;
    /// `true` if it was a texture.
    fn mean_color(&self, s: Spectrum<'a, 'i>) -> Result<(Vec3, bool)> {
        match s {
            Spectrum::Const(c) => Ok((c, false)),
            Spectrum::Texture { node, param } => {
                let mean = match self.texture_def(node, &param)? {
                    TextureDef::Bitmap { file, .. } => super::image_io::load_image(&file, &self.file, &self.texture_field(node, &param))?.mean(),
                    TextureDef::Checkerboard { color0, color1, .. } => (color0 + color1) * 0.5,
                };
                Ok((mean, true))
            }
        }
    }

    fn ior(&self, n: Node<'a, 'i>) -> Result<f32> {
        if n.tag_name().name() == "string" {
            let v = self.required(n, "value")?;
            return IOR_NAMES
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(v.trim()))
                .map(|&(_, x)| x)
                .ok_or_else(|| self.err(n, format!("unknown IOR name \"{v}\"")));
        }
        let x = self.float(n)?;
        if x <= 0.0 {
            return Err(self.err(n, format!("IOR {x} must be positive")));
        }
        Ok(x)
    }

    fn bsdf(&mut self, n: Node<'a, 'i>, name: &str) -> Result<BsdfDef> {
        let ty = self.required(n, "type")?;
        if ty == "twosided" {
            // Shaded alike from both sides; a BSDF outside `twosided` is black from behind.
            let inner: Vec<_> = Self::elements(n).collect();
            return match inner.as_slice() {
                [one] if one.tag_name().name() == "bsdf" => self.bsdf(*one, name).map(|d| BsdfDef { two_sided: true, ..d }),
                [one] if one.tag_name().name() == "ref" => {
                    let id = self.required(*one, "id")?;
                    let d = self.bsdfs.get(&id).cloned().ok_or_else(|| self.err(*one, format!("no <bsdf id=\"{id}\"> defined before this")))?;
                    Ok(BsdfDef { two_sided: true, ..d })
                }
                _ => Err(self.err(n, "twosided needs exactly one nested <bsdf> (two different sides are not supported)")),
            };
        }
        let mut alpha: Option<f32> = None;
        let (mut alpha_u, mut alpha_v) = (None, None);
        // Mitsuba's default microfacet distribution is Beckmann (0.6 and 3 alike).
        let mut dist = Distribution::Beckmann;
        let mut nonlinear = false;
        // Mitsuba's defaults: BK7 glass inside a dielectric, polypropylene (1.49) under a plastic
        // coat, air outside.
        let default_int = if ty.ends_with("plastic") { 1.49 } else { 1.5046f32 };
        let (mut int_ior, mut ext_ior) = (default_int, 1.000277f32);
        let mut reflectance: Option<Spectrum> = None;
        let mut specular: Option<Spectrum> = None;
        let mut transmittance: Option<Spectrum> = None;
        let (mut eta, mut k, mut preset, mut ext_eta) = (None, None, None, 1.0f32);
        for c in Self::elements(n) {
            let pname = c.attribute("name").unwrap_or("");
            match (ty.as_str(), pname) {
                (_, "alpha") => alpha = Some(self.float(c)?.max(0.0)),
                (_, "alphaU" | "alpha_u") => alpha_u = Some(self.float(c)?.max(0.0)),
                (_, "alphaV" | "alpha_v") => alpha_v = Some(self.float(c)?.max(0.0)),
                (_, "distribution") => {
                    let d = self.required(c, "value")?;
                    // Phong's exponent has no alpha at all; "as" (Ashikhmin–Shirley) is 0.5's
                    // anisotropic Phong.
                    dist = match d.as_str() {
                        "ggx" => Distribution::Ggx,
                        "beckmann" => Distribution::Beckmann,
                        _ => return Err(self.err(c, format!("microfacet distribution \"{d}\" is not supported (ggx, beckmann)"))),
                    };
                }
                ("diffuse" | "roughdiffuse", "reflectance") | ("plastic" | "roughplastic", "diffuseReflectance" | "diffuse_reflectance") => {
                    reflectance = Some(self.spectrum(c)?)
                }
                (_, "specularReflectance" | "specular_reflectance") => specular = Some(self.spectrum(c)?),
                ("dielectric" | "roughdielectric", "specularTransmittance" | "specular_transmittance") => transmittance = Some(self.spectrum(c)?),
                ("dielectric" | "roughdielectric" | "plastic" | "roughplastic", "intIOR" | "int_ior") => int_ior = self.ior(c)?,
                ("dielectric" | "roughdielectric" | "plastic" | "roughplastic", "extIOR" | "ext_ior") => ext_ior = self.ior(c)?,
                ("conductor" | "roughconductor", "eta") => eta = Some(self.color(c)?),
                ("conductor" | "roughconductor", "k") => k = Some(self.color(c)?),
                ("conductor" | "roughconductor", "material") => preset = Some(self.required(c, "value")?),
                ("conductor" | "roughconductor", "extEta" | "ext_eta") => ext_eta = self.ior(c)?,
                ("plastic" | "roughplastic", "nonlinear") => nonlinear = self.boolean(c)?,
                _ => return Err(self.err(c, format!("unsupported parameter of a \"{ty}\" BSDF"))),
            }
        }
        let roughness = match (alpha, alpha_u, alpha_v) {
            (Some(a), _, _) => a,
            (None, Some(u), Some(v)) => {
                if (u - v).abs() > 1e-3 {
                    self.warn(n, format!("anisotropic roughness ({u}, {v}) becomes isotropic {}", (u * v).sqrt()));
                }
                (u * v).sqrt()
            }
            (None, Some(a), None) | (None, None, Some(a)) => a,
            // Mitsuba's default roughness of the rough BSDFs.
            (None, None, None) => {
                if ty.starts_with("rough") {
                    0.1
                } else {
                    0.0
                }
            }
        };
        let roughness = if ty.starts_with("rough") { roughness } else { 0.0 };
        let specular_mean = |l: &Self, s: Option<Spectrum<'a, 'i>>, what: &str| -> Result<Vec3> {
            match s {
                None => Ok(Vec3::ONE),
                Some(s) => {
                    let (c, textured) = l.mean_color(s)?;
                    if textured {
                        l.warn(n, format!("a textured {what} becomes its mean {c}"));
                    }
                    Ok(c.min(Vec3::ONE))
                }
            }
        };
        let kind = match ty.as_str() {
            "diffuse" | "roughdiffuse" => {
                let albedo = self.color_param(reflectance.unwrap_or(Spectrum::Const(Vec3::splat(0.5))))?;
                MaterialKind::Lambert { albedo }
            }
            "plastic" | "roughplastic" => {
                let albedo = self.color_param(reflectance.unwrap_or(Spectrum::Const(Vec3::splat(0.5))))?;
                let s = specular_mean(self, specular, "specular reflectance")?;
                if (s - Vec3::ONE).abs().max_element() > 1e-3 {
                    self.warn(n, format!("plastic specularReflectance {s} is ignored (the coat reflects by Fresnel alone)"));
                }
                MaterialKind::Plastic { albedo, ior: int_ior / ext_ior, roughness, dist, nonlinear }
            }
            "dielectric" | "roughdielectric" => {
                let r = specular_mean(self, specular, "specular reflectance")?;
                let t = specular_mean(self, transmittance, "specular transmittance")?;
                if (r - t).abs().max_element() > 1e-3 {
                    self.warn(n, format!("reflectance {r} and transmittance {t} differ; both become {t}"));
                }
                MaterialKind::Dielectric { ior: int_ior / ext_ior, roughness, tint: t, dist }
            }
            "conductor" | "roughconductor" => {
                let (e, kk) = match (&preset, eta, k) {
                    // A perfect mirror (Mitsuba: η = 0, k = 1); k = 10⁴ gives F = 1 − 4·10⁻⁸.
                    (Some(p), None, None) if p == "none" => NONE_CONDUCTOR,
                    (Some(p), None, None) => {
                        let (_, e, kk) = MITSUBA3_CONDUCTORS.iter().find(|(m, _, _)| m.eq_ignore_ascii_case(p)).ok_or_else(|| {
                            let known: Vec<_> = MITSUBA3_CONDUCTORS.iter().map(|(m, _, _)| *m).collect();
                            self.err(n, format!("unknown conductor material \"{p}\" (known: {}, none; or give eta and k)", known.join(", ")))
                        })?;
                        (Vec3::from(*e), Vec3::from(*kk))
                    }
                    (None, Some(e), Some(kk)) => (e, kk),
                    // Mitsuba's default conductor is copper.
                    // Mitsuba 3's default conductor is that mirror (Mitsuba 0.6's was copper; Mitsuba 3
                    // renders 0.6 files with its own default too).
                    (None, None, None) => NONE_CONDUCTOR,
                    _ => return Err(self.err(n, "give either `material` or both `eta` and `k`")),
                };
                if e.min_element() <= 0.0 {
                    return Err(self.err(n, format!("eta {e} must be positive")));
                }
                let specular_tint = self.color_param(specular.unwrap_or(Spectrum::Const(Vec3::ONE)))?;
                MaterialKind::Conductor { eta: e / ext_eta, k: kk / ext_eta, roughness, specular_tint, dist }
            }
            other => return Err(self.err(n, format!("unsupported BSDF type \"{other}\""))),
        };
        Ok(BsdfDef { name: name.to_string(), kind, two_sided: false })
    }

    fn shape(&mut self, n: Node<'a, 'i>) -> Result<()> {
        let ty = self.required(n, "type")?;
        let mut to_world = Mat4::IDENTITY;
        let (mut filename, mut face_normals, mut flip) = (None, false, false);
        let (mut center, mut radius) = (Vec3::ZERO, 1.0f32);
        let mut bsdf: Option<BsdfDef> = None;
        let mut emission: Option<Vec3> = None;
        for c in Self::elements(n) {
            match (c.tag_name().name(), c.attribute("name").unwrap_or("")) {
                ("transform", "toWorld" | "to_world") => to_world = self.transform(c)?,
                ("string", "filename") if ty == "obj" => filename = Some(self.required(c, "value")?),
                ("boolean", "faceNormals" | "face_normals") => face_normals = self.boolean(c)?,
                ("boolean", "flipNormals" | "flip_normals") => flip = self.boolean(c)?,
                ("boolean", "flipTexCoords" | "flip_tex_coords") if ty == "obj" => {
                    if !self.boolean(c)? {
                        return Err(self.err(c, "flipTexCoords=false is not supported (OBJ texture coordinates are always flipped)"));
                    }
                }
                ("point", "center") if ty == "sphere" => center = self.point(c)?,
                ("float", "radius") if ty == "sphere" || ty == "disk" => {
                    radius = self.float(c)?;
                    if radius <= 0.0 {
                        return Err(self.err(c, format!("radius {radius} must be positive")));
                    }
                }
                ("ref", _) => {
                    let id = self.required(c, "id")?;
                    let def = self.bsdfs.get(&id).cloned().ok_or_else(|| self.err(c, format!("no <bsdf id=\"{id}\"> defined before this")))?;
                    if bsdf.replace(def).is_some() {
                        return Err(self.err(c, "a second BSDF for this shape"));
                    }
                }
                ("bsdf", _) => {
                    let name = format!("line {} bsdf", self.line(c));
                    let def = self.bsdf(c, &name)?;
                    if bsdf.replace(def).is_some() {
                        return Err(self.err(c, "a second BSDF for this shape"));
                    }
                }
                ("emitter", _) => {
                    let et = self.required(c, "type")?;
                    if et != "area" {
                        return Err(self.err(c, format!("a shape's emitter must be \"area\", not \"{et}\"")));
                    }
                    let mut radiance = None;
                    for p in Self::elements(c) {
                        match p.attribute("name") {
                            Some("radiance") => radiance = Some(self.color(p)?),
                            Some("samplingWeight" | "sampling_weight") => {}
                            _ => return Err(self.err(p, "unsupported area emitter parameter")),
                        }
                    }
                    emission = Some(radiance.ok_or_else(|| self.err(c, "an area emitter needs <rgb name=\"radiance\">"))?);
                }
                _ => return Err(self.err(c, format!("unsupported parameter of a \"{ty}\" shape"))),
            }
        }
        let det = Mat3::from_mat4(to_world).determinant();
        if det == 0.0 || !det.is_finite() {
            return Err(self.err(n, "the shape's toWorld transform is singular"));
        }
        // Mitsuba's default BSDF is a grey diffuse, but black on an emitter (Mitsuba 3's Shape).
        let default_albedo = if emission.is_some() { 0.0 } else { 0.5 };
        let def = bsdf.unwrap_or_else(|| BsdfDef { name: "default".into(), kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::splat(default_albedo)) }, two_sided: false });
        let emission = emission.unwrap_or(Vec3::ZERO);
        let obj_path = match (ty.as_str(), filename) {
            ("obj", Some(file)) => Some(self.dir.join(file)),
            ("obj", None) => return Err(self.err(n, "an obj shape needs <string name=\"filename\">")),
            _ => None,
        };
        if let Some(p) = obj_path.as_ref().filter(|p| !p.is_file()) {
            // Published scenes sometimes ship without a mesh (veach-ajar's teapots); the rest
            // of the scene is still worth rendering.
            self.warn(n, format!("mesh '{}' not found; skipping this shape", p.display()));
            return Ok(());
        }
        if matches!(ty.as_str(), "cube" | "disk" | "sphere") && kind_is_textured(&def.kind) {
            self.warn(n, format!("a textured BSDF on a {ty}: its texture coordinates follow our {ty}, not Mitsuba's"));
        }
        let material = self.material_for(&def, emission);
        let (v0, t0) = (self.b.mesh.positions.len(), self.b.mesh.triangles.len());
        let field = self.describe(n);
        let mesh: Option<TriMesh> = match ty.as_str() {
            "obj" => {
                let p = obj_path.expect("checked above");
                let overrides = HashMap::new();
                let choice = MaterialChoice { all: Some(material), by_name: &overrides };
                obj::load(&mut self.b, &p, &to_world, &choice, &field)?;
                None
            }
            "rectangle" => {
                // Mitsuba's rectangle has uv = ((x + 1)/2, (y + 1)/2); our quad puts v = 0 at
                // y = +1 (the top of an image seen from +Z).
                let mut q = primitives::quad();
                q.uvs.iter_mut().for_each(|uv| uv.y = 1.0 - uv.y);
                Some(q)
            }
            "cube" => Some(primitives::cube()),
            "disk" => Some(primitives::disk(1.0, 64)),
            "sphere" => Some(primitives::sphere(radius, 64).transformed(&Mat4::from_translation(center))),
            other => return Err(self.err(n, format!("unsupported shape type \"{other}\""))),
        };
        if let Some(m) = mesh {
            self.b.add_mesh(&m.transformed(&to_world), material, &field)?;
        }
        let mesh = &mut self.b.mesh;
        if face_normals && !mesh.normals.is_empty() {
            // A zero shading normal makes the renderer use the geometric one (Scene::surface).
            mesh.normals[v0..].fill(Vec3::ZERO);
        }
        if flip {
            for t in &mut mesh.triangles[t0..] {
                t.swap(1, 2);
            }
            if !mesh.normals.is_empty() {
                for nn in &mut mesh.normals[v0..] {
                    *nn = -*nn;
                }
            }
        }
        Ok(())
    }

    /// The scene material of a BSDF (emitting or not), shared between shapes that use the same
    /// BSDF without emission.
    fn material_for(&mut self, def: &BsdfDef, emission: Vec3) -> u32 {
        let name = if emission.max_element() > 0.0 { format!("{} (emitter {})", def.name, self.b.materials.len()) } else { def.name.clone() };
        let one_sided = !def.two_sided;
        if emission.max_element() <= 0.0 {
            if let Some(i) = self.b.materials.iter().position(|m| m.name == name && !m.is_emissive() && m.one_sided == one_sided) {
                return i as u32;
            }
        }
        self.b.add_material(Material { name, kind: def.kind.clone(), emission, two_sided_emission: false, one_sided })
    }

    fn environment(&self, n: Node<'a, 'i>) -> Result<Environment> {
        let ty = self.required(n, "type")?;
        if ty != "constant" {
            return Err(self.err(n, format!("unsupported emitter type \"{ty}\" (area emitters on shapes and \"constant\" are supported)")));
        }
        let mut radiance = Vec3::ONE;
        for c in Self::elements(n) {
            match c.attribute("name") {
                Some("radiance") => radiance = self.color(c)?,
                Some("samplingWeight" | "sampling_weight") => {}
                _ => return Err(self.err(c, "unsupported constant emitter parameter")),
            }
        }
        Ok(Environment::Constant(radiance))
    }
}

/// Mitsuba's `material="none"`: a perfect mirror.
const NONE_CONDUCTOR: (Vec3, Vec3) = (Vec3::ONE, Vec3::splat(1e4));

/// RGB complex IOR (η, k) of Mitsuba's named conductors as Mitsuba 3.9's `scalar_rgb` variant
/// uses them (read back from it with `mi.traverse`): within ~1e-3 of our TOML presets
/// (`CONDUCTOR_PRESETS`, integrated from the same spectra), but a Mitsuba scene should render
/// as Mitsuba renders it. The other metals of Mitsuba's list are not tabulated (an error).
#[allow(clippy::excessive_precision)]
const MITSUBA3_CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("Ag", [0.155276, 0.116728, 0.138388], [4.82835, 3.12222, 2.1469]),
    ("Al", [1.6575, 0.880405, 0.521244], [9.22381, 6.2695, 4.837]),
    ("Au", [0.143036, 0.375307, 1.44205], [3.983, 2.38556, 1.60336]),
    ("Cr", [4.36967, 2.91651, 1.6549], [5.20655, 4.23131, 3.7547]),
    ("Cu", [0.201005, 0.92375, 1.10222], [3.91326, 2.45305, 2.14209]),
];

/// Whether any colour of a material varies over the surface.
fn kind_is_textured(kind: &MaterialKind) -> bool {
    match kind {
        MaterialKind::Lambert { albedo } | MaterialKind::Plastic { albedo, .. } => albedo.is_textured(),
        MaterialKind::Conductor { specular_tint, .. } => specular_tint.is_textured(),
        MaterialKind::Dielectric { .. } => false,
    }
}
