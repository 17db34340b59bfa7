//! Scene files for the scene tests: a scratch folder per test, files written into it, loading
//! that must succeed or fail with a message naming the file, and small images.
#![allow(dead_code)]

use renderer::scene::{load_description, SceneDescription};
use std::path::{Path, PathBuf};

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// A fresh directory for one test's files.
pub fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("scene_loading").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

pub fn load(p: &Path) -> SceneDescription {
    match load_description(p) {
        Ok(d) => d,
        Err(e) => panic!("{} failed to load: {e}", p.display()),
    }
}

/// Loads a scene that must fail and checks the message names the file and every `needles`.
pub fn expect_error(p: &Path, needles: &[&str]) -> String {
    let msg = match load_description(p) {
        Ok(_) => panic!("{} loaded but should fail", p.display()),
        Err(e) => e.to_string(),
    };
    let fname = p.file_name().unwrap().to_str().unwrap();
    assert!(msg.contains(fname), "message does not name the file {fname}: {msg}");
    for n in needles {
        assert!(msg.contains(n), "message does not mention `{n}`: {msg}");
    }
    msg
}

pub const CAMERA: &str = "[camera]\nposition = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 40\nresolution = [32, 32]\n";

pub fn write_png(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    img.save(path).unwrap();
}

pub fn write_exr(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 3]) {
    let img = image::Rgb32FImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    image::DynamicImage::ImageRgb32F(img).save(path).unwrap();
}
