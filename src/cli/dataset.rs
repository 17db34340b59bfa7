//! `pixguide dataset`: randomized training shots (noisy inputs at several spp with every buffer
//! and per-sample descriptors, plus a high-spp reference), resumable and written atomically.

use super::progress;
use anyhow::{bail, Context, Result};
use clap::Args;
use renderer::film::{self, BufferRequest};
use renderer::integrator::{self, RenderOptions};
use renderer::randomize::{randomize, Original};
use renderer::rng::mix64;
use renderer::scene::Scene;
use serde::Serialize;
use serde_json::value::RawValue;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args)]
pub struct DatasetArgs {
    /// A text file listing scene files (one per line, relative to the list; # comments), or
    /// scene files directly, comma-separated.
    #[arg(long, default_value = "scenes/train.txt")]
    pub scenes: String,
    /// Training shots per scene (14 × 23 scenes × 128² is 4.2× the 2026-11 set's pixels;
    /// docs/dataset.md has the time it takes).
    #[arg(long, default_value_t = 14)]
    pub shots: u32,
    /// Noisy sample counts; each is a prefix of the largest (same seed, same streams). 64 is in
    /// the default so that the denoisers see inputs as converged as the 64-spp tests
    /// (docs/dataset.md).
    #[arg(long, value_delimiter = ',', default_value = "2,4,8,16,32,64")]
    pub spp: Vec<u32>,
    /// Reference samples per pixel.
    #[arg(long, default_value_t = 1024)]
    pub ref_spp: u32,
    /// Image size WxH.
    #[arg(long, default_value = "128x128")]
    pub size: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder (train/, val/, shots.jsonl, references.png).
    #[arg(short, long, default_value = "data/train-set")]
    pub output: PathBuf,
    /// Make only the K-th of N disjoint parts (K = 1..N; shot i goes to part i mod N + 1), e.g.
    /// one per Slurm array task or GNU parallel job. Each shot is the same as in a single run.
    /// Merge: put the parts' train/ and val/ folders into one output folder (or let every part
    /// write to the same shared folder) and run the same command without --shard: it finds
    /// every shot made and writes the index and contact sheet.
    #[arg(long, value_parser = parse_shard)]
    pub shard: Option<(usize, usize)>,
    /// Storage of the per-sample descriptors: bf16 (half the bytes, f32's range, 0.4 %
    /// relative; docs/formats.md) or f32.
    #[arg(long, value_enum, default_value = "bf16")]
    pub descriptor_precision: DescriptorPrecision,
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum DescriptorPrecision {
    Bf16,
    F32,
}

/// `K/N` with 1 ≤ K ≤ N → (K − 1, N).
fn parse_shard(s: &str) -> std::result::Result<(usize, usize), String> {
    let bad = || format!("--shard {s}: expected K/N with 1 <= K <= N, e.g. 3/8");
    let (k, n) = s.split_once('/').ok_or_else(bad)?;
    let (k, n): (usize, usize) = (k.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
    if k == 0 || n == 0 || k > n {
        return Err(bad());
    }
    Ok((k - 1, n))
}

pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s.split_once(['x', 'X']).with_context(|| format!("--size {s}: expected WxH, e.g. 128x128"))?;
    let (w, h): (u32, u32) = (
        w.trim().parse().with_context(|| format!("--size {s}: bad width"))?,
        h.trim().parse().with_context(|| format!("--size {s}: bad height"))?,
    );
    if w < 16 || h < 16 || w > 4096 || h > 4096 {
        bail!("--size {s}: each side must be between 16 and 4096 pixels");
    }
    Ok((w, h))
}

/// Scene files from a list file or a comma-separated list.
pub fn scene_list(spec: &str) -> Result<Vec<PathBuf>> {
    let p = Path::new(spec);
    if p.extension().is_some_and(|e| e == "txt") {
        let text = std::fs::read_to_string(p).with_context(|| format!("reading scene list {}", p.display()))?;
        let base = p.parent().unwrap_or(Path::new("."));
        Ok(text.lines().map(|l| l.split('#').next().unwrap().trim()).filter(|l| !l.is_empty()).map(|l| base.join(l)).collect())
    } else {
        Ok(spec.split(',').map(|s| PathBuf::from(s.trim())).collect())
    }
}

pub fn scene_name(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    if stem == "scene" {
        path.parent().and_then(|p| p.file_name()).map(|s| s.to_string_lossy().into_owned()).unwrap_or(stem)
    } else {
        stem
    }
}

struct Job {
    scene: usize,
    split: &'static str,
    shot: u32,
}

pub fn run(a: DatasetArgs) -> Result<()> {
    let (w, h) = parse_size(&a.size)?;
    let mut spps = a.spp.clone();
    spps.sort_unstable();
    spps.dedup();
    if spps.is_empty() || spps[0] == 0 {
        bail!("--spp needs positive sample counts");
    }
    let max_spp = *spps.last().unwrap();
    let paths = scene_list(&a.scenes)?;
    let mut jobs = Vec::new();
    for (i, _) in paths.iter().enumerate() {
        for shot in 0..a.shots {
            jobs.push(Job { scene: i, split: "train", shot });
        }
        // Validation: one shot per scene, with shot numbers training never uses.
        jobs.push(Job { scene: i, split: "val", shot: 100_000 });
    }
    std::fs::create_dir_all(&a.output).with_context(|| format!("creating {}", a.output.display()))?;
    // This part's shots: a fixed stride over the full job list, so the parts are disjoint,
    // cover every shot, and each shot keeps its seed.
    let mut mine: Vec<&Job> = match a.shard {
        Some((k, n)) => jobs.iter().enumerate().filter(|(i, _)| i % n == k).map(|(_, j)| j).collect(),
        None => jobs.iter().collect(),
    };
    // Made round by round: the validation shots first, then shot 0 of every scene, shot 1, …
    // A run stopped at any point leaves every scene with about as many shots, and
    // `--shots K` over the folder then indexes a balanced set of the rounds already made.
    mine.sort_by_key(|j| (j.split != "val", j.shot, j.scene));

    let label = match a.shard {
        Some((k, n)) => format!("dataset shots (part {}/{n})", k + 1),
        None => "dataset shots".to_string(),
    };
    let pb = progress::bar(mine.len() as u64, &label);
    if a.quiet {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let start = Instant::now();
    let (mut made, mut bytes) = (0u64, 0u64);
    // Every scene stays loaded: rounds visit them all in turn.
    let mut loaded: std::collections::HashMap<usize, (Scene, Original)> = std::collections::HashMap::new();
    for job in mine.iter().copied() {
        let name = scene_name(&paths[job.scene]);
        let dir = a.output.join(job.split).join(format!("{name}_{:06}", job.shot));
        if dir.join("shot.json").exists() {
            pb.inc(1);
            continue;
        }
        // `randomize` sets everything a shot changes from `orig`, so a shot does not depend on
        // which shots of the scene came before it.
        let (scene, orig) = match loaded.entry(job.scene) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => {
                let mut scene = Scene::load(&paths[job.scene])?;
                scene.camera.width = w;
                scene.camera.height = h;
                let orig = Original::of(&scene);
                e.insert((scene, orig))
            }
        };
        let shot_seed = mix64(a.seed ^ mix64(job.scene as u64 * 7919 + job.shot as u64));
        let params = randomize(scene, orig, &name, job.shot, shot_seed);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        pb.set_message(format!("{name} #{}", job.shot));
        let mut opts = RenderOptions::from_scene(scene, BufferRequest::ALL);
        opts.seed = shot_seed;
        for &spp in &spps {
            // Lower counts are prefixes of the largest render (same per-sample streams), as in
            // method.md §7.1; only the largest keeps its per-sample descriptors.
            opts.spp = spp;
            opts.request = if spp == max_spp { BufferRequest::ALL } else { BufferRequest { descriptors: false, ..BufferRequest::ALL } };
            let (frame, _) = integrator::render(scene, &opts, &|_| {})?;
            let exr = dir.join(format!("noisy_{spp}spp.exr"));
            film::exr_io::write_frame(&frame, &exr)?;
            if let Some(d) = &frame.descriptors {
                let precision = match a.descriptor_precision {
                    DescriptorPrecision::Bf16 => film::Precision::Bf16,
                    DescriptorPrecision::F32 => film::Precision::F32,
                };
                d.write_safetensors_as(&dir.join(format!("descriptors_{spp}spp.safetensors")), precision)?;
            }
        }
        let mut ref_opts = RenderOptions::from_scene(scene, BufferRequest { split: true, gbuffers: true, descriptors: false });
        ref_opts.spp = a.ref_spp;
        ref_opts.seed = mix64(shot_seed ^ 0x0005_EED0_F4EF);
        let (reference, _) = integrator::render(scene, &ref_opts, &|_| {})?;
        film::exr_io::write_frame(&reference, &dir.join("reference.exr"))?;
        film::png::write_radiance(&dir.join("reference.png"), w, h, &reference.radiance.mean, 0.0)?;
        let json = serde_json::to_string(&params)?;
        film::exr_io::write_atomically(&dir.join("shot.json"), json.as_bytes())?;
        made += 1;
        bytes += dir_size(&dir);
        pb.inc(1);
    }
    pb.finish_and_clear();
    // The index and the contact sheet are rebuilt from what is on disk, so they are complete
    // after a resumed run too.
    let (index, sheet) = write_index(&a.output, &jobs, &paths)?;
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{} shots made ({} already there) in {:.1} s: {:.3} shots/s, {:.1} MiB written; index {}, references {}",
        made,
        mine.len() as u64 - made,
        secs,
        made as f64 / secs.max(1e-9),
        bytes as f64 / (1 << 20) as f64,
        index.display(),
        sheet.display()
    );
    Ok(())
}

fn dir_size(dir: &Path) -> u64 {
    std::fs::read_dir(dir).map(|r| r.flatten().filter_map(|e| e.metadata().ok()).map(|m| m.len()).sum()).unwrap_or(0)
}

/// One line of shots.jsonl: the shot's split, its folder relative to the dataset, and its
/// shot.json as it is on disk.
#[derive(Serialize)]
struct IndexLine<'a> {
    split: &'a str,
    dir: String,
    params: &'a RawValue,
}

/// shots.jsonl (one line per shot with its split and folder) and references.png (all
/// reference thumbnails on one sheet).
fn write_index(out: &Path, jobs: &[Job], paths: &[PathBuf]) -> Result<(PathBuf, PathBuf)> {
    let index = out.join("shots.jsonl");
    let mut lines = Vec::new();
    let mut thumbs = Vec::new();
    for job in jobs {
        let dir = out.join(job.split).join(format!("{}_{:06}", scene_name(&paths[job.scene]), job.shot));
        let shot_json = dir.join("shot.json");
        let Ok(json) = std::fs::read_to_string(&shot_json) else { continue };
        let params: &RawValue = serde_json::from_str(&json).with_context(|| format!("parsing {}", shot_json.display()))?;
        let line = IndexLine { split: job.split, dir: format!("{}/{}", job.split, dir.file_name().unwrap().to_string_lossy()), params };
        lines.push(serde_json::to_string(&line)?);
        if let Ok(img) = image::open(dir.join("reference.png")) {
            thumbs.push(img.to_rgb8());
        }
    }
    let mut f = Vec::new();
    for l in &lines {
        writeln!(f, "{l}")?;
    }
    film::exr_io::write_atomically(&index, &f)?;
    let sheet = out.join("references.png");
    if let Some(first) = thumbs.first() {
        let (tw, th) = (first.width().min(128), first.height().min(128));
        let cols = 8u32.min(thumbs.len() as u32);
        let rows = (thumbs.len() as u32).div_ceil(cols);
        let mut canvas = image::RgbImage::new(cols * tw, rows * th);
        for (k, t) in thumbs.iter().enumerate() {
            let t = image::imageops::resize(t, tw, th, image::imageops::FilterType::Triangle);
            image::imageops::replace(&mut canvas, &t, ((k as u32 % cols) * tw) as i64, ((k as u32 / cols) * th) as i64);
        }
        canvas.save(&sheet).with_context(|| format!("writing {}", sheet.display()))?;
    }
    Ok((index, sheet))
}
