//! Release-mode ray benchmark against Embree on the shipped meshes and a displaced sphere:
//! `cargo run --release -p renderer --example ray_bench [threads] [robust]`.
//! Also compares obvhs build presets (build time vs rays/s) when PIXGUIDE_BENCH_PRESETS is set.

use renderer::bench::{displaced_sphere, embree_script, obj_mesh, ray_bench, trace, EmbreeSetup, RayBatch, SphereStyle};
use renderer::geometry::Accel;
use std::path::Path;
use std::time::Instant;
use tools_venv::embree_python;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let threads: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(2);
    let robust = args.iter().any(|a| a == "robust");
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let python = embree_python(&ws.join("target/embree-venv")).expect("embree venv");
    let setup = EmbreeSetup { python, script: embree_script(&ws), work_dir: ws.join("target/embree-bench"), robust, library: None };
    let meshes = [
        ("cornell-box-mcguire", obj_mesh(&ws.join("scenes/assets/cornell-box-mcguire/CornellBox-Original.obj")).expect("obj loads")),
        ("stanford-bunny", obj_mesh(&ws.join("scenes/assets/stanford-bunny/bunny.obj")).expect("obj loads")),
        ("sphere-1M", displaced_sphere(700, 700, SphereStyle::Bench)),
    ];
    for (name, mesh) in &meshes {
        let cam = RayBatch::camera(mesh, 500_000, 1);
        let rnd = RayBatch::random_in_bounds(mesh, 500_000, 2);
        if std::env::var_os("PIXGUIDE_BENCH_PRESETS").is_some() {
            for (pname, p) in [
                ("fastest", obvhs::BvhBuildParams::fastest_build()),
                ("very_fast", obvhs::BvhBuildParams::very_fast_build()),
                ("fast", obvhs::BvhBuildParams::fast_build()),
                ("medium", obvhs::BvhBuildParams::medium_build()),
                ("slow", obvhs::BvhBuildParams::slow_build()),
            ] {
                let t0 = Instant::now();
                let accel = Accel::build_with(mesh, p);
                let b = t0.elapsed().as_secs_f64();
                let mut rates = Vec::new();
                for batch in [&cam, &rnd] {
                    let t0 = Instant::now();
                    let _ = trace(&accel, batch, threads);
                    rates.push(batch.len() as f64 / t0.elapsed().as_secs_f64() * 1e-6);
                }
                println!(
                    "{name} preset {pname:<10} build {:>7.1} ms, camera {:.2} Mrays/s, random {:.2} Mrays/s",
                    b * 1e3,
                    rates[0],
                    rates[1]
                );
            }
        }
        let report = ray_bench(mesh, &[("camera", &cam), ("random", &rnd)], threads, 3, Some(&setup)).expect("bench runs");
        println!("== {name} (Embree {})\n{report}", if robust { "robust" } else { "fast" });
    }
}
