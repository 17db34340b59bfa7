//! Unidirectional path tracing with next-event estimation and multiple importance sampling
//! (power heuristic) for area lights and the environment, with the extra outputs the denoiser
//! needs gathered in the same pass: the diffuse/specular split (method.md §1.3), G-buffers at the
//! first non-specular vertex and per-sample path descriptors (§1.1).

use crate::film::descriptors::{field, FIELDS, VERTICES};
use crate::film::BufferRequest;
use crate::geometry::offset_ray_origin;
use crate::material::LobeKind;
use crate::math::{Frame, Ray};
use crate::rng::Pcg32;
use crate::sampling::power_heuristic;
use crate::scene::Scene;
use glam::Vec3;

/// Depth of a path that escaped before reaching a non-specular vertex (method.md §1.1).
pub const MISS_DEPTH: f32 = -0.1;

/// Everything one camera sample produces.
#[derive(Clone, Debug)]
pub struct SampleResult {
    pub radiance: Vec3,
    pub diffuse: Vec3,
    pub albedo: Vec3,
    /// World-space shading normal facing the incoming ray (converted to camera space by the film).
    pub normal: Vec3,
    /// Normalised depth (path length / (10·scene radius)), or `MISS_DEPTH`.
    pub depth: f32,
    pub descriptor: [f32; FIELDS],
    /// Rays traced (camera, continuation and shadow rays), for the rays/s statistic.
    pub rays: u32,
}

/// Radiance accumulated separately for the diffuse and the specular part. Before the first
/// diffuse vertex all throughput is "specular"; at that vertex the BSDF is split per lobe.
#[derive(Clone, Copy)]
struct SplitThroughput {
    diffuse: Vec3,
    specular: Vec3,
}

impl SplitThroughput {
    fn scale(&mut self, w: Vec3) {
        self.diffuse *= w;
        self.specular *= w;
    }
    fn total(&self) -> Vec3 {
        self.diffuse + self.specular
    }
}

/// Fraction of the light distance kept for shadow rays, so the ray stops just short of the
/// light's own surface (the light point is exact; a relative margin is scale-independent).
const SHADOW_EPS: f32 = 1e-4;

pub fn trace(scene: &Scene, ray: Ray, rng: &mut Pcg32, max_bounces: u32, russian_roulette: bool, req: BufferRequest) -> SampleResult {
    let mut out = SampleResult {
        radiance: Vec3::ZERO,
        diffuse: Vec3::ZERO,
        albedo: Vec3::ZERO,
        normal: Vec3::ZERO,
        depth: MISS_DEPTH,
        descriptor: [0.0; FIELDS],
        rays: 0,
    };
    let mut beta = SplitThroughput { diffuse: Vec3::ZERO, specular: Vec3::ONE };
    let mut l_diffuse = Vec3::ZERO;
    let mut l_specular = Vec3::ZERO;
    let mut split_started = false;
    let mut gbuffer_done = !req.gbuffers;
    let mut path_length = 0.0f32;
    let depth_norm = 1.0 / (10.0 * scene.radius);
    // Descriptor state: ∏ f·cos of the sampled continuations and ∏ of their pdfs.
    let mut prod_fcos = Vec3::ONE;
    let mut path_weight = 1.0f32;

    let mut ray = ray;
    let mut prev_pdf = 0.0f32;
    let mut prev_delta = true;
    let mut prev_p = ray.origin;

    for depth in 0..=max_bounces {
        out.rays += 1;
        let Some(hit) = scene.accel.intersect(&ray, f32::INFINITY) else {
            let mis = !(depth == 0 || prev_delta);
            let (le, light_pdf) = scene.lights.env_radiance_pdf(ray.dir, mis);
            if le.max_element() > 0.0 {
                let w = if mis { power_heuristic(prev_pdf, light_pdf) } else { 1.0 };
                l_diffuse += beta.diffuse * le * w;
                l_specular += beta.specular * le * w;
            }
            if req.descriptors {
                write3(&mut out.descriptor, field::LIGHT_INTENSITY, le);
                write3(&mut out.descriptor, field::RADIANCE_NO_WEIGHT, prod_fcos * le);
            }
            break;
        };
        let si = scene.surface(&ray, &hit);
        path_length += hit.t;
        let material = &scene.materials[si.material as usize];
        let wo_world = -ray.dir;

        if material.is_emissive() {
            let le = material.emitted(si.ng, wo_world);
            if le.max_element() > 0.0 {
                let w = if depth == 0 || prev_delta {
                    1.0
                } else {
                    power_heuristic(prev_pdf, scene.lights.pdf_triangle(si.prim, prev_p, si.p, si.ng))
                };
                l_diffuse += beta.diffuse * le * w;
                l_specular += beta.specular * le * w;
                if req.descriptors {
                    write3(&mut out.descriptor, field::LIGHT_INTENSITY, le);
                    write3(&mut out.descriptor, field::RADIANCE_NO_WEIGHT, prod_fcos * le);
                }
            }
        }
        if depth == max_bounces {
            break;
        }

        let bsdf = material.bsdf(si.uv, &scene.textures);
        if material.one_sided && !bsdf.is_transmissive() && wo_world.dot(si.ng) < 0.0 {
            // A one-sided surface (Mitsuba's BSDFs outside `twosided`) is black from behind.
            break;
        }
        // Reflection-only BSDFs are two-sided: orient both normals towards the viewer.
        // Dielectrics keep the geometric orientation, which tells inside from outside.
        let (mut ng, mut ns) = (si.ng, si.ns);
        if !bsdf.is_transmissive() && wo_world.dot(ng) < 0.0 {
            ng = -ng;
            ns = -ns;
        }
        // A shading normal that puts the viewer on the other side than the true surface would
        // make the BSDF see the wrong hemisphere; fall back to the geometric normal there.
        if wo_world.dot(ns) * wo_world.dot(ng) <= 0.0 {
            ns = ng;
        }
        let frame = Frame::from_normal(ns);
        let wo = frame.to_local(wo_world);

        if !gbuffer_done && !bsdf.is_delta() {
            out.albedo = bsdf.albedo();
            out.normal = if wo_world.dot(ns) >= 0.0 { ns } else { -ns };
            out.depth = path_length * depth_norm;
            gbuffer_done = true;
        }
        let first_diffuse = !split_started && bsdf.has_diffuse();

        // Next-event estimation.
        let u_select = rng.next_f32();
        let u_light = rng.next_2d();
        if !bsdf.is_delta() {
            if let Some(ls) = scene.lights.sample(si.p, u_select, u_light) {
                let wi = frame.to_local(ls.wi);
                let same_side = (ls.wi.dot(ng) > 0.0) == (wo_world.dot(ng) > 0.0);
                // Reflection needs the light on the viewer's side of the true surface, and
                // transmission the other side: the geometric normal decides, so shading normals
                // can't leak light through a surface.
                let f = bsdf.eval_split(wo, wi);
                let f = if bsdf.is_transmissive() || same_side { f } else { Default::default() };
                if f.total().max_element() > 0.0 {
                    let origin = offset_ray_origin(si.p, si.ng, ls.wi, si.extent);
                    let tmax =
                        if ls.dist.is_finite() { (si.p + ls.wi * ls.dist - origin).length() * (1.0 - SHADOW_EPS) } else { f32::INFINITY };
                    out.rays += 1;
                    if !scene.accel.occluded(&Ray::new(origin, ls.wi), tmax) {
                        let w = power_heuristic(ls.pdf, bsdf.pdf(wo, wi));
                        let c = ls.radiance * (w / ls.pdf);
                        if first_diffuse {
                            // At the first diffuse vertex only the diffuse lobe feeds "diffuse".
                            l_diffuse += beta.specular * f.diffuse * c;
                            l_specular += beta.specular * f.other * c;
                        } else {
                            let fc = f.total() * c;
                            l_diffuse += beta.diffuse * fc;
                            l_specular += beta.specular * fc;
                        }
                    }
                }
            }
        }

        // Continue the path by sampling the BSDF.
        let u_lobe = rng.next_f32();
        let u_bsdf = rng.next_2d();
        let Some(s) = bsdf.sample(wo, u_lobe, u_bsdf) else { break };
        if s.weight.max_element() <= 0.0 {
            // A black surface ends the path: nothing further can contribute.
            break;
        }
        let wi_world = frame.to_world(s.wi);
        let reflected = wi_world.dot(ng) > 0.0;
        let wo_above = wo_world.dot(ng) > 0.0;
        if s.lobe.transmission == (reflected == wo_above) {
            // The sample crossed (or failed to cross) the true surface against its lobe.
            break;
        }
        if req.descriptors && (depth as usize) < VERTICES {
            let d = depth as usize;
            write3(&mut out.descriptor, field::THROUGHPUT + 3 * d, s.f_cos);
            out.descriptor[field::BOUNCE_TYPE + d] = s.lobe.bitmask() as f32;
            out.descriptor[field::ROUGHNESS + d] = s.lobe.roughness;
            prod_fcos *= s.f_cos;
            path_weight *= s.pdf;
        }
        if first_diffuse {
            if s.lobe.kind == LobeKind::Specular {
                beta.specular *= s.weight;
            } else {
                let f = bsdf.eval_split(wo, s.wi);
                beta.diffuse = beta.specular * f.diffuse / s.pdf;
                beta.specular *= f.other / s.pdf;
            }
            split_started = true;
        } else {
            beta.scale(s.weight);
        }
        if !is_finite(beta.total()) {
            break;
        }

        prev_pdf = s.pdf;
        prev_delta = s.lobe.kind == LobeKind::Specular;
        prev_p = si.p;
        ray = Ray::new(offset_ray_origin(si.p, si.ng, wi_world, si.extent), wi_world);

        if russian_roulette && depth >= 3 {
            let q = (1.0 - beta.total().max_element()).clamp(0.05, 0.95);
            if rng.next_f32() < q {
                break;
            }
            beta.scale(Vec3::splat(1.0 / (1.0 - q)));
        }
    }

    if req.descriptors {
        out.descriptor[field::PATH_WEIGHT] = path_weight;
        for v in out.descriptor.iter_mut() {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
    }
    out.radiance = l_diffuse + l_specular;
    out.diffuse = l_diffuse;
    out
}

fn write3(d: &mut [f32; FIELDS], at: usize, v: Vec3) {
    d[at] = v.x;
    d[at + 1] = v.y;
    d[at + 2] = v.z;
}

fn is_finite(v: Vec3) -> bool {
    v.x.is_finite() && v.y.is_finite() && v.z.is_finite()
}
