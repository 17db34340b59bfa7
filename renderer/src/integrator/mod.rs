//! The render driver: tiles in parallel (rayon), one independent random stream per pixel
//! sample, per-pixel statistics in f64, and the requested extra buffers.

pub mod path;
pub mod wave;

use crate::camera::Camera;
use crate::film::descriptors::FIELDS;
use crate::film::{BufferRequest, Descriptors, Frame, PixelBuffer, Welford};
use crate::math::Ray;
use crate::rng::Pcg32;
use crate::scene::Scene;
use crate::{Error, Result};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Tile edge in pixels: small enough to balance 2 threads on a 64×64 image, large enough
/// that per-tile overhead is negligible.
pub const TILE: u32 = 16;

#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub spp: u32,
    pub seed: u64,
    pub max_bounces: u32,
    pub russian_roulette: bool,
    pub request: BufferRequest,
    /// Render only this window of pixels (x0, y0, width, height); the frame has the window's size.
    pub crop: Option<(u32, u32, u32, u32)>,
    /// Index of the first sample: samples `first_sample..first_sample + spp` are rendered, so a
    /// long render split into chunks uses exactly the streams of one unsplit render.
    pub first_sample: u32,
}

impl RenderOptions {
    /// The scene's own settings with the given buffer request.
    pub fn from_scene(scene: &Scene, request: BufferRequest) -> Self {
        RenderOptions {
            spp: scene.settings.spp,
            seed: scene.settings.seed,
            max_bounces: scene.settings.max_bounces,
            russian_roulette: scene.settings.russian_roulette,
            request,
            crop: None,
            first_sample: 0,
        }
    }
}

/// Counts reported after a render.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    pub wall: Duration,
    pub samples: u64,
    pub rays: u64,
}

impl RenderStats {
    pub fn summary(&self) -> String {
        let s = self.wall.as_secs_f64().max(1e-9);
        format!("{:.2} s wall, {:.3} M samples/s, {:.3} M rays/s", s, self.samples as f64 / s / 1e6, self.rays as f64 / s / 1e6)
    }
}

struct TileResult {
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    radiance: Vec<Welford>,
    diffuse: Vec<Welford>,
    specular: Vec<Welford>,
    albedo: Vec<Welford>,
    normal: Vec<Welford>,
    depth: Vec<Welford>,
    nonfinite: u64,
    rays: u64,
}

/// Renders `scene`. `progress` is called with the number of pixels finished so far (from any
/// thread). The image depends only on the options, never on the thread count.
pub fn render(scene: &Scene, opts: &RenderOptions, progress: &(dyn Fn(u64) + Sync)) -> Result<(Frame, RenderStats)> {
    let (cw, ch) = (scene.camera.width, scene.camera.height);
    let (x0, y0, width, height) = opts.crop.unwrap_or((0, 0, cw, ch));
    if opts.spp == 0 {
        return Err(Error::Invalid("spp must be at least 1".into()));
    }
    if width == 0 || height == 0 || x0 + width > cw || y0 + height > ch {
        return Err(Error::Invalid(format!("crop window {x0},{y0} {width}x{height} is not inside the {cw}x{ch} image")));
    }
    let req = opts.request;
    let desc_len = width as u64 * height as u64 * opts.spp as u64 * FIELDS as u64;
    if req.descriptors && desc_len > (1u64 << 32) {
        return Err(Error::Invalid(format!(
            "per-sample descriptors of {width}x{height} at {} spp need {} GiB; render fewer samples or a crop",
            opts.spp,
            (desc_len * 4) >> 30
        )));
    }

    let start = Instant::now();
    // With descriptors, tiles are bands of TILE full-width rows: each band's descriptors are
    // then one contiguous slice of the frame's buffer and are written there directly, so the
    // largest buffer by far (9.9 GB at 1024², 64 spp) never exists twice.
    let tile_w = if req.descriptors { width } else { TILE };
    let mut tiles = Vec::new();
    for ty in (0..height).step_by(TILE as usize) {
        for tx in (0..width).step_by(tile_w as usize) {
            tiles.push((tx, ty, tile_w.min(width - tx), TILE.min(height - ty)));
        }
    }
    let per_pixel = opts.spp as usize * FIELDS;
    let mut descriptors = if req.descriptors { vec![0.0f32; desc_len as usize] } else { Vec::new() };
    let slots: Vec<&mut [f32]> = if req.descriptors {
        descriptors.chunks_mut(TILE as usize * width as usize * per_pixel).collect()
    } else {
        tiles.iter().map(|_| <&mut [f32]>::default()).collect()
    };
    debug_assert_eq!(slots.len(), tiles.len());
    let done = AtomicU64::new(0);
    let cam = &scene.camera;
    let to_camera = |n: Vec3| Vec3::new(n.dot(cam.right), n.dot(cam.up), -n.dot(cam.forward));

    let use_wave = !req.gbuffers && !req.descriptors && wave::supported(scene);
    let run_batch = |t: &mut TileResult, batch: &mut Batch| {
        if batch.pixel.is_empty() {
            return;
        }
        batch.result.resize(batch.start.len(), wave::LaneResult::default());
        wave::trace_samples(scene, &batch.start, opts.seed, opts.max_bounces, opts.russian_roulette, &mut batch.result);
        for (&li, r) in batch.pixel.iter().zip(batch.result.iter()) {
            let (mut radiance, mut diffuse) = (r.radiance, r.diffuse);
            t.rays += r.rays as u64;
            if !(radiance.is_finite() && diffuse.is_finite()) {
                t.nonfinite += 1;
                radiance = Vec3::ZERO;
                diffuse = Vec3::ZERO;
            }
            push3(&mut t.radiance[li * 3..li * 3 + 3], radiance);
            if req.split {
                push3(&mut t.diffuse[li * 3..li * 3 + 3], diffuse);
                push3(&mut t.specular[li * 3..li * 3 + 3], (radiance - diffuse).max(Vec3::ZERO));
            }
        }
        batch.pixel.clear();
        batch.start.clear();
    };
    let results: Vec<TileResult> = tiles
        .par_iter()
        .zip(slots)
        .map(|(&(tx, ty, tw, th), slot)| {
            let n = (tw * th) as usize;
            let stats = |on: bool, c: usize| if on { vec![Welford::default(); n * c] } else { Vec::new() };
            let mut t = TileResult {
                x0: tx,
                y0: ty,
                w: tw,
                h: th,
                radiance: stats(true, 3),
                diffuse: stats(req.split, 3),
                specular: stats(req.split, 3),
                albedo: stats(req.gbuffers, 3),
                normal: stats(req.gbuffers, 3),
                depth: stats(req.gbuffers, 1),
                nonfinite: 0,
                rays: 0,
            };
            if use_wave {
                // Runs of up to `STREAM` samples in the order of the loop below (pixel by
                // pixel, sample by sample), their results taken in that order, so each pixel's
                // statistics see the same sequence.
                let mut batch = Batch::default();
                for ly in 0..th {
                    for lx in 0..tw {
                        let (px, py) = (x0 + tx + lx, y0 + ty + ly);
                        let li = (ly * tw + lx) as usize;
                        for s in 0..opts.spp {
                            batch.pixel.push(li);
                            batch.start.push(wave::SampleStart { px, py, sample: opts.first_sample + s });
                            if batch.pixel.len() == STREAM {
                                run_batch(&mut t, &mut batch);
                            }
                        }
                    }
                    if ly + 1 == th {
                        run_batch(&mut t, &mut batch);
                    }
                    progress(done.fetch_add(tw as u64, Ordering::Relaxed) + tw as u64);
                }
                return t;
            }
            for ly in 0..th {
                for lx in 0..tw {
                    let (px, py) = (x0 + tx + lx, y0 + ty + ly);
                    let pixel = py as u64 * cw as u64 + px as u64;
                    let li = (ly * tw + lx) as usize;
                    for s in 0..opts.spp {
                        let (mut rng, ray) = start_sample(cam, opts, px, py, pixel, s);
                        let mut r = path::trace(scene, ray, &mut rng, opts.max_bounces, opts.russian_roulette, req);
                        t.rays += r.rays as u64;
                        if !(r.radiance.is_finite() && r.diffuse.is_finite()) {
                            t.nonfinite += 1;
                            r.radiance = Vec3::ZERO;
                            r.diffuse = Vec3::ZERO;
                        }
                        push3(&mut t.radiance[li * 3..li * 3 + 3], r.radiance);
                        if req.split {
                            push3(&mut t.diffuse[li * 3..li * 3 + 3], r.diffuse);
                            // Non-negative by construction; max() only absorbs rounding.
                            push3(&mut t.specular[li * 3..li * 3 + 3], (r.radiance - r.diffuse).max(Vec3::ZERO));
                        }
                        if req.gbuffers {
                            push3(&mut t.albedo[li * 3..li * 3 + 3], r.albedo);
                            push3(&mut t.normal[li * 3..li * 3 + 3], to_camera(r.normal));
                            t.depth[li].push(r.depth);
                        }
                        if req.descriptors {
                            // A band's pixel li is its slot's pixel li (full-width rows).
                            let o = li * per_pixel + s as usize * FIELDS;
                            slot[o..o + FIELDS].copy_from_slice(&r.descriptor);
                        }
                    }
                }
                progress(done.fetch_add(tw as u64, Ordering::Relaxed) + tw as u64);
            }
            t
        })
        .collect();

    let pixels = (width * height) as usize;
    let buf = |on: bool, c: usize| if on { Some(PixelBuffer::new(c, pixels)) } else { None };
    let mut frame = Frame {
        width,
        height,
        spp: opts.spp,
        radiance: PixelBuffer::new(3, pixels),
        diffuse: buf(req.split, 3),
        specular: buf(req.split, 3),
        albedo: buf(req.gbuffers, 3),
        normal: buf(req.gbuffers, 3),
        depth: buf(req.gbuffers, 1),
        depth_scale: 10.0 * scene.radius,
        descriptors: req.descriptors.then_some(Descriptors { width, height, spp: opts.spp, data: descriptors }),
        nonfinite_samples: 0,
    };
    let mut rays = 0;
    for t in &results {
        frame.nonfinite_samples += t.nonfinite;
        rays += t.rays;
        for ly in 0..t.h {
            for lx in 0..t.w {
                let li = (ly * t.w + lx) as usize;
                let i = ((t.y0 + ly) * width + t.x0 + lx) as usize;
                frame.radiance.set(i, &t.radiance[li * 3..li * 3 + 3]);
                let pairs = [
                    (&mut frame.diffuse, &t.diffuse, 3),
                    (&mut frame.specular, &t.specular, 3),
                    (&mut frame.albedo, &t.albedo, 3),
                    (&mut frame.normal, &t.normal, 3),
                    (&mut frame.depth, &t.depth, 1),
                ];
                for (dst, src, c) in pairs {
                    if let Some(d) = dst {
                        d.set(i, &src[li * c..li * c + c]);
                    }
                }
            }
        }
    }
    let stats = RenderStats { wall: start.elapsed(), samples: pixels as u64 * opts.spp as u64, rays };
    Ok((frame, stats))
}

/// Samples handed to `wave::trace_samples` at once: enough that the stream's last rounds,
/// with fewer paths left than lanes, are a small part of it (a row of a 16-pixel tile at 256
/// spp), few enough that the buffers below stay small.
const STREAM: usize = 4096;

/// Samples waiting for `wave::trace_samples`: their pixel in the tile, where they start, and
/// (once traced) their results.
#[derive(Default)]
struct Batch {
    pixel: Vec<usize>,
    start: Vec<wave::SampleStart>,
    result: Vec<wave::LaneResult>,
}

/// A sample's own random stream and its camera ray (`wave::trace_samples` makes them with the
/// same operations, many at once, so both paths trace the same rays with the same streams).
#[inline(always)]
fn start_sample(cam: &Camera, opts: &RenderOptions, px: u32, py: u32, pixel: u64, s: u32) -> (Pcg32, Ray) {
    let mut rng = Pcg32::for_sample(opts.seed, pixel, (opts.first_sample + s) as u64);
    let film = Vec2::new(px as f32, py as f32) + rng.next_2d();
    (rng, cam.ray(film))
}

fn push3(acc: &mut [Welford], v: Vec3) {
    acc[0].push(v.x);
    acc[1].push(v.y);
    acc[2].push(v.z);
}
