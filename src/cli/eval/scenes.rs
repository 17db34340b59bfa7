//! The held-out test scenes of `--scenes` with their references, and rendering one for a
//! measurement.

use super::cache::file_id;
use anyhow::{bail, Context, Result};
use renderer::film::{BufferRequest, Frame};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub struct TestScene {
    pub name: String,
    pub path: PathBuf,
    pub reference: PathBuf,
    /// [`file_id`] of the reference: a re-rendered reference (a scene or renderer fix) makes
    /// every cached score of the scene stale.
    pub reference_id: String,
    pub width: u32,
    pub height: u32,
}

pub(super) fn scenes(list: &Path) -> Result<Vec<TestScene>> {
    let text = std::fs::read_to_string(list).with_context(|| format!("reading the scene list {}", list.display()))?;
    let dir = list.parent().unwrap_or(Path::new("."));
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let path = dir.join(line);
        // The scene's name is its folder's (scenes/<name>/scene.toml).
        let name = path.parent().and_then(|p| p.file_name()).map(|c| c.to_string_lossy().into_owned()).unwrap_or_default();
        if !path.exists() {
            bail!("{} line {}: scene {} does not exist", list.display(), n + 1, path.display());
        }
        let json = dir.join("references").join(format!("{name}.json"));
        let reference = dir.join("references").join(format!("{name}.exr"));
        if !reference.exists() {
            bail!("no reference for the test scene {name}: {} does not exist (render it with `pixguide reference`)", reference.display());
        }
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).with_context(|| format!("reading {}", json.display()))?)
                .with_context(|| format!("parsing {}", json.display()))?;
        let dim = |f: &str| -> Result<u32> {
            meta.get(f)
                .and_then(|v| v.as_u64())
                .filter(|&v| v > 0 && v < 1 << 16)
                .map(|v| v as u32)
                .with_context(|| format!("{}: field `{f}` is missing or not a positive integer", json.display()))
        };
        let reference_id = file_id(&reference)?;
        out.push(TestScene { name, path, reference, reference_id, width: dim("width")?, height: dim("height")? });
    }
    if out.is_empty() {
        bail!("{} lists no scenes", list.display());
    }
    Ok(out)
}

/// per-sample descriptors when asked. Returns the frame and its wall seconds.
pub(super) fn render(scene: &Scene, spp: u32, seed: u64, descriptors: bool) -> Result<(Frame, f64)> {
    let mut opts = RenderOptions::from_scene(scene, BufferRequest { split: true, gbuffers: true, descriptors });
    opts.spp = spp;
    opts.seed = seed;
    let t = Instant::now();
    let (frame, _) = integrator::render(scene, &opts, &|_| {})?;
    Ok((frame, t.elapsed().as_secs_f64()))
}

/// The scene at `w × h`, after one untimed 1-spp render: the first render after loading pays
/// one-off costs (first touch of the scene's fresh memory, waking the thread pool) that would
/// otherwise land on the time of the first spp measured (seen: 0.30 s at 2 spp against 0.07 s
/// at 4 spp).
pub(super) fn load_scene(s: &TestScene, w: u32, h: u32) -> Result<Scene> {
    let mut scene = Scene::load(&s.path).with_context(|| format!("loading {}", s.path.display()))?;
    scene.camera.width = w;
    scene.camera.height = h;
    render(&scene, 1, 0, false).with_context(|| format!("rendering {}", s.path.display()))?;
    Ok(scene)
}
