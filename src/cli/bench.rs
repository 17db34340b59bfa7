//! `pixguide bench`: throughput and overhead figures, each printed as a ratio against a baseline
//! measured in the same process (docs/performance.md records the output).

use crate::alloc_stats;
use anyhow::Result;
use clap::Args;
use renderer::film::BufferRequest;
use renderer::integrator::{self, RenderOptions};
use renderer::scene::Scene;
use std::path::PathBuf;

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
}

pub fn run(a: BenchArgs) -> Result<()> {
    let scene = Scene::load(&a.scene)?;
    println!("machine: {} threads", rayon::current_num_threads());
    buffer_overhead(&scene, &a)?;
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
    println!("{:<22} {:>10} {:>8} {:>14}", "buffers", "time [s]", "ratio", "peak heap [MiB]");
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
        println!("{:<22} {:>10.3} {:>7.2}x {:>14.1}", name, best, best / b, peak as f64 / (1 << 20) as f64);
    }
    Ok(())
}
