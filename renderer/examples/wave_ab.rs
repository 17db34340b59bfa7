//! A/B of the wavefront's instruction sets in one process, single-thread, interleaved run by
//! run: the Cornell box's camera samples (its 256² image, `SPP` per pixel, default 4; 5 bounces) through
//! `wave::trace_batch_variant` with variants given as arguments (0 SSE2, 1 AVX2, 2 AVX-512),
//! median of `REPS` runs in paths per CPU second of the thread, and each variant's rate
//! against the first one's, repetition by repetition. Checks that every variant returns the
//! same bits. A variant followed by `n` (`2n`) runs without the packet query
//! (`Accel::drop_packets`), the closest hits then one BVH query at a time; followed by `s`
//! (`2s`), with the packet query for closest hits only, the shadow rays one BVH query at a time
//! (`Accel::set_packet_shadows`).
use glam::Vec2;
use renderer::bench::thread_cpu_seconds;
use renderer::integrator::wave::{trace_batch_variant, LaneResult, LANES};
use renderer::rng::Pcg32;
use renderer::scene::Scene;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let variants: Vec<(u8, char)> = args
        .iter()
        .map(|a| {
            let mode = a.chars().last().filter(|c| matches!(c, 'n' | 's')).unwrap_or(' ');
            (a.trim_end_matches(['n', 's']).parse().expect("variant 0, 1 or 2, optionally followed by n or s"), mode)
        })
        .collect();
    let reps: usize = std::env::var("REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(7);
    let spp: u32 = std::env::var("SPP").ok().and_then(|s| s.parse().ok()).unwrap_or(4);
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let scene = Scene::load(&ws.join("scenes/cornell-box/scene.toml")).expect("scene");
    let mut bvh_only = Scene::load(&ws.join("scenes/cornell-box/scene.toml")).expect("scene");
    if !bvh_only.accel.drop_packets() {
        eprintln!("note: no packet query here (mesh too large or no AVX-512): `n` and `s` variants are the same");
    }
    let mut bvh_shadows = Scene::load(&ws.join("scenes/cornell-box/scene.toml")).expect("scene");
    bvh_shadows.accel.set_packet_shadows(false);
    let cam = &scene.camera;
    let mut starts = Vec::new();
    for py in 0..cam.height {
        for px in 0..cam.width {
            let pixel = py as u64 * cam.width as u64 + px as u64;
            for s in 0..spp {
                let mut rng = Pcg32::for_sample(1, pixel, s as u64);
                let film = Vec2::new(px as f32, py as f32) + rng.next_2d();
                starts.push((cam.ray(film), rng));
            }
        }
    }
    let run = |(v, mode): (u8, char)| -> (f64, Vec<LaneResult>) {
        let scene = match mode {
            'n' => &bvh_only,
            's' => &bvh_shadows,
            _ => &scene,
        };
        let mut out = Vec::with_capacity(starts.len());
        let t0 = thread_cpu_seconds().expect("thread clock");
        for chunk in starts.chunks(LANES) {
            let rays: Vec<_> = chunk.iter().map(|c| c.0).collect();
            let mut rngs: Vec<_> = chunk.iter().map(|c| c.1.clone()).collect();
            let r = trace_batch_variant(scene, &rays, &mut rngs, 5, false, v);
            out.extend_from_slice(&r[..chunk.len()]);
        }
        (thread_cpu_seconds().unwrap() - t0, out)
    };
    let bits = |o: &[LaneResult]| o.iter().flat_map(|r| r.radiance.to_array().map(f32::to_bits)).collect::<Vec<_>>();
    let reference = bits(&run(variants[0]).1);
    let mut times = vec![Vec::new(); variants.len()];
    for _ in 0..reps {
        for (k, &v) in variants.iter().enumerate() {
            let (t, o) = run(v);
            let b = bits(&o);
            if b != reference {
                let nd = b.iter().zip(&reference).filter(|(x, y)| x != y).count();
                let first = b.iter().zip(&reference).position(|(x, y)| x != y).unwrap();
                panic!(
                    "variant {} differs in {nd} of {} channels, first at {first}: {} vs {}",
                    args[k],
                    b.len(),
                    f32::from_bits(b[first]),
                    f32::from_bits(reference[first])
                );
            }
            times[k].push(t);
        }
    }
    // Runs of different variants in one repetition are adjacent in time, so their ratio is
    // less disturbed by the host's load than the medians are.
    for (k, v) in args.iter().enumerate().skip(1) {
        let mut r: Vec<f64> = times[0].iter().zip(&times[k]).map(|(a, b)| a / b).collect();
        r.sort_by(f64::total_cmp);
        let faster = r.iter().filter(|&&x| x > 1.0).count();
        println!(
            "variant {v} / variant {}: median of the per-repetition rate ratios {:.3} (faster in {faster} of {})",
            args[0],
            r[r.len() / 2],
            r.len()
        );
    }
    for (k, v) in args.iter().enumerate() {
        let mut t = times[k].clone();
        t.sort_by(f64::total_cmp);
        let med = t[t.len() / 2];
        println!("variant {v}: median {:.3} M paths/CPU s, best {:.3}", starts.len() as f64 / med / 1e6, starts.len() as f64 / t[0] / 1e6);
    }
}
