//! A/B of BVH variants in one process, single-thread, interleaved run by run (best and median
//! of `REPS` runs, per CPU second of the tracing thread), with node visits and block tests per
//! ray. Each variant is a node cost for the wide collapse (`Accel::build_tuned`), optionally
//! followed by `:sse2` to force the SSE2 node test, `:avx2` for the AVX2 query without AVX-512's
//! registers where the CPU has them, `:tri4` for the AVX2 node test with leaves
//! tested one `Tri4` block at a time, `:tri8` two blocks at a time (the default except on
//! a CPU that splits 256-bit operations, where `:tri4` is), `:4k` for the BVH's arrays on
//! ordinary pages instead of huge ones (`bvh::Pages`), and by an obvhs build preset
//! (`:very_fast`, `:fast`, `:medium`, `:slow`; by default `bvh::build_params`'s, which
//! depends on the mesh's size), e.g.
//! `REPS=7 cargo run --release -p renderer --example bvh_ab -- 3:sse2 3 4 3::slow`. Rays are
//! traced one `intersect` after another in a loop (`bench::trace_one_at_a_time`), or, for a
//! variant prefixed with `r` (`r5`), through `bench::trace`'s parallel iterator on the
//! one-thread pool. The variant `e` is Embree in this process (`renderer::embree`, the library
//! of `target/embree-venv`, fast mode; `er` its robust mode, `e2` kept to its AVX2 kernels, `eh` with
//! its `hugepages=1` option, or the Embree device configuration in `EHCFG` if set, e.g.
//! `EHCFG=verbose=2` to print its BVH's statistics), traced in the same kind of loop;
//! `e16` and `er16` trace 16-ray packets (`rtcIntersect16`, as Mitsuba's `llvm_ad_rgb` does on
//! an AVX-512 CPU), after checking that they answer as `rtcIntersect1` does.
//! `MESH=cornell` or `MESH=sphere` runs one of the two meshes; `SPHERE_N=80` makes the sphere
//! 80×80×2 triangles instead of 230×230×2 (to see the ratio with the mesh in cache), and
//! `MISS=1` replaces the camera rays by rays that start far outside the mesh's box and point
//! away from it (the per-ray setup and the root node's test alone). `SET=camera` or
//! `SET=random` times one of the two ray sets (for a profile of one).

use renderer::bench::{displaced_sphere, thread_cpu_seconds, trace, trace_one_at_a_time, RayBatch, SphereStyle};
use renderer::embree::{library_in_venv, Embree, EmbreeScene};
use renderer::geometry::bvh::{build_params, default_build_params};
use renderer::geometry::Accel;
use renderer::scene::Scene;
use std::path::Path;

fn main() {
    let variants: Vec<String> = std::env::args().skip(1).collect();
    let reps: usize = std::env::var("REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(7);
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let scene = Scene::load(&ws.join("scenes/cornell-box/scene.toml")).expect("scene");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let is_embree = |v: &str| v == "e" || v == "er" || v == "e2" || v == "eh" || v == "e16" || v == "er16";
    let lib = |config: Option<&str>| {
        variants.iter().any(|v| is_embree(v)).then(|| {
            let path = library_in_venv(&ws.join("target/embree-venv")).unwrap_or_else(|e| panic!("{e}"));
            Embree::load_with_config(&path, config).unwrap_or_else(|e| panic!("{e}"))
        })
    };
    let (embree, embree_avx2, embree_huge) =
        (lib(None), lib(Some("isa=avx2")), lib(Some(std::env::var("EHCFG").ok().as_deref().unwrap_or("hugepages=1"))));
    let only = std::env::var("MESH").unwrap_or_default();
    for (name, mesh) in [
        ("cornell", scene.mesh.clone()),
        ("sphere", {
            let n: u32 = std::env::var("SPHERE_N").ok().and_then(|s| s.parse().ok()).unwrap_or(230);
            displaced_sphere(n, n, SphereStyle::Bench)
        }),
    ] {
        if !only.is_empty() && only != name {
            continue;
        }
        let mut cam = RayBatch::camera(&mesh, 500_000, 1);
        if std::env::var("MISS").is_ok() {
            // Rays from far outside the mesh's box pointing away: setup and the root test only.
            let (lo, hi) = mesh.bounds();
            let (c, r) = ((lo + hi) * 0.5, (hi - lo).length());
            let mut b = RayBatch::default();
            for i in 0..cam.len() {
                let d = cam.dirs[i];
                b.push(c + d * (10.0 * r), d, f32::INFINITY);
            }
            cam = b;
        }
        let rnd = RayBatch::random_in_bounds(&mesh, 500_000, 2);
        let accels: Vec<Option<Accel>> = variants
            .iter()
            .map(|v| {
                if is_embree(v) {
                    return None;
                }
                let mut parts = v.trim_start_matches('r').split(':');
                let c = parts.next().unwrap_or("");
                let isa = parts.next().unwrap_or("");
                let params = match parts.next().unwrap_or("") {
                    "" => build_params(mesh.triangles.len()),
                    "very_fast" => default_build_params(),
                    "fastest" => obvhs::BvhBuildParams::fastest_build(),
                    "fast" => obvhs::BvhBuildParams::fast_build(),
                    "medium" => obvhs::BvhBuildParams::medium_build(),
                    "slow" => obvhs::BvhBuildParams::slow_build(),
                    p => panic!("unknown obvhs preset {p}"),
                };
                let mut a = Accel::build_tuned(&mesh, params, c.parse().expect("variant: a node cost"));
                a.set_avx2(isa != "sse2");
                match isa {
                    "tri4" => drop(a.set_tri8(false)),
                    "tri8" => drop(a.set_tri8(true)),
                    "4k" => a.set_huge_pages(false),
                    _ => (),
                }
                if isa == "avx2" {
                    a.set_avx512(false);
                }
                Some(a)
            })
            .collect();
        let scenes: Vec<Option<EmbreeScene>> = variants
            .iter()
            .map(|v| {
                let dev = match v.as_str() {
                    "e2" => &embree_avx2,
                    "eh" => &embree_huge,
                    _ => &embree,
                };
                is_embree(v).then(|| dev.as_ref().unwrap().scene(&mesh, v.starts_with("er")).unwrap_or_else(|e| panic!("{e}")))
            })
            .collect();
        for (v, a) in variants.iter().zip(&accels) {
            let Some(a) = a else { continue };
            let s = a.bvh_shape();
            print!("{name} [{v}]: {} nodes, fill {:.2}, {} blocks;", s.nodes, s.avg_fill, s.blocks);
            for (set, batch) in [("camera", &cam), ("random", &rnd)] {
                let (nodes, blocks) = batch.traversal_per_ray(a);
                print!(" {set} {nodes:.2} nodes {blocks:.2} blocks/ray;");
            }
            println!();
        }
        for (v, e) in variants.iter().zip(&scenes) {
            let Some(e) = e.as_ref().filter(|_| v.ends_with("16")) else { continue };
            for (set, batch) in [("camera", &cam), ("random", &rnd)] {
                let r = trace16(e, batch);
                let differ = (0..batch.len()).filter(|&i| r[i] != e.intersect(batch.origins[i], batch.dirs[i], batch.tmax[i])).count();
                println!("{name} {set} [{v}]: {differ} of {} rays answered differently by rtcIntersect1", batch.len());
            }
        }
        let only_set = std::env::var("SET").unwrap_or_default();
        for (set, batch) in [("camera", &cam), ("random", &rnd)] {
            if !only_set.is_empty() && only_set != set {
                continue;
            }
            let mut times = vec![Vec::new(); accels.len()];
            for _ in 0..reps {
                for (i, ((a, e), v)) in accels.iter().zip(&scenes).zip(&variants).enumerate() {
                    let s = pool.install(|| {
                        let c0 = thread_cpu_seconds().unwrap();
                        match (a, e) {
                            (Some(a), _) if v.starts_with('r') => drop(std::hint::black_box(trace(a, batch, 0))),
                            (Some(a), _) => drop(std::hint::black_box(trace_one_at_a_time(a, batch))),
                            (None, Some(e)) if v.ends_with("16") => drop(std::hint::black_box(trace16(e, batch))),
                            (None, Some(e)) => {
                                let r: Vec<_> =
                                    (0..batch.len()).map(|i| e.intersect(batch.origins[i], batch.dirs[i], batch.tmax[i])).collect();
                                drop(std::hint::black_box(r));
                            }
                            (None, None) => unreachable!("every variant is ours or Embree"),
                        }
                        thread_cpu_seconds().unwrap() - c0
                    });
                    times[i].push(batch.len() as f64 / s * 1e-6);
                }
            }
            for (v, t) in variants.iter().zip(&mut times) {
                t.sort_by(f64::total_cmp);
                println!("  {name} {set} [{v}]: best {:.2} median {:.2} Mrays/s", t[t.len() - 1], t[t.len() / 2]);
            }
        }
    }
}

/// `batch` through Embree in packets of 16 rays (the last one partial).
fn trace16(e: &EmbreeScene, batch: &RayBatch) -> Vec<Option<(u32, f32)>> {
    let mut r = vec![None; batch.len()];
    for (k, out) in r.chunks_mut(16).enumerate() {
        let s = 16 * k..16 * k + out.len();
        e.intersect16(&batch.origins[s.clone()], &batch.dirs[s.clone()], &batch.tmax[s], out);
    }
    r
}
