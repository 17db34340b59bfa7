//! Scene files a user got wrong: one test per error, each message naming the file and the field.

use glam::Vec3;
use renderer::light::Environment;
use std::path::{Path, PathBuf};

mod scene_files;
use scene_files::*;

fn scene_with(dir: &Path, name: &str, body: &str) -> PathBuf {
    write(dir, name, body)
}

const QUAD: &str = "[materials.m]\ntype = \"diffuse\"\n[[shapes]]\ntype = \"quad\"\nmaterial = \"m\"\n";

#[test]
fn toml_syntax_error_reports_line_and_column() {
    let dir = scratch("err_syntax");
    let p = scene_with(&dir, "syntax.toml", "[camera]\nposition = [0, 0, 5\ntarget = [0, 0, 0]\n");
    // The missing comma is found where the next line starts.
    expect_error(&p, &["line 3, column 1", "target"]);
}

#[test]
fn unknown_fields_are_errors() {
    let dir = scratch("err_unknown");
    let p = scene_with(&dir, "typo.toml", &format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nfovv = 40\n{QUAD}"));
    expect_error(&p, &["fovv", "line 4"]);
    let p = scene_with(&dir, "typo2.toml", &format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nalbdeo = [1, 1, 1]\n"));
    expect_error(&p, &["albdeo"]);
    let p = scene_with(&dir, "typo3.toml", &format!("{CAMERA}{QUAD}[environment]\ncolour = [1, 1, 1]\n"));
    expect_error(&p, &["colour"]);
    // A parameter of another material type is reported too.
    let p = scene_with(&dir, "wrongtype.toml", &format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nior = 1.5\n"));
    expect_error(&p, &["materials.m.ior"]);
}

#[test]
fn missing_mesh_and_texture_files_name_the_path_and_field() {
    let dir = scratch("err_missing");
    let p = scene_with(
        &dir,
        "mesh.toml",
        &format!("{CAMERA}{QUAD}[[shapes]]\ntype = \"quad\"\nmaterial = \"m\"\n[[shapes]]\ntype = \"obj\"\nfile = \"nothere.obj\"\n"),
    );
    expect_error(&p, &["shapes[2].file", "nothere.obj"]);
    let p = scene_with(&dir, "gltf.toml", &format!("{CAMERA}[[shapes]]\ntype = \"gltf\"\nfile = \"nothere.glb\"\n"));
    expect_error(&p, &["shapes[0].file", "nothere.glb"]);
    let p = scene_with(&dir, "tex.toml", &format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nalbedo_texture = \"nothere.png\"\n"));
    expect_error(&p, &["materials.m.albedo_texture", "nothere.png"]);
    let p = scene_with(&dir, "env.toml", &format!("{CAMERA}{QUAD}[environment]\nmap = \"nothere.exr\"\n"));
    expect_error(&p, &["environment.map", "nothere.exr"]);
    // A missing map_Kd texture of an MTL is an error too.
    write(&dir, "m.mtl", "newmtl a\nmap_Kd gone.png\n");
    write(&dir, "m.obj", "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n");
    let p = scene_with(&dir, "mtltex.toml", &format!("{CAMERA}[[shapes]]\ntype = \"obj\"\nfile = \"m.obj\"\n"));
    expect_error(&p, &["shapes[0].file", "gone.png", "map_Kd"]);
}

#[test]
fn non_finite_and_negative_values_name_the_field() {
    let dir = scratch("err_values");
    let cases: &[(&str, String, &str)] = &[
        ("fov_nan.toml", format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = nan\n{QUAD}"), "camera.fov"),
        ("fov_range.toml", format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 180\n{QUAD}"), "camera.fov"),
        ("pos_inf.toml", format!("[camera]\nposition = [0, inf, 5]\ntarget = [0, 0, 0]\n{QUAD}"), "camera.position"),
        ("same.toml", format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 5]\n{QUAD}"), "camera.target"),
        ("albedo_inf.toml", format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nalbedo = [inf, 0, 0]\n"), "materials.m.albedo"),
        ("albedo_big.toml", format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nalbedo = [2, 0, 0]\n"), "materials.m.albedo"),
        ("rough_neg.toml", format!("{CAMERA}[materials.m]\ntype = \"plastic\"\nroughness = -0.1\n"), "materials.m.roughness"),
        ("ior_zero.toml", format!("{CAMERA}[materials.m]\ntype = \"dielectric\"\nior = 0\n"), "materials.m.ior"),
        ("emit_neg.toml", format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nemission = [1, -1, 1]\n"), "materials.m.emission"),
        (
            "strength_nan.toml",
            format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nemission = [1, 1, 1]\nstrength = -nan\n"),
            "materials.m.strength",
        ),
        ("eta_neg.toml", format!("{CAMERA}[materials.m]\ntype = \"conductor\"\neta = [-1, 1, 1]\nk = [1, 1, 1]\n"), "materials.m.eta"),
        ("preset.toml", format!("{CAMERA}[materials.m]\ntype = \"conductor\"\npreset = \"Unobtainium\"\n"), "materials.m.preset"),
        ("translate.toml", format!("{CAMERA}{QUAD}translate = [0, nan, 0]\n"), "shapes[0].translate"),
        ("scale0.toml", format!("{CAMERA}{QUAD}scale = 0\n"), "shapes[0].scale"),
        ("angle.toml", format!("{CAMERA}{QUAD}rotate = {{ axis = [0, 1, 0], angle = inf }}\n"), "shapes[0].rotate.angle"),
        ("matrix.toml", format!("{CAMERA}{QUAD}matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]\n"), "shapes[0].matrix"),
        (
            "radius.toml",
            format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\n[[shapes]]\ntype = \"sphere\"\nmaterial = \"m\"\nradius = -1\n"),
            "shapes[0].radius",
        ),
        ("env_neg.toml", format!("{CAMERA}{QUAD}[environment]\ncolor = [1, 1, 1]\nscale = -2\n"), "environment.scale"),
        ("env_nan.toml", format!("{CAMERA}{QUAD}[environment]\ncolor = [nan, 1, 1]\n"), "environment.color"),
        ("spp0.toml", format!("{CAMERA}{QUAD}[render]\nspp = 0\n"), "render.spp"),
    ];
    for (name, body, field) in cases {
        expect_error(&scene_with(&dir, name, body), &[field]);
    }
}

#[test]
fn unknown_material_names_are_errors() {
    let dir = scratch("err_material");
    let p = scene_with(
        &dir,
        "unknown.toml",
        &format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\n[[shapes]]\ntype = \"cube\"\nmaterial = \"mm\"\n"),
    );
    expect_error(&p, &["shapes[0].material", "'mm'"]);
    write(&dir, "t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let p = scene_with(
        &dir,
        "override.toml",
        &format!("{CAMERA}[[shapes]]\ntype = \"obj\"\nfile = \"t.obj\"\nmaterials_override = {{ light = \"lamp\" }}\n"),
    );
    expect_error(&p, &["shapes[0].materials_override.light", "'lamp'"]);
}

#[test]
fn non_finite_texels_name_the_image() {
    let dir = scratch("err_texels");
    write_exr(&dir.join("bad_env.exr"), 4, 2, |x, y| if (x, y) == (3, 1) { [f32::NAN, 0.0, 0.0] } else { [1.0; 3] });
    let p = scene_with(&dir, "env.toml", &format!("{CAMERA}{QUAD}[environment]\ntype = \"map\"\nmap = \"bad_env.exr\"\n"));
    expect_error(&p, &["environment.map", "bad_env.exr", "(3, 1)"]);
    write_exr(&dir.join("bad_tex.exr"), 2, 2, |x, _| if x == 1 { [0.0, f32::INFINITY, 0.0] } else { [0.5; 3] });
    let p = scene_with(&dir, "tex.toml", &format!("{CAMERA}[materials.m]\ntype = \"diffuse\"\nalbedo_texture = \"bad_tex.exr\"\n"));
    expect_error(&p, &["materials.m.albedo_texture", "bad_tex.exr"]);
    // A conductor's tint texture must stay a reflectance: a texel above 1 is an error, and a
    // good one multiplies `specular_tint`.
    write_exr(&dir.join("tint.exr"), 2, 1, |x, _| if x == 1 { [1.5, 0.5, 0.5] } else { [0.5; 3] });
    let metal = |tex: &str| {
        format!("{CAMERA}{QUAD}[materials.cu]\ntype = \"conductor\"\npreset = \"Cu\"\nspecular_tint = [0.5, 1, 1]\nspecular_tint_texture = \"{tex}\"\n")
    };
    let p = scene_with(&dir, "tint.toml", &metal("tint.exr"));
    expect_error(&p, &["materials.cu.specular_tint_texture", "tint.exr", "above 1"]);
    write_exr(&dir.join("tint_ok.exr"), 2, 1, |x, _| [0.5 * x as f32, 1.0, 0.25]);
    let scene = load(&scene_with(&dir, "tint_ok.toml", &metal("tint_ok.exr")));
    let cu = scene.materials.iter().find(|m| m.name == "cu").unwrap();
    match &cu.kind {
        renderer::scene::MaterialKind::Conductor { specular_tint, .. } => {
            // Texel (1, 0) times the constant tint, read at its centre.
            let v = specular_tint.eval(glam::Vec2::new(0.75, 0.5), &scene.textures);
            assert!((v - Vec3::new(0.25, 1.0, 0.25)).length() < 1e-5, "{v}");
        }
        k => panic!("{k:?}"),
    }
    // A good EXR loads as linear values, unchanged.
    write_exr(&dir.join("good.exr"), 2, 1, |x, _| [0.25 * x as f32, 3.0, 0.0]);
    let p = scene_with(&dir, "good.toml", &format!("{CAMERA}{QUAD}[environment]\nmap = \"good.exr\"\nscale = 2\n"));
    match load(&p).environment {
        Environment::Map { image, scale, rotation_deg } => {
            assert_eq!((scale, rotation_deg), (2.0, 0.0));
            assert_eq!(image.texel(1, 0), Vec3::new(0.25, 3.0, 0.0));
        }
        e => panic!("{e:?}"),
    }
}

#[test]
fn non_finite_mesh_vertices_name_the_shape() {
    let dir = scratch("err_vertex");
    write(&dir, "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    let p = scene_with(&dir, "scene.toml", &format!("{CAMERA}[[shapes]]\ntype = \"obj\"\nfile = \"nan.obj\"\n"));
    expect_error(&p, &["shapes[0].file", "vertex 1"]);
    // Overflow through the transform is caught as well.
    let p = scene_with(&dir, "huge.toml", &format!("{CAMERA}{QUAD}scale = [1e38, 1, 1]\ntranslate = [3e38, 0, 0]\n"));
    expect_error(&p, &["shapes[0]", "not finite"]);
    // As is a scale whose determinant overflows.
    let p = scene_with(&dir, "huge_det.toml", &format!("{CAMERA}{QUAD}scale = 1e30\n"));
    expect_error(&p, &["shapes[0].scale"]);
}

#[test]
fn absurd_resolutions_are_errors() {
    let dir = scratch("err_resolution");
    for (i, res) in ["[0, 64]", "[64, 0]", "[16385, 16]", "[10000, 10000]"].iter().enumerate() {
        let p = scene_with(
            &dir,
            &format!("res{i}.toml"),
            &format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nresolution = {res}\n{QUAD}"),
        );
        expect_error(&p, &["camera.resolution"]);
    }
    // The largest legal square (8192² = 2^26 pixels) is accepted.
    let p = scene_with(&dir, "ok.toml", &format!("[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nresolution = [8192, 8192]\n{QUAD}"));
    assert_eq!(load(&p).camera.width, 8192);
}

#[test]
fn empty_scenes_are_errors_but_dark_ones_load() {
    let dir = scratch("err_empty");
    let p = scene_with(&dir, "empty.toml", CAMERA);
    expect_error(&p, &["shapes", "no triangles"]);
    write(&dir, "none.obj", "v 0 0 0\n");
    let p = scene_with(&dir, "empty_obj.toml", &format!("{CAMERA}[[shapes]]\ntype = \"obj\"\nfile = \"none.obj\"\n"));
    expect_error(&p, &["shapes"]);
    // No light and a black environment: allowed (a warning goes to stderr).
    let p = scene_with(&dir, "dark.toml", &format!("{CAMERA}{QUAD}"));
    assert_eq!(load(&p).mesh.triangles.len(), 2);
}

#[test]
fn unknown_extension_is_an_error() {
    let dir = scratch("err_ext");
    let p = scene_with(&dir, "scene.yaml", "camera: {}\n");
    expect_error(&p, &["unknown scene format"]);
}
