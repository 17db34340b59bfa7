//! A loaded scene written back out as Mitsuba 3 XML, so that Mitsuba renders exactly the
//! geometry, camera, materials and lights we render: our TOML scenes have no Mitsuba file of
//! their own. Used by the Mitsuba cross-check test and by `pixguide bench`'s side-by-side
//! integrator measurement.
//!
//! Everything a scene can hold is written with the meaning it has when we render it, so that
//! both renderers compute the same image:
//! - materials: Lambert → `diffuse`, conductor → `conductor`/`roughconductor` (η, k and the tint
//!   as `specular_reflectance`), dielectric → `dielectric`/`roughdielectric` (the tint as both
//!   specular reflectance and transmittance, exterior IOR 1), plastic → `plastic`/`roughplastic`
//!   (our `nonlinear` flag, exterior IOR 1); below `MIN_ALPHA` a lobe is the smooth BSDF, as ours
//!   is. Each is wrapped in `twosided` unless it is one-sided or transmits.
//! - colours: the value our BSDF sees (clamped as `Material::bsdf` clamps); image textures as
//!   linear EXR files with their scale baked in, checkerboards as `checkerboard`; a texture's uv
//!   transform is baked into the OBJ's texture coordinates (it is affine, so interpolating the
//!   transformed coordinates is the same as transforming the interpolated ones).
//! - lights: one-sided area emitters; a constant environment as `constant`; a lat-long map as
//!   `envmap`, resampled so that Mitsuba's lookup equals ours (see `write_envmap`) and turned by
//!   our rotation through `to_world`.
//!
//! Mitsuba has no two-sided area emitter, so two-sided emission (glTF's double-sided emissive
//! materials) is an error naming the material, never a silently different scene.

use crate::camera::FovAxis;
use crate::film::exr_io::write_rgb_planes;
use crate::light::EnvironmentView;
use crate::material::{mitsuba_nonlinear_albedo, ColorParam, Distribution, Material, MaterialKind, MIN_ALPHA};
use crate::scene::Scene;
use crate::{Error, Result};
use glam::{Affine2, Vec2, Vec3};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn unsupported(what: String) -> Error {
    Error::Invalid(format!("exporting the scene to Mitsuba XML: {what} is not supported"))
}

/// Writes `scene` as `dir/scene.xml` plus one or two OBJs per material (`dir/material<i>.obj`,
/// `dir/material<i>-flat.obj` for triangles without usable vertex normals), the textures
/// (`dir/material<i>-<parameter>.exr`) and the environment map (`dir/envmap.exr`), at the
/// camera's current resolution, and returns the XML's path.
pub fn export_mitsuba(scene: &Scene, dir: &Path) -> Result<PathBuf> {
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
    environment(scene, dir, &mut xml)?;
    let mesh = &scene.mesh;
    for (mi, material) in scene.materials.iter().enumerate() {
        let tris: Vec<usize> = (0..mesh.triangles.len()).filter(|&t| mesh.material[t] as usize == mi).collect();
        if tris.is_empty() {
            continue;
        }
        let (bsdf, to_uv) = bsdf(scene, material, mi, dir)?;
        let _ = writeln!(xml, "  {}", bsdf.replacen("<bsdf ", &format!("<bsdf id=\"m{mi}\" "), 1));
        let emitter = if material.is_emissive() {
            if material.two_sided_emission {
                return Err(unsupported(format!(
                    "two-sided emission (material {:?}): Mitsuba's area emitters emit on one side",
                    material.name
                )));
            }
            format!("<emitter type=\"area\"><rgb name=\"radiance\" value=\"{}\"/></emitter>", rgb(material.emission))
        } else {
            String::new()
        };
        // Shading normals only on non-emitters: Mitsuba's area emitter emits on the side of the
        // shading normal, ours on the geometric normal's.
        let usable = |t: usize| {
            !material.is_emissive()
                && !mesh.normals.is_empty()
                && mesh.triangles[t].iter().all(|&v| {
                    let n = mesh.normals[v as usize];
                    n.is_finite() && n.length_squared() > 0.0
                })
        };
        let (smooth, flat): (Vec<usize>, Vec<usize>) = tris.iter().partition(|&&t| usable(t));
        for (group, normals, suffix) in [(smooth, true, ""), (flat, false, "-flat")] {
            if group.is_empty() {
                continue;
            }
            let file = format!("material{mi}{suffix}.obj");
            let path = dir.join(&file);
            std::fs::write(&path, obj(scene, &group, normals, to_uv)).map_err(|e| Error::io(&path, e))?;
            let _ = writeln!(xml, "  <shape type=\"obj\"><string name=\"filename\" value=\"{file}\"/><ref id=\"m{mi}\"/>{emitter}</shape>");
        }
    }
    xml.push_str("</scene>\n");
    let path = dir.join("scene.xml");
    std::fs::write(&path, xml).map_err(|e| Error::io(&path, e))?;
    Ok(path)
}

fn rgb(v: Vec3) -> String {
    format!("{}, {}, {}", v.x, v.y, v.z)
}

/// A colour as a BSDF sees it after `Material::bsdf` and `Bsdf::resolved`: finite, in [0, 1].
fn unit_colour(v: Vec3) -> Vec3 {
    let f = |x: f32| if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    Vec3::new(f(v.x), f(v.y), f(v.z))
}

/// GGX or Beckmann alpha as our BSDFs use it: 0 (smooth) below `MIN_ALPHA`, at most 1.
fn alpha(roughness: f32) -> f32 {
    if roughness >= MIN_ALPHA {
        roughness.min(1.0)
    } else {
        0.0
    }
}

fn rough_params(a: f32, dist: Distribution) -> String {
    let d = match dist {
        Distribution::Ggx => "ggx",
        Distribution::Beckmann => "beckmann",
    };
    format!("<float name=\"alpha\" value=\"{a}\"/><string name=\"distribution\" value=\"{d}\"/>")
}

/// The Mitsuba BSDF of `material` (without an id) and the uv transform of its textured colour,
/// if it has one (a material has at most one colour parameter).
fn bsdf(scene: &Scene, material: &Material, mi: usize, dir: &Path) -> Result<(String, Option<Affine2>)> {
    let mut to_uv = None;
    // `map` turns the colour our BSDF sees into the one Mitsuba's BSDF must see.
    let mut colour = |name: &str, c: &ColorParam, map: &dyn Fn(Vec3) -> Vec3| -> Result<String> {
        let unit_colour = |v: Vec3| map(unit_colour(v));
        match c {
            ColorParam::Const(v) => Ok(format!("<rgb name=\"{name}\" value=\"{}\"/>", rgb(unit_colour(*v)))),
            ColorParam::Texture { index, scale, to_uv: t } => {
                let tex = scene.textures.get(*index as usize).ok_or_else(|| unsupported(format!("a missing texture {index}")))?;
                let file = format!("material{mi}-{name}.exr");
                let texels: Vec<Vec3> = tex.texels.iter().map(|&t| unit_colour(t * *scale)).collect();
                let plane = |k: usize| texels.iter().map(|t| t[k]).collect();
                let path = dir.join(&file);
                write_rgb_planes(&path, tex.width, tex.height, [plane(0), plane(1), plane(2)])?;
                to_uv = Some(*t);
                Ok(format!(
                    "<texture type=\"bitmap\" name=\"{name}\"><string name=\"filename\" value=\"{file}\"/><boolean name=\"raw\" value=\"true\"/><string name=\"filter_type\" value=\"bilinear\"/><string name=\"wrap_mode\" value=\"repeat\"/></texture>"
                ))
            }
            ColorParam::Checkerboard { color0, color1, to_uv: t } => {
                to_uv = Some(*t);
                Ok(format!(
                    "<texture type=\"checkerboard\" name=\"{name}\"><rgb name=\"color0\" value=\"{}\"/><rgb name=\"color1\" value=\"{}\"/></texture>",
                    rgb(unit_colour(*color0)),
                    rgb(unit_colour(*color1))
                ))
            }
        }
    };
    let finite = |v: Vec3, or: Vec3| if v.is_finite() { v } else { or };
    let (inner, transmits) = match &material.kind {
        MaterialKind::Lambert { albedo } => (format!("<bsdf type=\"diffuse\">{}</bsdf>", colour("reflectance", albedo, &|v| v)?), false),
        MaterialKind::Conductor { eta, k, roughness, specular_tint, dist } => {
            let a = alpha(*roughness);
            let (ty, rough) = if a > 0.0 { ("roughconductor", rough_params(a, *dist)) } else { ("conductor", String::new()) };
            let s = format!(
                "<bsdf type=\"{ty}\">{rough}<rgb name=\"eta\" value=\"{}\"/><rgb name=\"k\" value=\"{}\"/>{}</bsdf>",
                rgb(finite(*eta, Vec3::ONE)),
                rgb(finite(*k, Vec3::ZERO).max(Vec3::ZERO)),
                colour("specular_reflectance", specular_tint, &|v| v)?
            );
            (s, false)
        }
        MaterialKind::Dielectric { ior, roughness, tint, dist } => {
            let a = alpha(*roughness);
            let (ty, rough) = if a > 0.0 { ("roughdielectric", rough_params(a, *dist)) } else { ("dielectric", String::new()) };
            let eta = if ior.is_finite() && *ior > 0.0 { *ior } else { 1.0 };
            let t = rgb(finite(*tint, Vec3::ZERO).max(Vec3::ZERO));
            let s = format!(
                "<bsdf type=\"{ty}\">{rough}<float name=\"int_ior\" value=\"{eta}\"/><float name=\"ext_ior\" value=\"1\"/><rgb name=\"specular_reflectance\" value=\"{t}\"/><rgb name=\"specular_transmittance\" value=\"{t}\"/></bsdf>"
            );
            (s, true)
        }
        MaterialKind::Plastic { albedo, ior, roughness, dist, nonlinear } => {
            let a = alpha(*roughness);
            let (ty, rough) = if a > 0.0 { ("roughplastic", rough_params(a, *dist)) } else { ("plastic", String::new()) };
            // Plastic::new's clamp: the coat tables span η in [1, 3].
            let eta = if ior.is_finite() { ior.clamp(1.0, 3.0) } else { 1.5 };
            let s = format!(
                "<bsdf type=\"{ty}\">{rough}<float name=\"int_ior\" value=\"{eta}\"/><float name=\"ext_ior\" value=\"1\"/><boolean name=\"nonlinear\" value=\"{nonlinear}\"/>{}</bsdf>",
                colour("diffuse_reflectance", albedo, &|v| if *nonlinear { mitsuba_nonlinear_albedo(v, eta, a, *dist) } else { v })?
            );
            (s, false)
        }
    };
    // Ours shade a reflecting material alike from both sides unless it is one-sided; a
    // transmitting one is two-sided by nature (and Mitsuba's `twosided` refuses it).
    let s = if material.one_sided || transmits { inner } else { format!("<bsdf type=\"twosided\">{inner}</bsdf>") };
    Ok((s, to_uv))
}

/// The OBJ text of triangles `tris`, with vertex normals if `normals` and texture coordinates
/// (transformed by `to_uv`) if it is given. Each triangle is wound so that its winding normal is
/// our geometric normal (which vertex normals may have flipped: `Mesh::geometric_normal`), since
/// that decides which side an area light emits on, in both renderers.
fn obj(scene: &Scene, tris: &[usize], normals: bool, to_uv: Option<Affine2>) -> String {
    let mesh = &scene.mesh;
    let mut s = String::new();
    for &t in tris {
        let [a, b, c] = mesh.triangles[t];
        let [pa, pb, pc] = mesh.triangle(t);
        let order = if (pb - pa).cross(pc - pa).dot(mesh.geometric_normal(t)) < 0.0 { [a, c, b] } else { [a, b, c] };
        for v in order {
            let v = v as usize;
            let p = mesh.positions[v];
            let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
            if normals {
                let n = mesh.normals[v].normalize();
                let _ = writeln!(s, "vn {} {} {}", n.x, n.y, n.z);
            }
            if let Some(m) = to_uv {
                let uv = m.transform_point2(mesh.uvs.get(v).copied().unwrap_or(Vec2::ZERO));
                // Mitsuba's OBJ loader flips v (flip_tex_coords) back to our convention, v = 0 at the top.
                let _ = writeln!(s, "vt {} {}", uv.x, 1.0 - uv.y);
            }
        }
    }
    for k in 0..tris.len() {
        let f = |i: usize| match (to_uv.is_some(), normals) {
            (true, true) => format!("{i}/{i}/{i}"),
            (true, false) => format!("{i}/{i}"),
            (false, true) => format!("{i}//{i}"),
            (false, false) => i.to_string(),
        };
        let _ = writeln!(s, "f {} {} {}", f(3 * k + 1), f(3 * k + 2), f(3 * k + 3));
    }
    s
}

/// Appends the environment's emitter to `xml` (and writes its map).
fn environment(scene: &Scene, dir: &Path, xml: &mut String) -> Result<()> {
    match scene.lights.environment() {
        EnvironmentView::Black => {}
        EnvironmentView::Constant(c) => {
            let _ = writeln!(xml, "  <emitter type=\"constant\"><rgb name=\"radiance\" value=\"{}\"/></emitter>", rgb(c));
        }
        EnvironmentView::Map { width, height, texels, cos_rot: c, sin_rot: s } => {
            write_envmap(&dir.join("envmap.exr"), width, height, texels)?;
            // d_world = R_y(α) d_map; Mitsuba looks up to_world⁻¹ · d_world.
            let _ = writeln!(
                xml,
                "  <emitter type=\"envmap\"><string name=\"filename\" value=\"envmap.exr\"/><transform name=\"to_world\"><matrix value=\"{c} 0 {s} 0 0 1 0 0 {} 0 {c} 0 0 0 0 1\"/></transform></emitter>",
                -s
            );
        }
    }
    Ok(())
}

/// Our lat-long map resampled for Mitsuba's `envmap`, so that its bilinear lookup is ours.
///
/// Across (u), both look up x = u·W − 0.5 wrapping around: the columns stay. Down (v), ours
/// looks up y = v·H − 0.5 clamped to the first and last rows (texel centres at
/// v = (j + ½)/H), while Mitsuba's rows sit at v = k/(H' − 1), the first and last on the poles.
/// Our lookup is linear in v between knots at 0, ½/H, 3/2H, …, 1 − ½/H, 1, all multiples of
/// 1/2H, so H' = 2H + 1 rows at v = k/2H, each holding our value there (a texel row for odd k,
/// the mean of two neighbours for even k, the end rows at the poles), give the same function.
/// A one-column map becomes two equal columns (Mitsuba needs two).
fn write_envmap(path: &Path, width: usize, height: usize, texels: &[Vec3]) -> Result<()> {
    let (w_out, h_out, out) = resample_envmap(width, height, texels);
    let plane = |k: usize| out.iter().map(|t| t[k]).collect();
    Ok(write_rgb_planes(path, w_out as u32, h_out as u32, [plane(0), plane(1), plane(2)])?)
}

/// `write_envmap`'s image: its width, height and texels, row-major.
fn resample_envmap(width: usize, height: usize, texels: &[Vec3]) -> (usize, usize, Vec<Vec3>) {
    let w_out = width.max(2);
    let h_out = 2 * height + 1;
    let row = |j: usize| &texels[j * width..(j + 1) * width];
    let mut out = Vec::with_capacity(w_out * h_out);
    for k in 0..h_out {
        for x in 0..w_out {
            let x = x % width;
            let v = if k == 0 {
                row(0)[x]
            } else if k == 2 * height {
                row(height - 1)[x]
            } else if k % 2 == 1 {
                row(k / 2)[x]
            } else {
                0.5 * (row(k / 2 - 1)[x] + row(k / 2)[x])
            };
            out.push(v);
        }
    }
    (w_out, h_out, out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::{Environment, Lights};
    use crate::texture::Texture;

    /// Mitsuba 3's `envmap` lookup (src/emitters/envmap.cpp, `eval_spectrum` after
    /// `direction_to_uv`): the image gets a copy of its first column appended, then
    /// u ← u − ½/W (mod 1) and v stretch over (W, H − 1) texel steps, bilinear.
    fn mitsuba_envmap(w: usize, h: usize, texels: &[Vec3], to_world_inv: glam::Mat3, dir: Vec3) -> Vec3 {
        let d = to_world_inv * dir;
        let uv = Vec2::new(d.x.atan2(-d.z) / std::f32::consts::TAU, d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI);
        let (rx, ry) = (w + 1, h);
        let mut uv = uv - Vec2::new(0.5 / w as f32, 0.0);
        uv -= uv.floor();
        let uv = uv * Vec2::new((rx - 1) as f32, (ry - 1) as f32);
        let (px, py) = ((uv.x as usize).min(rx - 2), (uv.y as usize).min(ry - 2));
        let (fx, fy) = (uv.x - px as f32, uv.y - py as f32);
        let at = |x: usize, y: usize| texels[y * w + x % w];
        let a = at(px, py) * (1.0 - fx) + at(px + 1, py) * fx;
        let b = at(px, py + 1) * (1.0 - fx) + at(px + 1, py + 1) * fx;
        a * (1.0 - fy) + b * fy
    }

    /// The resampled map under Mitsuba's lookup gives our radiance in every direction, for maps
    /// whose texels all differ (a stretch, a half-texel shift or a mirrored axis would show as
    /// errors of the order of the texel contrast, 0.1–1 here).
    #[test]
    fn the_exported_envmap_under_mitsubas_lookup_is_our_environment() {
        let mut rng = crate::rng::Pcg32::new(7, 1);
        for (w, h, rotation) in [(8usize, 4usize, 0.0f32), (13, 7, 30.0), (1, 3, 230.0), (32, 16, -75.0)] {
            let texels: Vec<Vec3> = (0..w * h).map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) + 0.1).collect();
            let image = Texture { width: w as u32, height: h as u32, texels };
            let lights =
                Lights::build(&crate::geometry::Mesh::default(), &[], Environment::Map { image, rotation_deg: rotation, scale: 1.5 });
            let EnvironmentView::Map { width, height, texels, cos_rot: c, sin_rot: s } = lights.environment() else { panic!("not a map") };
            let (wo, ho, out) = resample_envmap(width, height, texels);
            let to_world = glam::Mat3::from_cols(Vec3::new(c, 0.0, -s), Vec3::Y, Vec3::new(s, 0.0, c));
            for _ in 0..2000 {
                let dir = crate::sampling::square_to_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
                let ours = lights.env_radiance(dir);
                let theirs = mitsuba_envmap(wo, ho, &out, to_world.inverse(), dir);
                assert!(
                    (ours - theirs).abs().max_element() < 2e-3 * ours.max_element(),
                    "{w}x{h} rot {rotation}: {dir}: ours {ours}, Mitsuba {theirs}"
                );
            }
        }
    }
}
