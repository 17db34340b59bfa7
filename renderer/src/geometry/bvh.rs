//! The ray-query BVH: obvhs builds a binary BVH (PLOC, then reinsertion optimisation), which is
//! collapsed (`collapse.rs`: surface-area-optimal, by dynamic programming as in Ylitie et al.
//! 2017, "Efficient incoherent ray traversal on GPUs through compressed wide BVHs") into an
//! 8-wide BVH of our own layout — float child boxes in structure-of-arrays form, tested all
//! eight at once with AVX2 where the CPU has it (detected at run time, `avx2.rs`), else four at
//! a time with SSE2, with the same hits — whose leaves (up to 16 triangles, chosen by the surface
//! area heuristic) are blocks of four triangles stored side by side and tested together
//! (`tri4.rs`; under AVX2 two blocks at a time). This file holds the layout and the traversal:
//! children are visited nearest first, the stacked ones prefetched, and any stacked subtree that
//! starts beyond the closest hit found so far is skipped. Large node and leaf arrays live on
//! transparent huge pages (`pages.rs`).
//!
//! Why not obvhs's own CWBVH traversal (the previous version, 0.41–0.45× Embree): its node test
//! dequantises child boxes on every visit, it orders children by ray octant rather than by
//! distance, and a subtree pushed on its stack is never re-culled against a closer hit found
//! later. Why not its box test: it clamps entry distances to 1e-4 (culling every hit closer than
//! that — fatal for a scene of size 1e-3) and shrinks 1/d for |d| < f32::EPSILON.
//!
//! Watertightness: the triangle test is Woop et al.'s (see `triangle.rs`), evaluated four
//! triangles at a time with exactly the same floating-point operations as the scalar version,
//! and the box test is conservative (every slab distance is widened by more than its rounding
//! error), so no ray that crosses a triangle's edge can be culled or slip through.

mod collapse;
mod pages;
mod tri4;

use super::triangle;
use collapse::Collapser;
use glam::{BVec4A, Vec3, Vec3A, Vec4, Vec4Swizzles};
use obvhs::aabb::Aabb;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::ploc::PlocBuilder;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use pages::Pages;
use std::hint::select_unpredictable;
use std::mem::MaybeUninit;
use tri4::{tri4_fast, tri4_scalar, Tri4, Tri4Result};

/// Children per node.
const W: usize = 8;
/// Groups of four children per node (one `Vec4` per group and box plane).
const G: usize = W / 4;
/// Largest leaf the surface-area heuristic may choose (four `Tri4` blocks).
const LEAF_CAP: u32 = 16;
/// Surface-area-heuristic cost of a node visit relative to one `Tri4` test, for the optimal
/// wide collapse of a mesh too large for the caches (more than `SMALL_MESH` triangles).
/// Measured on the displaced sphere (`examples/bvh_ab.rs`, docs/performance.md): 1 gives many
/// one-block leaves (38k leaves, nodes 6.9 of 8 full, 7.9 node visits per random ray); 3–5 give
/// fuller leaves and fewer nodes (3.4k at 3, 7.3 visits) and trace ~10% faster, within noise of
/// each other with one-block leaf tests. With AVX2's two-block leaf test (`avx2::tri8_test`),
/// which makes big leaves cheaper, 5 (2.5k nodes, 7.0 visits, 4.1 blocks per random ray) was
/// 2–4% faster than 3 in three A/B runs.
pub const C_NODE: f32 = 5.0;
/// The node cost for meshes of at most `SMALL_MESH` triangles, whose BVH stays in cache, so a
/// node visit costs about what a block test does. On the Cornell box (36 triangles), 3 makes
/// one node of eight leaves, as fast in the ray benchmark but ~7% slower in the integrator
/// (whose rays start on the walls) than 1.
pub const C_NODE_SMALL: f32 = 1.0;
/// Largest mesh collapsed with `C_NODE_SMALL`: 4096 triangles are ~200 KB of `Tri4` blocks.
/// (Chosen, not tuned: only 36 and 105,800 triangles were measured.)
pub const SMALL_MESH: usize = 4096;

/// The node cost for a mesh of `triangles` triangles.
pub fn node_cost(triangles: usize) -> f32 {
    if triangles <= SMALL_MESH {
        C_NODE_SMALL
    } else {
        C_NODE
    }
}
/// Most `Tri4` blocks in one leaf (the block count has 4 bits in a child reference).
const LEAF_BLOCKS_MAX: usize = 16;
/// Child reference: bit 31 set for a leaf, whose bits 27..31 hold the block count − 1 and bits
/// 0..27 the first block; otherwise the node index.
const LEAF_BIT: u32 = 1 << 31;
const BLOCK_BITS: u32 = 27;
/// Traversal stack entries kept on the call stack; deeper trees use a heap stack.
const STACK: usize = 256;

/// Relative widening of every slab distance, applied to the reciprocal direction once a ray
/// (`RayData::inv_lo`, `inv_hi`) rather than to each visit's distances, which put a multiply
/// on the chain from a node's load to its mask. (p − o)·((1/d)·(1 ± w)) is four roundings (of
/// p − o, of 1/d, of the scaling and of the product) away from (p − o)/d·(1 ± w), at most
/// 4·2^-24 relative, which w = 2^-20 covers with margin.
pub(super) const SLAB_WIDEN: f32 = 1.0 / (1 << 20) as f32;
/// The AVX2 node test's distances are fma(p, inv, c) with c ≈ −o·inv: the product p·inv is
/// rounded relative to |p·inv| ≤ |o·inv| + |t| (not to |t|, as (p − o)·inv is), and c twice
/// relative to |o·inv|. Five roundings of at most 2^-24·|o·inv| each, so each axis's entry is
/// moved down and its exit up by |o·inv|·2^-19 (32 × 2^-24, in `RayData::c_lo`, `c_hi`); the
/// parts relative to |t| are `SLAB_WIDEN`'s. A box grows by about |o|·2^-19 in world units.
const FMA_WIDEN: f32 = 1.0 / (1 << 19) as f32;
/// Smallest |d| component used for the reciprocal. 1/1e-20 stays finite through every product in
/// the box test for coordinates up to ~1e12, and an exactly axis-parallel ray then gets slabs
/// that extend ~1e20 · (distance to the plane) — far beyond any scene.
pub(super) const MIN_DIR: f32 = 1e-20;

/// Build parameters, chosen by measurement: with this BVH, obvhs's presets from
/// `very_fast_build` to `slow_build` (pre-splits, wider PLOC search, more reinsertion) traced the
/// displaced sphere within the noise of each other (±10%), and `very_fast_build` builds fastest.
pub fn default_build_params() -> BvhBuildParams {
    BvhBuildParams::very_fast_build()
}

/// Build parameters for a mesh of `triangles` triangles: `default_build_params`, except for a
/// mesh of at most `SMALL_MESH` triangles, which gets obvhs's `medium_build` (a wider PLOC
/// search and more reinsertion; milliseconds at that size). On the Cornell box it makes a BVH
/// of 2 nodes instead of 3 and traced its random rays 8 % and the integrator's paths 2–3 %
/// faster (`bvh_ab 1 1::medium`, `wave_ab`; docs/performance.md).
pub fn build_params(triangles: usize) -> BvhBuildParams {
    if triangles <= SMALL_MESH {
        BvhBuildParams::medium_build()
    } else {
        default_build_params()
    }
}

/// One 8-wide node: child boxes as [min x, min y, min z, max x, max y, max z][group], lane i of
/// group g being child 4g + i. Empty slots have an inverted infinite box and no bit in `valid`,
/// by which the node test drops them (its per-axis nearer and farther plane would enter an
/// inverted box).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Node {
    b: [[Vec4; G]; 6],
    child: [u32; W],
    /// Bit i set where slot i holds a child.
    valid: u32,
}

pub struct Bvh {
    nodes: Pages<Node>,
    blocks: Pages<Tri4>,
    /// Traversal stack entries the deepest path can need.
    stack_need: usize,
    /// Whether traversal prefetches the subtrees it stacks: only for a BVH larger than
    /// `PREFETCH_MIN_BYTES`, which waits on memory; a small one stays in L1/L2, where the
    /// four prefetches per stacked child are only instructions.
    prefetch_stacked: bool,
    /// Set where the CPU has AVX2 and FMA: traversal then tests the eight children of a node
    /// in one 8-wide AVX operation (`avx2::node_test`) instead of two SSE2 ones.
    #[cfg(target_arch = "x86_64")]
    avx2: Option<avx2::Avx2>,
}

/// Per-ray constants of the box and triangle tests.
struct RayData {
    /// Ray origin and reciprocal direction, splatted; the reciprocal scaled towards zero
    /// (`inv_lo`, for entry distances) and away from it (`inv_hi`, exit) by `SLAB_WIDEN`.
    o: [Vec4; 3],
    inv_lo: [Vec4; 3],
    inv_hi: [Vec4; 3],
    /// −o·inv_lo − e and −o·inv_hi + e per axis, for the AVX2 node test's fused
    /// p·inv + c (`avx2::node_test`): e = |o·inv|·`FMA_WIDEN` covers the rounding of these
    /// products, which is relative to o·inv rather than to the distance.
    c_lo: [Vec4; 3],
    c_hi: [Vec4; 3],
    /// Shear (Woop et al.): axes kx, ky, kz (kz dominant), factors sx, sy, sz, both splatted and
    /// scalar.
    k: [usize; 3],
    s: [Vec4; 3],
    ss: [f32; 3],
}

impl RayData {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> Option<RayData> {
        // 0·x is ±0 for a finite x and NaN otherwise: one test for all six components.
        let (ov, dv) = (Vec3A::from(o), Vec3A::from(d));
        if !(ov * 0.0 + dv * 0.0).cmpeq(Vec3A::ZERO).all() {
            return None;
        }
        // `triangle::shear_perm`'s axes. The permuted components are picked by vector selects of
        // swizzles: not read back at a computed index (a store and a reload on the way to the
        // division), and not by scalar selects, which LLVM compiled as branches on the dominant
        // axis and its sign even with `select_unpredictable` (four or five a ray, each taken
        // either way at random for random rays).
        let a = d.abs();
        let (z0, z1) = ((a.x > a.y) & (a.x > a.z), !(a.x > a.y) & (a.y > a.z));
        let d4 = Vec4::new(d.x, d.y, d.z, 0.0);
        let p = Vec4::select(BVec4A::splat(z0), d4.yzxw(), Vec4::select(BVec4A::splat(z1), d4.zxyw(), d4));
        let dkz = p.z;
        if dkz == 0.0 {
            return None;
        }
        let kz = 2 - z1 as usize - 2 * z0 as usize;
        let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
        let flip = dkz < 0.0;
        // Element by element: a select of two arrays was compiled as two arrays stored and
        // one read back through a pointer chosen by a cmov, in a 16-byte load that the
        // 8-byte stores could not forward (3.5 % of the random rays' samples on Zen 4).
        let k = [select_unpredictable(flip, ky, kx), select_unpredictable(flip, kx, ky), kz];
        let clamp = |x: f32| if x.abs() < MIN_DIR { MIN_DIR.copysign(x) } else { x };
        // The three reciprocals and the shear's 1/d[kz] in one division (each lane rounds as
        // the scalar division would): four scalar divisions were a latency chain at the start
        // of every query.
        let [ix, iy, iz, sz] = (Vec4::ONE / Vec4::new(clamp(d.x), clamp(d.y), clamp(d.z), dkz)).to_array();
        let p = Vec4::select(BVec4A::splat(flip), p.yxzw(), p);
        let (dkx, dky) = (p.x, p.y);
        let (sx, sy) = (dkx * sz, dky * sz);
        let (il, ih) = (Vec3::new(ix, iy, iz) * (1.0 - SLAB_WIDEN), Vec3::new(ix, iy, iz) * (1.0 + SLAB_WIDEN));
        let e = (o * Vec3::new(ix, iy, iz)).abs() * FMA_WIDEN;
        let (c_lo, c_hi) = (-(o * il) - e, -(o * ih) + e);
        Some(RayData {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            c_lo: [Vec4::splat(c_lo.x), Vec4::splat(c_lo.y), Vec4::splat(c_lo.z)],
            c_hi: [Vec4::splat(c_hi.x), Vec4::splat(c_hi.y), Vec4::splat(c_hi.z)],
            inv_lo: [Vec4::splat(ix * (1.0 - SLAB_WIDEN)), Vec4::splat(iy * (1.0 - SLAB_WIDEN)), Vec4::splat(iz * (1.0 - SLAB_WIDEN))],
            inv_hi: [Vec4::splat(ix * (1.0 + SLAB_WIDEN)), Vec4::splat(iy * (1.0 + SLAB_WIDEN)), Vec4::splat(iz * (1.0 + SLAB_WIDEN))],
            k,
            s: [Vec4::splat(sx), Vec4::splat(sy), Vec4::splat(sz)],
            ss: [sx, sy, sz],
        })
    }
}

/// Traversal stack entry: child reference and its entry distance.
type StackEntry = MaybeUninit<(u32, f32)>;
type Stack = [StackEntry; STACK];

/// Hit record inside the traversal: t, original triangle index, b1, b2.
type HitRec = (f32, u32, f32, f32);

/// What an any-hit (`ANY`) leaf test reports for a hit: a placeholder, since `occluded` only
/// asks whether there is one.
const ANY_HIT: HitRec = (0.0, u32::MAX, 0.0, 0.0);

/// What a traversal did, for statistics (`Bvh::intersect_counted`); the benchmark traversal
/// uses `NoProbe`, which compiles to nothing.
trait Probe {
    fn node(&mut self);
    fn block(&mut self);
}

struct NoProbe;

impl Probe for NoProbe {
    #[inline(always)]
    fn node(&mut self) {}
    #[inline(always)]
    fn block(&mut self) {}
}

/// Node visits and `Tri4` block tests summed over the rays counted.
#[derive(Clone, Copy, Debug, Default)]
pub struct TraversalCounts {
    pub rays: u64,
    pub nodes: u64,
    pub blocks: u64,
}

impl Probe for TraversalCounts {
    fn node(&mut self) {
        self.nodes += 1;
    }
    fn block(&mut self) {
        self.blocks += 1;
    }
}

/// Shape of the wide BVH.
#[derive(Clone, Copy, Debug)]
pub struct BvhShape {
    pub nodes: usize,
    /// Children (inner and leaf) per node, on average, of `W`.
    pub avg_fill: f64,
    pub leaves: usize,
    pub blocks: usize,
}

impl Bvh {
    /// `valid` lists the triangles to put in the BVH (the non-degenerate ones); `tris` are
    /// their vertices, indexed like `valid`. `c_node` is the surface-area-heuristic cost of a
    /// node visit relative to a `Tri4` test (`node_cost` unless tuning).
    pub fn build(tris: Vec<[Vec3; 3]>, valid: Vec<u32>, params: BvhBuildParams, c_node: f32) -> Bvh {
        debug_assert_eq!(tris.len(), valid.len());
        if tris.is_empty() {
            return Bvh::new(Vec::new(), Vec::new(), 0);
        }
        let obvhs_tris: Vec<Triangle> = tris.iter().map(|t| Triangle { v0: t[0].into(), v1: t[1].into(), v2: t[2].into() }).collect();
        let indices: Vec<u32> = (0..tris.len() as u32).collect();
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
        Collapser::new(&bvh2, &tris, &valid, c_node).run()
    }

    fn new(nodes: Vec<Node>, blocks: Vec<Tri4>, stack_need: usize) -> Bvh {
        let bytes = nodes.len() * std::mem::size_of::<Node>() + blocks.len() * std::mem::size_of::<Tri4>();
        Bvh {
            prefetch_stacked: bytes > PREFETCH_MIN_BYTES,
            nodes: Pages::new(nodes),
            blocks: Pages::new(blocks),
            stack_need,
            #[cfg(target_arch = "x86_64")]
            avx2: avx2::Avx2::detect(),
        }
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Whether traversal uses the AVX2 node test; `enable` asks for it (it is used only where
    /// the CPU has AVX2 and FMA, the default there) or for the SSE2 one (for tests and A/B
    /// benchmarks: both give identical results).
    pub fn set_avx2(&mut self, enable: bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            self.avx2 = if enable { avx2::Avx2::detect() } else { None };
            self.avx2.is_some()
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = enable;
            false
        }
    }

    /// Under AVX2, whether the query is compiled with AVX-512's registers too (the default where
    /// the CPU has AVX-512 F and VL; `query_avx512`) or not (for tests and A/B benchmarks: the
    /// same operations, so identical results); false without them.
    pub fn set_avx512(&mut self, enable: bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(isa) = &mut self.avx2 {
            isa.avx512 = enable && is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl");
            return isa.avx512;
        }
        let _ = enable;
        false
    }

    /// Under AVX2, whether leaves are tested two `Tri4` blocks at a time (the default, except
    /// on a CPU that splits 256-bit operations, `avx2::splits_256_bit_operations`) or one (for
    /// tests and A/B benchmarks: both give identical results); false without AVX2.
    pub fn set_tri8(&mut self, enable: bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(isa) = &mut self.avx2 {
            isa.tri8 = enable;
            return enable;
        }
        let _ = enable;
        false
    }

    /// Whether the node and leaf arrays are on huge pages where they are large (the default,
    /// `Pages`) or on ordinary ones (for A/B benchmarks: the same traversal).
    pub fn set_huge_pages(&mut self, enable: bool) {
        let (nodes, blocks) = (self.nodes.to_vec(), self.blocks.to_vec());
        (self.nodes, self.blocks) =
            if enable { (Pages::new(nodes), Pages::new(blocks)) } else { (Pages::in_vec(nodes), Pages::in_vec(blocks)) };
    }

    pub fn shape(&self) -> BvhShape {
        let children = self.nodes.iter().flat_map(|n| n.child).filter(|&c| c != u32::MAX);
        let (mut filled, mut leaves) = (0, 0);
        for c in children {
            filled += 1;
            leaves += (c & LEAF_BIT != 0) as usize;
        }
        BvhShape { nodes: self.nodes.len(), avg_fill: filled as f64 / self.nodes.len().max(1) as f64, leaves, blocks: self.blocks.len() }
    }

    /// `intersect`, counting node visits and block tests into `counts`.
    pub fn intersect_counted(&self, o: Vec3, d: Vec3, tmax: f32, counts: &mut TraversalCounts) -> Option<(f32, u32, f32, f32)> {
        counts.rays += 1;
        if self.nodes.is_empty() || !(tmax > 0.0) {
            return None;
        }
        let r = RayData::new(o, d)?;
        let mut best = None;
        let (mut fixed, mut heap): (Stack, _) = ([MaybeUninit::uninit(); STACK], Vec::new());
        let stack = self.stack(&mut fixed, &mut heap);
        self.traverse::<false, _, _>(Sse2, &r, tmax, &mut best, stack, counts);
        best
    }

    /// Closest hit with t in (0, tmax): (t, original triangle index, b1, b2).
    #[inline(always)]
    pub fn intersect(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<(f32, u32, f32, f32)> {
        #[cfg(target_arch = "x86_64")]
        if let Some(isa) = self.avx2 {
            // SAFETY: an `Avx2` exists only where `Avx2::detect` found AVX2, FMA and POPCNT on this CPU.
            if isa.avx512 {
                return unsafe { self.query_avx512::<false>(isa, o.x, o.y, o.z, d.x, d.y, d.z, tmax) };
            }
            return unsafe { self.query_avx2::<false>(isa, o.x, o.y, o.z, d.x, d.y, d.z, tmax) };
        }
        self.query::<false, _>(Sse2, o, d, tmax)
    }

    /// Any hit with t in (0, tmax).
    #[inline(always)]
    pub fn occluded(&self, o: Vec3, d: Vec3, tmax: f32) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some(isa) = self.avx2 {
            // SAFETY: as in `intersect`.
            if isa.avx512 {
                return unsafe { self.query_avx512::<true>(isa, o.x, o.y, o.z, d.x, d.y, d.z, tmax) }.is_some();
            }
            return unsafe { self.query_avx2::<true>(isa, o.x, o.y, o.z, d.x, d.y, d.z, tmax) }.is_some();
        }
        self.query::<true, _>(Sse2, o, d, tmax).is_some()
    }

    /// `intersect` (or with `ANY`, `occluded`) with node test `isa`.
    #[inline(always)]
    fn query<const ANY: bool, T: NodeTest>(&self, isa: T, o: Vec3, d: Vec3, tmax: f32) -> Option<HitRec> {
        if self.nodes.is_empty() || !(tmax > 0.0) {
            return None;
        }
        let r = RayData::new(o, d)?;
        let mut best = None;
        // No closure here (a `with_stack(|stack| …)`): a closure is a function of its own,
        // compiled without `query_avx2`'s target features unless inlined.
        let (mut fixed, mut heap): (Stack, _) = ([MaybeUninit::uninit(); STACK], Vec::new());
        let stack = self.stack(&mut fixed, &mut heap);
        self.traverse::<ANY, _, _>(isa, &r, tmax, &mut best, stack, &mut NoProbe);
        best
    }

    /// A traversal stack of `stack_need` entries: `fixed` on the call stack where that is
    /// enough, else `heap`.
    #[inline(always)]
    fn stack<'s>(&self, fixed: &'s mut Stack, heap: &'s mut Vec<StackEntry>) -> &'s mut [StackEntry] {
        if self.stack_need <= STACK {
            fixed
        } else {
            heap.resize(self.stack_need, MaybeUninit::uninit());
            heap
        }
    }

    /// `query` with the AVX2 node test, compiled with AVX2 and FMA enabled (so the rest of the
    /// query, inlined here, is VEX-encoded too; Rust never fuses a multiply and an add by
    /// itself, so only the node test's explicit ones differ, and results stay bit-identical to
    /// the SSE2 path's, `avx2::node_test`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt")]
    ///
    /// The ray comes as six scalars, which arrive in registers: as two `Vec3`s it was passed
    /// through memory, and the callers' component-wise stores could not be forwarded to the
    /// 8-byte load here (a stall on every query, 8% of this function's samples).
    fn query_avx2<const ANY: bool>(
        &self,
        isa: avx2::Avx2,
        ox: f32,
        oy: f32,
        oz: f32,
        dx: f32,
        dy: f32,
        dz: f32,
        tmax: f32,
    ) -> Option<HitRec> {
        self.query::<ANY, _>(isa, Vec3::new(ox, oy, oz), Vec3::new(dx, dy, dz), tmax)
    }

    /// `query_avx2` compiled for a CPU that also has AVX-512 (F and VL): the same 256-bit
    /// operations, so the same results bit for bit, but LLVM gets 32 vector registers instead of
    /// 16 (the two-block leaf test spilled to the stack with 16) and compares into mask
    /// registers. 2–5 % faster in the ray benchmark (docs/performance.md).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,popcnt,avx512f,avx512vl")]
    fn query_avx512<const ANY: bool>(
        &self,
        isa: avx2::Avx2,
        ox: f32,
        oy: f32,
        oz: f32,
        dx: f32,
        dy: f32,
        dz: f32,
        tmax: f32,
    ) -> Option<HitRec> {
        self.query::<ANY, _>(isa, Vec3::new(ox, oy, oz), Vec3::new(dx, dy, dz), tmax)
    }

    /// Closest hit (or, with `ANY`, the first hit found) in (0, tmax), into `best`.
    /// `stack` holds at least `stack_need` entries.
    #[inline(always)]
    fn traverse<const ANY: bool, P: Probe, T: NodeTest>(
        &self,
        isa: T,
        r: &RayData,
        mut tmax: f32,
        best: &mut Option<HitRec>,
        stack: &mut [MaybeUninit<(u32, f32)>],
        probe: &mut P,
    ) {
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT == 0 {
                let node = &self.nodes[cur as usize];
                probe.node();
                let (mask, tnear) = isa.node_test(node, r, tmax);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        cur = node.child[first];
                        continue;
                    }
                    // The hit children go on the stack, the nearest last, which is popped at
                    // once, so it is the next node: distances decreasing upwards. Ordered
                    // without branching on distances, which for incoherent rays compare either
                    // way at random: two children by a select, more each straight to its
                    // place, the number of hit children stacked below it (`NodeTest::below`,
                    // which also orders equal distances). An insertion sort, branching on every
                    // comparison, traced the displaced sphere's random rays 6-9 % slower
                    // (docs/performance.md). A shadow ray stops at any hit, so order only pays
                    // for closest hits.
                    if rest & (rest - 1) == 0 {
                        let second = rest.trailing_zeros() as usize;
                        let (a, b) = ((node.child[first], tnear[first]), (node.child[second], tnear[second]));
                        if self.prefetch_stacked {
                            self.prefetch(a.0);
                            self.prefetch(b.0);
                        }
                        let (far, near) = select_unpredictable(a.1 < b.1, (b, a), (a, b));
                        stack[sp] = MaybeUninit::new(far);
                        sp += 1;
                        cur = near.0;
                        continue;
                    }
                    let base = sp;
                    let top = mask.count_ones() as usize - 1;
                    let mut next = 0;
                    let mut m = mask;
                    while m != 0 {
                        let c = m.trailing_zeros() as usize;
                        m &= m - 1;
                        let e = (node.child[c], tnear[c]);
                        if self.prefetch_stacked {
                            self.prefetch(e.0);
                        }
                        let place = if ANY { sp - base } else { (isa.below(&tnear, c) & mask).count_ones() as usize };
                        stack[base + place] = MaybeUninit::new(e);
                        next = select_unpredictable(place == top, e.0, next);
                        sp += 1;
                    }
                    sp -= 1;
                    cur = next;
                    continue;
                }
            } else {
                let first = (cur & ((1 << BLOCK_BITS) - 1)) as usize;
                let n = ((cur & !LEAF_BIT) >> BLOCK_BITS) as usize + 1;
                if isa.leaf_test::<ANY, P>(&self.blocks[first..first + n], r, &mut tmax, best, probe) {
                    return;
                }
            }
            // Pop the next subtree that may still hold a closer hit.
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                // SAFETY: entries below sp were written by pushes.
                let (c, t) = unsafe { stack[sp].assume_init() };
                if t < tmax {
                    cur = c;
                    break;
                }
            }
        }
    }
}

/// Smallest BVH (nodes and blocks) whose traversal prefetches: a mesh of `SMALL_MESH`
/// triangles has ~200 KB of blocks, which this CPU's 1 MiB L2 keeps.
const PREFETCH_MIN_BYTES: usize = 256 << 10;

impl Bvh {
    /// Starts loading a stacked subtree's node or leaf block while the nearer one is traversed:
    /// traversal of a mesh that does not fit in L2 waits mostly on memory, and this overlaps
    /// the waits.
    #[inline(always)]
    fn prefetch(&self, c: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let p = if c & LEAF_BIT == 0 {
                self.nodes.as_ptr().wrapping_add(c as usize) as *const i8
            } else {
                self.blocks.as_ptr().wrapping_add((c & ((1 << BLOCK_BITS) - 1)) as usize) as *const i8
            };
            // Two nodes' lines for either kind: the child and the next node in the array,
            // which the collapse writes as the child's sibling, often stacked too; of a leaf,
            // its first three blocks, or its blocks and its sibling leaf's first. With four
            // lines (one node) the displaced sphere's random rays traced 1.4–5 % slower on
            // Zen 4 in one process (docs/performance.md, "A Zen 4 machine"). A count by kind
            // made a loop whose exit mispredicted as the kinds alternate; fixed, the sphere
            // traced 3–5 % faster ("A Zen 1 machine").
            const LINES: usize = 2 * std::mem::size_of::<Node>() / 64;
            for l in 0..LINES {
                // SAFETY: prefetching is a hint and never faults, even for an address outside
                // the allocation (wrapping_add keeps the pointer arithmetic defined).
                unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * l)) };
            }
        }
    }
}

/// A node test, for traversal to be monomorphised over.
trait NodeTest: Copy {
    /// Hit mask and conservative entry distances of the eight children of `node` for the ray
    /// segment (0, tmax).
    fn node_test(self, node: &Node, r: &RayData, tmax: f32) -> (u32, [f32; W]);

    /// The lanes to stack below lane `c` among a node's hit children, a mask that gives every
    /// lane its own place: those whose entry distance `tnear` is greater, and of equal ones
    /// here the lower lanes.
    #[inline(always)]
    fn below(self, tnear: &[f32; W], c: usize) -> u32 {
        let t4 = Vec4::splat(tnear[c]);
        let (a, b) = (Vec4::from_slice(&tnear[..4]), Vec4::from_slice(&tnear[4..]));
        let (farther, equal) = (a.cmpgt(t4).bitmask() | b.cmpgt(t4).bitmask() << 4, a.cmpeq(t4).bitmask() | b.cmpeq(t4).bitmask() << 4);
        farther | (equal & ((1 << c) - 1))
    }

    /// Tests the blocks of a leaf in order, each against the closest hit so far (`tmax`,
    /// `best`); true where `ANY` and a hit was found (traversal then stops).
    #[inline(always)]
    fn leaf_test<const ANY: bool, P: Probe>(
        self,
        blocks: &[Tri4],
        r: &RayData,
        tmax: &mut f32,
        best: &mut Option<HitRec>,
        probe: &mut P,
    ) -> bool {
        leaf_test_tri4::<ANY, P>(blocks, r, tmax, best, probe)
    }
}

/// `NodeTest::leaf_test` one `Tri4` block at a time.
#[inline(always)]
fn leaf_test_tri4<const ANY: bool, P: Probe>(
    blocks: &[Tri4],
    r: &RayData,
    tmax: &mut f32,
    best: &mut Option<HitRec>,
    probe: &mut P,
) -> bool {
    for blk in blocks {
        probe.block();
        let tie_id = best.map_or(0, |h| h.1);
        let h = match tri4_fast::<ANY>(blk, r, *tmax, tie_id) {
            Tri4Result::Miss => continue,
            Tri4Result::Hit(h) => h,
            Tri4Result::EdgeZero => match tri4_scalar(blk, r, *tmax, tie_id) {
                Some(h) => h,
                None => continue,
            },
        };
        *tmax = h.0;
        *best = Some(h);
        if ANY {
            return true;
        }
    }
    false
}

/// The baseline node test: glam's `Vec4`, SSE2 on x86-64 (scalar or NEON elsewhere).
#[derive(Clone, Copy)]
struct Sse2;

impl NodeTest for Sse2 {
    #[inline(always)]
    fn node_test(self, node: &Node, r: &RayData, tmax: f32) -> (u32, [f32; W]) {
        node_test(node, r, tmax)
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2;

/// Hit mask and conservative entry distances of the eight children of `node` for the ray
/// segment (0, tmax).
#[inline(always)]
fn node_test(node: &Node, r: &RayData, tmax: f32) -> (u32, [f32; W]) {
    let tmax4 = Vec4::splat(tmax);
    let mut mask = 0;
    let mut tnear = [0.0f32; W];
    for g in 0..G {
        let t = |plane: usize, axis: usize| {
            let p = node.b[plane][g] - r.o[axis];
            (p * r.inv_lo[axis], p * r.inv_hi[axis])
        };
        // Entry and exit along each axis are the nearer and farther of its two planes, by a
        // min and a max: planes picked per ray by the direction's signs cost the ray's setup
        // and every visit six indexed loads (the Cornell box's rays traced 7–14 % slower).
        let ((x0, x0h), (x1, x1h), (y0, y0h), (y1, y1h), (z0, z0h), (z1, z1h)) = (t(0, 0), t(3, 0), t(1, 1), t(4, 1), t(2, 2), t(5, 2));
        // Rounding keeps signs, so a box behind the ray stays behind; scaling a distance
        // towards zero (entry) or away from it (exit) covers its rounding error.
        let tn = x0.min(x1).max(y0.min(y1)).max(z0.min(z1).max(Vec4::ZERO));
        let tf = x0h.max(x1h).min(y0h.max(y1h)).min(z0h.max(z1h).min(tmax4));
        mask |= tn.cmple(tf).bitmask() << (4 * g);
        tnear[4 * g..4 * g + 4].copy_from_slice(&tn.to_array());
    }
    (mask & node.valid, tnear)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `RayData::new` picks its shear by selects; it must be `triangle::shear_axes`'s exactly
    /// (axes and factors bit for bit, the same rays refused), or the BVH's triangle test would
    /// disagree with the scalar one. Directions with tied magnitudes, zeros and every sign
    /// pattern, which decide the dominant axis and the swap, plus random ones.
    #[test]
    fn ray_shear_matches_triangle_shear_axes() {
        let vals = [0.0f32, -0.0, 1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 1e-30, -3e38];
        let mut dirs = Vec::new();
        for &x in &vals {
            for &y in &vals {
                for &z in &vals {
                    dirs.push(Vec3::new(x, y, z));
                }
            }
        }
        let mut rng = crate::rng::Pcg32::new(9, 0);
        for _ in 0..10_000 {
            dirs.push(Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5));
        }
        let mut checked = 0;
        for d in dirs {
            let want = triangle::shear_axes(d);
            let got = RayData::new(Vec3::new(0.25, -1.0, 3.0), d);
            assert_eq!(want.is_some(), got.is_some(), "direction {d:?}");
            let (Some((k, s)), Some(r)) = (want, got) else { continue };
            assert_eq!(k, r.k, "axes of {d:?}");
            assert_eq!(s.map(f32::to_bits), r.ss.map(f32::to_bits), "factors of {d:?}");
            checked += 1;
        }
        assert!(checked > 10_000, "only {checked} directions had a shear");
    }

    /// The node tests never cull a child box that the ray segment (0, tmax) touches, and never
    /// put its entry past the true one (traversal culls stacked children by it): checked
    /// against the slab test in f64, whose error is far below `SLAB_WIDEN`, on lines aimed at
    /// box edges and corners (so that entry and exit nearly meet), at scales 1e-3 to 1e4, with
    /// flat boxes and segments ending at the box. Without the widening (`SLAB_WIDEN` = 0) the
    /// f32 test culls some of these boxes.
    #[test]
    fn node_tests_never_cull_a_box_the_segment_touches() {
        let mut rng = crate::rng::Pcg32::new(23, 0);
        let (mut checked, mut close) = (0, 0);
        for _ in 0..5000 {
            let scale = 10f32.powi(rng.below(8) as i32 - 3);
            // Half the rays and their boxes 10^2 to 10^5 times their size from the world origin,
            // where the AVX2 test's fused distances round relative to |o·inv| (`FMA_WIDEN`).
            let base = if rng.next_f32() < 0.5 {
                Vec3::ZERO
            } else {
                Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5) * 10f32.powi(rng.below(4) as i32 + 2) * scale
            };
            let o = base + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5) * 4.0 * scale;
            let d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5);
            // Components below `MIN_DIR`'s clamp would test a slightly different line.
            if d.abs().min_element() < 1e-3 {
                continue;
            }
            let Some(r) = RayData::new(o, d) else { continue };
            let mut node = Node { b: [[Vec4::ZERO; G]; 6], child: [0; W], valid: (1 << W) - 1 };
            let mut tmax = [f32::INFINITY; W];
            for (lane, seg) in tmax.iter_mut().enumerate() {
                let lo = base + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 * scale - 2.0 * scale;
                let ext = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale;
                // Every fourth box flat along one axis.
                let ext = if lane % 4 == 0 { ext * Vec3::new(0.0, 1.0, 1.0) } else { ext };
                let hi = lo + ext;
                // A point on an edge or corner of the box, the line from o through it.
                let mut p = lo + ext * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                for axis in 0..3 {
                    if rng.next_f32() < 0.7 {
                        p[axis] = if rng.next_f32() < 0.5 { lo[axis] } else { hi[axis] };
                    }
                }
                let s = (p - o).dot(d) / d.length_squared();
                // The line through o along d passes p's projection; shift the box so that p
                // lies on the line (up to f32 rounding, which makes entry and exit nearly meet).
                let shift = o + d * s - p;
                let (lo, hi) = (lo + shift, hi + shift);
                for axis in 0..3 {
                    node.b[axis][lane / 4][lane % 4] = lo[axis];
                    node.b[3 + axis][lane / 4][lane % 4] = hi[axis];
                }
                // Some segments end at the point itself.
                if rng.next_f32() < 0.25 && s > 0.0 {
                    *seg = s;
                }
            }
            let (node, r) = (&node, &r);
            type Test<'a> = Box<dyn Fn(f32) -> (u32, [f32; W]) + 'a>;
            let mut isas: Vec<Test> = vec![Box::new(move |t| node_test(node, r, t))];
            #[cfg(target_arch = "x86_64")]
            if let Some(a) = avx2::Avx2::detect() {
                isas.push(Box::new(move |t| a.node_test(node, r, t)));
            }
            for lane in 0..W {
                let (mut entry, mut exit) = (0.0f64, tmax[lane] as f64);
                for axis in 0..3 {
                    let (ta, tb) = (
                        (node.b[axis][lane / 4][lane % 4] as f64 - o[axis] as f64) / d[axis] as f64,
                        (node.b[3 + axis][lane / 4][lane % 4] as f64 - o[axis] as f64) / d[axis] as f64,
                    );
                    entry = entry.max(ta.min(tb));
                    exit = exit.min(ta.max(tb));
                }
                if entry > exit {
                    continue;
                }
                checked += 1;
                close += (exit - entry <= 1e-6 * entry.abs().max(exit.abs())) as usize;
                for test in &isas {
                    let (mask, tnear) = test(tmax[lane]);
                    assert!(
                        mask >> lane & 1 == 1,
                        "culled: box {lane} of {:?}, ray {o} {d}, tmax {}, entry {entry} exit {exit}",
                        node.b,
                        tmax[lane]
                    );
                    assert!(tnear[lane] as f64 <= entry, "entry {} past {entry}", tnear[lane]);
                }
            }
        }
        assert!(checked > 10_000 && close > 1000, "{checked} boxes touched, {close} of them nearly at a single point");
    }

    /// The heap stack (for trees deeper than `STACK` allows) gives the same answers as the
    /// fixed one, and a mesh of nested triangles at scales 1 … 2^-40 (a deep binary tree)
    /// still matches the scalar test on every triangle.
    #[test]
    fn heap_stack_and_deep_trees_agree_with_brute_force() {
        let mut tris = Vec::new();
        for k in 0..400 {
            let s = 0.5f32.powi(k / 10) * (1.0 + (k % 10) as f32 * 0.05);
            tris.push([Vec3::new(-s, -s, s * 0.1), Vec3::new(s, -s, s * 0.2), Vec3::new(0.0, s, s * 0.3)]);
        }
        let valid: Vec<u32> = (0..tris.len() as u32).collect();
        let bvh = Bvh::build(tris.clone(), valid, default_build_params(), node_cost(400));
        let mut heap = Bvh::new(bvh.nodes.to_vec(), bvh.blocks.to_vec(), STACK + 1);
        heap.stack_need = heap.stack_need.max(bvh.stack_need);
        let mut rng = crate::rng::Pcg32::new(5, 0);
        let mut hits = 0;
        for _ in 0..5000 {
            let scale = 0.5f32.powi(rng.below(40) as i32);
            let o = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 2.0) * scale;
            let d = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, -2.0).normalize();
            let want = (0..tris.len())
                .filter_map(|i| {
                    let sh = triangle::RayShear::new(o, d)?;
                    let [a, b, c] = tris[i];
                    triangle::intersect(&sh, a.into(), b.into(), c.into(), f32::INFINITY).map(|h| h.0)
                })
                .fold(None, |m: Option<f32>, t| Some(m.map_or(t, |m| m.min(t))));
            let got = bvh.intersect(o, d, f32::INFINITY);
            assert_eq!(want, got.map(|h| h.0), "ray {o} {d}");
            let got_heap = heap.intersect(o, d, f32::INFINITY);
            assert_eq!(got.map(|h| (h.0, h.1)), got_heap.map(|h| (h.0, h.1)));
            assert_eq!(heap.occluded(o, d, f32::INFINITY), got.is_some());
            hits += got.is_some() as usize;
        }
        // Enough hits at many scales for the comparison to mean something.
        assert!(hits > 1000, "only {hits} hits");
    }
}
