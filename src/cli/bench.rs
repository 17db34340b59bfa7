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
    let scene = Scene::load(&a.scene)?;
    let threads = rayon::current_num_threads();
    println!("machine: {threads} threads");
    buffer_overhead(&scene, &a)?;
    let settings = Settings {
        width: a.integrator_size.0,
        height: a.integrator_size.1,
        spp: a.integrator_spp,
        max_bounces: a.bounces,
        repeat: a.repeat,
        threads,
    };
    integrator_vs_mitsuba(&a.scene, &settings, !a.no_mitsuba)?;
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
    println!(
        "\nbuffer overhead: {} at {}x{}, {} spp (best of {})",
        a.scene.display(),
        scene.camera.width,
        scene.camera.height,
        a.spp,
        a.repeat
    );
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

/// BVH build and closest-hit rays/s on camera and random rays, against Embree on the same rays.
fn rays(scene: &Scene, a: &BenchArgs, threads: usize) -> Result<()> {
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
    for (name, mesh) in
        [(a.scene.display().to_string(), &scene.mesh), (format!("displaced sphere ({} triangles)", big.triangles.len()), &big)]
    {
        let cam = RayBatch::camera(mesh, a.rays, 1);
        let rnd = RayBatch::random_in_bounds(mesh, a.rays, 2);
        let report = ray_bench(mesh, &[("camera", &cam), ("random", &rnd)], threads, a.repeat as usize, embree.as_ref())?;
        println!("\nrays: {name} (Embree fast mode; 1t rates per CPU second of the tracing thread)\n{report}");
    }
    Ok(())
}
