//! `pixguide bench`: throughput and overhead figures, each printed as a ratio against a baseline
//! measured in the same process (docs/performance.md records the output).

use crate::alloc_stats;
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
    /// Scene for the buffer-overhead and integrator measurements.
    #[arg(long, default_value = "scenes/cornell-box/scene.toml")]
    pub scene: PathBuf,
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
}

pub fn run(a: BenchArgs) -> Result<()> {
    let scene = Scene::load(&a.scene)?;
    let threads = rayon::current_num_threads();
    println!("machine: {threads} threads");
    buffer_overhead(&scene, &a)?;
    integrator_throughput(&scene, &a)?;
    rays(&scene, &a, threads)?;
    Ok(())
}

/// Render time and peak heap of radiance only, + split and G-buffers, + per-sample descriptors
/// (issue floor: everything together ≤ 1.3× the radiance-only time).
fn buffer_overhead(scene: &Scene, a: &BenchArgs) -> Result<()> {
    let configs = [
        ("radiance only", BufferRequest::RADIANCE_ONLY),
        ("+ split + G-buffers", BufferRequest { split: true, gbuffers: true, descriptors: false }),
        ("+ descriptors (all)", BufferRequest::ALL),
    ];
    println!("\nbuffer overhead: {} at {}x{}, {} spp (best of {})", a.scene.display(), scene.camera.width, scene.camera.height, a.spp, a.repeat);
    println!("{:<22} {:>10} {:>8} {:>16}", "buffers", "time [s]", "ratio", "peak heap [MiB]");
    let mut base = None;
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
    }
    Ok(())
}

/// Full-integrator paths/s (camera samples per second) on the scene.
fn integrator_throughput(scene: &Scene, a: &BenchArgs) -> Result<()> {
    let mut opts = RenderOptions::from_scene(scene, BufferRequest::RADIANCE_ONLY);
    opts.spp = a.spp;
    let (_, st) = integrator::render(scene, &opts, &|_| {})?;
    println!("\nintegrator: {} — {:.3} M paths/s, {:.3} M rays/s", a.scene.display(), st.samples as f64 / st.wall.as_secs_f64() / 1e6, st.rays as f64 / st.wall.as_secs_f64() / 1e6);
    Ok(())
}

/// BVH build and closest-hit rays/s on camera and random rays, against Embree on the same rays.
fn rays(scene: &Scene, a: &BenchArgs, threads: usize) -> Result<()> {
    let embree = if a.no_embree {
        None
    } else {
        let ws = Path::new(".");
        match embree_python(&ws.join("target/embree-venv")) {
            Ok(python) => Some(EmbreeSetup { python, script: embree_script(ws), work_dir: ws.join("target/embree-bench"), robust: false }),
            Err(e) => {
                eprintln!("warning: Embree comparison skipped: {e}");
                None
            }
        }
    };
    let big = displaced_sphere(230, 230, SphereStyle::Bench);
    for (name, mesh) in [(a.scene.display().to_string(), &scene.mesh), (format!("displaced sphere ({} triangles)", big.triangles.len()), &big)] {
        let cam = RayBatch::camera(mesh, a.rays, 1);
        let rnd = RayBatch::random_in_bounds(mesh, a.rays, 2);
        let report = ray_bench(mesh, &[("camera", &cam), ("random", &rnd)], threads, a.repeat as usize, embree.as_ref())?;
        println!("\nrays: {name} (Embree fast mode; 1t rates per CPU second of the tracing thread)\n{report}");
    }
    Ok(())
}
