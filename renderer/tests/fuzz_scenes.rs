//! Fuzz tests of the scene readers: TOML scenes, OBJ+MTL meshes (tobj), glTF/GLB and Mitsuba
//! XML, each fed mutated copies of real scene files and arbitrary text built from the format's
//! own tokens. `Scene::load` must return `Ok` or an error, never panic, hang or allocate beyond
//! the cap (the harness: fuzz_support/mod.rs).

mod fuzz_support;

use fuzz_support::*;
use renderer::scene::Scene;
use std::path::{Path, PathBuf};

#[global_allocator]
static ALLOC: CappedAlloc = CappedAlloc;

/// A copy of the repository's scenes/ folder made of symlinks, with real directories for the
/// scene folders so that a mutated scene file written into one resolves `../common/…`,
/// `../assets/…` and its own siblings as the original does.
fn mirror_scenes(dir: &Path) -> PathBuf {
    let src = repo().join("scenes");
    let dst = dir.join("scenes");
    std::fs::create_dir_all(&dst).unwrap();
    for e in std::fs::read_dir(&src).unwrap() {
        let e = e.unwrap();
        let to = dst.join(e.file_name());
        if e.path().is_dir() && e.file_name() != "assets" && e.file_name() != "common" {
            std::fs::create_dir_all(&to).unwrap();
            for f in std::fs::read_dir(e.path()).unwrap() {
                let f = f.unwrap();
                std::os::unix::fs::symlink(f.path(), to.join(f.file_name())).unwrap();
            }
        } else {
            std::os::unix::fs::symlink(e.path(), &to).unwrap();
        }
    }
    dst
}

/// Runs `cases` mutated cases over `sources`: each case writes the mutated bytes to `target(i)`
/// (a path beside the source's own references) and loads `load_path(i)`.
fn fuzz_files(name: &str, cases: u32, salt: u64, sources: &[(PathBuf, PathBuf)], load_path: impl Fn(usize) -> PathBuf) {
    let originals: Vec<Vec<u8>> = sources.iter().map(|(s, _)| std::fs::read(s).unwrap()).collect();
    run_cases(name, cases, salt, Inputs::Mutated, &mutated(sources.len()), |tally, (i, edits)| {
        let (source, target) = &sources[i];
        std::fs::write(target, apply_all(&originals[i], &edits)).unwrap();
        let path = load_path(i);
        guarded(tally, label(source, &edits), move || Scene::load(&path))
    });
}

/// Arbitrary token soup written to `path` and loaded.
fn fuzz_soup(name: &str, cases: u32, salt: u64, tokens: &'static [&'static str], path: PathBuf) {
    run_cases(name, cases, salt, Inputs::Arbitrary, &token_soup(tokens, 96), |tally, bytes| {
        std::fs::write(&path, &bytes).unwrap();
        let p = path.clone();
        guarded(tally, format!("{} = {:?}", path.display(), String::from_utf8_lossy(&bytes)), move || Scene::load(&p))
    });
}

/// Every TOML scene shipped under scenes/.
fn toml_scenes() -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(repo().join("scenes")).unwrap() {
        let d = e.unwrap().path();
        if d.is_dir() {
            for f in std::fs::read_dir(&d).unwrap() {
                let f = f.unwrap().path();
                if f.extension().is_some_and(|x| x == "toml") {
                    out.push(f);
                }
            }
        }
    }
    out.sort();
    assert!(out.len() >= 20, "expected the shipped scenes, found {}", out.len());
    out
}

#[test]
fn mutated_toml_scenes_load_or_fail_cleanly() {
    let dir = scratch("toml");
    let scenes = mirror_scenes(&dir);
    let sources: Vec<(PathBuf, PathBuf)> = toml_scenes()
        .into_iter()
        .map(|s| {
            let folder = s.parent().unwrap().file_name().unwrap().to_owned();
            (s, scenes.join(folder).join("fuzz-case.toml"))
        })
        .collect();
    let targets: Vec<PathBuf> = sources.iter().map(|(_, t)| t.clone()).collect();
    fuzz_files("toml", 192, 1, &sources, |i| targets[i].clone());
}

const TOML_TOKENS: &[&str] = &[
    "\n",
    "[camera]\n",
    "[render]\n",
    "[environment]\n",
    "[materials.a]\n",
    "[[shapes]]\n",
    "position = ",
    "target = ",
    "resolution = ",
    "fov = ",
    "spp = ",
    "type = ",
    "\"diffuse\"",
    "\"conductor\"",
    "\"sphere\"",
    "\"grid\"",
    "\"lathe\"",
    "\"heightfield\"",
    "\"obj\"",
    "\"map\"",
    "material = \"a\"",
    "albedo = ",
    "emission = ",
    "segments = ",
    "count = ",
    "profile = ",
    "map = ",
    "file = ",
    "[",
    "]",
    ", ",
    "[1, 2, 3]",
    "[0, 0]",
    "{ axis = [0, 1, 0], angle = 90 }",
    "\"",
    "=",
    ".",
    "rotate = ",
    "scale = ",
    "matrix = ",
];

#[test]
fn arbitrary_toml_fails_cleanly() {
    let dir = scratch("toml_soup");
    fuzz_soup("toml soup", 256, 2, TOML_TOKENS, dir.join("scene.toml"));
}

/// OBJ meshes (and their MTL files) from scenes/assets, each loaded through a one-shape TOML
/// scene beside it. The MTL is mutated in some cases and the OBJ in the others.
#[test]
fn mutated_obj_and_mtl_load_or_fail_cleanly() {
    let dir = scratch("obj");
    let assets = repo().join("scenes/assets");
    let meshes = [
        "cornell-box-tinyobj/cornell_box.obj",
        "cornell-box-mcguire/CornellBox-Original.obj",
        "veach-ajar/models/Mesh005.obj",
        "veach-ajar/models/Mesh014.obj",
        "veach-ajar/models/Light.obj",
    ];
    let camera = "[camera]\nposition = [0, 1, 4]\ntarget = [0, 1, 0]\nresolution = [32, 32]\n";
    let mut sources = Vec::new();
    let mut scene_of = Vec::new();
    for (k, m) in meshes.iter().enumerate() {
        let src = assets.join(m);
        let case_dir = dir.join(format!("mesh{k}"));
        std::fs::create_dir_all(&case_dir).unwrap();
        let scene = case_dir.join("scene.toml");
        std::fs::write(&scene, format!("{camera}[[shapes]]\ntype = \"obj\"\nfile = \"mesh.obj\"\n")).unwrap();
        // The MTL keeps its own name, which the OBJ's `mtllib` refers to.
        let mtl = src.with_extension("mtl");
        if mtl.is_file() {
            let copy = case_dir.join(mtl.file_name().unwrap());
            std::fs::copy(&mtl, &copy).unwrap();
            std::fs::copy(&src, case_dir.join("mesh.obj")).unwrap();
            sources.push((mtl, copy));
            scene_of.push(scene.clone());
        }
        sources.push((src, case_dir.join("mesh.obj")));
        scene_of.push(scene);
    }
    // A mutated MTL must not carry over into the next case of the same mesh.
    let originals: Vec<(PathBuf, PathBuf)> = sources.clone();
    fuzz_files("obj", 192, 3, &sources, |i| {
        for (j, (src, dst)) in originals.iter().enumerate() {
            if j != i && scene_of[j] == scene_of[i] {
                std::fs::copy(src, dst).unwrap();
            }
        }
        scene_of[i].clone()
    });
}

const OBJ_TOKENS: &[&str] = &[
    "\n",
    "v ",
    "vt ",
    "vn ",
    "f ",
    "o ",
    "g ",
    "s 1",
    "usemtl a",
    "mtllib m.mtl",
    "1",
    "2",
    "3",
    "-1",
    "-4",
    "/",
    "//",
    "1/1/1 ",
    "0.5 ",
    " ",
    "#",
    "l 1 2",
    "p 1",
];

#[test]
fn arbitrary_obj_fails_cleanly() {
    let dir = scratch("obj_soup");
    std::fs::write(
        dir.join("scene.toml"),
        "[camera]\nposition = [0, 0, 4]\ntarget = [0, 0, 0]\nresolution = [8, 8]\n[[shapes]]\ntype = \"obj\"\nfile = \"mesh.obj\"\n",
    )
    .unwrap();
    let mesh = dir.join("mesh.obj");
    let scene = dir.join("scene.toml");
    run_cases("obj soup", 256, 4, Inputs::Arbitrary, &token_soup(OBJ_TOKENS, 128), |tally, bytes| {
        std::fs::write(&mesh, &bytes).unwrap();
        let p = scene.clone();
        guarded(tally, format!("mesh.obj = {:?}", String::from_utf8_lossy(&bytes)), move || Scene::load(&p))
    });
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for i in 0..4 {
            s.push(if i <= c.len() { T[(n >> (18 - 6 * i) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

/// No glTF file is shipped, so the sources are written here: a quad in a two-level node tree,
/// with a camera, three materials (textured, emissive metal, glass), as a .gltf with embedded
/// buffer and texture and as a .glb with an external texture.
fn gltf_sources(dir: &Path) -> [(String, Vec<u8>); 2] {
    let mut buf = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
        p.iter().for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
    }
    for _ in 0..4 {
        [0f32, 0., 1.].iter().for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
    }
    for t in [[0f32, 1.], [1., 1.], [1., 0.], [0., 0.]] {
        t.iter().for_each(|v| buf.extend_from_slice(&v.to_le_bytes()));
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        buf.extend_from_slice(&i.to_le_bytes());
    }
    let mut png = std::io::Cursor::new(Vec::new());
    image::RgbImage::from_pixel(2, 2, image::Rgb([0, 255, 0])).write_to(&mut png, image::ImageFormat::Png).unwrap();
    let png = png.into_inner();
    std::fs::write(dir.join("green.png"), &png).unwrap();
    let json = |buffer: &str, image: &str| {
        format!(
            r#"{{"asset": {{"version": "2.0"}},
 "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior"],
 "scene": 0, "scenes": [{{"nodes": [0, 2]}}],
 "nodes": [{{"translation": [0, 0, -2], "children": [1]}}, {{"scale": [2, 2, 2], "rotation": [0, 0, 0, 1], "mesh": 0}}, {{"camera": 0, "translation": [0, 0.5, 3]}}],
 "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.7, "aspectRatio": 2.0, "znear": 0.1}}}}],
 "meshes": [{{"name": "quad", "primitives": [
   {{"attributes": {{"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}}, "indices": 3, "material": 0}},
   {{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 3, "material": 1, "mode": 4}},
   {{"attributes": {{"POSITION": 0}}, "material": 2, "mode": 6}}]}}],
 "materials": [
   {{"name": "painted", "pbrMetallicRoughness": {{"baseColorFactor": [1, 0.5, 0.5, 1], "baseColorTexture": {{"index": 0}}, "metallicFactor": 0, "roughnessFactor": 1}}}},
   {{"name": "lamp", "emissiveFactor": [1, 0.5, 0.25], "doubleSided": true, "emissiveTexture": {{"index": 0}},
     "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": 4}}}},
     "pbrMetallicRoughness": {{"metallicFactor": 1, "roughnessFactor": 0.5}}}},
   {{"name": "glass", "pbrMetallicRoughness": {{"metallicFactor": 0}},
     "extensions": {{"KHR_materials_transmission": {{"transmissionFactor": 1}}, "KHR_materials_ior": {{"ior": 1.33}}}}}}],
 "textures": [{{"source": 0}}],
 "images": [{{"uri": "{image}"}}],
 "buffers": [{{"byteLength": {len}{buffer}}}],
 "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 128}}, {{"buffer": 0, "byteOffset": 128, "byteLength": 12}}],
 "accessors": [
   {{"bufferView": 0, "byteOffset": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
   {{"bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 4, "type": "VEC3"}},
   {{"bufferView": 0, "byteOffset": 96, "componentType": 5126, "count": 4, "type": "VEC2"}},
   {{"bufferView": 1, "byteOffset": 0, "componentType": 5123, "count": 6, "type": "SCALAR"}}]}}"#,
            len = buf.len()
        )
    };
    let embedded = json(
        &format!(r#", "uri": "data:application/octet-stream;base64,{}""#, base64(&buf)),
        &format!("data:image/png;base64,{}", base64(&png)),
    );
    let mut chunk = json("", "green.png").into_bytes();
    while chunk.len() % 4 != 0 {
        chunk.push(b' ');
    }
    let mut bin = buf.clone();
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&((12 + 8 + chunk.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&chunk);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    [("quad.gltf".into(), embedded.into_bytes()), ("quad.glb".into(), glb)]
}

#[test]
fn mutated_gltf_and_glb_load_or_fail_cleanly() {
    let dir = scratch("gltf");
    let sources = gltf_sources(&dir);
    // The unmutated sources are valid: the mutations start from files the loader accepts.
    for (name, bytes) in &sources {
        let p = dir.join(format!("valid-{name}"));
        std::fs::write(&p, bytes).unwrap();
        if let Err(e) = Scene::load(&p) {
            panic!("the glTF source {name} does not load: {e}");
        }
    }
    run_cases("gltf", 256, 5, Inputs::Mutated, &mutated(sources.len()), |tally, (i, edits)| {
        let (name, bytes) = &sources[i];
        let p = dir.join(format!("case-{name}"));
        std::fs::write(&p, apply_all(bytes, &edits)).unwrap();
        guarded(tally, label(Path::new(name), &edits), move || Scene::load(&p))
    });
}

const GLTF_TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"asset\"",
    "{\"version\": \"2.0\"}",
    "\"scenes\"",
    "\"nodes\"",
    "\"children\"",
    "\"mesh\"",
    "\"meshes\"",
    "\"primitives\"",
    "\"attributes\"",
    "\"POSITION\"",
    "\"indices\"",
    "\"accessors\"",
    "\"bufferViews\"",
    "\"buffers\"",
    "\"byteLength\"",
    "\"count\"",
    "\"type\"",
    "\"VEC3\"",
    "\"SCALAR\"",
    "\"componentType\"",
    "5126",
    "5123",
    "\"bufferView\"",
    "\"buffer\"",
    "\"uri\"",
    "\"data:application/octet-stream;base64,AAAAAAAAAAAAAAAA\"",
    "\"scene\"",
    "0",
    "1",
    "\"camera\"",
    "\"cameras\"",
    "\"matrix\"",
];

#[test]
fn arbitrary_gltf_fails_cleanly() {
    let dir = scratch("gltf_soup");
    fuzz_soup("gltf soup", 256, 6, GLTF_TOKENS, dir.join("scene.gltf"));
}

#[test]
fn mutated_mitsuba_xml_loads_or_fails_cleanly() {
    let dir = scratch("mitsuba");
    let scenes = mirror_scenes(&dir);
    let tests = dir.join("mitsuba-scenes");
    std::fs::create_dir_all(&tests).unwrap();
    let mut sources = vec![(repo().join("scenes/veach-ajar/scene.xml"), scenes.join("veach-ajar/fuzz-case.xml"))];
    for name in ["metals.xml", "glass.xml", "plastics.xml"] {
        sources.push((repo().join("renderer/tests/mitsuba-scenes").join(name), tests.join(format!("fuzz-{name}"))));
    }
    let targets: Vec<PathBuf> = sources.iter().map(|(_, t)| t.clone()).collect();
    fuzz_files("mitsuba", 128, 7, &sources, |i| targets[i].clone());
}

const XML_TOKENS: &[&str] = &[
    "<scene version=\"3.0.0\">",
    "</scene>",
    "<shape type=\"rectangle\">",
    "<shape type=\"sphere\">",
    "<shape type=\"obj\">",
    "</shape>",
    "<bsdf type=\"diffuse\" id=\"a\">",
    "<bsdf type=\"twosided\">",
    "</bsdf>",
    "<ref id=\"a\"/>",
    "<rgb name=\"reflectance\" value=\"",
    "\"/>",
    "<float name=\"radius\" value=\"",
    "<transform name=\"to_world\">",
    "</transform>",
    "<scale value=\"",
    "<matrix value=\"",
    "<sensor type=\"perspective\">",
    "</sensor>",
    "<float name=\"fov\" value=\"",
    "<film type=\"hdrfilm\">",
    "</film>",
    "<integer name=\"width\" value=\"",
    "<emitter type=\"area\">",
    "</emitter>",
    "<emitter type=\"constant\">",
    "<!--",
    "-->",
    "<!DOCTYPE scene [<!ENTITY a \"aaaa\">]>",
    "&a;",
    ", ",
    "\n",
];

#[test]
fn arbitrary_mitsuba_xml_fails_cleanly() {
    let dir = scratch("mitsuba_soup");
    fuzz_soup("mitsuba soup", 256, 8, XML_TOKENS, dir.join("scene.xml"));
}
