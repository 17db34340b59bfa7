//! `<shape>`: OBJ meshes and Mitsuba's built-in shapes (rectangle, cube, disk, sphere) with
//! their transforms, normal options, BSDF and area emitter, added to the scene's mesh.

use super::{BsdfDef, Loader};
use crate::scene::obj::{self, MaterialChoice};
use crate::scene::primitives::{self, TriMesh};
use crate::scene::{ColorParam, Material, MaterialKind};
use crate::Result;
use glam::{Mat3, Mat4, Vec3};
use roxmltree::Node;
use std::collections::HashMap;

impl<'a, 'i> Loader<'a, 'i> {
    pub(super) fn shape(&mut self, n: Node<'a, 'i>) -> Result<()> {
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
                    let def =
                        self.bsdfs.get(&id).cloned().ok_or_else(|| self.err(c, format!("no <bsdf id=\"{id}\"> defined before this")))?;
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
                ("emitter", _) => emission = Some(self.area_emitter(c)?),
                _ => return Err(self.err(c, format!("unsupported parameter of a \"{ty}\" shape"))),
            }
        }
        let det = Mat3::from_mat4(to_world).determinant();
        if det == 0.0 || !det.is_finite() {
            return Err(self.err(n, "the shape's toWorld transform is singular"));
        }
        // Mitsuba's default BSDF is a grey diffuse, but black on an emitter (Mitsuba 3's Shape).
        let default_albedo = if emission.is_some() { 0.0 } else { 0.5 };
        let def = bsdf.unwrap_or_else(|| BsdfDef {
            name: "default".into(),
            kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::splat(default_albedo)) },
            two_sided: false,
        });
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
        let name =
            if emission.max_element() > 0.0 { format!("{} (emitter {})", def.name, self.b.materials.len()) } else { def.name.clone() };
        let one_sided = !def.two_sided;
        if emission.max_element() <= 0.0 {
            if let Some(i) = self.b.materials.iter().position(|m| m.name == name && !m.is_emissive() && m.one_sided == one_sided) {
                return i as u32;
            }
        }
        self.b.add_material(Material { name, kind: def.kind.clone(), emission, two_sided_emission: false, one_sided })
    }
}

/// Whether any colour of a material varies over the surface.
fn kind_is_textured(kind: &MaterialKind) -> bool {
    match kind {
        MaterialKind::Lambert { albedo } | MaterialKind::Plastic { albedo, .. } => albedo.is_textured(),
        MaterialKind::Conductor { specular_tint, .. } => specular_tint.is_textured(),
        MaterialKind::Dielectric { .. } => false,
    }
}
