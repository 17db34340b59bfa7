//! Quick single-thread ray benchmark against Embree on the two `pixguide bench` meshes:
//! `cargo run --release -p renderer --example bvh_quick [rays]`.

use renderer::bench::{displaced_sphere, embree_script, ray_bench, EmbreeSetup, RayBatch, SphereStyle};
use renderer::geometry::Accel;
use renderer::scene::Scene;
use std::path::Path;
use tools_venv::embree_python;

fn main() {
    let rays: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(500_000);
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let python = embree_python(&ws.join("target/embree-venv")).expect("embree venv");
    let setup = EmbreeSetup { python, script: embree_script(&ws), work_dir: ws.join("target/embree-bench"), robust: false, library: None };
    let scene = Scene::load(&ws.join("scenes/cornell-box/scene.toml")).expect("scene");
    for (name, mesh) in [("cornell", scene.mesh.clone()), ("sphere", displaced_sphere(230, 230, SphereStyle::Bench))] {
        let cam = RayBatch::camera(&mesh, rays, 1);
        let rnd = RayBatch::random_in_bounds(&mesh, rays, 2);
        let accel = Accel::build(&mesh);
        let shape = accel.bvh_shape();
        print!(
            "== {name}: {} nodes, {:.2} of 8 children filled on average, {} leaves, {} Tri4 blocks; per ray",
            shape.nodes, shape.avg_fill, shape.leaves, shape.blocks
        );
        for (set, batch) in [("camera", &cam), ("random", &rnd)] {
            let (nodes, blocks) = batch.traversal_per_ray(&accel);
            print!(" {set}: {nodes:.2} node visits, {blocks:.2} block tests;");
        }
        println!();
        let report = ray_bench(&mesh, &[("camera", &cam), ("random", &rnd)], 1, 3, Some(&setup)).expect("bench runs");
        println!("== {name}\n{report}");
    }
}
