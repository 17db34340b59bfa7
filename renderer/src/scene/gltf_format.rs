//! glTF 2.0 (`.gltf` with external or base64 buffers, or binary `.glb`) via the gltf crate.
//!
//! Every triangle primitive (triangles, strips and fans) of the default scene's node tree is
//! loaded with its node transform. Materials (metallic-roughness) map onto ours:
//! - `metallic ≥ 0.5` → conductor with a nearly flat Fresnel (η = 1, k = 20: F₀ ≈ 0.99) and
//!   `specular_tint` = base colour (× the base-colour texture's mean), so the tint sets F₀ the
//!   way glTF's base colour does;
//! - else `KHR_materials_transmission` factor ≥ 0.5 → dielectric, `ior` from `KHR_materials_ior`
//!   (default 1.5), `tint` = base colour;
//! - else perceptual roughness < 0.9 → plastic (ior as above), else diffuse; albedo = base colour
//!   factor × base-colour texture;
//! - GGX alpha = roughness² in all cases;
//! - emission = emissiveFactor × `KHR_materials_emissive_strength` (× the emissive texture's
//!   mean); `doubleSided` makes the emission two-sided;
//! - a primitive without material gets a grey (0.5) diffuse (not glTF's metallic default).
//!
//! glTF texture coordinates already put (0,0) at the top-left of the image, which is our
//! convention, so they are not flipped.

use super::builder::{warn, Builder, MAX_RESOLUTION_SIDE};
use super::obj::MaterialChoice;
use super::primitives::TriMesh;
use super::{image_io, ColorParam, Material, MaterialKind, RenderSettings, SceneDescription};
use crate::light::Environment;
use crate::{Error, Result};
use glam::{Mat4, Vec2, Vec3};
use gltf::mesh::Mode;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Image height of a render set up from a glTF camera (the width follows its aspect ratio).
pub const DEFAULT_HEIGHT: u32 = 512;

/// The first perspective camera of a glTF file, in world space.
#[derive(Clone, Copy, Debug)]
pub struct GltfCamera {
    pub position: Vec3,
    pub forward: Vec3,
    pub up: Vec3,
    pub yfov_deg: f32,
    pub aspect: Option<f32>,
    pub index: usize,
}

/// Loads a glTF/GLB file given directly as the scene.
pub fn load_scene(path: &Path) -> Result<SceneDescription> {
    let mut b = Builder::new(path);
    let no_override = HashMap::new();
    let camera = load(&mut b, path, &Mat4::IDENTITY, &MaterialChoice { all: None, by_name: &no_override }, "scene")?;
    let camera = match camera {
        Some(c) => {
            let aspect = c.aspect.filter(|a| a.is_finite() && *a > 0.0).unwrap_or(1.0);
            let width = ((DEFAULT_HEIGHT as f32 * aspect).round() as u32).clamp(1, MAX_RESOLUTION_SIDE);
            crate::camera::Camera::look_at(c.position, c.position + c.forward, c.up, c.yfov_deg, width, DEFAULT_HEIGHT).ok_or_else(
                || Error::scene(path, format!("cameras[{}]", c.index), "degenerate camera (zero direction or fov outside (0°, 180°))"),
            )?
        }
        None => {
            warn(path, "no perspective camera; using one that frames the scene bounds");
            b.framing_camera(DEFAULT_HEIGHT, DEFAULT_HEIGHT)?
        }
    };
    b.finish(camera, RenderSettings::default(), Environment::Constant(Vec3::ZERO))
}

/// Loads `path` (referenced by `field` of the scene being built), transforms it by `transform`
/// and appends it to `b`. Returns the file's first perspective camera, if any.
pub(crate) fn load(b: &mut Builder, path: &Path, transform: &Mat4, choice: &MaterialChoice, field: &str) -> Result<Option<GltfCamera>> {
    let bytes = std::fs::read(path).map_err(|e| Error::scene(&b.file, field, format!("cannot read glTF '{}': {e}", path.display())))?;
    let fail = |b: &Builder, msg: String| Error::scene(&b.file, field, format!("glTF '{}': {msg}", path.display()));
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| fail(b, format!("{e}")))?;
    let root = document.into_json();
    check_position_accessors(&root).map_err(|m| fail(b, m))?;
    let document = gltf::Document::from_json(root).map_err(|e| fail(b, format!("{e}")))?;
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let mut blob = blob;
    let doc = &document;
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for buffer in doc.buffers() {
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| fail(b, format!("buffers[{}]: no GLB binary chunk", buffer.index())))?,
            gltf::buffer::Source::Uri(uri) => read_uri(uri, &dir).map_err(|e| fail(b, format!("buffers[{}]: {e}", buffer.index())))?,
        };
        if data.len() < buffer.length() {
            return Err(fail(b, format!("buffers[{}] holds {} bytes, declares {}", buffer.index(), data.len(), buffer.length())));
        }
        buffers.push(data);
    }
    let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) else {
        return Ok(None);
    };
    let mut ctx = Ctx { dir, buffers, materials: HashMap::new(), textures: HashMap::new() };
    let mut camera = None;
    let node_count = doc.nodes().count();
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, *transform)).collect();
    stack.reverse();
    let mut visits = 0usize;
    while let Some((node, parent)) = stack.pop() {
        // In a valid file every node has at most one parent, so a tree visits each node once;
        // more visits mean a cycle or shared children, which could otherwise never terminate.
        visits += 1;
        if visits > node_count {
            return Err(fail(b, "the node hierarchy is not a tree (a node has two parents or is its own ancestor)".into()));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if camera.is_none() {
            if let Some(cam) = node.camera() {
                match cam.projection() {
                    gltf::camera::Projection::Perspective(p) => {
                        camera = Some(GltfCamera {
                            position: world.transform_point3(Vec3::ZERO),
                            forward: world.transform_vector3(-Vec3::Z),
                            up: world.transform_vector3(Vec3::Y),
                            yfov_deg: p.yfov().to_degrees(),
                            aspect: p.aspect_ratio(),
                            index: cam.index(),
                        })
                    }
                    gltf::camera::Projection::Orthographic(_) => {
                        warn(&b.file, format!("{field}: orthographic cameras[{}] ignored", cam.index()))
                    }
                }
            }
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                let name = format!("{field} (meshes[{}] '{}' primitive {})", mesh.index(), mesh.name().unwrap_or(""), prim.index());
                let material = ctx.material(b, &prim.material(), choice, field)?;
                let uv_set = prim.material().pbr_metallic_roughness().base_color_texture().map_or(0, |t| t.tex_coord());
                let tri = match read_primitive(&prim, &ctx.buffers, uv_set) {
                    Ok(Some(t)) => t,
                    Ok(None) => continue,
                    Err(e) => return Err(Error::scene(&b.file, &name, format!("glTF '{}': {e}", path.display()))),
                };
                b.add_mesh(&tri.transformed(&world), material, &name)?;
            }
        }
        let children: Vec<_> = node.children().collect();
        for child in children.into_iter().rev() {
            stack.push((child, world));
        }
    }
    Ok(camera)
}

struct Ctx {
    dir: PathBuf,
    buffers: Vec<Vec<u8>>,
    /// Scene material of each glTF material index (None = the default material).
    materials: HashMap<Option<usize>, u32>,
    /// Scene texture of each glTF texture index.
    textures: HashMap<usize, u32>,
}

impl Ctx {
    fn material(&mut self, b: &mut Builder, m: &gltf::Material, choice: &MaterialChoice, field: &str) -> Result<u32> {
        if let Some(all) = choice.all {
            return Ok(all);
        }
        if let Some(&i) = self.materials.get(&m.index()) {
            return Ok(i);
        }
        let i = match (m.index(), m.name().and_then(|n| choice.by_name.get(n))) {
            (None, _) => b.default_material(),
            (Some(_), Some(&i)) => i,
            (Some(index), None) => {
                let converted = self.convert(b, m, &format!("{field} (materials[{index}])"))?;
                b.add_material(converted)
            }
        };
        self.materials.insert(m.index(), i);
        Ok(i)
    }

    fn convert(&mut self, b: &mut Builder, m: &gltf::Material, field: &str) -> Result<Material> {
        let check = |b: &Builder, what: &str, v: Vec3| -> Result<Vec3> {
            if !v.is_finite() || v.min_element() < 0.0 {
                return Err(Error::scene(&b.file, field, format!("{what} {v} must be finite and non-negative")));
            }
            Ok(v)
        };
        let pbr = m.pbr_metallic_roughness();
        let [r, g, bl, _] = pbr.base_color_factor();
        let base = check(b, "baseColorFactor", Vec3::new(r, g, bl))?.min(Vec3::ONE);
        let metallic = pbr.metallic_factor();
        let roughness = pbr.roughness_factor();
        let ior = m.ior().unwrap_or(1.5);
        let transmission = m.transmission().map_or(0.0, |t| t.transmission_factor());
        let strength = m.emissive_strength().unwrap_or(1.0);
        for (what, v) in [
            ("metallicFactor", metallic),
            ("roughnessFactor", roughness),
            ("ior", ior),
            ("transmissionFactor", transmission),
            ("emissiveStrength", strength),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(Error::scene(&b.file, field, format!("{what} {v} must be finite and non-negative")));
            }
        }
        if ior <= 0.0 {
            return Err(Error::scene(&b.file, field, "ior must be positive"));
        }
        let alpha = roughness * roughness;
        let base_tex = match pbr.base_color_texture() {
            Some(info) => Some(self.texture(b, &info.texture(), &format!("{field}.baseColorTexture"))?),
            None => None,
        };
        let albedo = match base_tex {
            Some(index) => ColorParam::texture(index, base),
            None => ColorParam::Const(base),
        };
        let mean_base = base * base_tex.map_or(Vec3::ONE, |t| b.textures[t as usize].mean());
        let kind = if metallic >= 0.5 {
            MaterialKind::Conductor {
                eta: Vec3::ONE,
                k: Vec3::splat(20.0),
                roughness: alpha,
                specular_tint: ColorParam::Const(mean_base),
                dist: Default::default(),
            }
        } else if transmission >= 0.5 {
            MaterialKind::Dielectric { ior, roughness: alpha, tint: mean_base, dist: Default::default() }
        } else if roughness < 0.9 {
            MaterialKind::Plastic { albedo, ior, roughness: alpha, dist: Default::default(), nonlinear: true }
        } else {
            MaterialKind::Lambert { albedo }
        };
        let mut emission = check(b, "emissiveFactor", Vec3::from(m.emissive_factor()))? * strength;
        if let Some(info) = m.emissive_texture() {
            let t = self.texture(b, &info.texture(), &format!("{field}.emissiveTexture"))?;
            emission *= b.textures[t as usize].mean();
        }
        let emission = check(b, "emission (factor × strength)", emission)?;
        let index = m.index().unwrap_or(0);
        Ok(Material {
            name: m.name().map_or_else(|| format!("gltf material {index}"), str::to_string),
            kind,
            emission,
            two_sided_emission: m.double_sided(),
            one_sided: false,
        })
    }

    fn texture(&mut self, b: &mut Builder, t: &gltf::Texture, field: &str) -> Result<u32> {
        if let Some(&i) = self.textures.get(&t.index()) {
            return Ok(i);
        }
        let image = t.source();
        let name = format!("images[{}]", image.index());
        let i = match image.source() {
            gltf::image::Source::View { view, .. } => {
                let bytes = view_bytes(&view, &self.buffers)
                    .ok_or_else(|| Error::scene(&b.file, field, format!("{name}: buffer view out of range")))?;
                let tex = image_io::decode_image(bytes, &name, &b.file, field)?;
                b.add_texture(tex)
            }
            gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => {
                let bytes = read_uri(uri, &self.dir).map_err(|e| Error::scene(&b.file, field, format!("{name}: {e}")))?;
                let tex = image_io::decode_image(&bytes, &name, &b.file, field)?;
                b.add_texture(tex)
            }
            gltf::image::Source::Uri { uri, .. } => {
                let p = self.dir.join(percent_decode(uri));
                b.albedo_texture(&p, field)?
            }
        };
        self.textures.insert(t.index(), i);
        Ok(i)
    }
}

fn view_bytes<'a>(view: &gltf::buffer::View, buffers: &'a [Vec<u8>]) -> Option<&'a [u8]> {
    let data = buffers.get(view.buffer().index())?;
    let end = view.offset().checked_add(view.length())?;
    data.get(view.offset()..end)
}

/// True when every element of `acc` lies inside its buffer view and buffer, so the gltf crate's
/// reader (which slices without checking) cannot panic on a malformed file.
fn accessor_in_bounds(acc: &gltf::Accessor, buffers: &[Vec<u8>]) -> bool {
    let Some(view) = acc.view() else { return false };
    let Some(bytes) = view_bytes(&view, buffers) else { return false };
    if acc.count() == 0 {
        return true;
    }
    let stride = view.stride().unwrap_or(acc.size());
    let last = (acc.count() - 1).checked_mul(stride).and_then(|x| x.checked_add(acc.offset())).and_then(|x| x.checked_add(acc.size()));
    last.is_some_and(|end| end <= bytes.len())
}

/// Reads one primitive as a triangle list; `Ok(None)` for points and lines (skipped).
fn read_primitive(prim: &gltf::Primitive, buffers: &[Vec<u8>], uv_set: u32) -> std::result::Result<Option<TriMesh>, String> {
    let mode = prim.mode();
    if matches!(mode, Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
        return Ok(None);
    }
    for (semantic, acc) in prim.attributes() {
        if !accessor_in_bounds(&acc, buffers) {
            return Err(format!("accessor {} ({semantic:?}) lies outside its buffer (or is sparse, which is not supported)", acc.index()));
        }
    }
    if let Some(acc) = prim.indices() {
        if !accessor_in_bounds(&acc, buffers) {
            return Err(format!("index accessor {} lies outside its buffer", acc.index()));
        }
    }
    let reader = prim.reader(|buf| buffers.get(buf.index()).map(|d| d.as_slice()));
    let positions: Vec<Vec3> = reader.read_positions().ok_or("no POSITION attribute")?.map(Vec3::from).collect();
    let n = positions.len();
    let normals: Vec<Vec3> = reader.read_normals().map(|it| it.map(|v| Vec3::from(v).normalize_or_zero()).collect()).unwrap_or_default();
    let uvs: Vec<Vec2> = reader.read_tex_coords(uv_set).map(|it| it.into_f32().map(Vec2::from).collect()).unwrap_or_default();
    let indices: Vec<u32> = match reader.read_indices() {
        Some(it) => it.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!("index {i} out of range ({n} vertices)"));
    }
    let triangles: Vec<[u32; 3]> = match mode {
        Mode::TriangleStrip => (0..indices.len().saturating_sub(2))
            .map(|i| if i % 2 == 0 { [indices[i], indices[i + 1], indices[i + 2]] } else { [indices[i + 1], indices[i], indices[i + 2]] })
            .collect(),
        Mode::TriangleFan => (1..indices.len().saturating_sub(1)).map(|i| [indices[0], indices[i], indices[i + 1]]).collect(),
        _ => indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    };
    let normals = if normals.len() == n { normals } else { Vec::new() };
    let uvs = if uvs.len() == n { uvs } else { Vec::new() };
    Ok(Some(TriMesh { positions, normals, uvs, triangles }))
}

/// gltf-json 1.4's validation reads `accessors[i]` for every primitive's POSITION attribute
/// before checking that `i` exists, and panics on a file where it does not; this check runs first.
fn check_position_accessors(root: &gltf::json::Root) -> std::result::Result<(), String> {
    let semantic = gltf::json::validation::Checked::Valid(gltf::json::mesh::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(i) = prim.attributes.get(&semantic) {
                if i.value() >= root.accessors.len() {
                    return Err(format!(
                        "meshes[{m}].primitives[{p}].attributes.POSITION: accessor {} does not exist ({} accessors)",
                        i.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Bytes of a buffer or image URI: a base64 `data:` URI or a path relative to `dir`.
fn read_uri(uri: &str, dir: &Path) -> std::result::Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest.split_once(";base64,").ok_or("data URI is not base64")?;
        return base64_decode(payload).ok_or_else(|| "malformed base64 in data URI".to_string());
    }
    if uri.contains("://") {
        return Err(format!("unsupported URI '{uri}' (only relative paths and data URIs)"));
    }
    let p = dir.join(percent_decode(uri));
    std::fs::read(&p).map_err(|e| format!("cannot read '{}': {e}", p.display()))
}

/// URI percent-decoding; malformed escapes are kept literally.
fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard base64 (RFC 4648) with optional padding and ignored whitespace.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        };
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_strings() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8gd29ybGQ").unwrap(), b"hello world");
        assert_eq!(base64_decode("AAEC/w==").unwrap(), vec![0, 1, 2, 255]);
        assert!(base64_decode("a*b").is_none());
    }

    /// Found by renderer/tests/fuzz_scenes.rs: gltf-json's own validation panicked here.
    #[test]
    fn position_accessor_out_of_range_is_an_error_not_a_panic() {
        let dir = std::env::temp_dir().join(format!("pixguide-gltf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad-position.gltf");
        let json = r#"{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": 65536}}]}]}"#;
        std::fs::write(&p, json).unwrap();
        let e = load_scene(&p).err().expect("an error").to_string();
        std::fs::remove_dir_all(&dir).ok();
        assert!(e.contains("bad-position.gltf") && e.contains("meshes[0].primitives[0].attributes.POSITION") && e.contains("65536"), "{e}");
    }

    #[test]
    fn percent_decoding_handles_bad_escapes() {
        assert_eq!(percent_decode("a%20b.png"), "a b.png");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("%zz"), "%zz");
        assert_eq!(percent_decode("%"), "%");
        assert_eq!(percent_decode("%é1"), "%é1");
    }
}
