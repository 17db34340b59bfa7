//! `pixguide bench`: throughput and overhead figures, each printed as a ratio against a baseline
//! measured in the same process (docs/performance.md records the output).

use crate::alloc_stats;
use crate::cli::bench_mitsuba::{integrator_vs_mitsuba, Settings};
use anyhow::Result;
use clap::Args;
use renderer::bench::{displaced_sphere, embree_script, ray_bench, EmbreeSetup, RayBatch, SphereStyle};
use renderer::film::BufferRequest;
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use std::path::{Path, PathBuf};
use tools_venv::embree_python;

#[derive(Args)]
pub struct BenchArgs {
    /// Scene for the buffer-overhead and integrator measurements; repeat it to measure several
    /// in one run (a summary table closes the run). The rays section uses the first.
    #[arg(long, default_value = "scenes/cornell-box/scene.toml")]
    pub scene: Vec<PathBuf>,
    /// Samples per pixel for the buffer-overhead measurement.
    #[arg(long, default_value_t = 8)]
    pub spp: u32,
    /// Repetitions per configuration; the fastest is reported (the least disturbed by other load).
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Rays per ray set in the BVH benchmark.
    #[arg(long, default_value_t = 500_000)]
    pub rays: usize,
    /// Skip the Embree comparison (it needs a Python venv with embreex under target/).
    #[arg(long)]
    pub no_embree: bool,
    /// Skip the Mitsuba 3 comparison of the integrator (it needs a Python venv with mitsuba
    /// under target/, installed from PyPI on first use).
    #[arg(long)]
    pub no_mitsuba: bool,
    /// Image size for the integrator measurement (ours and Mitsuba's), WIDTHxHEIGHT.
    #[arg(long, default_value = "128x128", value_parser = crate::cli::bench_mitsuba::parse_size)]
    pub integrator_size: (u32, u32),
    /// Samples per pixel for the integrator measurement: enough that Mitsuba's per-render
    /// overhead (tracing the integrator anew each call) is small next to its rendering.
    #[arg(long, default_value_t = 1024)]
    pub integrator_spp: u32,
    /// Bounces for the integrator measurement (Mitsuba's max_depth is one more: it counts
    /// path segments).
    #[arg(long, default_value_t = 5)]
    pub bounces: u32,
}

pub fn run(a: BenchArgs) -> Result<()> {
    let threads = rayon::current_num_threads();
    println!("machine: {threads} threads, {}", cpu_model());
    let settings = Settings {
        width: a.integrator_size.0,
        height: a.integrator_size.1,
        spp: a.integrator_spp,
        max_bounces: a.bounces,
        repeat: a.repeat,
        threads,
    };
    let mut summary = Vec::new();
    for path in &a.scene {
        let scene = Scene::load(path)?;
        let buffers = buffer_overhead(&scene, path, &a)?;
        let vs = integrator_vs_mitsuba(path, &settings, !a.no_mitsuba)?;
        summary.push((path.display().to_string(), buffers, vs));
    }
    if summary.len() > 1 {
        println!(
            "
summary (ours/Mitsuba: paths/s, best against best and the median of the run-by-run pairs; buffers: time with them on / radiance only)"
        );
        println!("{:<40} {:>10} {:>10} {:>10} {:>10} {:>12}", "scene", "ours Mp/s", "best", "median", "+split+G", "+descriptors");
        let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}x"));
        let mut logs = Vec::new();
        for (name, [g, all], vs) in &summary {
            if let Some(r) = vs.best_ratio {
                logs.push(r.ln());
            }
            println!(
                "{:<40} {:>10.3} {:>10} {:>10} {:>9.2}x {:>11.2}x",
                name,
                vs.ours_paths_per_sec * 1e-6,
                fmt(vs.best_ratio),
                fmt(vs.median_ratio),
                g,
                all
            );
        }
        if !logs.is_empty() {
            let geo = (logs.iter().sum::<f64>() / logs.len() as f64).exp();
            println!("geometric mean of ours/Mitsuba (best) over {} scenes: {geo:.2}x", logs.len());
        }
    }
    let first = a.scene.first().ok_or_else(|| anyhow::anyhow!("no --scene"))?;
    rays(&Scene::load(first)?, first, &a, threads)?;
    Ok(())
}

/// The CPU's model name (/proc/cpuinfo), for the record beside every figure.
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split_once(':')).map(|(_, v)| v.trim().to_string()))
        .unwrap_or_else(|| "CPU model unknown".into())
}

/// Render time and peak heap of radiance only, + split and G-buffers, + per-sample descriptors
/// (issue floor: everything together ≤ 1.3× the radiance-only time); returns the last two as
/// ratios to the first.
fn buffer_overhead(scene: &Scene, path: &Path, a: &BenchArgs) -> Result<[f64; 2]> {
    let configs = [
        ("radiance only", BufferRequest::RADIANCE_ONLY),
        ("+ split + G-buffers", BufferRequest { split: true, gbuffers: true, descriptors: false }),
        ("+ descriptors (all)", BufferRequest::ALL),
    ];
    println!(
        "\nbuffer overhead: {} at {}x{}, {} spp (best of {})",
        path.display(),
        scene.camera.width,
        scene.camera.height,
        a.spp,
        a.repeat
    );
    println!("{:<22} {:>10} {:>8} {:>16}", "buffers", "time [s]", "ratio", "peak heap [MiB]");
    // One untimed render first: a scene's one-time costs (the plastic coat's tables, page
    // faults of the first frame) would otherwise land on the radiance-only time alone.
    let mut warm = RenderOptions::from_scene(scene, BufferRequest::RADIANCE_ONLY);
    warm.spp = 1;
    integrator::render(scene, &warm, &|_| {})?;
    let mut base = None;
    let mut ratios = Vec::new();
    for (name, req) in configs {
        let mut opts = RenderOptions::from_scene(scene, req);
        opts.spp = a.spp;
        let mut best = f64::INFINITY;
        let mut peak = 0usize;
        for _ in 0..a.repeat.max(1) {
            let before = alloc_stats::reset_peak();
            let (frame, stats) = integrator::render(scene, &opts, &|_| {})?;
            peak = peak.max(alloc_stats::peak() - before);
            best = best.min(stats.wall.as_secs_f64());
            drop(frame);
        }
        let b = *base.get_or_insert(best);
        println!("{:<22} {:>10.3} {:>7.2}x {:>16.1}", name, best, best / b, peak as f64 / (1 << 20) as f64);
        ratios.push(best / b);
    }
    Ok([ratios[1], ratios[2]])
}

/// BVH build and closest-hit rays/s on camera and random rays, against Embree on the same rays.
fn rays(scene: &Scene, path: &Path, a: &BenchArgs, threads: usize) -> Result<()> {
    let embree = if a.no_embree {
        None
    } else {
        let ws = Path::new(".");
        match embree_python(&ws.join("target/embree-venv")) {
            Ok(python) => {
                // The same library in this process as well: the tighter comparison.
                let venv = ws.join("target/embree-venv");
                let library = match renderer::embree::library_in_venv(&venv).and_then(|p| renderer::embree::Embree::load(&p)) {
                    Ok(lib) => Some(lib),
                    Err(e) => {
                        eprintln!("warning: Embree in this process skipped (embreex's figures still shown): {e}");
                        None
                    }
                };
                Some(EmbreeSetup { python, script: embree_script(ws), work_dir: ws.join("target/embree-bench"), robust: false, library })
            }
            Err(e) => {
                eprintln!("warning: Embree comparison skipped: {e}");
                None
            }
        }
    };
    let big = displaced_sphere(230, 230, SphereStyle::Bench);
    for (name, mesh) in [(path.display().to_string(), &scene.mesh), (format!("displaced sphere ({} triangles)", big.triangles.len()), &big)]
    {
        let cam = RayBatch::camera(mesh, a.rays, 1);
        let rnd = RayBatch::random_in_bounds(mesh, a.rays, 2);
        let report = ray_bench(mesh, &[("camera", &cam), ("random", &rnd)], threads, a.repeat as usize, embree.as_ref())?;
        println!("\nrays: {name} (Embree fast mode; 1t rates per CPU second of the tracing thread)\n{report}");
    }
    Ok(())
}
