//! Triangle geometry and ray queries: one obvhs CWBVH over every triangle of the scene,
//! a watertight ray/triangle test, and robust ray-origin offsets.

pub mod bvh;
pub mod packet;
#[cfg(test)]
mod tests;
pub mod triangle;

use crate::math::Ray;
use glam::{Vec2, Vec3};

/// All triangles of a scene in world space, as one indexed soup.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals; empty, or the same length as `positions`.
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates; empty, or the same length as `positions`.
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    /// Material index of each triangle (into `Scene::materials`).
    pub material: Vec<u32>,
}

impl Mesh {
    /// Appends another mesh (already in world space) whose triangles all use `material`.
    pub fn append(&mut self, positions: &[Vec3], normals: &[Vec3], uvs: &[Vec2], triangles: &[[u32; 3]], material: u32) {
        let base = self.positions.len() as u32;
        let had_normals = !self.normals.is_empty() || self.positions.is_empty();
        let had_uvs = !self.uvs.is_empty() || self.positions.is_empty();
        // Keep the per-vertex arrays aligned: pad whichever side lacks the attribute.
        if !normals.is_empty() && !had_normals {
            self.normals.resize(self.positions.len(), Vec3::ZERO);
        }
        if !uvs.is_empty() && !had_uvs {
            self.uvs.resize(self.positions.len(), Vec2::ZERO);
        }
        self.positions.extend_from_slice(positions);
        if !self.normals.is_empty() || !normals.is_empty() {
            if normals.is_empty() {
                self.normals.resize(self.positions.len(), Vec3::ZERO);
            } else {
                self.normals.extend_from_slice(normals);
            }
        }
        if !self.uvs.is_empty() || !uvs.is_empty() {
            if uvs.is_empty() {
                self.uvs.resize(self.positions.len(), Vec2::ZERO);
            } else {
                self.uvs.extend_from_slice(uvs);
            }
        }
        self.triangles.extend(triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        self.material.extend(std::iter::repeat_n(material, triangles.len()));
    }

    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[i];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }
}

/// A closest hit: distance along the ray, triangle index (into `Mesh::triangles`), and the
/// barycentrics (b1, b2) of the hit (b0 = 1 − b1 − b2).
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub bary: Vec2,
}

/// The ray-query structure over a [`Mesh`].
pub struct Accel {
    bvh: bvh::Bvh,
    /// The packet query, for a mesh of at most `packet::PACKET_MAX` triangles on a CPU with
    /// AVX-512.
    packets: Option<packet::Packets>,
}

impl Accel {
    /// Builds the BVH (in parallel). Degenerate triangles are kept in the mesh but can never be hit.
    pub fn build(mesh: &Mesh) -> Accel {
        Accel::build_with(mesh, bvh::build_params(mesh.triangles.len()))
    }

    /// [`Accel::build`] with explicit obvhs build parameters (for benchmarking the presets).
    pub fn build_with(mesh: &Mesh, params: obvhs::BvhBuildParams) -> Accel {
        Accel::build_tuned(mesh, params, bvh::node_cost(mesh.triangles.len()))
    }

    /// [`Accel::build_with`] with the surface-area-heuristic cost of a node visit relative to
    /// a 4-triangle leaf block test (for tuning it; the default is `bvh::node_cost`).
    pub fn build_tuned(mesh: &Mesh, params: obvhs::BvhBuildParams, c_node: f32) -> Accel {
        let n = mesh.positions.len();
        // Triangles with an out-of-range index, a non-finite vertex or zero area are left out
        // of the BVH entirely, so no traversal or build step ever sees them.
        let (tris, valid): (Vec<[Vec3; 3]>, Vec<u32>) = mesh
            .triangles
            .iter()
            .enumerate()
            .filter(|(_, t)| t.iter().all(|&v| (v as usize) < n))
            .map(|(i, t)| ([mesh.positions[t[0] as usize], mesh.positions[t[1] as usize], mesh.positions[t[2] as usize]], i as u32))
            .filter(|(p, _)| !triangle::is_degenerate(p[0], p[1], p[2]))
            .unzip();
        let packets = packet::Packets::new(&tris, &valid);
        Accel { bvh: bvh::Bvh::build(tris, valid, params, c_node), packets }
    }

    /// Number of CWBVH nodes (0 for a mesh without a single valid triangle).
    pub fn node_count(&self) -> usize {
        self.bvh.node_count()
    }

    /// Whether traversal uses the AVX2 node test (see [`bvh::Bvh::set_avx2`]): `enable`
    /// false forces the SSE2 one, for tests and A/B benchmarks.
    pub fn set_avx2(&mut self, enable: bool) -> bool {
        self.bvh.set_avx2(enable)
    }

    /// Whether the AVX2 query is compiled with AVX-512 registers too (see [`bvh::Bvh::set_avx512`]).
    pub fn set_avx512(&mut self, enable: bool) -> bool {
        self.bvh.set_avx512(enable)
    }

    /// Whether AVX2 traversal tests leaves two blocks at a time (see [`bvh::Bvh::set_tri8`]).
    pub fn set_tri8(&mut self, enable: bool) -> bool {
        self.bvh.set_tri8(enable)
    }

    /// Whether the BVH's arrays are on huge pages where large (see [`bvh::Bvh::set_huge_pages`]).
    pub fn set_huge_pages(&mut self, enable: bool) {
        self.bvh.set_huge_pages(enable)
    }

    /// Shape of the BVH (node count, average fill).
    pub fn bvh_shape(&self) -> bvh::BvhShape {
        self.bvh.shape()
    }

    /// [`Accel::intersect`], counting node visits and leaf block tests (statistics).
    pub fn intersect_counted(&self, ray: &Ray, tmax: f32, counts: &mut bvh::TraversalCounts) -> Option<Hit> {
        self.bvh.intersect_counted(ray.origin, ray.dir, tmax, counts).map(|(t, prim, b1, b2)| Hit { t, prim, bary: Vec2::new(b1, b2) })
    }

    /// Closest hit with t in (0, tmax).
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray, tmax: f32) -> Option<Hit> {
        self.bvh.intersect(ray.origin, ray.dir, tmax).map(|(t, prim, b1, b2)| Hit { t, prim, bary: Vec2::new(b1, b2) })
    }

    /// The packet query, where this mesh and CPU have one (see [`packet::Packets`]).
    pub fn packets(&self) -> Option<&packet::Packets> {
        self.packets.as_ref()
    }

    /// The BVH, for the packet query's undecided lanes (`packet::Packets::intersect_batch`).
    pub fn bvh(&self) -> &bvh::Bvh {
        &self.bvh
    }

    /// Leaves the packet query out (for A/B benchmarks); returns whether there was one.
    pub fn drop_packets(&mut self) -> bool {
        self.packets.take().is_some()
    }

    /// Whether the integrator's shadow rays use the packet query (the default) or the BVH one
    /// by one (for A/B benchmarks); returns whether there is a packet query.
    pub fn set_packet_shadows(&mut self, on: bool) -> bool {
        self.packets.as_mut().map(|p| p.set_shadows(on)).is_some()
    }

    /// Closest hits with t in (0, tmax) of the rays `rays[i]` with `live[i]`, into `out[i]`
    /// (`None` for the others): through the packet query, sixteen rays at a time, where this
    /// mesh and CPU have one and at least `packet::MIN_LANES` rays are left; else one by one.
    /// The same answers as [`Accel::intersect`] (see `packet` for the one exception).
    #[inline]
    pub fn intersect_live(&self, rays: &[Ray], live: &[bool], tmax: f32, out: &mut [Option<Hit>]) {
        let Some(p) = &self.packets else {
            for i in 0..rays.len() {
                out[i] = if live[i] { self.intersect(&rays[i], tmax) } else { None };
            }
            return;
        };
        let mut lanes = [0usize; packet::WIDTH];
        let mut k = 0;
        let mut left = live[..rays.len()].iter().filter(|&&l| l).count();
        for i in 0..rays.len() {
            if !live[i] {
                out[i] = None;
            } else if left >= packet::MIN_LANES || k > 0 {
                lanes[k] = i;
                k += 1;
                left -= 1;
                if k == packet::WIDTH || left == 0 {
                    p.intersect_lanes(&self.bvh, rays, &lanes[..k], tmax, out);
                    k = 0;
                }
            } else {
                out[i] = self.intersect(&rays[i], tmax);
                left -= 1;
            }
        }
    }

    /// Any hit with t in (0, tmax) (shadow rays).
    #[inline(always)]
    pub fn occluded(&self, ray: &Ray, tmax: f32) -> bool {
        self.bvh.occluded(ray.origin, ray.dir, tmax)
    }
}

/// Integer ULP steps per unit of normal for coordinates far from zero (Wächter & Binder).
const INT_SCALE: f32 = 256.0;
/// Below this fraction of the magnitude (see `offset_ray_origin`) a coordinate's own ULPs are
/// too fine to step over the rounding error of the other coordinates, so it gets a float offset
/// instead.
const ORIGIN_FRACTION: f32 = 1.0 / 32.0;
/// Float offset in units of the magnitude for such coordinates. Wächter & Binder use a fixed
/// 2^-16 below a fixed |p_i| < 1/32; that is 1.5% of a scene of size 1e-3, so both are made
/// relative to the magnitude (identical to the paper for a magnitude of 1).
const FLOAT_SCALE: f32 = 1.0 / 65536.0;
/// Magnitude floor so a point at the exact origin of a degenerate scene still moves.
const MIN_MAGNITUDE: f32 = 1e-8;

/// Moves `p` off the surface along the geometric normal `ng` on the side of `dir`, by an amount
/// that scales with the magnitude of the coordinates (Wächter & Binder, Ray Tracing Gems ch. 6),
/// so spawned rays neither re-hit their own triangle nor tunnel through thin geometry at scene
/// scales from 1e-3 to 1e4. `extent` is the largest vertex coordinate (in absolute value) of the
/// triangle `p` lies on (`SurfaceHit::extent`): the rounding error of an interpolated hit point,
/// and of the triangle test, is relative to the vertices, not to `p`, so the magnitude is the
/// larger of |p|∞ and `extent`. (Relative to |p|∞ alone, a point 1e-4 from the world origin on a
/// floor spanning ±1 moved by 6e-9, below the triangle test's ~1e-7 error there: the floor could
/// be hit again at t ≈ 1e-7.)
#[inline]
pub fn offset_ray_origin(p: Vec3, ng: Vec3, dir: Vec3, extent: f32) -> Vec3 {
    if !p.is_finite() || !ng.is_finite() {
        return p;
    }
    let n = if ng.dot(dir) < 0.0 { -ng } else { ng };
    // `max` ignores a NaN extent.
    let mag = p.abs().max_element().max(extent).max(MIN_MAGNITUDE);
    let near_zero = mag * ORIGIN_FRACTION;
    let float_step = FLOAT_SCALE * mag;
    Vec3::new(
        offset_component(p.x, n.x, near_zero, float_step),
        offset_component(p.y, n.y, near_zero, float_step),
        offset_component(p.z, n.z, near_zero, float_step),
    )
}

/// One coordinate of [`offset_ray_origin`]. Both candidate offsets are computed and one is
/// selected, without a branch: which one applies depends on the hit point, so a branch on it
/// is mispredicted often.
#[inline(always)]
fn offset_component(pi: f32, ni: f32, near_zero: f32, float_step: f32) -> f32 {
    let by_float = pi + float_step * ni;
    // Stepping the bit pattern moves by whole ULPs whatever the magnitude; the step is applied
    // away from zero when n_i points away from zero, towards it otherwise. Wrapping arithmetic
    // is what an overflowing step did in release builds before (a huge `ng` only).
    let steps = (INT_SCALE * ni) as i32;
    let steps = if pi < 0.0 { steps.wrapping_neg() } else { steps };
    let stepped = f32::from_bits((pi.to_bits() as i32).wrapping_add(steps) as u32);
    let by_ulps = if stepped.is_finite() { stepped } else { pi };
    if pi.abs() < near_zero {
        by_float
    } else {
        by_ulps
    }
}

impl Mesh {
    /// Unit geometric normal of triangle `i`: the winding normal, flipped to agree with the
    /// vertex normals when the mesh has them (files disagree on winding; their normals are what
    /// the author looked at). Zero for degenerate triangles.
    pub fn geometric_normal(&self, i: usize) -> Vec3 {
        let [p0, p1, p2] = self.triangle(i);
        let n = (p1 - p0).cross(p2 - p0);
        let len = n.length();
        if !(len > 0.0) || !len.is_finite() {
            return Vec3::ZERO;
        }
        let mut n = n / len;
        if !self.normals.is_empty() {
            let [a, b, c] = self.triangles[i];
            let avg = self.normals[a as usize] + self.normals[b as usize] + self.normals[c as usize];
            if avg.dot(n) < 0.0 {
                n = -n;
            }
        }
        n
    }

    /// Area of triangle `i` (0 for degenerate ones).
    pub fn area(&self, i: usize) -> f32 {
        let [p0, p1, p2] = self.triangle(i);
        let a = 0.5 * (p1 - p0).cross(p2 - p0).length();
        if a.is_finite() {
            a
        } else {
            0.0
        }
    }

    /// Axis-aligned bounds of all vertices used by triangles.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in &self.positions {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if self.positions.is_empty() {
            (Vec3::ZERO, Vec3::ZERO)
        } else {
            (lo, hi)
        }
    }
}
