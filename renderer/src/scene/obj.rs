//! Wavefront OBJ (+ MTL) meshes via tobj: polygons triangulated (fan), one index per vertex.
//!
//! MTL materials become Lambertian: `Kd` (default 0.5 grey) or `map_Kd` (the texture alone,
//! sRGB), with `Ke` as emission. A scene can replace any MTL material by name, or all of them
//! (see `MaterialChoice`). OBJ texture coordinates have v = 0 at the bottom of the image; they are
//! flipped to `Texture`'s top-row-first convention.

use super::builder::{warn, Builder};
use super::primitives::TriMesh;
use super::{ColorParam, Material, MaterialKind};
use crate::{Error, Result};
use glam::{Mat4, Vec2, Vec3};
use std::cell::RefCell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// How a mesh file's own materials map to scene materials.
pub struct MaterialChoice<'a> {
    /// Every triangle gets this material.
    pub all: Option<u32>,
    /// Scene materials replacing the file's materials of the same name.
    pub by_name: &'a HashMap<String, u32>,
}

/// Loads `path` (referenced by `field` of the scene), transforms it and appends it to `b`.
#[allow(clippy::field_reassign_with_default)]
pub(crate) fn load(b: &mut Builder, path: &Path, transform: &Mat4, choice: &MaterialChoice, field: &str) -> Result<()> {
    let bytes = std::fs::read(path).map_err(|e| Error::scene(&b.file, field, format!("cannot read mesh '{}': {e}", path.display())))?;
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    // The MTL actually read, and the names that could not be found.
    let found_mtl: RefCell<Option<PathBuf>> = RefCell::new(None);
    let missing_mtl: RefCell<Vec<PathBuf>> = RefCell::new(Vec::new());
    let mtl_problem: RefCell<Option<String>> = RefCell::new(None);
    // Field by field: the struct grows with tobj's optional features.
    let mut options = tobj::LoadOptions::default();
    options.triangulate = true;
    options.single_index = true;
    options.ignore_points = true;
    options.ignore_lines = true;
    let (models, materials) = tobj::load_obj_buf(&mut &bytes[..], &options, |mtl: &Path| {
        // Exporters often write the mtllib path relative to somewhere else (McGuire's Cornell box
        // says `scenes/CornellBox-Original.mtl`): fall back to the bare file name beside the OBJ.
        let direct = dir.join(mtl);
        let candidate = if direct.is_file() { Some(direct) } else { mtl.file_name().map(|n| dir.join(n)).filter(|p| p.is_file()) };
        match candidate {
            Some(p) => {
                let r = std::fs::read(&p).map_err(|_| tobj::LoadError::OpenFileFailed).and_then(|text| {
                    check_mtl(&text).map_err(|m| {
                        mtl_problem.borrow_mut().get_or_insert(format!("'{}' {m}", p.display()));
                        tobj::LoadError::MaterialParseError
                    })?;
                    tobj::load_mtl_buf(&mut &text[..])
                });
                if r.is_ok() && found_mtl.borrow().is_none() {
                    *found_mtl.borrow_mut() = Some(p);
                }
                r
            }
            None => {
                missing_mtl.borrow_mut().push(mtl.to_path_buf());
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    })
    .map_err(|e| Error::scene(&b.file, field, format!("cannot parse OBJ '{}': {e}", path.display())))?;

    let materials = match materials {
        Ok(m) => m,
        Err(e) => {
            let missing = missing_mtl.borrow();
            if let Some(problem) = mtl_problem.borrow().as_ref() {
                warn(&b.file, format!("{field}: MTL {problem}; using grey diffuse"));
            } else if missing.is_empty() {
                warn(&b.file, format!("{field}: MTL of '{}' unreadable ({e}); using grey diffuse", path.display()));
            } else {
                let names: Vec<_> = missing.iter().map(|p| p.display().to_string()).collect();
                warn(&b.file, format!("{field}: MTL file(s) {} of '{}' not found; using grey diffuse", names.join(", "), path.display()));
            }
            Vec::new()
        }
    };
    let mtl_dir = found_mtl.borrow().as_ref().and_then(|p| p.parent().map(Path::to_path_buf)).unwrap_or(dir);

    // Scene indices of the file's materials, converted on first use.
    let mut mapped: Vec<Option<u32>> = vec![None; materials.len()];
    for model in &models {
        let mesh = &model.mesh;
        let material = match (choice.all, mesh.material_id) {
            (Some(m), _) => m,
            (None, Some(id)) if id < materials.len() => match mapped[id] {
                Some(m) => m,
                None => {
                    let mtl = &materials[id];
                    let m = match choice.by_name.get(&mtl.name) {
                        Some(&m) => m,
                        None => {
                            let converted = convert_material(b, mtl, &mtl_dir, field)?;
                            b.add_material(converted)
                        }
                    };
                    mapped[id] = Some(m);
                    m
                }
            },
            _ => b.default_material(),
        };
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])).collect();
        let n = positions.len();
        let normals: Vec<Vec3> = if mesh.normals.len() == 3 * n {
            mesh.normals.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2]).normalize_or_zero()).collect()
        } else {
            Vec::new()
        };
        let uvs: Vec<Vec2> = if mesh.texcoords.len() == 2 * n {
            mesh.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], 1.0 - t[1])).collect()
        } else {
            Vec::new()
        };
        let triangles: Vec<[u32; 3]> = mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        let tri = TriMesh { positions, normals, uvs, triangles };
        let object = format!("{field} (object '{}')", model.name);
        b.add_mesh(&tri.transformed(transform), material, &object)?;
    }
    Ok(())
}

/// tobj 4.0 unwraps the colour of a `Ka`/`Kd`/`Ks`/`Ke` line with fewer than three numbers
/// (a panic), so such lines are refused before the MTL reaches it.
fn check_mtl(text: &[u8]) -> std::result::Result<(), String> {
    for (i, line) in String::from_utf8_lossy(text).lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next() {
            if words.count() < 3 {
                return Err(format!("line {}: {key} needs three numbers", i + 1));
            }
        }
    }
    Ok(())
}

fn convert_material(b: &mut Builder, mtl: &tobj::Material, mtl_dir: &Path, field: &str) -> Result<Material> {
    let color = |b: &Builder, key: &str, v: Option<[f32; 3]>, default: Vec3| -> Result<Vec3> {
        let c = v.map(Vec3::from).unwrap_or(default);
        if !c.is_finite() || c.min_element() < 0.0 {
            return Err(Error::scene(&b.file, field, format!("MTL material '{}': {key} {c} must be finite and non-negative", mtl.name)));
        }
        Ok(c)
    };
    let kd = color(b, "Kd", mtl.diffuse, Vec3::splat(0.5))?;
    let ke = color(b, "Ke", mtl.emissive, Vec3::ZERO)?;
    let albedo = match &mtl.diffuse_texture {
        Some(tex) => {
            let sub = format!("{field} (MTL material '{}' map_Kd)", mtl.name);
            ColorParam::texture(b.albedo_texture(&mtl_dir.join(tex), &sub)?, Vec3::ONE)
        }
        None => ColorParam::Const(kd.min(Vec3::ONE)),
    };
    Ok(Material {
        name: mtl.name.clone(),
        kind: MaterialKind::Lambert { albedo },
        emission: ke,
        two_sided_emission: false,
        one_sided: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Found by renderer/tests/fuzz_scenes.rs: a truncated `Kd` line panicked inside tobj.
    #[test]
    fn short_colour_line_in_the_mtl_is_a_warning_not_a_panic() {
        let dir = std::env::temp_dir().join(format!("pixguide-obj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let obj = dir.join("tri.obj");
        std::fs::write(&obj, "mtllib tri.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n").unwrap();
        std::fs::write(dir.join("tri.mtl"), "newmtl red\nKd 0.5\n").unwrap();
        assert_eq!(check_mtl(b"newmtl red\nKd 0.5\n").unwrap_err(), "line 2: Kd needs three numbers");
        let mut b = Builder::new(&dir.join("scene.toml"));
        let none = HashMap::new();
        load(&mut b, &obj, &Mat4::IDENTITY, &MaterialChoice { all: None, by_name: &none }, "shapes[0].file").unwrap();
        std::fs::remove_dir_all(&dir).ok();
        // The material falls back to grey, as for a missing MTL.
        assert_eq!(b.mesh.triangles.len(), 1);
        assert_eq!(b.materials[b.mesh.material[0] as usize].name, "default");
    }
}
