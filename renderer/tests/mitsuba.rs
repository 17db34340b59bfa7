//! The Mitsuba XML loader (renderer/src/scene/mitsuba/) on the shipped "Veach, Ajar" scene
//! and on small hand-written scenes, including the errors for what it does not read.

mod common;

use glam::{Vec2, Vec3};
use renderer::camera::FovAxis;
use renderer::film::BufferRequest;
use renderer::scene::{load_description, ColorParam, MaterialKind, Scene};
use std::path::{Path, PathBuf};

fn veach() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/assets/veach-ajar/scene.xml")
}

/// Writes `xml` to a fresh file and loads it; the OBJ and texture paths resolve against the
/// veach-ajar folder, so each test file lives there under a unique name.
fn load_xml(name: &str, xml: &str) -> Result<renderer::scene::SceneDescription, String> {
    let dir = std::env::temp_dir().join(format!("pixguide-mitsuba-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("scene.xml");
    let assets = veach().parent().unwrap().canonicalize().unwrap();
    std::fs::write(&p, xml.replace("ASSETS", &assets.to_string_lossy())).unwrap();
    let r = load_description(&p).map_err(|e| e.to_string());
    std::fs::remove_dir_all(&dir).ok();
    r
}

fn load_err(name: &str, xml: &str) -> String {
    match load_xml(name, xml) {
        Ok(_) => panic!("{name}: loaded, but should have failed"),
        Err(e) => e,
    }
}

const CAMERA: &str = r#"<sensor type="perspective"><float name="fov" value="45"/>
  <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film></sensor>"#;

#[test]
fn veach_ajar_loads_with_its_shapes_materials_emitter_and_camera() {
    let d = load_description(&veach()).unwrap_or_else(|e| panic!("{e}"));
    // 22 shapes in the file; the 6 that use the missing teapot meshes (Mesh000, Mesh009) are
    // skipped, leaving the light rectangle and 15 OBJ shapes. Every loaded shape keeps its
    // material: the 9 BSDFs they reference plus the light's own emitting copy.
    let mut names: Vec<_> = d.materials.iter().map(|m| m.name.clone()).collect();
    names.sort();
    assert_eq!(d.materials.len(), 10, "{names:?}");
    for want in ["Landscape", "Table", "DoorHandle", "Door", "Diffuse", "Floor", "DoorFrame", "PictureFrame", "Hinge"] {
        assert!(names.iter().any(|n| n == want), "{want} missing from {names:?}");
    }
    // Pot2, Pot3 and Material are only used by the skipped teapots.
    assert!(!names.iter().any(|n| n == "Pot2" || n == "Material"), "{names:?}");
    let used: std::collections::BTreeSet<u32> = d.mesh.material.iter().copied().collect();
    assert_eq!(used.len(), 10, "every material is used by some triangle");
    // The only emitter is the rectangle (2 triangles) with radiance 1000.
    let emissive: Vec<_> = d.mesh.material.iter().filter(|&&m| d.materials[m as usize].is_emissive()).collect();
    assert_eq!(emissive.len(), 2);
    let light = d.materials.iter().find(|m| m.is_emissive()).unwrap();
    assert_eq!(light.emission, Vec3::splat(1000.0));
    // Three bitmap textures (landscape, table, door); the door is diffuse with its texture.
    assert_eq!(d.textures.len(), 3);
    let door = d.materials.iter().find(|m| m.name == "Door").unwrap();
    assert!(matches!(door.kind, MaterialKind::Lambert { albedo: ColorParam::Texture { .. } }));
    // Aluminium eta/k and Beckmann alpha 0.25 on the door handle.
    let handle = d.materials.iter().find(|m| m.name == "DoorHandle").unwrap();
    match handle.kind {
        MaterialKind::Conductor { eta, k, roughness, .. } => {
            assert!((eta - Vec3::new(1.65746, 0.880369, 0.521229)).abs().max_element() < 1e-5);
            assert!((k - Vec3::new(9.22387, 6.26952, 4.837)).abs().max_element() < 1e-5);
            assert_eq!(roughness, 0.25);
        }
        ref other => panic!("DoorHandle is {other:?}"),
    }
    // Camera: the toWorld matrix's translation column and its +Z column (Mitsuba looks along +Z).
    let cam = &d.camera;
    assert!((cam.position - Vec3::new(4.05402, 1.61647, -2.30652)).length() < 1e-4, "{}", cam.position);
    let want = Vec3::new(-0.990015, -0.0323, -0.137213).normalize();
    assert!(cam.forward.dot(want) > 0.99999, "forward {} vs {want}", cam.forward);
    assert!(cam.up.dot(Vec3::new(-0.0319925, 0.999478, -0.00443408)) > 0.9999, "up {}", cam.up);
    assert_eq!((cam.width, cam.height), (1280, 720));
    // fov 60° along x (Mitsuba's default axis): vertical = 2·atan(tan 30° · 720/1280) ≈ 36.0°.
    assert_eq!(cam.fov_axis, FovAxis::X);
    let vfov = 2.0 * cam.tan_half_vfov().atan().to_degrees();
    assert!((vfov - 35.98).abs() < 0.02, "{vfov}");
    // The floor's specular reflectance is a checkerboard of 0.8 (at uv 0) and 0.2, 20 × 80
    // periods over the uv square.
    let floor = d.materials.iter().find(|m| m.name == "Floor").unwrap();
    match &floor.kind {
        MaterialKind::Conductor { specular_tint: ColorParam::Checkerboard { color0, color1, to_uv }, .. } => {
            assert_eq!((*color0, *color1), (Vec3::splat(0.8), Vec3::splat(0.2)));
            assert_eq!(to_uv.transform_point2(Vec2::new(1.0, 1.0)), Vec2::new(20.0, 80.0));
            assert_eq!(to_uv.transform_point2(Vec2::ZERO), Vec2::ZERO);
        }
        other => panic!("Floor is {other:?}"),
    }
    // maxDepth 13 = 12 scattering events; 64 samples from the sampler.
    assert_eq!(d.settings.max_bounces, 12);
    assert_eq!(d.settings.spp, 64);
}

#[test]
fn malformed_xml_names_file_and_line() {
    let e = load_err("malformed", "<scene version=\"0.5.0\">\n  <shape type=\"obj\">\n</scene>\n");
    assert!(e.contains("scene.xml") && e.contains("line 3") && e.contains("malformed XML"), "{e}");
}

#[test]
fn unknown_elements_and_types_name_file_line_and_element() {
    let e = load_err("unknown", &format!("<scene version=\"0.5.0\">\n{CAMERA}\n  <volume type=\"grid\"/>\n</scene>\n"));
    assert!(e.contains("scene.xml") && e.contains("line 5") && e.contains("<volume") && e.contains("unsupported element"), "{e}");
    let e = load_err("bsdf", "<scene version=\"0.5.0\">\n<bsdf type=\"hair\" id=\"h\"/>\n</scene>");
    assert!(e.contains("line 2") && e.contains("hair"), "{e}");
    let e = load_err(
        "param",
        "<scene version=\"0.5.0\">\n<bsdf type=\"diffuse\" id=\"d\">\n  <float name=\"sheen\" value=\"1\"/>\n</bsdf>\n</scene>",
    );
    assert!(e.contains("line 3") && e.contains("sheen"), "{e}");
    let e = load_err("ref", "<scene version=\"0.5.0\">\n<shape type=\"cube\">\n  <ref id=\"nope\"/>\n</shape>\n</scene>");
    assert!(e.contains("line 3") && e.contains("nope"), "{e}");
    let e = load_err(
        "metal",
        "<scene version=\"0.5.0\">\n<bsdf type=\"conductor\" id=\"c\"><string name=\"material\" value=\"Unobtainium\"/></bsdf>\n</scene>",
    );
    assert!(e.contains("line 2") && e.contains("Unobtainium"), "{e}");
}

#[test]
fn defaults_refs_primitives_and_emitters() {
    let xml = format!(
        r#"<scene version="0.5.0">
  <default name="albedo" value="0.25"/>
  {CAMERA}
  <bsdf type="twosided" id="grey"><bsdf type="diffuse"><rgb name="reflectance" value="$albedo, $albedo, $albedo"/></bsdf></bsdf>
  <bsdf type="roughplastic" id="coat"><rgb name="diffuseReflectance" value="0.1 0.2 0.3"/><float name="alpha" value="0.2"/><float name="intIOR" value="1.6"/></bsdf>
  <bsdf type="dielectric" id="water"><string name="intIOR" value="water"/></bsdf>
  <shape type="cube"><ref id="grey"/></shape>
  <shape type="sphere"><point name="center" x="0" y="3" z="0"/><float name="radius" value="0.5"/><ref id="water"/></shape>
  <shape type="rectangle"><transform name="toWorld"><scale value="2"/><translate y="-2"/></transform><ref id="coat"/>
    <emitter type="area"><rgb name="radiance" value="4"/></emitter></shape>
  <shape type="obj"><string name="filename" value="ASSETS/models/Light.obj"/><ref id="grey"/></shape>
</scene>"#
    );
    let d = load_xml("ok", &xml).unwrap_or_else(|e| panic!("{e}"));
    let grey = d.materials.iter().find(|m| m.name == "grey").unwrap();
    assert!(matches!(grey.kind, MaterialKind::Lambert { albedo: ColorParam::Const(c) } if c == Vec3::splat(0.25)));
    // The cube and the OBJ share one material; the emitting rectangle gets its own copy of coat.
    assert_eq!(d.materials.len(), 3, "{:?}", d.materials.iter().map(|m| &m.name).collect::<Vec<_>>());
    let coat = d.materials.iter().find(|m| m.is_emissive()).unwrap();
    assert!(matches!(coat.kind, MaterialKind::Plastic { ior, roughness, .. } if (ior - 1.6 / 1.000277).abs() < 1e-4 && roughness == 0.2));
    let water = d.materials.iter().find(|m| m.name == "water").unwrap();
    assert!(matches!(water.kind, MaterialKind::Dielectric { ior, .. } if (ior - 1.333 / 1.000277).abs() < 1e-4));
    // The rectangle ([-1,1]² in XY) is scaled by 2, then moved down 2: x = ±2, y ∈ {−4, 0}, z = 0.
    let emitting: Vec<_> = (0..d.mesh.triangles.len()).filter(|&i| d.materials[d.mesh.material[i] as usize].is_emissive()).collect();
    assert_eq!(emitting.len(), 2);
    for &i in &emitting {
        for v in d.mesh.triangles[i] {
            let p = d.mesh.positions[v as usize];
            assert!((p.x.abs() - 2.0).abs() < 1e-5 && ((p.y + 2.0).abs() - 2.0).abs() < 1e-5 && p.z.abs() < 1e-5, "{p}");
        }
    }
    // The sphere is centred at y = 3 with radius 0.5.
    let ys: Vec<f32> = (0..d.mesh.triangles.len())
        .filter(|&i| d.materials[d.mesh.material[i] as usize].name == "water")
        .flat_map(|i| d.mesh.triangles[i].map(|v| d.mesh.positions[v as usize].y))
        .collect();
    let (lo, hi) = ys.iter().fold((f32::MAX, f32::MIN), |(a, b), &y| (a.min(y), b.max(y)));
    assert!((lo - 2.5).abs() < 1e-4 && (hi - 3.5).abs() < 1e-4, "{lo}..{hi}");
    // Camera from the lookat: looking down −Z from z = 5.
    assert!(d.camera.forward.dot(-Vec3::Z) > 0.99999);
    assert_eq!((d.camera.width, d.camera.height), (64, 32));

    let e = load_err(
        "nodefault",
        "<scene version=\"0.5.0\">\n<bsdf type=\"diffuse\" id=\"d\"><float name=\"reflectance\" value=\"$missing\"/></bsdf>\n</scene>",
    );
    assert!(e.contains("line 2") && e.contains("$missing"), "{e}");
}

// ---------------------------------------------------------------- camera: fov axis and --size

/// The test scene (scenes/veach-ajar/scene.xml) with its asset paths made absolute and its film
/// set to `w` × `h`.
fn veach_test_scene(w: u32, h: u32) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/veach-ajar/scene.xml");
    let xml = std::fs::read_to_string(&p).unwrap().replace("../assets/veach-ajar", "ASSETS");
    let (w0, h0) = (r#"<default name="width" value="176" />"#, r#"<default name="height" value="128" />"#);
    assert!(xml.contains(w0) && xml.contains(h0), "the test scene's film defaults changed");
    xml.replace(w0, &format!(r#"<default name="width" value="{w}" />"#)).replace(h0, &format!(r#"<default name="height" value="{h}" />"#))
}

#[test]
fn a_new_image_size_keeps_the_mitsuba_view() {
    // What `pixguide render scenes/veach-ajar/scene.xml --size 320x180` does (src/cli/render.rs
    // sets the camera's width and height) against the same XML with a 320×180 film.
    let mut resized = load_xml("size-176", &veach_test_scene(176, 128)).unwrap_or_else(|e| panic!("{e}")).camera;
    resized.width = 320;
    resized.height = 180;
    let direct = load_xml("size-320", &veach_test_scene(320, 180)).unwrap_or_else(|e| panic!("{e}")).camera;
    assert_eq!((direct.width, direct.height), (320, 180));
    for y in [0.0, 0.5, 37.25, 90.0, 179.5, 180.0] {
        for x in [0.0, 0.5, 101.75, 160.0, 319.5, 320.0] {
            let f = Vec2::new(x, y);
            assert_eq!(resized.ray(f).dir, direct.ray(f).dir, "ray through pixel position {f}");
            assert_eq!(resized.ray(f).origin, direct.ray(f).origin);
        }
    }
    // Both keep the declared 60° across the image (Mitsuba's default fov axis is x).
    let t = 30f32.to_radians().tan();
    for cam in [&resized, &direct] {
        let e = cam.tan_half_extent();
        assert!((e.x - t).abs() < 1e-6 && (e.y - t * 180.0 / 320.0).abs() < 1e-6, "{e}");
    }
}

#[test]
fn each_fov_axis_gives_its_half_angle_tangent() {
    // A 64 × 32 film with fov 45°: t = tan 22.5° along the named extent.
    let t = 22.5f32.to_radians().tan();
    let diag = (64f32 * 64.0 + 32.0 * 32.0).sqrt();
    let cases = [
        ("x", FovAxis::X, Vec2::new(t, t / 2.0)),
        ("y", FovAxis::Y, Vec2::new(2.0 * t, t)),
        ("diagonal", FovAxis::Diagonal, Vec2::new(t * 64.0 / diag, t * 32.0 / diag)),
        // The film is wider than high: its smaller extent is the height.
        ("smaller", FovAxis::Smaller, Vec2::new(2.0 * t, t)),
        ("larger", FovAxis::Larger, Vec2::new(t, t / 2.0)),
    ];
    for (spelling, tag) in [("fovAxis", "0.5.0"), ("fov_axis", "3.0.0")] {
        for (name, axis, want) in cases {
            let xml = format!(
                r#"<scene version="{tag}"><sensor type="perspective"><float name="fov" value="45"/><string name="{spelling}" value="{name}"/>
  <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/></film></sensor>
  <shape type="cube"/></scene>"#
            );
            let cam = load_xml(&format!("axis-{name}-{spelling}"), &xml).unwrap_or_else(|e| panic!("{e}")).camera;
            assert_eq!(cam.fov_axis, axis);
            let got = cam.tan_half_extent();
            assert!((got - want).abs().max_element() < 1e-6, "{spelling}={name}: {got} vs {want}");
            // The ray to the middle of the right edge and of the top edge.
            let d = cam.ray(Vec2::new(64.0, 16.0)).dir;
            assert!((d.dot(cam.right) / d.dot(cam.forward) - want.x).abs() < 1e-5, "{name}: right edge");
            let d = cam.ray(Vec2::new(32.0, 0.0)).dir;
            assert!((d.dot(cam.up) / d.dot(cam.forward) - want.y).abs() < 1e-5, "{name}: top edge");
        }
    }
    let e = load_err("axis-bad", "<scene version=\"0.5.0\">\n<sensor type=\"perspective\"><float name=\"fov\" value=\"45\"/>\n<string name=\"fovAxis\" value=\"z\"/></sensor>\n</scene>");
    assert!(e.contains("line 3") && e.contains("\"z\"") && e.contains("fov axis"), "{e}");
}

#[test]
fn mitsuba3_parameter_names_are_read() {
    let xml = r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="30"/><string name="fov_axis" value="Y"/><float name="near_clip" value="0.1"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="12"/></sampler>
    <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="20"/></film></sensor>
  <bsdf type="roughconductor" id="m"><float name="alpha_u" value="0.2"/><float name="alpha_v" value="0.2"/>
    <texture type="checkerboard" name="specular_reflectance"><transform name="to_uv"><scale value="3"/></transform></texture></bsdf>
  <shape type="rectangle"><ref id="m"/></shape>
</scene>"#;
    let d = load_xml("mitsuba3", xml).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((d.settings.max_bounces, d.settings.spp), (3, 12));
    assert_eq!(d.camera.fov_axis, FovAxis::Y);
    match &d.materials[0].kind {
        MaterialKind::Conductor { roughness, specular_tint: ColorParam::Checkerboard { color0, color1, to_uv }, .. } => {
            assert!((roughness - 0.2).abs() < 1e-6);
            // Mitsuba's defaults 0.4 and 0.2.
            assert_eq!((*color0, *color1), (Vec3::splat(0.4), Vec3::splat(0.2)));
            assert_eq!(to_uv.transform_point2(Vec2::new(1.0, 0.5)), Vec2::new(3.0, 1.5));
        }
        other => panic!("{other:?}"),
    }
}

// ---------------------------------------------------------------- textures

#[test]
fn checkerboard_is_color0_at_the_uv_origin_and_alternates_each_half_period() {
    let (c0, c1) = (Vec3::new(0.8, 0.7, 0.6), Vec3::new(0.1, 0.2, 0.3));
    let board = ColorParam::Checkerboard { color0: c0, color1: c1, to_uv: glam::Affine2::IDENTITY };
    for (uv, want) in [
        ((0.0, 0.0), c0),
        ((0.1, 0.1), c0),
        ((0.6, 0.1), c1),
        ((0.1, 0.6), c1),
        ((0.6, 0.6), c0),
        // ½ belongs to the lower half (Mitsuba 3 tests frac > ½).
        ((0.5, 0.5), c0),
        ((0.5, 0.51), c1),
        // Period 1, and negative coordinates continue the pattern (frac(−0.4) = 0.6).
        ((1.1, 2.2), c0),
        ((-0.4, 0.1), c1),
        ((-0.4, -0.4), c0),
    ] {
        assert_eq!(board.eval(Vec2::new(uv.0, uv.1), &[]), want, "uv {uv:?}");
    }

    // From XML: Mitsuba 0.6's uscale/vscale/uoffset/voffset (uv · scale + offset) and Mitsuba 3's
    // to_uv; here both map uv to (4u + 0.25, 2v).
    let old = r#"<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.8, 0.7, 0.6"/><rgb name="color1" value="0.1, 0.2, 0.3"/>
        <float name="uscale" value="4"/><float name="vscale" value="2"/><float name="uoffset" value="0.25"/></texture>"#;
    let new = r#"<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.8, 0.7, 0.6"/><rgb name="color1" value="0.1, 0.2, 0.3"/>
        <transform name="to_uv"><scale x="4" y="2"/><translate x="0.25"/></transform></texture>"#;
    for (label, tex) in [("old", old), ("new", new)] {
        let xml = format!(
            r#"<scene version="0.5.0">{CAMERA}<bsdf type="diffuse" id="d">{tex}</bsdf><shape type="rectangle"><ref id="d"/></shape></scene>"#
        );
        let d = load_xml(&format!("checker-{label}"), &xml).unwrap_or_else(|e| panic!("{e}"));
        let albedo = match &d.materials[0].kind {
            MaterialKind::Lambert { albedo } => albedo.clone(),
            other => panic!("{other:?}"),
        };
        // (u, v) → (4u + 0.25, 2v): u = 0.05 → 0.45 (lower half), u = 0.1 → 0.65 (upper half).
        assert_eq!(albedo.eval(Vec2::new(0.05, 0.1), &[]), c0, "{label}");
        assert_eq!(albedo.eval(Vec2::new(0.1, 0.1), &[]), c1, "{label}");
        assert_eq!(albedo.eval(Vec2::new(0.1, 0.3), &[]), c0, "{label}");
        // Mitsuba's rectangle puts uv (0, 0) at its (−1, −1) corner.
        let corner = d.mesh.positions.iter().position(|p| (p.x + 1.0).abs() < 1e-6 && (p.y + 1.0).abs() < 1e-6).unwrap();
        assert_eq!(d.mesh.uvs[corner], Vec2::ZERO);
    }
}

/// A white furnace: a unit sphere filling the view inside a constant environment of radiance 1,
/// made of a perfect-mirror conductor (`none`: η = 1, k = 10⁴) and the given specular
/// reflectance element(s); 4 spp at 24 × 24.
fn furnace(name: &str, bsdf: &str, reflectance: &str) -> renderer::film::Frame {
    let xml = format!(
        r#"<scene version="0.5.0">
  <sensor type="perspective"><float name="fov" value="20"/>
    <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/></film></sensor>
  <bsdf type="{bsdf}" id="metal"><string name="material" value="none"/><float name="alpha" value="0.3"/>{reflectance}</bsdf>
  <shape type="sphere"><float name="radius" value="1"/><ref id="metal"/></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>"#
    );
    let d = load_xml(name, &xml).unwrap_or_else(|e| panic!("{e}"));
    let scene = Scene::new(name, d).unwrap();
    common::render(&scene, 4, 7, 5, BufferRequest::RADIANCE_ONLY)
}

#[test]
fn conductor_with_a_constant_texture_renders_like_the_same_rgb() {
    let dir = std::env::temp_dir().join(format!("pixguide-mitsuba-{}-const-exr", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exr = dir.join("tint.exr");
    let c = [0.9f32, 0.6, 0.3];
    image::DynamicImage::ImageRgb32F(image::Rgb32FImage::from_pixel(2, 2, image::Rgb(c))).save(&exr).unwrap();
    let rgb = r#"<rgb name="specularReflectance" value="0.9, 0.6, 0.3"/>"#.to_string();
    let checker = r#"<texture type="checkerboard" name="specular_reflectance"><rgb name="color0" value="0.9, 0.6, 0.3"/><rgb name="color1" value="0.9 0.6 0.3"/><float name="uscale" value="7"/></texture>"#.to_string();
    let bitmap =
        format!(r#"<texture type="bitmap" name="specular_reflectance"><string name="filename" value="{}"/></texture>"#, exr.display());
    for bsdf in ["conductor", "roughconductor"] {
        let want = furnace(&format!("furnace-{bsdf}-rgb"), bsdf, &rgb);
        for (label, tex) in [("checkerboard", &checker), ("bitmap", &bitmap)] {
            let got = furnace(&format!("furnace-{bsdf}-{label}"), bsdf, tex);
            assert!(got.radiance.mean == want.radiance.mean, "{bsdf} with a constant {label} renders differently from the RGB");
        }
        if bsdf == "conductor" {
            // Smooth: each central pixel (within 5° of the axis, incidence below 30°) sees the
            // environment once through the sphere, F · tint, F = 1 for the mirror `none`
            // (k = 10⁴: 1 − F ≈ 4e-8).
            let f = 1.0;
            let central =
                want.radiance.mean.chunks(3).enumerate().filter(|(i, _)| (6..18).contains(&(i % 24)) && (6..18).contains(&(i / 24)));
            for (_, px) in central {
                for k in 0..3 {
                    assert!((px[k] - f * c[k]).abs() < 2e-3, "pixel {px:?} vs {:?}", c.map(|x| x * f));
                }
            }
        }
    }
    // And a real checkerboard is not a constant: the two colours both appear.
    let board = r#"<texture type="checkerboard" name="specular_reflectance"><rgb name="color0" value="0.9"/><rgb name="color1" value="0.1"/><float name="uscale" value="8"/><float name="vscale" value="8"/></texture>"#;
    let f = furnace("furnace-board", "conductor", board);
    let lum: Vec<f32> = f.radiance.mean.chunks(3).map(|p| p[0]).collect();
    assert!(lum.iter().any(|&l| l > 0.8) && lum.iter().any(|&l| l < 0.2), "{lum:?}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_texture_references_name_the_file_and_field() {
    let metal = |tex: &str| format!("<scene version=\"0.5.0\">\n<bsdf type=\"roughconductor\" id=\"m\">\n{tex}\n</bsdf>\n</scene>");
    // A missing image: the scene file, the texture's line, the BSDF parameter and the image path.
    let e = load_err(
        "tex-missing",
        &metal(r#"<texture type="bitmap" name="specular_reflectance"><string name="filename" value="no-such-image.png"/></texture>"#),
    );
    assert!(
        e.contains("scene.xml") && e.contains("line 3") && e.contains("specular_reflectance") && e.contains("no-such-image.png"),
        "{e}"
    );
    // An unknown texture type.
    let e = load_err("tex-type", &metal(r#"<texture type="gradient" name="specularReflectance"/>"#));
    assert!(e.contains("scene.xml") && e.contains("line 3") && e.contains("specularReflectance") && e.contains("\"gradient\""), "{e}");
    // A reference to a texture that is not defined.
    let e = load_err("tex-ref", &metal(r#"<ref name="specular_reflectance" id="wood"/>"#));
    assert!(e.contains("line 3") && e.contains("specular_reflectance") && e.contains("wood"), "{e}");
    // A bitmap without a file name, an unknown checkerboard parameter, a textured colour.
    let e = load_err("tex-nofile", &metal(r#"<texture type="bitmap" name="specular_reflectance"/>"#));
    assert!(e.contains("line 3") && e.contains("specular_reflectance") && e.contains("filename"), "{e}");
    let e = load_err(
        "tex-param",
        &metal("<texture type=\"checkerboard\" name=\"specular_reflectance\">\n<float name=\"blur\" value=\"1\"/></texture>"),
    );
    assert!(e.contains("line 4") && e.contains("blur") && e.contains("specular_reflectance"), "{e}");
    let e = load_err(
        "tex-nested",
        &metal(r#"<texture type="checkerboard" name="specular_reflectance"><texture type="bitmap" name="color0"/></texture>"#),
    );
    assert!(e.contains("color0") && e.contains("constant colour"), "{e}");
    // The same missing image as a top-level texture referenced by a diffuse BSDF.
    let e = load_err(
        "tex-ref-missing",
        "<scene version=\"0.5.0\">\n<texture type=\"bitmap\" id=\"wood\"><string name=\"filename\" value=\"gone.jpg\"/></texture>\n<bsdf type=\"diffuse\" id=\"d\"><ref name=\"reflectance\" id=\"wood\"/></bsdf>\n</scene>",
    );
    assert!(e.contains("line 2") && e.contains("reflectance") && e.contains("gone.jpg"), "{e}");
}

/// An approximated feature (anisotropic roughness made isotropic) loads with a warning, and a
/// strict load refuses it with the file, the line and the substitution named; a scene without
/// approximations loads strictly too (so the refusal is about the feature, not the mode).
#[test]
fn strict_loading_refuses_substitutions_by_line() {
    let dir = std::env::temp_dir().join(format!("pixguide-mitsuba-{}-strict", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = |bsdf: &str| {
        format!(
            r#"<scene version="3.0.0">{CAMERA}
  <shape type="rectangle">{bsdf}</shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter></scene>"#
        )
    };
    let aniso = dir.join("aniso.xml");
    std::fs::write(
        &aniso,
        scene(r#"<bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.4"/></bsdf>"#),
    )
    .unwrap();
    let plain = dir.join("plain.xml");
    std::fs::write(&plain, scene(r#"<bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf>"#)).unwrap();
    assert!(Scene::load(&aniso).is_ok(), "a substitution is only a warning by default");
    let e = Scene::load_strict(&aniso).err().expect("strict load must refuse the substitution").to_string();
    assert!(e.contains("aniso.xml") && e.contains("line 4") && e.contains("anisotropic roughness"), "{e}");
    assert!(Scene::load_strict(&plain).is_ok());
    // The strict mode ends with its load: a later normal load only warns.
    assert!(Scene::load(&aniso).is_ok());
    std::fs::remove_dir_all(&dir).ok();
}

/// Every test and training scene (scenes/test.txt, scenes/train.txt) is written out by the
/// Mitsuba exporter: one BSDF per material in use, of the type its kind maps to, and the
/// environment as the scene has it. (Whether Mitsuba then renders the same image is the
/// network-tier cross-check's business, for the test scenes.)
#[test]
fn every_shipped_scene_exports_to_mitsuba() {
    use renderer::light::EnvironmentView;
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let out = std::env::temp_dir().join(format!("pixguide-export-{}", std::process::id()));
    let mut count = 0;
    for list in ["test.txt", "train.txt"] {
        let text = std::fs::read_to_string(scenes.join(list)).unwrap();
        for line in text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')) {
            let path = scenes.join(line);
            if path.extension().is_some_and(|e| e == "xml") {
                continue;
            }
            let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{line}: {e}"));
            let dir = out.join(line.replace('/', "_"));
            let xml = renderer::scene::export_mitsuba(&scene, &dir).unwrap_or_else(|e| panic!("{line}: {e}"));
            let text = std::fs::read_to_string(&xml).unwrap();
            for (mi, m) in scene.materials.iter().enumerate() {
                if !scene.mesh.material.contains(&(mi as u32)) {
                    continue;
                }
                let def =
                    text.lines().find(|l| l.contains(&format!("id=\"m{mi}\""))).unwrap_or_else(|| panic!("{line}: no BSDF for {}", m.name));
                let ty = match m.kind {
                    MaterialKind::Lambert { .. } => "diffuse\"",
                    MaterialKind::Conductor { .. } => "conductor\"",
                    MaterialKind::Dielectric { .. } => "dielectric\"",
                    MaterialKind::Plastic { .. } => "plastic\"",
                };
                assert!(def.contains(ty), "{line}: material {} is not a {ty} BSDF: {def}", m.name);
            }
            let env = match scene.lights.environment() {
                EnvironmentView::Black => None,
                EnvironmentView::Constant(_) => Some("constant"),
                EnvironmentView::Map { .. } => Some("envmap"),
            };
            assert_eq!(env.is_some(), text.contains("<emitter type=\"constant\"") || text.contains("<emitter type=\"envmap\""), "{line}");
            if let Some(ty) = env {
                assert!(text.contains(&format!("<emitter type=\"{ty}\"")), "{line}: no {ty} emitter");
            }
            if env == Some("envmap") {
                assert!(dir.join("envmap.exr").is_file(), "{line}: no envmap.exr");
            }
            count += 1;
        }
    }
    std::fs::remove_dir_all(&out).ok();
    assert!(count >= 30, "only {count} scenes exported");
}
