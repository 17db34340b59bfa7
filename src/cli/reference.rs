//! `pixguide reference`: high-spp references of the test scenes, rendered in chunks that are
//! kept on disk so an interrupted run resumes where it stopped. Chunks use consecutive sample
//! indices of one seed, so the merged result is the same render as an unchunked one.

use super::dataset::{scene_list, scene_name};
use super::progress;
use anyhow::{Context, Result};
use clap::Args;
use renderer::film::{self, BufferRequest, Frame};
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args)]
pub struct ReferenceArgs {
    /// Scene list (text file, one scene per line) or comma-separated scene files.
    #[arg(long, default_value = "scenes/test.txt")]
    pub scenes: String,
    #[arg(long, default_value_t = 8000)]
    pub spp: u32,
    /// Samples per chunk (the unit of resumption).
    #[arg(long, default_value_t = 500)]
    pub chunk: u32,
    /// Render seed (references use their own seed, never a test's).
    #[arg(long, default_value_t = 8000)]
    pub seed: u64,
    /// Override the scene's resolution (WxH).
    #[arg(long)]
    pub size: Option<String>,
    #[arg(short, long, default_value = "scenes/references")]
    pub output: PathBuf,
    /// Re-render references that already exist.
    #[arg(long)]
    pub force: bool,
}

/// What scenes/references/<name>.json records beside each reference.
#[derive(Serialize, Deserialize)]
pub struct ReferenceInfo {
    pub scene: String,
    pub spp: u32,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    pub render_seconds: f64,
    pub command: String,
}

pub fn run(a: ReferenceArgs) -> Result<()> {
    let scenes = scene_list(&a.scenes)?;
    std::fs::create_dir_all(&a.output)?;
    let partial = a.output.join(".partial");
    for path in &scenes {
        let name = scene_name(path);
        let out = a.output.join(format!("{name}.exr"));
        if out.exists() && !a.force {
            println!("{name}: {} exists, skipped", out.display());
            continue;
        }
        let mut scene = Scene::load(path)?;
        if let Some(s) = &a.size {
            let (w, h) = super::dataset::parse_size(s)?;
            scene.camera.width = w;
            scene.camera.height = h;
        }
        std::fs::create_dir_all(&partial)?;
        let chunks = a.spp.div_ceil(a.chunk);
        let pb = progress::bar(chunks as u64, &format!("{name} {}spp", a.spp));
        let mut merged: Option<Frame> = None;
        let mut seconds = 0.0;
        for c in 0..chunks {
            let first = c * a.chunk;
            let spp = a.chunk.min(a.spp - first);
            let file = partial.join(format!("{name}_{first:06}_{spp}.exr"));
            let secs_file = file.with_extension("seconds");
            let frame = if file.exists() && secs_file.exists() {
                seconds += std::fs::read_to_string(&secs_file)?.trim().parse::<f64>().unwrap_or(0.0);
                film::exr_io::read_frame(&file)?
            } else {
                let mut opts = RenderOptions::from_scene(&scene, BufferRequest { split: true, gbuffers: true, descriptors: false });
                opts.spp = spp;
                opts.seed = a.seed;
                opts.first_sample = first;
                let t = Instant::now();
                let (frame, _) = integrator::render(&scene, &opts, &|_| {})?;
                let s = t.elapsed().as_secs_f64();
                seconds += s;
                film::exr_io::write_frame(&frame, &file)?;
                film::exr_io::write_atomically(&secs_file, format!("{s}").as_bytes())?;
                frame
            };
            match &mut merged {
                None => merged = Some(frame),
                Some(m) => m.merge(&frame)?,
            }
            pb.inc(1);
        }
        pb.finish_and_clear();
        let mut frame = merged.context("no samples rendered")?;
        // Everything that reads a reference scores radiance against it (eval, the regression
        // and shipped-weight tests, `--reference`): the split and G-buffers would triple the
        // committed file for nothing.
        (frame.diffuse, frame.specular, frame.albedo, frame.normal, frame.depth) = (None, None, None, None, None);
        film::exr_io::write_frame(&frame, &out)?;
        film::png::write_radiance(&out.with_extension("png"), frame.width, frame.height, &frame.radiance.mean, 0.0)?;
        let info = ReferenceInfo {
            scene: path.display().to_string(),
            spp: frame.spp,
            seed: a.seed,
            width: frame.width,
            height: frame.height,
            render_seconds: seconds,
            command: std::env::args().collect::<Vec<_>>().join(" "),
        };
        film::exr_io::write_atomically(&out.with_extension("json"), serde_json::to_string_pretty(&info)?.as_bytes())?;
        for c in 0..chunks {
            let first = c * a.chunk;
            let f = partial.join(format!("{name}_{first:06}_{}.exr", a.chunk.min(a.spp - first)));
            std::fs::remove_file(&f).ok();
            std::fs::remove_file(f.with_extension("seconds")).ok();
        }
        println!("{name}: {} spp in {:.1} s -> {}", frame.spp, seconds, out.display());
    }
    std::fs::remove_dir(&partial).ok();
    write_readme(&a.output)
}

/// Regenerates scenes/references/README.md from the .json sidecars.
fn write_readme(dir: &Path) -> Result<()> {
    let mut rows = Vec::new();
    let mut entries: Vec<_> =
        std::fs::read_dir(dir)?.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == "json")).collect();
    entries.sort();
    for p in entries {
        let info: ReferenceInfo =
            serde_json::from_str(&std::fs::read_to_string(&p)?).with_context(|| format!("reading {}", p.display()))?;
        let name = p.file_stem().unwrap().to_string_lossy().into_owned();
        rows.push(format!(
            "| {name} | `{}` | {}x{} | {} | {} | {:.0} | `{}` |",
            info.scene, info.width, info.height, info.spp, info.seed, info.render_seconds, info.command
        ));
    }
    let text = format!(
        "# Test-scene references\n\nEach `<scene>.exr` holds radiance and its variance of the mean (docs/formats.md), rendered by the command in the table on this\nproject's 2-core machine; `<scene>.png` is a preview. Regenerate (resumable) with\n`cargo run --release -- reference`. The table is rewritten from the `.json` sidecars.\n\n| scene | file | size | spp | seed | render time [s] | command |\n|---|---|---|---|---|---|---|\n{}\n",
        rows.join("\n")
    );
    film::exr_io::write_atomically(&dir.join("README.md"), text.as_bytes())?;
    Ok(())
}
