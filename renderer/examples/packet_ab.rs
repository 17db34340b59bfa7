//! The packet query (`geometry::packet`, sixteen rays against every triangle) against one BVH
//! query per ray, in one process, one thread, interleaved run by run: the Cornell box's camera
//! rays (4 per pixel of its 256² image) and the first bounce rays from their hits (cosine
//! directions, origins offset as the integrator offsets them). Prints the median ns per ray of
//! each and checks that both answer alike, bit for bit.
//!
//! `REPS=9 target/release/examples/packet_ab [scene]`
use glam::Vec2;
use renderer::bench::thread_cpu_seconds;
use renderer::geometry::{offset_ray_origin, packet::WIDTH, Hit};
use renderer::math::{Frame, Ray};
use renderer::rng::Pcg32;
use renderer::scene::Scene;
use std::path::Path;

fn main() {
    let reps: usize = std::env::var("REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(7);
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let path = std::env::args().nth(1).map(Into::into).unwrap_or_else(|| ws.join("scenes/cornell-box/scene.toml"));
    let scene = Scene::load(&path).expect("scene");
    if scene.accel.packets().is_none() {
        eprintln!(
            "no packet query for this scene on this CPU (more than {} triangles, or no AVX-512)",
            renderer::geometry::packet::PACKET_MAX
        );
        return;
    }
    let cam = &scene.camera;
    let (mut cams, mut bounces) = (Vec::new(), Vec::new());
    for py in 0..cam.height {
        for px in 0..cam.width {
            let pixel = py as u64 * cam.width as u64 + px as u64;
            for s in 0..4 {
                let mut rng = Pcg32::for_sample(1, pixel, s);
                let r = cam.ray(Vec2::new(px as f32, py as f32) + rng.next_2d());
                cams.push(r);
                if let Some(h) = scene.accel.intersect(&r, f32::INFINITY) {
                    let si = scene.surface(&r, &h);
                    let n = if si.ng.dot(r.dir) > 0.0 { -si.ng } else { si.ng };
                    let d = Frame::from_normal(n).to_world(renderer::sampling::square_to_cosine_hemisphere(rng.next_2d()));
                    bounces.push(Ray::new(offset_ray_origin(si.p, si.ng, d, si.extent), d));
                }
            }
        }
    }
    let live = [true; WIDTH];
    let packets = |set: &[Ray], out: &mut Vec<Option<Hit>>| {
        out.clear();
        let mut o = [None; WIDTH];
        for ch in set.chunks(WIDTH) {
            scene.accel.intersect_live(ch, &live[..ch.len()], f32::INFINITY, &mut o[..ch.len()]);
            out.extend_from_slice(&o[..ch.len()]);
        }
    };
    let singles = |set: &[Ray], out: &mut Vec<Option<Hit>>| {
        out.clear();
        out.extend(set.iter().map(|r| scene.accel.intersect(r, f32::INFINITY)));
    };
    let key = |h: &Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.bary.x.to_bits(), h.bary.y.to_bits()));
    for (name, set) in [("camera", &cams), ("bounce", &bounces)] {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let (mut ta, mut tb) = (Vec::new(), Vec::new());
        for _ in 0..reps {
            let t0 = thread_cpu_seconds().expect("thread clock");
            singles(set, &mut a);
            let t1 = thread_cpu_seconds().unwrap();
            packets(set, &mut b);
            let t2 = thread_cpu_seconds().unwrap();
            ta.push((t1 - t0) / set.len() as f64 * 1e9);
            tb.push((t2 - t1) / set.len() as f64 * 1e9);
        }
        let differ = a.iter().zip(&b).filter(|(x, y)| key(x) != key(y)).count();
        ta.sort_by(f64::total_cmp);
        tb.sort_by(f64::total_cmp);
        println!(
            "{name} rays ({}): BVH {:.1} ns/ray, packets {:.1} ns/ray ({:.2}x); answers differing: {differ}",
            set.len(),
            ta[reps / 2],
            tb[reps / 2],
            ta[reps / 2] / tb[reps / 2]
        );
    }
}
