//! A wavefront form of `path::trace` for the common case: every material Lambertian (textured or
//! not), lights only emissive triangles, radiance (and the diffuse split) only. `LANES` paths
//! advance together bounce by bounce; their state is kept in structure-of-arrays form, and each
//! bounce is three stages:
//!
//! 1. per path (scalar): the closest-hit query, surface geometry, emission found by the path,
//!    the BSDF's albedo, the random numbers and the light selection; on a mesh with a packet
//!    query (`geometry::packet`: at most 48 triangles, AVX-512) the live paths' closest hits
//!    come first, sixteen at a time;
//! 2. all lanes at once, branch-free: normal orientation, shading frame, the light point, the
//!    connection, the BSDF value and densities, the MIS weight, the shadow ray, the BSDF sample
//!    (its concentric disk map included), the new throughput and the next ray. Written as
//!    loops over the lanes that LLVM vectorises, compiled for AVX-512 (16 lanes a register),
//!    AVX2 + FMA or the SSE2 baseline, whichever the CPU has (chosen at run time);
//! 3. per path (scalar): the shadow query, its contribution, Russian roulette.
//!
//! A render's samples stream through the lanes (`trace_samples`): a lane whose path has ended
//! takes the next sample before the next round, so lanes at different bounces share a round
//! and the batch stays full (a batch that ran until its last path ended ran its later bounces
//! with fewer and fewer live paths: on the Cornell box, whose open front lets paths escape,
//! most batches end with a handful).
//!
//! Every path performs exactly `path::trace`'s floating-point operations in its order, with its
//! own random stream, so the images are bit-identical to `trace`'s (no FMA contraction: Rust
//! never fuses a multiply and an add unless told to).

use crate::camera::RayMaker;
use crate::geometry::packet::{BatchHits, BATCH};
use crate::geometry::Hit;
use crate::light::connect_parts;
use crate::material::{Bsdf, MaterialKind};
use crate::math::{is_finite3, Frame, Ray, INV_PI};
use crate::rng::Pcg32;
use crate::scene::Scene;
use glam::{Vec2, Vec3};

/// Paths per batch (the packet query's batch: `geometry::packet::BATCH`).
pub const LANES: usize = BATCH;

/// Fraction of the light distance kept for shadow rays (`path::SHADOW_EPS`).
const SHADOW_EPS: f32 = 1e-4;

/// Whether `trace_batch` can render `scene` (the radiance and diffuse buffers only).
pub fn supported(scene: &Scene) -> bool {
    scene.lights.triangles_only() && scene.materials.iter().all(|m| matches!(m.kind, MaterialKind::Lambert { .. }))
}

/// What one path of a batch produced.
#[derive(Clone, Copy, Debug, Default)]
pub struct LaneResult {
    pub radiance: Vec3,
    pub diffuse: Vec3,
    pub rays: u32,
}

type L = [f32; LANES];
type B = [bool; LANES];

#[derive(Clone, Copy)]
struct V3 {
    x: L,
    y: L,
    z: L,
}

impl V3 {
    #[inline(always)]
    fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }
    #[inline(always)]
    fn set(&mut self, i: usize, v: Vec3) {
        self.x[i] = v.x;
        self.y[i] = v.y;
        self.z[i] = v.z;
    }
}

/// The batch: path state, and what the stages hand each other.
struct Wave {
    // Path state.
    alive: B,
    split_started: B,
    prev_delta: B,
    prev_pdf: L,
    prev_p: V3,
    org: V3,
    dir: V3,
    /// `org` and `dir` as rays, written one stage before the queries read them: a ray put
    /// together from the lanes right before a query is reloaded with a failed store forward.
    ray: [Ray; LANES],
    beta_d: V3,
    beta_s: V3,
    l_d: V3,
    l_s: V3,
    // Stage 1 → 2.
    p: V3,
    /// `SurfaceHit::extent`, for the ray offsets.
    extent: L,
    ng: V3,
    ns: V3,
    albedo: V3,
    u_light: [Vec2; LANES],
    u_bsdf: [Vec2; LANES],
    has_light: B,
    lp0: V3,
    lp1: V3,
    lp2: V3,
    ln: V3,
    l_area: L,
    l_two_sided: B,
    l_max: L,
    l_pmf: L,
    l_emission: V3,
    // Stage 2 → 3.
    shadow: B,
    sh_org: V3,
    sh_dir: V3,
    sh_tmax: L,
    sh_ray: [Ray; LANES],
    add_d: V3,
    add_s: V3,
    cont: B,
}

/// Where a sample starts: its pixel (x, y) in the whole image and its number in the pixel.
#[derive(Clone, Copy, Debug, Default)]
pub struct SampleStart {
    pub px: u32,
    pub py: u32,
    pub sample: u32,
}

/// Traces the samples `starts` of a render seeded with `seed` into `out` (one result a start,
/// in the same order), `LANES` paths at a time: a lane whose path ends takes the next sample
/// at once (path regeneration), so the batch stays full from the first bounce to the last
/// instead of running on with fewer and fewer live paths. Each sample's stream and camera ray
/// are made exactly as `integrator::start_sample` makes them one by one (`Pcg32::for_sample`,
/// then the film position's two draws and `Camera::ray`), `LANES` at once; a path's result
/// does not depend on the lane it runs in or on its neighbours, so every sample is traced
/// bit for bit as `trace_batch` (and `path::trace`) would trace it.
pub fn trace_samples(scene: &Scene, starts: &[SampleStart], seed: u64, max_bounces: u32, rr: bool, out: &mut [LaneResult]) {
    assert_eq!(starts.len(), out.len());
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        if has!("avx512f") && has!("avx512vl") && has!("avx512dq") && has!("avx2") && has!("fma") {
            // SAFETY: the CPU has the features (checked just above).
            return unsafe { trace_samples_avx512(scene, starts, seed, max_bounces, rr, out) };
        }
        if has!("avx2") && has!("fma") {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { trace_samples_avx2(scene, starts, seed, max_bounces, rr, out) };
        }
    }
    trace_samples_impl(scene, starts, seed, max_bounces, rr, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512dq")]
unsafe fn trace_samples_avx512(scene: &Scene, starts: &[SampleStart], seed: u64, max_bounces: u32, rr: bool, out: &mut [LaneResult]) {
    trace_samples_impl(scene, starts, seed, max_bounces, rr, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn trace_samples_avx2(scene: &Scene, starts: &[SampleStart], seed: u64, max_bounces: u32, rr: bool, out: &mut [LaneResult]) {
    trace_samples_impl(scene, starts, seed, max_bounces, rr, out)
}

#[inline(always)]
fn trace_samples_impl(scene: &Scene, starts: &[SampleStart], seed: u64, max_bounces: u32, rr: bool, out: &mut [LaneResult]) {
    let mut src = StartSource {
        starts,
        seed,
        origin: scene.camera.position,
        maker: scene.camera.ray_maker(),
        width: scene.camera.width as u64,
        made: 0,
        taken: 0,
        state: [0; LANES],
        inc: [0; LANES],
        dir: V3 { x: [0.0; LANES], y: [0.0; LANES], z: [0.0; LANES] },
        out,
    };
    drive(scene, &mut src, max_bounces, rr);
}

/// Where a lane's next path comes from and where its result goes (`drive`).
trait Source {
    /// The next path: its number (for `finish`), camera ray and stream.
    fn next(&mut self) -> Option<(usize, Ray, Pcg32)>;
    /// Path `slot` has ended with `result`; `rng` is its stream after the path.
    fn finish(&mut self, slot: usize, result: LaneResult, rng: Pcg32);
}

/// `trace_samples`'s paths: sample starts, made `LANES` at a time.
struct StartSource<'a> {
    starts: &'a [SampleStart],
    seed: u64,
    origin: Vec3,
    maker: RayMaker,
    width: u64,
    /// Starts made so far (`made - LANES..made` are in the arrays below) and handed out.
    made: usize,
    taken: usize,
    state: [u64; LANES],
    inc: [u64; LANES],
    dir: V3,
    out: &'a mut [LaneResult],
}

impl StartSource<'_> {
    /// Streams and camera rays of the next `LANES` starts, in one loop that vectorises: every
    /// lane, the missing ones past the end too (as pixel 0), so that it has no branch.
    #[inline(always)]
    fn make(&mut self) {
        let base = self.made;
        for i in 0..LANES {
            let st = self.starts.get(base + i).copied().unwrap_or_default();
            let pixel = st.py as u64 * self.width + st.px as u64;
            let mut rng = Pcg32::for_sample(self.seed, pixel, st.sample as u64);
            let film = Vec2::new(st.px as f32, st.py as f32) + rng.next_2d();
            (self.state[i], self.inc[i]) = rng.parts();
            self.dir.set(i, self.maker.ray(film).dir);
        }
        self.made += LANES;
    }
}

impl Source for StartSource<'_> {
    #[inline(always)]
    fn next(&mut self) -> Option<(usize, Ray, Pcg32)> {
        if self.taken == self.starts.len() {
            return None;
        }
        if self.taken == self.made {
            self.make();
        }
        let k = self.taken % LANES;
        let slot = self.taken;
        self.taken += 1;
        Some((slot, Ray::new(self.origin, self.dir.get(k)), Pcg32::from_parts(self.state[k], self.inc[k])))
    }

    #[inline(always)]
    fn finish(&mut self, slot: usize, result: LaneResult, _rng: Pcg32) {
        self.out[slot] = result;
    }
}

/// `trace_batch`'s paths: given rays and streams, the streams handed back at the end.
struct BatchSource<'a> {
    rays: &'a [Ray],
    rngs: &'a mut [Pcg32],
    taken: usize,
    out: [LaneResult; LANES],
}

impl Source for BatchSource<'_> {
    #[inline(always)]
    fn next(&mut self) -> Option<(usize, Ray, Pcg32)> {
        let slot = self.taken;
        let ray = *self.rays.get(slot)?;
        self.taken += 1;
        Some((slot, ray, self.rngs[slot].clone()))
    }

    #[inline(always)]
    fn finish(&mut self, slot: usize, result: LaneResult, rng: Pcg32) {
        self.out[slot] = result;
        self.rngs[slot] = rng;
    }
}

/// Traces `rays.len()` (at most `LANES`) camera rays with their random streams, as
/// `path::trace` would one by one with a radiance-only request.
pub fn trace_batch(scene: &Scene, rays: &[Ray], rngs: &mut [Pcg32], max_bounces: u32, russian_roulette: bool) -> [LaneResult; LANES] {
    trace_batch_variant(scene, rays, rngs, max_bounces, russian_roulette, 2)
}

/// `trace_batch` compiled for the SSE2 baseline (`variant` 0), AVX2 + FMA (1) or AVX-512 (2),
/// each falling back to the one below where the CPU lacks it: for A/B timing.
#[doc(hidden)]
pub fn trace_batch_variant(
    scene: &Scene,
    rays: &[Ray],
    rngs: &mut [Pcg32],
    max_bounces: u32,
    rr: bool,
    variant: u8,
) -> [LaneResult; LANES] {
    assert!(rays.len() <= LANES && rays.len() == rngs.len());
    #[cfg(target_arch = "x86_64")]
    {
        use std::is_x86_feature_detected as has;
        if variant >= 2 && has!("avx512f") && has!("avx512vl") && has!("avx2") && has!("fma") {
            // SAFETY: the CPU has the features (checked just above).
            return unsafe { trace_batch_avx512(scene, rays, rngs, max_bounces, rr) };
        }
        if variant >= 1 && has!("avx2") && has!("fma") {
            // SAFETY: the CPU has AVX2 and FMA (checked just above).
            return unsafe { trace_batch_avx2(scene, rays, rngs, max_bounces, rr) };
        }
    }
    trace_batch_impl(scene, rays, rngs, max_bounces, rr)
}

/// Stage 2 in 512-bit registers (and the BVH queries, which are calls, unchanged): 4–6 % more
/// paths per second than `trace_batch_avx2` on an AVX-512 Xeon (`examples/wave_ab.rs`,
/// docs/performance.md). The same operations, so the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
unsafe fn trace_batch_avx512(scene: &Scene, rays: &[Ray], rngs: &mut [Pcg32], max_bounces: u32, rr: bool) -> [LaneResult; LANES] {
    trace_batch_impl(scene, rays, rngs, max_bounces, rr)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn trace_batch_avx2(scene: &Scene, rays: &[Ray], rngs: &mut [Pcg32], max_bounces: u32, rr: bool) -> [LaneResult; LANES] {
    trace_batch_impl(scene, rays, rngs, max_bounces, rr)
}

#[inline(always)]
fn trace_batch_impl(scene: &Scene, rays: &[Ray], rngs: &mut [Pcg32], max_bounces: u32, rr: bool) -> [LaneResult; LANES] {
    let mut src = BatchSource { rays, rngs, taken: 0, out: [LaneResult::default(); LANES] };
    drive(scene, &mut src, max_bounces, rr);
    src.out
}

/// Per-lane bookkeeping of `drive`: which path a lane runs (`FREE`: none), at which bounce,
/// with which stream, and how many rays it has traced.
struct Lanes {
    slot: [usize; LANES],
    depth: [u32; LANES],
    rays: [u32; LANES],
    rngs: [Pcg32; LANES],
}

const FREE: usize = usize::MAX;

/// Runs every path of `src` through the stages, one bounce of every lane per round, until the
/// source is empty and every lane's path has ended; a lane whose path ends is refilled from
/// `src` before the next round.
#[inline(always)]
fn drive<S: Source>(scene: &Scene, src: &mut S, max_bounces: u32, rr: bool) {
    // SAFETY: every field is a plain array of f32, bool, Vec2 or Ray, for which all-zero is valid.
    let mut w: Wave = unsafe { std::mem::zeroed() };
    let mut lanes =
        Lanes { slot: [FREE; LANES], depth: [0; LANES], rays: [0; LANES], rngs: std::array::from_fn(|_| Pcg32::from_parts(0, 1)) };
    let mut exhausted = false;
    loop {
        if !exhausted {
            for i in 0..LANES {
                if lanes.slot[i] != FREE {
                    continue;
                }
                let Some((slot, r, rng)) = src.next() else {
                    exhausted = true;
                    break;
                };
                // A path's start state, as a fresh batch has it.
                lanes.slot[i] = slot;
                lanes.depth[i] = 0;
                lanes.rays[i] = 0;
                lanes.rngs[i] = rng;
                w.alive[i] = true;
                w.split_started[i] = false;
                w.prev_delta[i] = true;
                w.prev_pdf[i] = 0.0;
                w.org.set(i, r.origin);
                w.dir.set(i, r.dir);
                w.ray[i] = r;
                w.prev_p.set(i, r.origin);
                w.beta_d.set(i, Vec3::ZERO);
                w.beta_s.set(i, Vec3::ONE);
                w.l_d.set(i, Vec3::ZERO);
                w.l_s.set(i, Vec3::ZERO);
            }
        }
        if !w.alive.iter().any(|&a| a) {
            break;
        }
        stage_hit(scene, &mut w, &mut lanes, max_bounces);
        stage_shade(&mut w);
        stage_shadow(scene, &mut w, &mut lanes, rr);
        for i in 0..LANES {
            if lanes.slot[i] == FREE {
                continue;
            }
            if w.alive[i] {
                lanes.depth[i] += 1;
                continue;
            }
            let (l_d, l_s) = (w.l_d.get(i), w.l_s.get(i));
            let result = LaneResult { radiance: l_d + l_s, diffuse: l_d, rays: lanes.rays[i] };
            src.finish(lanes.slot[i], result, lanes.rngs[i].clone());
            lanes.slot[i] = FREE;
        }
    }
}

/// Stage 1, path by path: `path::trace` from the closest-hit query to the light selection.
#[inline(always)]
fn stage_hit(scene: &Scene, w: &mut Wave, lanes: &mut Lanes, max_bounces: u32) {
    // Where the mesh has a packet query, the live lanes' closest hits first, sixteen at a time.
    let packets = scene.accel.packets();
    let mut hits = BatchHits::default();
    if let Some(p) = packets {
        let live = lane_mask(&w.alive);
        p.intersect_batch(
            scene.accel.bvh(),
            [&w.org.x, &w.org.y, &w.org.z],
            [&w.dir.x, &w.dir.y, &w.dir.z],
            live,
            f32::INFINITY,
            &mut hits,
        );
    }
    for i in 0..LANES {
        w.has_light[i] = false;
        if !w.alive[i] {
            continue;
        }
        let depth = lanes.depth[i];
        let rng = &mut lanes.rngs[i];
        let ray = w.ray[i];
        let (beta_d, beta_s) = (w.beta_d.get(i), w.beta_s.get(i));
        lanes.rays[i] += 1;
        let hit = if packets.is_some() {
            (hits.prim[i] >= 0).then(|| Hit { t: hits.t[i], prim: hits.prim[i] as u32, bary: Vec2::new(hits.b1[i], hits.b2[i]) })
        } else {
            scene.accel.intersect(&ray, f32::INFINITY)
        };
        let Some(hit) = hit else {
            let le = scene.lights.env_radiance(ray.dir);
            if le.max_element() > 0.0 {
                let wgt = if depth == 0 || w.prev_delta[i] { 1.0 } else { power_heuristic(w.prev_pdf[i], scene.lights.env_pdf(ray.dir)) };
                w.l_d.set(i, w.l_d.get(i) + beta_d * le * wgt);
                w.l_s.set(i, w.l_s.get(i) + beta_s * le * wgt);
            }
            w.alive[i] = false;
            continue;
        };
        let si = scene.surface_inline(&ray, &hit);
        let material = &scene.materials[si.material as usize];
        let wo_world = -ray.dir;
        if material.is_emissive() {
            let le = material.emitted(si.ng, wo_world);
            if le.max_element() > 0.0 {
                let wgt = if depth == 0 || w.prev_delta[i] {
                    1.0
                } else {
                    power_heuristic(w.prev_pdf[i], scene.lights.pdf_triangle(si.prim, w.prev_p.get(i), si.p, si.ng))
                };
                w.l_d.set(i, w.l_d.get(i) + beta_d * le * wgt);
                w.l_s.set(i, w.l_s.get(i) + beta_s * le * wgt);
            }
        }
        if depth == max_bounces {
            w.alive[i] = false;
            continue;
        }
        let Bsdf::Lambert { albedo } = material.bsdf(si.uv, &scene.textures) else {
            unreachable!("wave::supported admits Lambertian materials only")
        };
        // `Bsdf::resolved`.
        let albedo = if is_finite3(albedo) { albedo.max(Vec3::ZERO) } else { Vec3::ZERO }.min(Vec3::ONE);
        if material.one_sided && wo_world.dot(si.ng) < 0.0 {
            w.alive[i] = false;
            continue;
        }
        w.p.set(i, si.p);
        w.extent[i] = si.extent;
        w.ng.set(i, si.ng);
        w.ns.set(i, si.ns);
        w.albedo.set(i, albedo);

        let u_select = rng.next_f32();
        w.u_light[i] = rng.next_2d();
        let _u_lobe = rng.next_f32();
        let u_bsdf = rng.next_2d();
        // `Bsdf::sample`'s input checks: the draws are always finite, so only `wo` is left (stage 2).
        w.u_bsdf[i] = u_bsdf;
        if let Some((light, pmf)) = scene.lights.select_triangle(u_select) {
            w.has_light[i] = true;
            w.lp0.set(i, light.vertices[0]);
            w.lp1.set(i, light.vertices[1]);
            w.lp2.set(i, light.vertices[2]);
            w.ln.set(i, light.normal);
            w.l_area[i] = light.area;
            w.l_two_sided[i] = light.two_sided;
            w.l_max[i] = light.max_emission;
            w.l_pmf[i] = pmf;
            w.l_emission.set(i, light.emission);
        }
    }
}

/// Stage 2, every lane at once and branch-free: the rest of the bounce but the shadow query.
/// Lanes that are not alive compute garbage that nothing reads.
#[inline(always)]
fn stage_shade(w: &mut Wave) {
    for i in 0..LANES {
        let alive = w.alive[i];
        let p = w.p.get(i);
        let ng0 = w.ng.get(i);
        let wo_world = -w.dir.get(i);
        let albedo = w.albedo.get(i);
        let (beta_d, beta_s) = (w.beta_d.get(i), w.beta_s.get(i));
        let first_diffuse = !w.split_started[i];

        // Lambert is reflection-only: both normals towards the viewer, as in `trace`.
        let flip = wo_world.dot(ng0) < 0.0;
        let ng = if flip { -ng0 } else { ng0 };
        let ns = if flip { -w.ns.get(i) } else { w.ns.get(i) };
        let ns = if wo_world.dot(ns) * wo_world.dot(ng) <= 0.0 { ng } else { ns };
        let frame = Frame::from_normal(ns);
        let wo = frame.to_local(wo_world);
        let wo_ok = is_finite3(wo);

        // Next-event estimation (`Lights::sample`, `Bsdf::eval_split`, `Bsdf::pdf`).
        let b = crate::sampling::square_to_triangle(w.u_light[i]);
        let (p0, p1, p2) = (w.lp0.get(i), w.lp1.get(i), w.lp2.get(i));
        let p_light = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
        let (conn, l_wi, l_dist, l_pdf) = connect_parts(p, p_light, w.ln.get(i), w.l_pmf[i], w.l_area[i], w.l_two_sided[i], w.l_max[i]);
        let wi = frame.to_local(l_wi);
        let same_side = (l_wi.dot(ng) > 0.0) == (wo_world.dot(ng) > 0.0);
        let eval_ok = wo_ok & is_finite3(wi) & (wo.z > 0.0) & (wi.z > 0.0);
        let f_d = if eval_ok { albedo * (wi.z * INV_PI) } else { Vec3::ZERO };
        let f_d = if is_finite3(f_d) { f_d.max(Vec3::ZERO) } else { Vec3::ZERO };
        let f_o = Vec3::ZERO;
        let (f_d, f_o) = if same_side { (f_d, f_o) } else { (Vec3::ZERO, Vec3::ZERO) };
        let f_total = f_d + f_o;
        let shadow = alive & w.has_light[i] & conn & (f_total.max_element() > 0.0);
        let origin = offset_ray_origin(p, ng0, l_wi, w.extent[i]);
        let tmax = if l_dist.is_finite() { (p + l_wi * l_dist - origin).length() * (1.0 - SHADOW_EPS) } else { f32::INFINITY };
        let pdf_b = if eval_ok { wi.z * INV_PI } else { 0.0 };
        let pdf_b = if pdf_b.is_finite() && pdf_b > 0.0 { pdf_b } else { 0.0 };
        let mis = power_heuristic(l_pdf, pdf_b);
        let c = w.l_emission.get(i) * (mis / l_pdf);
        let (add_d, add_s) = if first_diffuse {
            (beta_s * f_d * c, beta_s * f_o * c)
        } else {
            let fc = f_total * c;
            (beta_d * fc, beta_s * fc)
        };
        w.shadow[i] = shadow;
        w.sh_org.set(i, origin);
        w.sh_dir.set(i, l_wi);
        w.sh_tmax[i] = tmax;
        w.add_d.set(i, add_d);
        w.add_s.set(i, add_s);

        // BSDF sampling (`Bsdf::sample` → `lambert::sample`), then `trace`'s checks.
        let s_wi = crate::sampling::square_to_cosine_hemisphere(w.u_bsdf[i]);
        let s_pdf = s_wi.z * INV_PI;
        let s_weight = albedo;
        let s_fcos = albedo * s_pdf;
        let sampled = wo_ok
            & (wo.z > 0.0)
            & (s_wi.z > 0.0)
            & (s_pdf > 0.0)
            & s_pdf.is_finite()
            & is_finite3(s_weight)
            & is_finite3(s_fcos)
            & is_finite3(s_wi)
            & (s_weight.min_element() >= 0.0)
            & (s_fcos.min_element() >= 0.0)
            & (s_wi != Vec3::ZERO);
        let wi_world = frame.to_world(s_wi);
        let reflected = wi_world.dot(ng) > 0.0;
        let wo_above = wo_world.dot(ng) > 0.0;
        let ok = sampled & (s_weight.max_element() > 0.0) & (reflected == wo_above);
        let (nbeta_d, nbeta_s) = if first_diffuse {
            // `Bsdf::eval_split(wo, s.wi)` of the sampled (diffuse) lobe.
            let e_ok = is_finite3(s_wi) & (wo.z > 0.0) & (s_wi.z > 0.0);
            let e_d = if e_ok { albedo * (s_wi.z * INV_PI) } else { Vec3::ZERO };
            let e_d = if is_finite3(e_d) { e_d.max(Vec3::ZERO) } else { Vec3::ZERO };
            (beta_s * e_d / s_pdf, beta_s * (Vec3::ZERO / s_pdf))
        } else {
            (beta_d * s_weight, beta_s * s_weight)
        };
        let ok = ok & is_finite3(nbeta_d + nbeta_s);
        let cont = alive & ok;
        w.cont[i] = cont;
        // Selects rather than a branch, so that the loop stays vectorisable.
        let next_org = offset_ray_origin(p, ng0, wi_world, w.extent[i]);
        w.beta_d.set(i, if cont { nbeta_d } else { beta_d });
        w.beta_s.set(i, if cont { nbeta_s } else { beta_s });
        w.split_started[i] |= cont;
        w.prev_pdf[i] = if cont { s_pdf } else { w.prev_pdf[i] };
        w.prev_delta[i] &= !cont;
        w.prev_p.set(i, if cont { p } else { w.prev_p.get(i) });
        w.org.set(i, if cont { next_org } else { w.org.get(i) });
        w.dir.set(i, if cont { wi_world } else { -wo_world });
    }
}

/// Stage 3, path by path: shadow rays, their contributions, Russian roulette.
#[inline(always)]
fn stage_shadow(scene: &Scene, w: &mut Wave, lanes: &mut Lanes, rr: bool) {
    // Where the mesh has a packet query, the shadow rays sixteen at a time.
    let packets = scene.accel.packets().filter(|p| p.shadows());
    let mut occluded = 0u32;
    if let Some(p) = packets {
        let live = lane_mask(&w.shadow);
        occluded = p.occluded_batch(
            scene.accel.bvh(),
            [&w.sh_org.x, &w.sh_org.y, &w.sh_org.z],
            [&w.sh_dir.x, &w.sh_dir.y, &w.sh_dir.z],
            &w.sh_tmax,
            live,
        );
    } else {
        w.sh_ray[0] = Ray::new(w.sh_org.get(0), w.sh_dir.get(0));
    }
    for i in 0..LANES {
        // The next lane's shadow ray, one query ahead (see `Wave::ray`).
        if packets.is_none() && i + 1 < LANES {
            w.sh_ray[i + 1] = Ray::new(w.sh_org.get(i + 1), w.sh_dir.get(i + 1));
        }
        if w.shadow[i] {
            lanes.rays[i] += 1;
            let blocked = if packets.is_some() { occluded & (1 << i) != 0 } else { scene.accel.occluded(&w.sh_ray[i], w.sh_tmax[i]) };
            if !blocked {
                w.l_d.set(i, w.l_d.get(i) + w.add_d.get(i));
                w.l_s.set(i, w.l_s.get(i) + w.add_s.get(i));
            }
        }
        w.ray[i] = Ray::new(w.org.get(i), w.dir.get(i));
        if !w.alive[i] {
            continue;
        }
        if !w.cont[i] {
            w.alive[i] = false;
            continue;
        }
        if rr && lanes.depth[i] >= 3 {
            let (bd, bs) = (w.beta_d.get(i), w.beta_s.get(i));
            let q = (1.0 - (bd + bs).max_element()).clamp(0.05, 0.95);
            if lanes.rngs[i].next_f32() < q {
                w.alive[i] = false;
                continue;
            }
            let k = Vec3::splat(1.0 / (1.0 - q));
            w.beta_d.set(i, bd * k);
            w.beta_s.set(i, bs * k);
        }
    }
}

/// Bit i set where lane i's flag is.
#[inline(always)]
fn lane_mask(flags: &B) -> u32 {
    (0..LANES).fold(0u32, |m, i| m | ((flags[i] as u32) << i))
}

#[inline(always)]
fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let a = pdf_a * pdf_a;
    let b = pdf_b * pdf_b;
    let r = a / (a + b);
    let r = if !a.is_finite() { 1.0 } else { r };
    let r = if !b.is_finite() { 0.0 } else { r };
    if a == 0.0 {
        0.0
    } else {
        r
    }
}

/// `geometry::offset_ray_origin` with one change that keeps its results: the integer step
/// count `(256·n_i) as i32` is converted without saturation, on values made to lie in i32's
/// range first (|n_i| ≤ 1 for the unit normals here, so nothing is ever replaced). Vectorised,
/// the saturating conversion costs a compare-and-blend sequence per component (3% of the
/// render); this is one `cvttps2dq`.
#[inline(always)]
fn offset_ray_origin(p: Vec3, ng: Vec3, dir: Vec3, extent: f32) -> Vec3 {
    const INT_SCALE: f32 = 256.0;
    const ORIGIN_FRACTION: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const MIN_MAGNITUDE: f32 = 1e-8;
    let n = if ng.dot(dir) < 0.0 { -ng } else { ng };
    let mag = p.abs().max_element().max(extent).max(MIN_MAGNITUDE);
    let near_zero = mag * ORIGIN_FRACTION;
    let float_step = FLOAT_SCALE * mag;
    let component = |pi: f32, ni: f32| {
        let by_float = pi + float_step * ni;
        let scaled = INT_SCALE * ni;
        // In range for the conversion (NaN included: it fails the comparison).
        let scaled = if scaled.abs() < 1.0e9 { scaled } else { 0.0 };
        // SAFETY: `scaled` is finite and |scaled| < 1e9 < 2^31.
        let steps: i32 = unsafe { scaled.to_int_unchecked() };
        let steps = if pi < 0.0 { steps.wrapping_neg() } else { steps };
        let stepped = f32::from_bits((pi.to_bits() as i32).wrapping_add(steps) as u32);
        let by_ulps = if stepped.is_finite() { stepped } else { pi };
        if pi.abs() < near_zero {
            by_float
        } else {
            by_ulps
        }
    };
    let out = Vec3::new(component(p.x, n.x), component(p.y, n.y), component(p.z, n.z));
    if !p.is_finite() || !ng.is_finite() {
        p
    } else {
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::film::BufferRequest;
    use crate::integrator::{path, render, RenderOptions};
    use std::path::Path;

    fn load(rel: &str) -> Scene {
        Scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)).unwrap()
    }

    /// Every lane of a batch equals `path::trace` of the same camera ray and stream, bit for bit.
    fn check_against_trace(scene: &Scene, rr: bool) {
        assert!(supported(scene));
        let cam = &scene.camera;
        let (w, h) = (cam.width, cam.height);
        let mut checked = 0;
        for k in 0..40u64 {
            // Batches of every length from 1 to LANES.
            let len = 1 + (k as usize % LANES);
            let mut rays = Vec::new();
            let mut rngs = Vec::new();
            let mut reference = Vec::new();
            for j in 0..len as u64 {
                let pixel = (k * 7919 + j * 104_729) % (w as u64 * h as u64);
                let mut rng = Pcg32::for_sample(3, pixel, j);
                let film = Vec2::new((pixel % w as u64) as f32, (pixel / w as u64) as f32) + rng.next_2d();
                let ray = cam.ray(film);
                let mut r2 = rng.clone();
                reference.push(path::trace(scene, ray, &mut r2, 5, rr, BufferRequest::RADIANCE_ONLY));
                rays.push(ray);
                rngs.push(rng);
            }
            // The dispatched code and each instruction set's (SSE2, AVX2 + FMA, AVX-512; a
            // variant the CPU lacks runs the next one down).
            let mut results = vec![trace_batch(scene, &rays, &mut rngs.clone(), 5, rr)];
            for variant in 0..=2 {
                results.push(trace_batch_variant(scene, &rays, &mut rngs.clone(), 5, rr, variant));
            }
            for (g, r) in results.iter().flat_map(|res| &res[..len]).zip(reference.iter().cycle()) {
                assert_eq!(g.radiance.to_array().map(f32::to_bits), r.radiance.to_array().map(f32::to_bits));
                assert_eq!(g.diffuse.to_array().map(f32::to_bits), r.diffuse.to_array().map(f32::to_bits));
                assert_eq!(g.rays, r.rays);
                checked += 1;
            }
        }
        assert!(checked > 1200);
    }

    #[test]
    fn batches_equal_trace_bit_for_bit() {
        for scene in ["scenes/cornell-box/scene.toml", "scenes/cornell-bunny/scene.toml"] {
            let s = load(scene);
            check_against_trace(&s, false);
            check_against_trace(&s, true);
        }
    }

    /// Samples streamed through the lanes (`trace_samples`: started in the batch, a lane
    /// refilled as soon as its path ends) trace what the same samples started one by one
    /// (`Pcg32::for_sample`, `Camera::ray`) trace through `path::trace`, bit for bit, for
    /// streams shorter than, as long as and longer than a batch, with and without Russian
    /// roulette (which ends paths at different bounces, so lanes are refilled mid-stream).
    #[test]
    fn streamed_samples_equal_samples_traced_alone() {
        for scene in ["scenes/cornell-box/scene.toml", "scenes/cornell-bunny/scene.toml"] {
            let s = load(scene);
            let cam = &s.camera;
            for rr in [false, true] {
                for len in [1, 2, 7, LANES - 1, LANES, LANES + 1, 3 * LANES + 5, 257] {
                    let starts: Vec<SampleStart> = (0..len as u32)
                        .map(|j| SampleStart { px: (j * 37 + len as u32) % cam.width, py: (j * 11) % cam.height, sample: j % 3 + 1000 })
                        .collect();
                    let mut got = vec![LaneResult::default(); len];
                    trace_samples(&s, &starts, 9, 5, rr, &mut got);
                    for (st, g) in starts.iter().zip(&got) {
                        let mut rng = Pcg32::for_sample(9, st.py as u64 * cam.width as u64 + st.px as u64, st.sample as u64);
                        let ray = cam.ray(Vec2::new(st.px as f32, st.py as f32) + rng.next_2d());
                        let r = path::trace(&s, ray, &mut rng, 5, rr, BufferRequest::RADIANCE_ONLY);
                        assert_eq!(
                            g.radiance.to_array().map(f32::to_bits),
                            r.radiance.to_array().map(f32::to_bits),
                            "{scene} len {len} rr {rr}"
                        );
                        assert_eq!(g.diffuse.to_array().map(f32::to_bits), r.diffuse.to_array().map(f32::to_bits));
                        assert_eq!(g.rays, r.rays);
                    }
                }
            }
        }
    }

    /// A render through the wavefront (radiance and split only) and one through `path::trace`
    /// (G-buffers requested) give the same radiance and diffuse buffers.
    #[test]
    fn wavefront_render_equals_scalar_render() {
        let s = load("scenes/cornell-box/scene.toml");
        let mut opts = RenderOptions::from_scene(&s, BufferRequest { split: true, gbuffers: false, descriptors: false });
        opts.spp = 5;
        opts.crop = Some((40, 30, 37, 21));
        let (a, _) = render(&s, &opts, &|_| {}).unwrap();
        opts.request.gbuffers = true;
        let (b, _) = render(&s, &opts, &|_| {}).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.radiance.mean), bits(&b.radiance.mean));
        assert_eq!(bits(&a.radiance.var), bits(&b.radiance.var));
        let (da, db) = (a.diffuse.unwrap(), b.diffuse.unwrap());
        assert_eq!(bits(&da.mean), bits(&db.mean));
    }
}
