//! End-to-end: the `pixguide render` command on a shipped scene, as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn pixguide() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pixguide"))
}

fn out_dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn render_with_aovs_writes_every_file() {
    let d = out_dir("render-aovs");
    let exr = d.join("cornell.exr");
    let out = pixguide()
        .args(["render", "scenes/cornell-box/scene.toml", "--spp", "2", "--aovs", "--quiet", "--png"])
        .arg(d.join("cornell.png"))
        .arg("-o")
        .arg(&exr)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(out.status.success(), "render failed: {}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("samples/s") && stdout.contains("rays/s"), "summary line missing: {stdout}");
    for f in [
        "cornell.exr",
        "cornell.png",
        "cornell.descriptors.safetensors",
        "cornell.contact.png",
        "cornell.albedo.png",
        "cornell.normal.png",
        "cornell.depth.png",
        "cornell.diffuse.png",
        "cornell.specular.png",
    ] {
        let p = d.join(f);
        assert!(p.metadata().map(|m| m.len() > 0).unwrap_or(false), "{} was not written", p.display());
    }
    let frame = renderer::film::exr_io::read_frame(&exr).unwrap();
    assert_eq!(frame.spp, 2);
    assert!(frame.albedo.is_some() && frame.normal.is_some() && frame.depth.is_some() && frame.diffuse.is_some());
    assert!(frame.all_finite());
    let desc = renderer::film::Descriptors::read_safetensors(&d.join("cornell.descriptors.safetensors")).unwrap();
    assert_eq!((desc.width, desc.height, desc.spp), (frame.width, frame.height, 2));
}

#[test]
fn missing_scene_is_a_clear_error() {
    let out = pixguide().args(["render", "no/such/scene.toml", "--quiet"]).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no/such/scene.toml"), "error must name the file: {err}");
    assert!(!err.contains("panicked"), "{err}");
}
