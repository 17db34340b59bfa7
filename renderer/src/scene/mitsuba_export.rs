//! A loaded scene written back out as Mitsuba 3 XML, so that Mitsuba renders exactly the
//! geometry, camera and materials we render: the TOML Cornell box has no Mitsuba file of its
//! own. Used by the Mitsuba cross-check test and by `pixguide bench`'s side-by-side integrator
//! measurement. Only what such scenes use is supported (constant Lambert colours, one-sided area
//! lights, no environment); anything else is an error naming the material, never a silently
//! different scene.

use crate::camera::FovAxis;
use crate::material::{ColorParam, MaterialKind};
use crate::scene::Scene;
use crate::{Error, Result};
use glam::Vec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Writes `scene` as `dir/scene.xml` plus one OBJ per material (`dir/material<i>.obj`), at the
/// camera's current resolution, and returns the XML's path.
pub fn export_mitsuba(scene: &Scene, dir: &Path) -> Result<PathBuf> {
    let unsupported = |what: String| Error::Invalid(format!("exporting the scene to Mitsuba XML: {what} is not supported"));
    if scene.lights.env_radiance(Vec3::Y) != Vec3::ZERO {
        return Err(unsupported("an environment light".into()));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let c = &scene.camera;
    // Mitsuba's camera looks down +z with +x to the left.
    let left = -c.right;
    let m = [
        [left.x, c.up.x, c.forward.x, c.position.x],
        [left.y, c.up.y, c.forward.y, c.position.y],
        [left.z, c.up.z, c.forward.z, c.position.z],
    ];
    let axis = match c.fov_axis {
        FovAxis::X => "x",
        FovAxis::Y => "y",
        FovAxis::Diagonal => "diagonal",
        FovAxis::Smaller => "smaller",
        FovAxis::Larger => "larger",
    };
    let mut xml = String::from("<scene version=\"3.0.0\">\n");
    let mat: Vec<String> = m.iter().flatten().map(|v| v.to_string()).chain(["0", "0", "0", "1"].map(String::from)).collect();
    let _ = writeln!(
        xml,
        "  <sensor type=\"perspective\"><float name=\"fov\" value=\"{}\"/><string name=\"fov_axis\" value=\"{axis}\"/>\n    <transform name=\"to_world\"><matrix value=\"{}\"/></transform>\n    <film type=\"hdrfilm\"><integer name=\"width\" value=\"{}\"/><integer name=\"height\" value=\"{}\"/></film></sensor>",
        2.0 * c.tan_half_fov.atan().to_degrees(),
        mat.join(" "),
        c.width,
        c.height
    );
    let rgb = |v: Vec3| format!("{}, {}, {}", v.x, v.y, v.z);
    let mesh = &scene.mesh;
    for (mi, material) in scene.materials.iter().enumerate() {
        let tris: Vec<usize> = (0..mesh.triangles.len()).filter(|&t| mesh.material[t] as usize == mi).collect();
        if tris.is_empty() {
            continue;
        }
        let bsdf = match &material.kind {
            MaterialKind::Lambert { albedo: ColorParam::Const(a) } => {
                format!("<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"{}\"/></bsdf>", rgb(*a))
            }
            other => return Err(unsupported(format!("material {:?} ({other:?})", material.name))),
        };
        let emitter = if material.is_emissive() {
            if material.two_sided_emission {
                return Err(unsupported(format!("two-sided emission (material {:?})", material.name)));
            }
            format!("<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>", rgb(material.emission))
        } else {
            String::new()
        };
        let mut obj = String::new();
        // Shading normals only on non-emitters: an emitter's front is its winding on both sides.
        let normals = !mesh.normals.is_empty() && !material.is_emissive();
        for &t in &tris {
            for &v in &mesh.triangles[t] {
                let p = mesh.positions[v as usize];
                let _ = writeln!(obj, "v {} {} {}", p.x, p.y, p.z);
                if normals {
                    let n = mesh.normals[v as usize];
                    let _ = writeln!(obj, "vn {} {} {}", n.x, n.y, n.z);
                }
            }
        }
        for k in 0..tris.len() {
            let (a, b, c) = (3 * k + 1, 3 * k + 2, 3 * k + 3);
            let _ = if normals { writeln!(obj, "f {a}//{a} {b}//{b} {c}//{c}") } else { writeln!(obj, "f {a} {b} {c}") };
        }
        let file = format!("material{mi}.obj");
        let path = dir.join(&file);
        std::fs::write(&path, obj).map_err(|e| Error::io(&path, e))?;
        let _ = writeln!(
            xml,
            "  <shape type=\"obj\"><string name=\"filename\" value=\"{file}\"/><bsdf type=\"twosided\">{bsdf}</bsdf>{emitter}</shape>"
        );
    }
    xml.push_str("</scene>\n");
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).map_err(|e| Error::io(&path, e))?;
    Ok(path)
}
