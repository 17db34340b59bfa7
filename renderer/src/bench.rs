//! Ray-tracing benchmark: BVH build time and closest-hit rays/s on camera rays and on random
//! rays, next to Embree's rays/s on the very same rays: through the embreex Python binding and
//! `tools/embree/trace.py` in another process, and through the same library loaded into this one
//! (`crate::embree`), in its fast and its robust mode. Also the plumbing the Embree cross-check
//! test uses. The venv that holds the binding is built outside this library, by the
//! `tools-venv` crate (tools/venv/).

use crate::geometry::{Accel, Hit, Mesh};
use crate::math::Ray;
use crate::rng::Pcg32;
use crate::{Error, Result};
use glam::Vec3;
use rayon::prelude::*;
use std::fmt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// A set of rays in structure-of-arrays form (the layout the Embree helper reads).
#[derive(Clone, Debug, Default)]
pub struct RayBatch {
    pub origins: Vec<Vec3>,
    pub dirs: Vec<Vec3>,
    pub tmax: Vec<f32>,
}

impl RayBatch {
    pub fn len(&self) -> usize {
        self.origins.len()
    }
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }
    pub fn push(&mut self, o: Vec3, d: Vec3, tmax: f32) {
        self.origins.push(o);
        self.dirs.push(d);
        self.tmax.push(tmax);
    }
    pub fn ray(&self, i: usize) -> Ray {
        Ray::new(self.origins[i], self.dirs[i])
    }

    /// Node visits and leaf-block tests per ray of `accel`'s closest-hit queries on this batch.
    pub fn traversal_per_ray(&self, accel: &Accel) -> (f64, f64) {
        let mut c = crate::geometry::bvh::TraversalCounts::default();
        for i in 0..self.len() {
            accel.intersect_counted(&self.ray(i), self.tmax[i], &mut c);
        }
        let rays = c.rays.max(1) as f64;
        (c.nodes as f64 / rays, c.blocks as f64 / rays)
    }

    /// `n` primary rays of a pinhole camera looking at the mesh's bounding-box centre from a
    /// fixed oblique direction (40° vertical field of view, square film, one jittered ray per
    /// film position). A quarter of them are instead aimed from the same eye exactly at points
    /// on edges shared by two triangles (quad diagonals included), where a non-watertight test
    /// lets rays through. Only edges that are not silhouettes as seen from the eye are used: a
    /// ray grazing a silhouette edge may hit or miss, and both answers are right.
    pub fn camera(mesh: &Mesh, n: usize, seed: u64) -> RayBatch {
        let (lo, hi) = mesh.bounds();
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-20);
        let eye = centre + Vec3::new(0.45, 0.35, 1.0).normalize() * (radius * 2.6);
        let forward = (centre - eye).normalize();
        let right = forward.cross(Vec3::Y).normalize_or(Vec3::X);
        let up = right.cross(forward);
        let tan_half = (20.0f32).to_radians().tan();
        let side = ((n as f64 * 0.75).sqrt().ceil() as usize).max(1);
        let mut rng = Pcg32::new(seed, 11);
        let mut batch = RayBatch::default();
        let n_film = n - n / 4;
        for i in 0..n_film {
            let (x, y) = ((i % side) as f32 + rng.next_f32(), ((i / side) % side) as f32 + rng.next_f32());
            let sx = (2.0 * x / side as f32 - 1.0) * tan_half;
            let sy = (1.0 - 2.0 * y / side as f32) * tan_half;
            batch.push(eye, (forward + right * sx + up * sy).normalize(), f32::INFINITY);
        }
        let edges = interior_edges(mesh, eye);
        for _ in n_film..n {
            let target = if edges.is_empty() {
                centre
            } else {
                let (a, b) = edges[rng.below(edges.len() as u32) as usize];
                if rng.below(2) == 0 {
                    a + (b - a) * 0.5
                } else {
                    a + (b - a) * rng.next_f32()
                }
            };
            let d = (target - eye).normalize_or(forward);
            batch.push(eye, d, f32::INFINITY);
        }
        batch
    }

    /// `n` rays from a uniformly random point of the (slightly enlarged) bounding box towards
    /// another, unbounded beyond it: incoherent rays like those of later path bounces.
    pub fn random_in_bounds(mesh: &Mesh, n: usize, seed: u64) -> RayBatch {
        let (lo, hi) = mesh.bounds();
        let pad = (hi - lo) * 0.05;
        let (lo, ext) = (lo - pad, (hi - lo) + pad * 2.0);
        let mut rng = Pcg32::new(seed, 12);
        let mut batch = RayBatch::default();
        while batch.len() < n {
            let a = lo + ext * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let b = lo + ext * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
            let d = (b - a).normalize_or_zero();
            if d != Vec3::ZERO {
                batch.push(a, d, f32::INFINITY);
            }
        }
        batch
    }
}

/// Edges (as vertex positions) shared by exactly two non-degenerate triangles whose third
/// vertices lie on opposite sides of the plane through the eye and the edge, so a ray from the
/// eye through the edge must hit one of the two triangles. Vertices are matched by position,
/// since OBJ loaders duplicate them per normal/uv.
fn interior_edges(mesh: &Mesh, eye: Vec3) -> Vec<(Vec3, Vec3)> {
    use std::collections::HashMap;
    let key = |p: Vec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    // Edge (its two vertices' keys) → (edge start, edge end, the third vertex) per triangle.
    type Edges = HashMap<([u32; 3], [u32; 3]), Vec<(Vec3, Vec3, Vec3)>>;
    let mut map = Edges::new();
    for i in 0..mesh.triangles.len() {
        if !(mesh.area(i) > 0.0) {
            continue;
        }
        let p = mesh.triangle(i);
        for k in 0..3 {
            let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let (a, b) = if key(a) < key(b) { (a, b) } else { (b, a) };
            map.entry((key(a), key(b))).or_default().push((a, b, c));
        }
    }
    let mut edges: Vec<(Vec3, Vec3)> = map
        .into_values()
        .filter(|v| v.len() == 2)
        .filter_map(|v| {
            let (a, b, c1) = v[0];
            let c2 = v[1].2;
            let m = ((a - eye).as_dvec3()).cross((b - eye).as_dvec3());
            let s1 = m.dot((c1 - eye).as_dvec3());
            let s2 = m.dot((c2 - eye).as_dvec3());
            (s1 * s2 < 0.0).then_some((a, b))
        })
        .collect();
    // HashMap order is random per process: sort so the batch is reproducible.
    edges.sort_by_key(|e| (key(e.0), key(e.1)));
    edges
}

/// Closest hits of every ray of `batch`, on `threads` threads (0 = rayon's global pool).
pub fn trace(accel: &Accel, batch: &RayBatch, threads: usize) -> Vec<Option<Hit>> {
    let run = || (0..batch.len()).into_par_iter().with_min_len(1024).map(|i| accel.intersect(&batch.ray(i), batch.tmax[i])).collect();
    if threads == 0 {
        run()
    } else {
        match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
            Ok(pool) => pool.install(run),
            Err(_) => run(),
        }
    }
}

/// Closest hits of every ray of `batch` on the calling thread, one `Accel::intersect` after
/// another: the single-thread figure, measured as Embree's is (embreex loops `rtcIntersect1`
/// over the rays), without a thread pool's splitting and collecting, which cost 5–9 % of the
/// Cornell box's rate on one thread (docs/performance.md).
pub fn trace_one_at_a_time(accel: &Accel, batch: &RayBatch) -> Vec<Option<Hit>> {
    (0..batch.len()).map(|i| accel.intersect(&batch.ray(i), batch.tmax[i])).collect()
}

/// Embree's answer for each ray: primitive index and t, and its query / build times.
pub struct EmbreeResult {
    pub hits: Vec<Option<(u32, f32)>>,
    pub query_seconds: f64,
    pub build_seconds: f64,
    /// CPU time of the (single) querying thread.
    pub query_cpu_seconds: f64,
}

/// CPU time the calling thread has run, in seconds (`CLOCK_THREAD_CPUTIME_ID`, to the
/// nanosecond); `None` where unavailable.
///
/// Not `/proc/thread-self/schedstat`, which this used before 2026-12-02: for a running thread
/// its figure is only brought up to date at scheduler ticks (4 ms apart under HZ=250), so a
/// 20–50 ms benchmark run was timed to ±10–20 %. The clock updates the thread's runtime when read.
pub fn thread_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid timespec for the call to write.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } != 0 {
            return None;
        }
        Some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(unix))]
    None
}

/// Location of the Python helper, relative to the workspace root.
pub fn embree_script(workspace: &Path) -> PathBuf {
    workspace.join("tools/embree/trace.py")
}

/// Traces `batch` against `mesh` with Embree via `script`, exchanging binary files in `work_dir`.
/// Primitive ids are indices into `mesh.triangles`. `robust` sets Embree's robust scene flag
/// (watertight, slower).
pub fn embree_trace(python: &Path, script: &Path, work_dir: &Path, mesh: &Mesh, batch: &RayBatch, robust: bool) -> Result<EmbreeResult> {
    std::fs::create_dir_all(work_dir).map_err(|e| Error::io(work_dir, e))?;
    let tag = format!("{}-{}", std::process::id(), batch.len());
    let input = work_dir.join(format!("rays-{tag}.bin"));
    let output = work_dir.join(format!("hits-{tag}.bin"));
    let n_tris = mesh.triangles.len();
    let mut buf: Vec<u8> = Vec::with_capacity(24 + n_tris * 36 + batch.len() * 28);
    buf.extend_from_slice(b"PGRT0001");
    buf.extend_from_slice(&(n_tris as u64).to_le_bytes());
    buf.extend_from_slice(&(batch.len() as u64).to_le_bytes());
    let mut put = |v: f32| buf.extend_from_slice(&v.to_le_bytes());
    for i in 0..n_tris {
        for p in mesh.triangle(i) {
            // Embree rejects non-finite vertices; such triangles can never be hit anyway.
            let p = if p.is_finite() { p } else { Vec3::ZERO };
            put(p.x);
            put(p.y);
            put(p.z);
        }
    }
    for v in batch.origins.iter().chain(&batch.dirs) {
        put(v.x);
        put(v.y);
        put(v.z);
    }
    for &t in &batch.tmax {
        // Embree wants a finite tfar for a ray segment; 1e37 is its "unbounded" idiom too.
        put(t.min(1e37));
    }
    std::fs::write(&input, &buf).map_err(|e| Error::io(&input, e))?;
    let out = Command::new(python)
        .arg(script)
        .arg(&input)
        .arg(&output)
        .arg(if robust { "robust" } else { "fast" })
        .output()
        .map_err(|e| Error::io(script, e))?;
    let _ = std::fs::remove_file(&input);
    if !out.status.success() {
        return Err(Error::Invalid(format!("{} failed: {}", script.display(), String::from_utf8_lossy(&out.stderr))));
    }
    let data = std::fs::read(&output).map_err(|e| Error::io(&output, e))?;
    let _ = std::fs::remove_file(&output);
    let n = batch.len();
    let bad = |m: &str| Error::scene(&output, "contents", m.to_string());
    if data.len() != 40 + n * 8 || &data[..8] != b"PGRH0002" {
        return Err(bad("unexpected size or magic"));
    }
    let u64_at = |o: usize| u64::from_le_bytes(data[o..o + 8].try_into().unwrap());
    if u64_at(8) as usize != n {
        return Err(bad("ray count differs"));
    }
    let query_seconds = f64::from_bits(u64_at(16));
    let build_seconds = f64::from_bits(u64_at(24));
    let query_cpu_seconds = f64::from_bits(u64_at(32));
    let hits = (0..n)
        .map(|i| {
            let o = 40 + i * 4;
            let prim = i32::from_le_bytes(data[o..o + 4].try_into().unwrap());
            let o = 40 + n * 4 + i * 4;
            let t = f32::from_le_bytes(data[o..o + 4].try_into().unwrap());
            (prim >= 0).then_some((prim as u32, t))
        })
        .collect();
    Ok(EmbreeResult { hits, query_seconds, build_seconds, query_cpu_seconds })
}

/// Figures for one ray set.
#[derive(Clone, Debug)]
pub struct RaySetReport {
    pub name: String,
    pub rays: usize,
    pub hit_fraction: f64,
    /// Our closest-hit rays/s on `threads` threads (per wall-clock second) and on one thread
    /// (per CPU second of that thread, so that other processes taking the CPU on a shared
    /// machine do not count; wall clock where thread CPU time is unavailable).
    pub ours_mt: f64,
    pub ours_1t: f64,
    /// Embree's single-thread rays/s (embreex loops rtcIntersect1 on one thread), per CPU second
    /// of that thread like `ours_1t`.
    pub embree_1t: Option<f64>,
    /// Median over the repetitions of ours (1t) / Embree (1t), each pair run back to back: on a
    /// machine whose neighbours move both rates by up to 45 % between runs (the KVM guest of
    /// 2026-11-29, docs/performance.md), a steadier figure than the ratio of the two bests,
    /// which may come from different moments.
    pub pair_ratio_median: Option<f64>,
    /// Lowest and highest of those ratios: how far the machine moved them.
    pub pair_ratio_range: Option<(f64, f64)>,
    /// Embree called in this process (`EmbreeSetup::library`), in its fast mode and in its
    /// robust (watertight, as our BVH is) mode; empty without the library.
    pub in_process: Vec<InProcessFigures>,
}

/// Embree in this process, in one mode, on one ray set.
#[derive(Clone, Debug)]
pub struct InProcessFigures {
    pub robust: bool,
    /// Best single-thread rays/s (a loop of `rtcIntersect1`, like ours; per CPU second).
    pub best_1t: f64,
    /// Median over the repetitions of ours (1t) / it (1t), measured back to back.
    pub pair_ratio_median: f64,
    /// Lowest and highest of those ratios.
    pub pair_ratio_range: (f64, f64),
    /// Fraction of rays on which it and we disagree about hit or miss: a check of the binding
    /// (the fast mode is not watertight, so a few rays through edges may differ).
    pub hit_disagreement: f64,
    /// Best scene build (wall clock, Embree's TBB threads).
    pub build_seconds: f64,
}

#[derive(Clone, Debug)]
pub struct RayBenchReport {
    pub triangles: usize,
    pub threads: usize,
    pub build_seconds: f64,
    pub bvh_nodes: usize,
    pub embree_build_seconds: Option<f64>,
    pub sets: Vec<RaySetReport>,
}

/// Where Embree lives, if it should be run.
pub struct EmbreeSetup {
    pub python: PathBuf,
    pub script: PathBuf,
    pub work_dir: PathBuf,
    /// Embree's robust (watertight) mode instead of its fastest one.
    pub robust: bool,
    /// The same Embree library loaded into this process (`crate::embree`), traced in a loop
    /// like ours, in its fast and its robust mode, right after our single-thread run: the
    /// tighter comparison.
    pub library: Option<crate::embree::Embree>,
}

/// Builds the BVH of `mesh` (timed; the best of three builds), then traces each ray set with
/// `threads` threads, with one, and with Embree if `embree` is given (in this process right
/// after our single-thread run, fast then robust mode, where `EmbreeSetup::library` is loaded;
/// then through embreex), alternating run by run (best of `repeats` runs each; our BVH is built
/// anew, untimed, for every run after the first, and so is each in-process Embree scene, whose
/// build is timed apart). Rays/s count closest-hit queries only; see `RaySetReport` for the clocks.
pub fn ray_bench(
    mesh: &Mesh,
    sets: &[(&str, &RayBatch)],
    threads: usize,
    repeats: usize,
    embree: Option<&EmbreeSetup>,
) -> Result<RayBenchReport> {
    let threads = threads.max(1);
    let pool = |n: usize| rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| Error::Invalid(e.to_string()));
    let pool_mt = pool(threads)?;
    let pool_1t = pool(1)?;
    let mut build_seconds = f64::INFINITY;
    let mut accel = None;
    for _ in 0..3 {
        let t0 = Instant::now();
        let a = pool_mt.install(|| Accel::build(mesh));
        build_seconds = build_seconds.min(t0.elapsed().as_secs_f64());
        accel = Some(a);
    }
    let mut accel = accel.expect("built three times");
    let bvh_nodes = accel.node_count();
    // Rays/s and hits; with `cpu`, on one thread (a loop on the pool's one thread) and per CPU
    // second of that thread, else on the pool's threads and per wall-clock second.
    let rate = |accel: &Accel, p: &rayon::ThreadPool, batch: &RayBatch, cpu: bool| {
        let (s, r) = p.install(|| {
            if cpu {
                seconds_on_this_thread(|| trace_one_at_a_time(accel, batch))
            } else {
                let t0 = Instant::now();
                let r = trace(accel, batch, 0);
                (t0.elapsed().as_secs_f64(), r)
            }
        });
        (batch.len() as f64 / s, r)
    };
    let mut reports = Vec::new();
    let mut embree_build = None;
    for (name, batch) in sets {
        // Ours and Embree alternate, run by run, so that both see the same share of whatever
        // else loads the machine; the best run of each is reported.
        let (mut ours_mt, mut ours_1t, mut hits) = (0.0f64, 0.0f64, 0);
        let mut embree_1t: Option<f64> = None;
        let mut pair_ratios = Vec::new();
        // Embree in this process: fast mode, robust mode.
        let mut lib = [InProcessRuns::new(false), InProcessRuns::new(true)];
        for rep in 0..repeats.max(1) {
            if rep > 0 {
                // A BVH of its own each time, as Embree builds its scene anew in each run (a
                // new process): four copies of one BVH traced 10-15 % apart in medians in one
                // process on the KVM guest of 2026-11-29 (docs/performance.md), and the best
                // of the runs should not be one placement of ours against several of Embree's.
                accel = pool_mt.install(|| Accel::build(mesh));
            }
            let (r, h) = rate(&accel, &pool_mt, batch, false);
            ours_mt = ours_mt.max(r);
            hits = h.iter().filter(|h| h.is_some()).count();
            // Embree in this process: a scene of its own each run, as our BVH is rebuilt, built
            // before either is traced, and traced on the thread ours is; who goes first
            // alternates from run to run, so that neither always finds the caches as the
            // other left them.
            let embree_lib = embree.and_then(|e| e.library.as_ref());
            let mut scenes = Vec::new();
            if let Some(embree_lib) = embree_lib {
                for runs in &mut lib {
                    let t0 = Instant::now();
                    let scene = embree_lib.scene(mesh, runs.robust).map_err(|e| Error::Invalid(e.to_string()))?;
                    runs.build = runs.build.min(t0.elapsed().as_secs_f64());
                    scenes.push(scene);
                }
            }
            let theirs_first = rep % 2 == 1;
            let trace_theirs = |scenes: &[crate::embree::EmbreeScene]| {
                scenes
                    .iter()
                    .map(|scene| {
                        pool_1t.install(|| {
                            seconds_on_this_thread(|| {
                                (0..batch.len())
                                    .map(|i| scene.intersect(batch.origins[i], batch.dirs[i], batch.tmax[i]))
                                    .collect::<Vec<_>>()
                            })
                        })
                    })
                    .collect::<Vec<_>>()
            };
            let early = if theirs_first { trace_theirs(&scenes) } else { Vec::new() };
            let (one, ours_hits) = rate(&accel, &pool_1t, batch, true);
            ours_1t = ours_1t.max(one);
            let theirs = if theirs_first { early } else { trace_theirs(&scenes) };
            for (runs, (secs, theirs)) in lib.iter_mut().zip(theirs) {
                let their_rate = batch.len() as f64 / secs;
                runs.ratios.push(one / their_rate);
                runs.best = runs.best.max(their_rate);
                let differ = ours_hits.iter().zip(&theirs).filter(|(a, b)| a.is_some() != b.is_some()).count();
                runs.disagreement = differ as f64 / batch.len().max(1) as f64;
            }
            if let Some(e) = embree {
                let r = embree_trace(&e.python, &e.script, &e.work_dir, mesh, batch, e.robust)?;
                let secs = if r.query_cpu_seconds > 0.0 { r.query_cpu_seconds } else { r.query_seconds };
                let e_rate = batch.len() as f64 / secs;
                pair_ratios.push(one / e_rate);
                embree_1t = Some(embree_1t.unwrap_or(0.0).max(e_rate));
                embree_build = Some(embree_build.map_or(r.build_seconds, |b: f64| b.min(r.build_seconds)));
            }
        }
        reports.push(RaySetReport {
            name: name.to_string(),
            rays: batch.len(),
            hit_fraction: hits as f64 / batch.len().max(1) as f64,
            ours_mt,
            ours_1t,
            embree_1t,
            pair_ratio_median: median(&pair_ratios),
            pair_ratio_range: range(&pair_ratios),
            in_process: lib.iter().filter_map(InProcessRuns::figures).collect(),
        });
    }
    Ok(RayBenchReport {
        triangles: mesh.triangles.len(),
        threads,
        build_seconds,
        bvh_nodes,
        embree_build_seconds: embree_build,
        sets: reports,
    })
}

/// What the runs of Embree in this process in one mode gave so far.
struct InProcessRuns {
    robust: bool,
    best: f64,
    ratios: Vec<f64>,
    disagreement: f64,
    build: f64,
}

impl InProcessRuns {
    fn new(robust: bool) -> InProcessRuns {
        InProcessRuns { robust, best: 0.0, ratios: Vec::new(), disagreement: 0.0, build: f64::INFINITY }
    }

    /// `None` where no run was made.
    fn figures(&self) -> Option<InProcessFigures> {
        Some(InProcessFigures {
            robust: self.robust,
            best_1t: self.best,
            pair_ratio_median: median(&self.ratios)?,
            pair_ratio_range: range(&self.ratios)?,
            hit_disagreement: self.disagreement,
            build_seconds: self.build,
        })
    }
}

/// Runs `f` on the calling thread and returns the seconds it took with its result: CPU seconds
/// of this thread where Linux tells them (other processes taking the CPU do not count), else
/// wall clock.
fn seconds_on_this_thread<R>(f: impl FnOnce() -> R) -> (f64, R) {
    let (t0, c0) = (Instant::now(), thread_cpu_seconds());
    let r = f();
    let wall = t0.elapsed().as_secs_f64();
    match (c0, thread_cpu_seconds()) {
        (Some(a), Some(b)) if b > a => (b - a, r),
        _ => (wall, r),
    }
}

/// Lowest and highest value; `None` for no values.
pub fn range(v: &[f64]) -> Option<(f64, f64)> {
    let lo = v.iter().copied().min_by(f64::total_cmp)?;
    let hi = v.iter().copied().max_by(f64::total_cmp)?;
    Some((lo, hi))
}

/// Median (mean of the two middle values for an even count); `None` for no values.
pub fn median(v: &[f64]) -> Option<f64> {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    (n > 0).then(|| if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

impl fmt::Display for RayBenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} triangles: BVH build {:.1} ms on {} threads ({} BVH8 nodes)",
            self.triangles,
            self.build_seconds * 1e3,
            self.threads,
            self.bvh_nodes
        )?;
        if let Some(b) = self.embree_build_seconds {
            writeln!(f, "  Embree scene build {:.1} ms (embreex default: TBB threads)", b * 1e3)?;
        }
        for p in self.sets.first().map_or(&[][..], |s| &s.in_process[..]) {
            writeln!(
                f,
                "  Embree scene build in this process, {} mode: {:.1} ms (TBB threads)",
                if p.robust { "robust" } else { "fast" },
                p.build_seconds * 1e3
            )?;
        }
        for s in &self.sets {
            write!(
                f,
                "  {:<8} {:>8} rays, {:>5.1}% hit: ours {:>6.2} Mrays/s ({}t), {:>6.2} Mrays/s (1t)",
                s.name,
                s.rays,
                s.hit_fraction * 100.0,
                s.ours_mt * 1e-6,
                self.threads,
                s.ours_1t * 1e-6
            )?;
            if let Some(e) = s.embree_1t {
                write!(
                    f,
                    "; Embree {:>6.2} Mrays/s (1t); ours/Embree 1t {:.2}x, ours {}t / (Embree 1t x {}) {:.2}x",
                    e * 1e-6,
                    s.ours_1t / e,
                    self.threads,
                    self.threads,
                    s.ours_mt / (e * self.threads as f64)
                )?;
                if let (Some(m), Some((lo, hi))) = (s.pair_ratio_median, s.pair_ratio_range) {
                    write!(f, "; median of the run-by-run 1t ratios {m:.2}x (runs {lo:.2}-{hi:.2}x)")?;
                }
            }
            writeln!(f)?;
            for p in &s.in_process {
                writeln!(
                    f,
                    "  {:<8} Embree in this process, {:<6} {:>6.2} Mrays/s (1t): ours/Embree 1t {:.2}x, median of the run-by-run ratios {:.2}x (runs {:.2}-{:.2}x); hit/miss differs on {:.4}% of rays",
                    "",
                    if p.robust { "robust" } else { "fast" },
                    p.best_1t * 1e-6,
                    s.ours_1t / p.best_1t,
                    p.pair_ratio_median,
                    p.pair_ratio_range.0,
                    p.pair_ratio_range.1,
                    p.hit_disagreement * 100.0
                )?;
            }
        }
        Ok(())
    }
}

/// The triangles of an OBJ file as a bare mesh: positions only, every triangle with material 0,
/// faces triangulated by tobj (its GPU load options). The shipped meshes of the ray benchmark
/// and the Embree cross-check, without the scene loader's materials and transforms.
pub fn obj_mesh(path: &Path) -> Result<Mesh> {
    let (models, _) = tobj::load_obj(path, &tobj::GPU_LOAD_OPTIONS).map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))?;
    let mut mesh = Mesh::default();
    for m in models {
        let p: Vec<Vec3> = m.mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let t: Vec<[u32; 3]> = m.mesh.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        mesh.append(&p, &[], &[], &t, 0);
    }
    Ok(mesh)
}

/// Which of the two test meshes `displaced_sphere` builds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SphereStyle {
    /// The benchmark's large mesh (`pixguide bench`, the examples): one displacement frequency,
    /// centred on the origin, every quad split along the same diagonal, so long diagonals are
    /// shared.
    Bench,
    /// The Embree cross-check's mesh: a second, finer ripple on top, moved off the origin, and
    /// the quads split along alternating diagonals: many long, thin shared diagonals near the
    /// poles.
    CrossCheck,
}

/// A displaced sphere as a latitude/longitude grid of n × m quads: 2·n·m triangles
/// (`displaced_sphere(230, 230, _)` has 105,800).
pub fn displaced_sphere(n: u32, m: u32, style: SphereStyle) -> Mesh {
    let cross_check = style == SphereStyle::CrossCheck;
    let mut positions = Vec::new();
    for j in 0..=n {
        let theta = std::f32::consts::PI * j as f32 / n as f32;
        for i in 0..=m {
            let phi = std::f32::consts::TAU * i as f32 / m as f32;
            let mut r = 1.0 + 0.08 * (5.0 * theta).sin() * (7.0 * phi).cos();
            if cross_check {
                r += 0.02 * (23.0 * phi + 3.0 * theta).sin();
            }
            let p = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin()) * r;
            positions.push(if cross_check { p + Vec3::new(0.3, -0.2, 0.1) } else { p });
        }
    }
    let idx = |i: u32, j: u32| j * (m + 1) + i;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..m {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if cross_check && (i + j) % 2 == 1 {
                tris.extend([[a, b, d], [b, c, d]]);
            } else {
                tris.extend([[a, b, c], [a, c, d]]);
            }
        }
    }
    let mut mesh = Mesh::default();
    mesh.append(&positions, &[], &[], &tris, 0);
    mesh
}

#[cfg(test)]
mod tests {
    use super::{median, range};

    #[test]
    fn range_is_the_lowest_and_highest() {
        assert_eq!(range(&[]), None);
        assert_eq!(range(&[0.9, 0.7, 1.1, 0.8]), Some((0.7, 1.1)));
    }

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }
}
