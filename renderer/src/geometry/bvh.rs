//! One obvhs CWBVH (compressed 8-wide BVH) over all valid triangles, traversed with obvhs's
//! `traverse!` macro but with our own child-box test and our own (watertight) triangle test.
//!
//! Why a custom box test: obvhs's `CwBvhNode::intersect_ray` clamps box entry distances to
//! 1e-4 (so any hit closer than 1e-4 is culled — fatal for a scene of size 1e-3) and its
//! `safe_inverse` shrinks 1/d for |d| < f32::EPSILON, which can cull boxes a nearly axis-parallel
//! ray does pass through. Ours has no tmin clamp, a conservative reciprocal, and widens every
//! slab by a few ULPs of the terms it was computed from, so rounding never culls a box that the
//! ray touches (watertightness is only as good as the weakest culling test).

use super::triangle::{self, RayShear};
use glam::{UVec2, Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::cwbvh::node::CwBvhNode;
use obvhs::cwbvh::CwBvh;
use obvhs::ploc::PlocBuilder;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Relative widening of every slab distance: the slab distance is two roundings of a product and
/// one of a sum away from exact, plus the rounding of 1/d and of (p - o); 2^-20 (8 ULPs) bounds
/// all of them with margin.
const SLAB_WIDEN: f32 = 1.0 / (1 << 20) as f32;
/// Smallest |d| component used for the reciprocal. 1/1e-20 stays finite through every product in
/// the box test for coordinates up to ~1e12, and an exactly axis-parallel ray then gets slabs
/// that extend ~1e20 · (distance to the plane) — far beyond any scene.
const MIN_DIR: f32 = 1e-20;

/// Build parameters, chosen by measurement (`examples/ray_bench.rs` with PIXGUIDE_BENCH_PRESETS,
/// 2 threads): on the bunny (56k) and a 980k-triangle sphere, obvhs's presets from
/// `very_fast_build` to `slow_build` traced within ±10% of each other (measurement noise on a
/// shared machine), while `very_fast_build` built fastest (bunny 24 ms vs 33 ms medium; sphere
/// 0.52 s vs 0.85 s medium, 1.5 s slow).
pub fn default_build_params() -> BvhBuildParams {
    BvhBuildParams::very_fast_build()
}

pub struct Bvh {
    cwbvh: CwBvh,
    /// Triangle vertices in BVH leaf order (`cwbvh.primitive_indices` order), so a leaf's
    /// triangles are contiguous in memory.
    tris: Vec<[Vec3A; 3]>,
    /// Original triangle index (into `Mesh::triangles`) of each entry of `tris`.
    prim_ids: Vec<u32>,
}

/// Per-ray constants of the box test.
struct NodeRay {
    origin: Vec3A,
    inv_dir: Vec3A,
    neg: [bool; 3],
}

impl NodeRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> NodeRay {
        let inv = |x: f32| 1.0 / if x.abs() < MIN_DIR { MIN_DIR.copysign(x) } else { x };
        NodeRay {
            origin: o.into(),
            inv_dir: Vec3A::new(inv(d.x), inv(d.y), inv(d.z)),
            neg: [d.x < 0.0, d.y < 0.0, d.z < 0.0],
        }
    }
}

impl Bvh {
    /// `valid` lists the triangles to put in the BVH (the non-degenerate ones); `positions` are
    /// their vertices, indexed like `valid`.
    pub fn build(tris: Vec<[Vec3; 3]>, valid: Vec<u32>, params: BvhBuildParams) -> Bvh {
        debug_assert_eq!(tris.len(), valid.len());
        if tris.is_empty() {
            return Bvh { cwbvh: CwBvh::default(), tris: Vec::new(), prim_ids: Vec::new() };
        }
        let obvhs_tris: Vec<Triangle> =
            tris.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
        let indices: Vec<u32> = (0..tris.len() as u32).collect();
        // The obvhs helper `build_cwbvh_from_tris` does the same steps, plus a full validation
        // pass in debug builds that costs more than the build itself.
        let mut bvh2 = if params.pre_split {
            let mut aabbs: Vec<Aabb> = obvhs_tris.iter().map(|t| t.aabb()).collect();
            let largest = aabbs.iter().map(|a| a.half_area()).fold(0.0f32, f32::max);
            let avg = aabbs.iter().map(|a| a.half_area()).sum::<f32>() / aabbs.len() as f32;
            let mut idx = indices;
            obvhs::splits::split_aabbs_preset(&mut aabbs, &mut idx, &obvhs_tris, avg, largest);
            let mut b = PlocBuilder::with_capacity(aabbs.len()).build(
                params.ploc_search_distance,
                &aabbs,
                idx,
                params.sort_precision,
                params.search_depth_threshold,
            );
            b.uses_spatial_splits = true;
            b
        } else {
            PlocBuilder::with_capacity(obvhs_tris.len()).build(
                params.ploc_search_distance,
                &obvhs_tris,
                indices,
                params.sort_precision,
                params.search_depth_threshold,
            )
        };
        ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
        let cwbvh = bvh2_to_cwbvh(&bvh2, params.max_prims_per_leaf.clamp(1, 3), true, false);
        let ordered: Vec<[Vec3A; 3]> = cwbvh.primitive_indices.iter().map(|&i| tris[i as usize].map(Vec3A::from)).collect();
        let prim_ids = cwbvh.primitive_indices.iter().map(|&i| valid[i as usize]).collect();
        Bvh { cwbvh, tris: ordered, prim_ids }
    }

    pub fn node_count(&self) -> usize {
        self.cwbvh.nodes.len()
    }

    /// Closest hit with t in (0, tmax): (t, original triangle index, b1, b2).
    #[inline]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, u32, f32, f32)> {
        if self.cwbvh.nodes.is_empty() || !(tmax > 0.0) {
            return None;
        }
        let shear = RayShear::new(o, d)?;
        let nr = NodeRay::new(o, d);
        let mut cur_tmax = tmax;
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut state = self.cwbvh.new_traversal(d.into());
        let mut node: &CwBvhNode;
        obvhs::traverse!(self.cwbvh, node, state, intersect_node(node, &nr, state.oct_inv4, cur_tmax), {
            let slot = state.primitive_id as usize;
            let [p0, p1, p2] = self.tris[slot];
            if let Some((t, b1, b2)) = triangle::intersect(&shear, p0, p1, p2, cur_tmax) {
                cur_tmax = t;
                best = Some((t, slot as u32, b1, b2));
            }
        });
        best.map(|(t, slot, b1, b2)| (t, self.prim_ids[slot as usize], b1, b2))
    }

    /// Any hit with t in (0, tmax).
    #[inline]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmax: f32) -> bool {
        if self.cwbvh.nodes.is_empty() || !(tmax > 0.0) {
            return false;
        }
        let Some(shear) = RayShear::new(o, d) else { return false };
        let nr = NodeRay::new(o, d);
        let mut state = self.cwbvh.new_traversal(d.into());
        let mut node: &CwBvhNode;
        let mut hit = false;
        'outer: {
            obvhs::traverse!(self.cwbvh, node, state, intersect_node(node, &nr, state.oct_inv4, tmax), {
                let [p0, p1, p2] = self.tris[state.primitive_id as usize];
                if triangle::intersect(&shear, p0, p1, p2, tmax).is_some() {
                    hit = true;
                    break 'outer;
                }
            });
        }
        hit
    }
}

/// Hit mask of the eight children of `node` (the CWBVH child-ordering bits, as obvhs's own test
/// produces them) for the ray segment (0, tmax).
#[inline(always)]
fn intersect_node(node: &CwBvhNode, r: &NodeRay, oct_inv4: u32, tmax: f32) -> u32 {
    let e = node.compute_extent();
    let adj_inv = e * r.inv_dir;
    let adj_orig = (Vec3A::from(node.p) - r.origin) * r.inv_dir;
    // Absolute rounding bound of q·adj_inv + adj_orig for q in [0, 255], per axis.
    let slack = (adj_orig.abs() + adj_inv.abs() * 255.0) * SLAB_WIDEN;
    let lo = adj_orig - slack;
    let hi = adj_orig + slack;
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mask = box_mask(node, r, adj_inv, lo, hi, tmax);
    let mut hit_mask = 0u32;
    let mut m = mask;
    while m != 0 {
        let child = m.trailing_zeros() as usize;
        m &= m - 1;
        let child_bits = ((child_bits8 >> (child * 8)) as u32) & 0xff;
        let bit_index = ((bit_index8 >> (child * 8)) as u32) & 0xff;
        hit_mask |= child_bits << bit_index;
    }
    hit_mask
}

/// Bit i set when child i's box overlaps the ray segment. Empty child slots have all-zero
/// quantized boxes; they may report a hit, but their child bits are zero so they add nothing.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn box_mask(node: &CwBvhNode, r: &NodeRay, adj_inv: Vec3A, lo: Vec3A, hi: Vec3A, tmax: f32) -> u32 {
    // SAFETY: SSE2 is part of the x86_64 baseline; all loads are from 8-byte arrays.
    unsafe {
        let zero = _mm_setzero_si128();
        // Eight u8 → two f32x4 (children 0-3 and 4-7).
        #[inline(always)]
        unsafe fn load8(v: &[u8; 8], zero: __m128i) -> (__m128, __m128) {
            unsafe {
                let b = _mm_loadl_epi64(v.as_ptr() as *const __m128i);
                let w = _mm_unpacklo_epi8(b, zero);
                (_mm_cvtepi32_ps(_mm_unpacklo_epi16(w, zero)), _mm_cvtepi32_ps(_mm_unpackhi_epi16(w, zero)))
            }
        }
        let (near_x, far_x) = if r.neg[0] { (&node.child_max_x, &node.child_min_x) } else { (&node.child_min_x, &node.child_max_x) };
        let (near_y, far_y) = if r.neg[1] { (&node.child_max_y, &node.child_min_y) } else { (&node.child_min_y, &node.child_max_y) };
        let (near_z, far_z) = if r.neg[2] { (&node.child_max_z, &node.child_min_z) } else { (&node.child_min_z, &node.child_max_z) };
        let (nx0, nx1) = load8(near_x, zero);
        let (fx0, fx1) = load8(far_x, zero);
        let (ny0, ny1) = load8(near_y, zero);
        let (fy0, fy1) = load8(far_y, zero);
        let (nz0, nz1) = load8(near_z, zero);
        let (fz0, fz1) = load8(far_z, zero);
        let ix = _mm_set1_ps(adj_inv.x);
        let iy = _mm_set1_ps(adj_inv.y);
        let iz = _mm_set1_ps(adj_inv.z);
        // With a negative direction component the near plane is the max plane; its slab
        // distance is still q·inv + orig, and the widening must move it towards smaller t.
        let (lx, hx) = (_mm_set1_ps(lo.x), _mm_set1_ps(hi.x));
        let (ly, hy) = (_mm_set1_ps(lo.y), _mm_set1_ps(hi.y));
        let (lz, hz) = (_mm_set1_ps(lo.z), _mm_set1_ps(hi.z));
        let t0 = _mm_setzero_ps();
        let t1 = _mm_set1_ps(tmax);
        let test = |nx, fx, ny, fy, nz, fz| {
            let tn = _mm_max_ps(
                _mm_max_ps(_mm_add_ps(_mm_mul_ps(nx, ix), lx), _mm_add_ps(_mm_mul_ps(ny, iy), ly)),
                _mm_max_ps(_mm_add_ps(_mm_mul_ps(nz, iz), lz), t0),
            );
            let tf = _mm_min_ps(
                _mm_min_ps(_mm_add_ps(_mm_mul_ps(fx, ix), hx), _mm_add_ps(_mm_mul_ps(fy, iy), hy)),
                _mm_min_ps(_mm_add_ps(_mm_mul_ps(fz, iz), hz), t1),
            );
            _mm_movemask_ps(_mm_cmple_ps(tn, tf)) as u32
        };
        test(nx0, fx0, ny0, fy0, nz0, fz0) | (test(nx1, fx1, ny1, fy1, nz1, fz1) << 4)
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn box_mask(node: &CwBvhNode, r: &NodeRay, adj_inv: Vec3A, lo: Vec3A, hi: Vec3A, tmax: f32) -> u32 {
    let mut mask = 0;
    for c in 0..8 {
        let pick = |neg: bool, mn: &[u8; 8], mx: &[u8; 8]| if neg { (mx[c] as f32, mn[c] as f32) } else { (mn[c] as f32, mx[c] as f32) };
        let (nx, fx) = pick(r.neg[0], &node.child_min_x, &node.child_max_x);
        let (ny, fy) = pick(r.neg[1], &node.child_min_y, &node.child_max_y);
        let (nz, fz) = pick(r.neg[2], &node.child_min_z, &node.child_max_z);
        let tn = (nx * adj_inv.x + lo.x).max(ny * adj_inv.y + lo.y).max(nz * adj_inv.z + lo.z).max(0.0);
        let tf = (fx * adj_inv.x + hi.x).min(fy * adj_inv.y + hi.y).min(fz * adj_inv.z + hi.z).min(tmax);
        if tn <= tf {
            mask |= 1 << c;
        }
    }
    mask
}
