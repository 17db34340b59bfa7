//! Closest hits and shadow rays' any hits of up to sixteen rays at once on a small mesh, without
//! a BVH: every triangle is tested against all the rays together, one ray per lane of a
//! 512-bit register (AVX-512), skipping clusters of up to four nearby triangles whose box no
//! lane enters (the BVH's box test, lane by lane). In the Cornell box's wavefront 31 % of the
//! shadow packets' cluster tests skip their triangles and 23 % of the closest-hit packets'
//! (`SPP=1 wave_ab 2`, counted once; docs/journal/performance.md, commit 92324a2).
//!
//! On a mesh of a few dozen triangles (McGuire's Cornell box has 36) a BVH query is short but
//! serial: the reciprocal's division, a node test, a sorted stack and the leaf tests, with
//! branches on data between them, for ~1.4 node and ~1.6 block tests a ray. The wavefront
//! integrator has many independent rays at a time; here each triangle costs about sixty vector
//! operations for sixteen of them and nothing branches on the data but "did any lane pass"
//! (docs/performance.md, "Sixteen rays against every triangle").
//!
//! Each lane performs exactly the scalar test's floating-point operations (Woop et al.'s
//! watertight test, `triangle::intersect_sheared`, with `triangle::shear_axes`'s dominant axis),
//! triangle after triangle against the closest hit so far, as a traversal does against its
//! shrinking `tmax`; strictly closer, so that of hits at exactly the same distance the lowest
//! triangle index stays, the BVH's rule. The lane's own axes are picked by a permute of the
//! triangle's nine coordinates. One difference from `shear_axes` changes nothing: the two other
//! axes are not swapped for a negative dominant component, which negates u, v, w, their sum and
//! `t_scaled` exactly (rounding is symmetric) and leaves t and the barycentrics as they are. A
//! lane in which an edge function rounds to zero is answered by the BVH (whose scalar fallback
//! redoes such edges in f64).
//!
//! With the range test before the division widened as the BVH's (`triangle::RANGE_WIDEN`), a
//! hit agrees with the BVH's bit for bit, with one exception: the BVH tests a triangle only if
//! the ray enters its leaf's box, and here if some lane enters its cluster's (other boxes), so
//! a spurious hit that rounding could produce for a ray starting within the test's error (~1e-7
//! of the vertices' magnitude) of a triangle's plane, outside its box, may be found by one and
//! not the other. Spawned rays start beyond that error
//! (`geometry::offset_ray_origin`); in the Cornell box's 2.1 million paths of
//! `SPP=32 wave_ab 2n 2` none differs.

use super::{bvh, bvh::Bvh, triangle, Hit};
use crate::math::Ray;
use glam::{Vec2, Vec3};

/// Largest mesh given a packet query. The cost is linear in the triangles; on the Cornell box
/// (36) a ray costs 0.66–0.76× a BVH query (`examples/packet_ab.rs`: 42–46 against 60 ns for
/// camera rays, 54–69 against 81–94 ns for bounce rays; docs/performance.md), so about 50
/// triangles would break even. Only 36 was measured.
pub const PACKET_MAX: usize = 48;

/// Rays per packet.
pub const WIDTH: usize = 16;

/// Fewest rays `Accel::intersect_live` and `Packets::intersect_batch` send as a packet: a
/// packet costs about the same for one ray as for sixteen, about what 10 BVH queries cost on
/// the Cornell box. 8 and 12 measured level in the wavefront (`wave_ab 2n 2`: 1.149 and
/// 1.147–1.156).
pub const MIN_LANES: usize = 8;

/// One triangle's vertices (x, y, z of each, then padding): one 64-byte load, from which each
/// lane permutes out its own axes.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Tri([f32; 16]);

/// Triangles of one cluster (`Packets::clusters`): a range of `Packets::tris` and its box.
#[derive(Clone, Copy)]
struct Cluster {
    lo: [f32; 3],
    hi: [f32; 3],
    start: u32,
    end: u32,
}

/// Most triangles in a cluster.
const CLUSTER: usize = 4;

/// The mesh in packet form: its valid triangles grouped into clusters of up to `CLUSTER`
/// nearby ones, `pos[j]` being `tris[j]`'s position among the mesh's valid triangles, whose
/// indices are `ids`.
pub struct Packets {
    tris: Vec<Tri>,
    pos: Vec<i32>,
    clusters: Vec<Cluster>,
    ids: Vec<u32>,
    /// Whether the integrator sends its shadow rays here (`occluded_batch`) rather than to
    /// the BVH one by one: always, but for A/B benchmarks (`Accel::set_packet_shadows`).
    shadows: bool,
}

impl Packets {
    /// `None` for a mesh of more than `PACKET_MAX` triangles or a CPU without AVX-512 F.
    /// `tris` are the valid triangles' vertices and `valid` their indices, as `Bvh::build`
    /// takes them.
    pub fn new(tris: &[[Vec3; 3]], valid: &[u32]) -> Option<Packets> {
        if tris.is_empty() || tris.len() > PACKET_MAX || !has_avx512() {
            return None;
        }
        let mut order: Vec<usize> = (0..tris.len()).collect();
        let mut ranges = Vec::new();
        split(tris, &mut order, 0, &mut ranges);
        let packed = order
            .iter()
            .map(|&i| {
                let mut a = [0.0f32; 16];
                for (v, p) in tris[i].iter().enumerate() {
                    a[3 * v..3 * v + 3].copy_from_slice(&p.to_array());
                }
                Tri(a)
            })
            .collect();
        let clusters = ranges
            .iter()
            .map(|&(start, end)| {
                let (lo, hi) = order[start..end]
                    .iter()
                    .flat_map(|&i| tris[i])
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)));
                Cluster { lo: lo.to_array(), hi: hi.to_array(), start: start as u32, end: end as u32 }
            })
            .collect();
        Some(Packets { tris: packed, pos: order.iter().map(|&i| i as i32).collect(), clusters, ids: valid.to_vec(), shadows: true })
    }

    /// Whether shadow rays go through `occluded_batch`.
    pub fn shadows(&self) -> bool {
        self.shadows
    }

    pub(super) fn set_shadows(&mut self, on: bool) {
        self.shadows = on;
    }

    /// Closest hits with t in (0, tmax) of `rays` (at most `WIDTH`) into `out`; lanes the
    /// vector test cannot decide go to `bvh`.
    pub fn intersect(&self, bvh: &Bvh, rays: &[Ray], tmax: f32, out: &mut [Option<Hit>]) {
        assert!(rays.len() <= WIDTH);
        let lanes: [usize; WIDTH] = std::array::from_fn(|i| i);
        self.intersect_lanes(bvh, rays, &lanes[..rays.len()], tmax, out);
    }

    /// `intersect` of the rays `rays[l]` for l in `lanes` (at most `WIDTH`), into `out[l]`.
    #[inline]
    pub fn intersect_lanes(&self, bvh: &Bvh, rays: &[Ray], lanes: &[usize], tmax: f32, out: &mut [Option<Hit>]) {
        assert!(lanes.len() <= WIDTH);
        #[cfg(target_arch = "x86_64")]
        {
            let mut res = Lanes::default();
            // SAFETY: a `Packets` exists only where `has_avx512` found AVX-512 F.
            let redo = unsafe { self.query_avx512(rays, lanes, &[tmax; WIDTH], &mut res) };
            for (j, &l) in lanes.iter().enumerate() {
                out[l] = if redo & (1 << j) != 0 {
                    let r = &rays[l];
                    bvh.intersect(r.origin, r.dir, tmax).map(|(t, prim, b1, b2)| Hit { t, prim, bary: Vec2::new(b1, b2) })
                } else if res.id[j] >= 0 {
                    Some(Hit { t: res.t[j], prim: self.ids[res.id[j] as usize], bary: Vec2::new(res.b1[j], res.b2[j]) })
                } else {
                    None
                };
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (bvh, rays, lanes, tmax, out);
            unreachable!("Packets::new makes none without AVX-512");
        }
    }
}

/// Orders `order` (positions into `tris`) so that clusters of at most `CLUSTER` nearby
/// triangles are contiguous, and appends each cluster's range (offset by `base`) to `out`: a
/// median split of the centroids along their widest axis, recursively.
fn split(tris: &[[Vec3; 3]], order: &mut [usize], base: usize, out: &mut Vec<(usize, usize)>) {
    if order.len() <= CLUSTER {
        out.push((base, base + order.len()));
        return;
    }
    let centroid = |i: usize| tris[i][0] + tris[i][1] + tris[i][2];
    let (lo, hi) = order.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &i| (lo.min(centroid(i)), hi.max(centroid(i))));
    let axis = (hi - lo).max_position();
    order.sort_by(|&a, &b| centroid(a)[axis].total_cmp(&centroid(b)[axis]).then(a.cmp(&b)));
    let mid = order.len() / 2;
    let (left, right) = order.split_at_mut(mid);
    split(tris, left, base, out);
    split(tris, right, base + mid, out);
}

/// Rays of the wavefront integrator's batch (`integrator::wave::LANES`), in its layout.
pub const BATCH: usize = 32;

/// Closest hits of a batch's rays, one array a field: `prim[i]` is the triangle lane i hit,
/// −1 for none (and for lanes that were not live).
#[derive(Clone, Copy)]
pub struct BatchHits {
    pub t: [f32; BATCH],
    pub prim: [i32; BATCH],
    pub b1: [f32; BATCH],
    pub b2: [f32; BATCH],
}

impl Default for BatchHits {
    fn default() -> Self {
        BatchHits { t: [0.0; BATCH], prim: [-1; BATCH], b1: [0.0; BATCH], b2: [0.0; BATCH] }
    }
}

impl Packets {
    /// Closest hits with t in (0, tmax) of the rays i with bit i of `live` set (origin
    /// `org[axis][i]`, direction `dir[axis][i]`), into `out`: the live lanes are packed into
    /// packets and their answers put back in place by AVX-512's compress, expand, gather and
    /// scatter, with no pass over the lanes one by one. A packet of fewer than `MIN_LANES`
    /// rays goes to `bvh` ray by ray, as do lanes the vector test cannot decide.
    pub fn intersect_batch(&self, bvh: &Bvh, org: [&[f32; BATCH]; 3], dir: [&[f32; BATCH]; 3], live: u32, tmax: f32, out: &mut BatchHits) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a `Packets` exists only where `has_avx512` found AVX-512 F.
        unsafe {
            self.intersect_batch_avx512(bvh, org, dir, live, tmax, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (bvh, org, dir, live, tmax, out);
            unreachable!("Packets::new makes none without AVX-512");
        }
    }
}

impl Packets {
    /// Which of the rays i with bit i of `live` set (origin `org[axis][i]`, direction
    /// `dir[axis][i]`) are blocked in (0, `tmax[i]`): bit i of the result, as `Bvh::occluded`
    /// answers. The live lanes go in packets as in `intersect_batch`; each lane stops at its
    /// first hit and the packet when every lane has one. Rays of a packet smaller than
    /// `MIN_LANES`, and lanes the vector test cannot decide, go to `bvh` one by one.
    pub fn occluded_batch(&self, bvh: &Bvh, org: [&[f32; BATCH]; 3], dir: [&[f32; BATCH]; 3], tmax: &[f32; BATCH], live: u32) -> u32 {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: a `Packets` exists only where `has_avx512` found AVX-512 F.
        unsafe {
            self.occluded_batch_avx512(bvh, org, dir, tmax, live)
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (bvh, org, dir, tmax, live);
            unreachable!("Packets::new makes none without AVX-512");
        }
    }
}

/// `out`'s lane `l` from a BVH query.
fn single(bvh: &Bvh, org: [&[f32; BATCH]; 3], dir: [&[f32; BATCH]; 3], l: usize, tmax: f32, out: &mut BatchHits) {
    let o = Vec3::new(org[0][l], org[1][l], org[2][l]);
    let d = Vec3::new(dir[0][l], dir[1][l], dir[2][l]);
    match bvh.intersect(o, d, tmax) {
        Some((t, prim, b1, b2)) => {
            (out.t[l], out.prim[l], out.b1[l], out.b2[l]) = (t, prim as i32, b1, b2);
        }
        None => out.prim[l] = -1,
    }
}

fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// What the vector test found per lane: distance, barycentrics and the triangle's position in
/// `Packets::tris` (−1: no hit).
#[derive(Default)]
struct Lanes {
    t: [f32; WIDTH],
    b1: [f32; WIDTH],
    b2: [f32; WIDTH],
    id: [i32; WIDTH],
}

#[cfg(target_arch = "x86_64")]
impl Packets {
    /// `intersect_batch`.
    ///
    /// # Safety
    /// Only where the CPU has AVX-512 F.
    #[target_feature(enable = "avx512f")]
    unsafe fn intersect_batch_avx512(
        &self,
        bvh: &Bvh,
        org: [&[f32; BATCH]; 3],
        dir: [&[f32; BATCH]; 3],
        live: u32,
        tmax: f32,
        out: &mut BatchHits,
    ) {
        use std::arch::x86_64::*;
        out.prim = [-1; BATCH];
        // SAFETY (whole block): AVX-512 F is present (the caller's contract); gathers and
        // scatters index lanes of 32-element arrays (0..32, from the lane numbers) or
        // `self.ids` (a triangle position the kernel found, below `self.tris.len()`).
        unsafe {
            let run = |o: [__m512; 3], d: [__m512; 3], idx: __m512i, count: u32, out: &mut BatchHits| {
                if count == 0 {
                    return;
                }
                let mut lane = [0i32; 16];
                _mm512_storeu_si512(lane.as_mut_ptr() as *mut _, idx);
                if (count as usize) < MIN_LANES {
                    for &l in &lane[..count as usize] {
                        single(bvh, org, dir, l as usize, tmax, out);
                    }
                    return;
                }
                let active = ((1u32 << count) - 1) as u16;
                let k = self.kernel::<false>(o, d, active, _mm512_set1_ps(tmax));
                let decided = active & !k.redo;
                let hit = decided & _mm512_cmpge_epi32_mask(k.id, _mm512_setzero_si512());
                let prim = _mm512_mask_i32gather_epi32::<4>(_mm512_set1_epi32(-1), hit, k.id, self.ids.as_ptr() as *const i32);
                _mm512_mask_i32scatter_epi32::<4>(out.prim.as_mut_ptr(), decided, idx, prim);
                _mm512_mask_i32scatter_ps::<4>(out.t.as_mut_ptr(), hit, idx, k.t);
                _mm512_mask_i32scatter_ps::<4>(out.b1.as_mut_ptr(), hit, idx, k.b1);
                _mm512_mask_i32scatter_ps::<4>(out.b2.as_mut_ptr(), hit, idx, k.b2);
                let mut redo = k.redo & active;
                while redo != 0 {
                    let j = redo.trailing_zeros() as usize;
                    redo &= redo - 1;
                    single(bvh, org, dir, lane[j] as usize, tmax, out);
                }
            };
            for group in packets_of(live) {
                let ([ox, oy, oz, dx, dy, dz], idx, count) = pack([org[0], org[1], org[2], dir[0], dir[1], dir[2]], group);
                run([ox, oy, oz], [dx, dy, dz], idx, count, out);
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
impl Packets {
    /// `occluded_batch`.
    ///
    /// # Safety
    /// Only where the CPU has AVX-512 F.
    #[target_feature(enable = "avx512f")]
    unsafe fn occluded_batch_avx512(
        &self,
        bvh: &Bvh,
        org: [&[f32; BATCH]; 3],
        dir: [&[f32; BATCH]; 3],
        tmax: &[f32; BATCH],
        live: u32,
    ) -> u32 {
        use std::arch::x86_64::*;
        let blocked = |l: usize| {
            let o = Vec3::new(org[0][l], org[1][l], org[2][l]);
            bvh.occluded(o, Vec3::new(dir[0][l], dir[1][l], dir[2][l]), tmax[l])
        };
        let mut occluded = 0u32;
        // SAFETY (whole block): AVX-512 F is present (the caller's contract).
        unsafe {
            let mut run = |o: [__m512; 3], d: [__m512; 3], t: __m512, idx: __m512i, count: u32| {
                if count == 0 {
                    return;
                }
                let mut lane = [0i32; 16];
                _mm512_storeu_si512(lane.as_mut_ptr() as *mut _, idx);
                if (count as usize) < MIN_LANES {
                    for &l in &lane[..count as usize] {
                        occluded |= (blocked(l as usize) as u32) << l;
                    }
                    return;
                }
                let active = ((1u32 << count) - 1) as u16;
                let k = self.kernel::<true>(o, d, active, t);
                let mut hit = active & _mm512_cmpge_epi32_mask(k.id, _mm512_setzero_si512());
                while hit != 0 {
                    occluded |= 1 << lane[hit.trailing_zeros() as usize];
                    hit &= hit - 1;
                }
                let mut redo = k.redo & active;
                while redo != 0 {
                    let l = lane[redo.trailing_zeros() as usize];
                    occluded |= (blocked(l as usize) as u32) << l;
                    redo &= redo - 1;
                }
            };
            for group in packets_of(live) {
                let ([ox, oy, oz, dx, dy, dz, t], idx, count) = pack([org[0], org[1], org[2], dir[0], dir[1], dir[2], tmax], group);
                run([ox, oy, oz], [dx, dy, dz], t, idx, count);
            }
        }
        occluded
    }
}

/// A batch's live lanes (bit i: lane i) in packets of at most sixteen: one packet of them all
/// where there are no more, else the low sixteen lanes' and the high sixteen's (0: no packet).
#[cfg(target_arch = "x86_64")]
fn packets_of(live: u32) -> [u32; 2] {
    if live.count_ones() <= 16 {
        [live, 0]
    } else {
        [live & 0xffff, live & 0xffff_0000]
    }
}

/// The lanes of `group` (bit i: lane i of the batch, at most sixteen of them) packed to the
/// bottom of sixteen-lane registers, the high half's lanes expanded into the places after the
/// low half's: each array's values, the lane numbers, and how many.
///
/// # Safety
/// Only where the CPU has AVX-512 F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn pack<const N: usize>(
    arrays: [&[f32; BATCH]; N],
    group: u32,
) -> ([std::arch::x86_64::__m512; N], std::arch::x86_64::__m512i, u32) {
    use std::arch::x86_64::*;
    let (m0, m1) = (group as u16, (group >> 16) as u16);
    let (c0, c1) = (m0.count_ones(), m1.count_ones());
    debug_assert!(c0 + c1 <= 16, "a packet holds sixteen lanes");
    let place = (((1u32 << c1) - 1) << c0) as u16;
    // SAFETY: AVX-512 F is present (the caller's contract); the loads read sixteen floats of
    // 32-float arrays at 0 or 16.
    unsafe {
        let v = arrays.map(|a| {
            let lo = _mm512_maskz_compress_ps(m0, _mm512_loadu_ps(a.as_ptr()));
            _mm512_mask_expand_ps(lo, place, _mm512_maskz_compress_ps(m1, _mm512_loadu_ps(a.as_ptr().add(16))))
        });
        let iota = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
        let lo = _mm512_maskz_compress_epi32(m0, iota);
        let idx = _mm512_mask_expand_epi32(lo, place, _mm512_maskz_compress_epi32(m1, _mm512_add_epi32(iota, _mm512_set1_epi32(16))));
        (v, idx, c0 + c1)
    }
}

/// What `Packets::kernel` found per lane: distance, barycentrics, the triangle's position in
/// `Packets::tris` (−1: no hit), and the lanes it left undecided, where an edge function
/// rounded to zero.
#[cfg(target_arch = "x86_64")]
struct KernelOut {
    t: std::arch::x86_64::__m512,
    b1: std::arch::x86_64::__m512,
    b2: std::arch::x86_64::__m512,
    id: std::arch::x86_64::__m512i,
    redo: u16,
}

#[cfg(target_arch = "x86_64")]
impl Packets {
    /// The vector test, lane i in (0, tmax[i]). Returns the lanes (bit i: ray i) it left
    /// undecided, where an edge function rounded to zero.
    ///
    /// # Safety
    /// Only where the CPU has AVX-512 F.
    #[target_feature(enable = "avx512f")]
    unsafe fn query_avx512(&self, rays: &[Ray], lanes: &[usize], tmax: &[f32; WIDTH], res: &mut Lanes) -> u16 {
        use std::arch::x86_64::*;
        // The rays in structure-of-arrays form (lanes past `lanes.len()` stay zero: no
        // direction).
        let mut oa = [[0.0f32; WIDTH]; 3];
        let mut da = [[0.0f32; WIDTH]; 3];
        for (j, &l) in lanes.iter().enumerate() {
            let r = &rays[l];
            for axis in 0..3 {
                oa[axis][j] = r.origin[axis];
                da[axis][j] = r.dir[axis];
            }
        }
        // SAFETY: AVX-512 F is present (the caller's contract); every load and store reads or
        // writes a whole array of sixteen 4-byte elements.
        unsafe {
            let load = |a: &[f32; WIDTH]| _mm512_loadu_ps(a.as_ptr());
            let o = [load(&oa[0]), load(&oa[1]), load(&oa[2])];
            let d = [load(&da[0]), load(&da[1]), load(&da[2])];
            let active = ((1u32 << lanes.len()) - 1) as u16;
            let k = self.kernel::<false>(o, d, active, _mm512_loadu_ps(tmax.as_ptr()));
            _mm512_storeu_ps(res.t.as_mut_ptr(), k.t);
            _mm512_storeu_ps(res.b1.as_mut_ptr(), k.b1);
            _mm512_storeu_ps(res.b2.as_mut_ptr(), k.b2);
            _mm512_storeu_si512(res.id.as_mut_ptr() as *mut _, k.id);
            k.redo
        }
    }

    /// The vector test of the rays in the lanes of `active` (origins `o`, directions `d`, one
    /// axis a register), lane i in (0, tmax[i]): its closest hit, or with `ANY` its first (a
    /// lane stops at it, the test when every lane has one), whose triangle `id` is then all
    /// the answer.
    ///
    /// # Safety
    /// Only where the CPU has AVX-512 F.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn kernel<const ANY: bool>(
        &self,
        o: [std::arch::x86_64::__m512; 3],
        d: [std::arch::x86_64::__m512; 3],
        active: u16,
        tmax: std::arch::x86_64::__m512,
    ) -> KernelOut {
        use std::arch::x86_64::*;
        // SAFETY (whole block): AVX-512 F is present (the caller's contract); every load
        // reads a whole 64-byte triangle.
        unsafe {
            let zero = _mm512_setzero_ps();
            let sign = _mm512_set1_epi32(i32::MIN);
            let [ox0, oy0, oz0] = o;
            let [dx, dy, dz] = d;
            // Per lane, as `Bvh::intersect`: no hit for tmax ≤ 0 or NaN, or a non-finite origin
            // or direction (0·x is 0 exactly for a finite x) …
            let finite = |v: __m512| _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(_mm512_mul_ps(v, zero), zero);
            let mut active = active
                & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(tmax, zero)
                & finite(ox0)
                & finite(oy0)
                & finite(oz0)
                & finite(dx)
                & finite(dy)
                & finite(dz);
            // … and the dominant axis kz of `triangle::shear_axes` (x over y over z on ties),
            // with the others in cyclic order (kx, ky) = (kz + 1, kz + 2) mod 3, unswapped.
            let abs = |v: __m512| _mm512_castsi512_ps(_mm512_andnot_si512(sign, _mm512_castps_si512(v)));
            let (ax, ay, az) = (abs(dx), abs(dy), abs(dz));
            let x_gt_y = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ax, ay);
            let kz_x = x_gt_y & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ax, az);
            let kz_y = !x_gt_y & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ay, az);
            // Component kz, kz + 1 and kz + 2 of a vector: (z, x, y) by default.
            let pick = |x: __m512, y: __m512, z: __m512| {
                let c = _mm512_mask_mov_ps(_mm512_mask_mov_ps(z, kz_x, x), kz_y, y);
                let c1 = _mm512_mask_mov_ps(_mm512_mask_mov_ps(x, kz_x, y), kz_y, z);
                let c2 = _mm512_mask_mov_ps(_mm512_mask_mov_ps(y, kz_x, z), kz_y, x);
                (c1, c2, c)
            };
            let (dkx, dky, dkz) = pick(dx, dy, dz);
            let (ox, oy, oz) = pick(ox0, oy0, oz0);
            active &= _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(dkz, zero);
            let sz = _mm512_div_ps(_mm512_set1_ps(1.0), dkz);
            let (sx, sy) = (_mm512_mul_ps(dkx, sz), _mm512_mul_ps(dky, sz));
            let kzv =
                _mm512_mask_mov_epi32(_mm512_mask_mov_epi32(_mm512_set1_epi32(2), kz_x, _mm512_set1_epi32(0)), kz_y, _mm512_set1_epi32(1));
            let one = _mm512_set1_epi32(1);
            let three = _mm512_set1_epi32(3);
            // (kz + 1) mod 3 and (kz + 2) mod 3, kz in 0..3.
            let wrap = |a: __m512i| _mm512_mask_sub_epi32(a, _mm512_cmpge_epi32_mask(a, three), a, three);
            let kxv = wrap(_mm512_add_epi32(kzv, one));
            let kyv = wrap(_mm512_add_epi32(kxv, one));
            let at = |vertex: i32, k: __m512i| _mm512_add_epi32(k, _mm512_set1_epi32(3 * vertex));
            let ix = [at(0, kxv), at(1, kxv), at(2, kxv)];
            let iy = [at(0, kyv), at(1, kyv), at(2, kyv)];
            let iz = [at(0, kzv), at(1, kzv), at(2, kzv)];
            let inf = _mm512_set1_ps(f32::INFINITY);
            // The BVH's widened reciprocals (`bvh::RayData`), for its box test on the clusters.
            let min_dir = _mm512_set1_ps(bvh::MIN_DIR);
            let clamped = |v: __m512| {
                let tiny = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(abs(v), min_dir);
                _mm512_mask_blend_ps(tiny, v, _mm512_or_ps(_mm512_and_ps(v, _mm512_castsi512_ps(sign)), min_dir))
            };
            let inv = [dx, dy, dz].map(|v| _mm512_div_ps(_mm512_set1_ps(1.0), clamped(v)));
            let inv_lo = inv.map(|i| _mm512_mul_ps(i, _mm512_set1_ps(1.0 - bvh::SLAB_WIDEN)));
            let inv_hi = inv.map(|i| _mm512_mul_ps(i, _mm512_set1_ps(1.0 + bvh::SLAB_WIDEN)));
            let org = [ox0, oy0, oz0];
            let mut best_t = tmax;
            // `best_t · RANGE_WIDEN`, for the range test before the division.
            let widen = _mm512_set1_ps(triangle::RANGE_WIDEN);
            let mut best_tw = _mm512_mul_ps(best_t, widen);
            let mut best_id = _mm512_set1_epi32(-1);
            let (mut best_det, mut best_v, mut best_w) = (zero, zero, zero);
            let mut redo: u16 = 0;
            let mut occluded: u16 = 0;
            'clusters: for c in &self.clusters {
                // `bvh::node_test`'s box test of the segment (0, best_t), lane by lane: a
                // cluster no lane enters holds no hit for any (as for the BVH, a hit is inside
                // the box, which the test's widening keeps conservative).
                let slab = |a: usize| {
                    let (p0, p1) = (_mm512_sub_ps(_mm512_set1_ps(c.lo[a]), org[a]), _mm512_sub_ps(_mm512_set1_ps(c.hi[a]), org[a]));
                    let near = _mm512_min_ps(_mm512_mul_ps(p0, inv_lo[a]), _mm512_mul_ps(p1, inv_lo[a]));
                    let far = _mm512_max_ps(_mm512_mul_ps(p0, inv_hi[a]), _mm512_mul_ps(p1, inv_hi[a]));
                    (near, far)
                };
                let ((xn, xf), (yn, yf), (zn, zf)) = (slab(0), slab(1), slab(2));
                let tn = _mm512_max_ps(_mm512_max_ps(xn, yn), _mm512_max_ps(zn, zero));
                let tf = _mm512_min_ps(_mm512_min_ps(xf, yf), _mm512_min_ps(zf, best_t));
                if _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(active, tn, tf) == 0 {
                    continue;
                }
                for j in c.start as usize..c.end as usize {
                    // SAFETY: the clusters' ranges partition `tris`, and `pos` has its length.
                    let tv = _mm512_load_ps(self.tris.get_unchecked(j).0.as_ptr());
                    let pos = _mm512_set1_epi32(*self.pos.get_unchecked(j));
                    // `triangle::intersect`'s sheared vertex: a[kx] − sx·a[kz], a[ky] − sy·a[kz],
                    // sz·a[kz], with a = p − origin.
                    let sheared = |v: usize| {
                        let az = _mm512_sub_ps(_mm512_permutexvar_ps(iz[v], tv), oz);
                        let x = _mm512_sub_ps(_mm512_sub_ps(_mm512_permutexvar_ps(ix[v], tv), ox), _mm512_mul_ps(sx, az));
                        let y = _mm512_sub_ps(_mm512_sub_ps(_mm512_permutexvar_ps(iy[v], tv), oy), _mm512_mul_ps(sy, az));
                        (x, y, _mm512_mul_ps(sz, az))
                    };
                    let (ax, ay, az) = sheared(0);
                    let (bx, by, bz) = sheared(1);
                    let (cx, cy, cz) = sheared(2);
                    let u = _mm512_sub_ps(_mm512_mul_ps(cx, by), _mm512_mul_ps(cy, bx));
                    let v = _mm512_sub_ps(_mm512_mul_ps(ax, cy), _mm512_mul_ps(ay, cx));
                    let w = _mm512_sub_ps(_mm512_mul_ps(bx, ay), _mm512_mul_ps(by, ax));
                    // The tests below are compares masked by the previous one's result, so that the
                    // lanes' masks stay in mask registers (ANDed as `u16`s, they travelled through
                    // general registers and back, a dozen instructions a triangle).
                    // Lanes with no edge function zero; the others are the BVH's.
                    let nz = _mm512_mask_cmp_ps_mask::<_CMP_NEQ_UQ>(active, u, zero);
                    let nz = _mm512_mask_cmp_ps_mask::<_CMP_NEQ_UQ>(nz, v, zero);
                    let nz = _mm512_mask_cmp_ps_mask::<_CMP_NEQ_UQ>(nz, w, zero);
                    redo |= active ^ nz;
                    // With no function zero, "some negative and some positive" is "the sign bits
                    // differ": (u ^ v) | (u ^ w) has its sign bit set (ternary-logic table 0x7E).
                    let (ui, vi, wi) = (_mm512_castps_si512(u), _mm512_castps_si512(v), _mm512_castps_si512(w));
                    let same = _mm512_mask_testn_epi32_mask(nz, _mm512_ternarylogic_epi32::<0x7E>(ui, vi, wi), sign);
                    let det = _mm512_add_ps(_mm512_add_ps(u, v), w);
                    let t_scaled = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(u, az), _mm512_mul_ps(v, bz)), _mm512_mul_ps(w, cz));
                    // ts = −t_scaled and d = −det where det < 0: flipping the sign bit.
                    let det_sign = _mm512_and_si512(_mm512_castps_si512(det), sign);
                    let ts = _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(t_scaled), det_sign));
                    let d = _mm512_castsi512_ps(_mm512_andnot_si512(sign, _mm512_castps_si512(det)));
                    let pass = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(same, d, zero);
                    let pass = _mm512_mask_cmp_ps_mask::<_CMP_LT_OQ>(pass, d, inf);
                    let pass = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(pass, ts, zero);
                    let pass = _mm512_mask_cmp_ps_mask::<_CMP_LT_OQ>(pass, ts, _mm512_mul_ps(best_tw, d));
                    // Most triangles are missed by every lane, which the tests without the
                    // division decide (a 512-bit division issues once per 16 cycles).
                    if pass != 0 {
                        let t = _mm512_maskz_div_ps(pass, t_scaled, det);
                        let ahead = _mm512_mask_cmp_ps_mask::<_CMP_GT_OQ>(pass, t, zero);
                        let closer = _mm512_mask_cmp_ps_mask::<_CMP_LT_OQ>(ahead, t, best_t);
                        if ANY {
                            // As the BVH's any-hit query: a hit in (0, tmax) ends the lane.
                            best_id = _mm512_mask_mov_epi32(best_id, closer, pos);
                            occluded |= closer;
                            active &= !closer;
                            if active == 0 {
                                break 'clusters;
                            }
                            continue;
                        }
                        // Closer, or as close with a lower index: the BVH's rule for ties, since
                        // the clusters do not keep the index order. Nothing is as close as the
                        // initial `tmax` with a lower index than no hit's −1.
                        let tie = _mm512_mask_cmplt_epi32_mask(_mm512_mask_cmp_ps_mask::<_CMP_EQ_OQ>(ahead, t, best_t), pos, best_id);
                        let hit = closer | tie;
                        best_t = _mm512_mask_mov_ps(best_t, hit, t);
                        best_tw = _mm512_mask_mul_ps(best_tw, hit, t, widen);
                        best_id = _mm512_mask_mov_epi32(best_id, hit, pos);
                        best_det = _mm512_mask_mov_ps(best_det, hit, det);
                        best_v = _mm512_mask_mov_ps(best_v, hit, v);
                        best_w = _mm512_mask_mov_ps(best_w, hit, w);
                    }
                }
            }
            if ANY {
                // A lane with a hit is answered, whatever edge rounded to zero on its way.
                return KernelOut { t: best_t, b1: zero, b2: zero, id: best_id, redo: redo & !occluded };
            }
            // The barycentrics as the scalar test computes them: v and w times 1/det.
            let inv = _mm512_div_ps(_mm512_set1_ps(1.0), best_det);
            KernelOut { t: best_t, b1: _mm512_mul_ps(best_v, inv), b2: _mm512_mul_ps(best_w, inv), id: best_id, redo }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::RayBatch;
    use crate::geometry::{Accel, Mesh};
    use crate::rng::Pcg32;

    fn check(mesh: &Mesh, batch: &RayBatch) -> usize {
        let accel = Accel::build(mesh);
        let Some(p) = accel.packets() else {
            eprintln!("no packet query on this CPU (AVX-512 F missing) or mesh: nothing to compare");
            return 0;
        };
        let rays: Vec<Ray> = (0..batch.len()).map(|i| batch.ray(i)).collect();
        let mut hits = 0;
        for (k, chunk) in rays.chunks(WIDTH).enumerate() {
            // Every packet width, from a single lane to sixteen.
            let chunk = &chunk[..chunk.len().min(1 + k % WIDTH)];
            let mut out = [None; WIDTH];
            p.intersect(&accel.bvh, chunk, f32::INFINITY, &mut out);
            for (r, got) in chunk.iter().zip(out) {
                let want = accel.intersect(r, f32::INFINITY);
                let key = |h: Option<Hit>| h.map(|h| (h.t.to_bits(), h.prim, h.bary.x.to_bits(), h.bary.y.to_bits()));
                assert_eq!(key(got), key(want), "ray {r:?}");
                hits += got.is_some() as usize;
            }
        }
        hits
    }

    /// `intersect_batch` answers every live lane as the BVH does and no other, bit for bit,
    /// whatever the live lanes (one packet, two, or lanes left to the BVH one by one).
    #[test]
    fn batch_query_equals_bvh_queries() {
        let scene =
            crate::scene::Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.toml")).unwrap();
        let accel = Accel::build(&scene.mesh);
        let Some(p) = accel.packets() else {
            assert!(!has_avx512(), "a CPU with AVX-512 F has a packet query for the Cornell box");
            return;
        };
        let batch = RayBatch::random_in_bounds(&scene.mesh, 64 * BATCH, 5);
        let mut rng = Pcg32::new(6, 0);
        let (mut hits, mut counts) = (0, [0u32; 2]);
        for k in 0..64 {
            let rays: Vec<Ray> = (0..BATCH).map(|i| batch.ray(k * BATCH + i)).collect();
            let axis = |f: fn(&Ray) -> Vec3, a: usize| -> [f32; BATCH] { std::array::from_fn(|i| f(&rays[i])[a]) };
            let org = [0, 1, 2].map(|a| axis(|r| r.origin, a));
            let dir = [0, 1, 2].map(|a| axis(|r| r.dir, a));
            // From all lanes live down to a few.
            let keep = 1.0 - k as f32 / 64.0;
            let live = (0..BATCH).fold(0u32, |m, i| m | (((rng.next_f32() < keep) as u32) << i));
            counts[(live.count_ones() <= 16) as usize] += 1;
            let mut out = BatchHits::default();
            p.intersect_batch(&accel.bvh, [&org[0], &org[1], &org[2]], [&dir[0], &dir[1], &dir[2]], live, f32::INFINITY, &mut out);
            for (i, r) in rays.iter().enumerate() {
                let want = if live & (1 << i) != 0 { accel.intersect(r, f32::INFINITY) } else { None };
                let got = (out.prim[i] >= 0).then(|| (out.t[i].to_bits(), out.prim[i] as u32, out.b1[i].to_bits(), out.b2[i].to_bits()));
                assert_eq!(got, want.map(|h| (h.t.to_bits(), h.prim, h.bary.x.to_bits(), h.bary.y.to_bits())), "batch {k}, lane {i}");
                hits += got.is_some() as usize;
            }
        }
        assert!(hits > 500 && counts[0] > 5 && counts[1] > 5, "{hits} hits, {counts:?} batches of two packets / one");
    }

    /// Segments between points of the mesh (shadow rays from one surface to another, ending
    /// just short of it, as the integrator's) and random rays with random, infinite, zero,
    /// negative and NaN `tmax`, in batches with every number of live lanes.
    fn check_occluded(mesh: &Mesh, seed: u64) -> [usize; 2] {
        let accel = Accel::build(mesh);
        let Some(p) = accel.packets() else {
            assert!(!has_avx512() || mesh.triangles.len() > PACKET_MAX, "a CPU with AVX-512 F has a packet query for this mesh");
            return [0, 0];
        };
        let mut rng = Pcg32::new(seed, 7);
        let on_mesh = |rng: &mut Pcg32| {
            let t = mesh.triangles[rng.below(mesh.triangles.len() as u32) as usize].map(|v| mesh.positions[v as usize]);
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            (t[0] * (1.0 - u - v) + t[1] * u + t[2] * v, (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero())
        };
        let random = RayBatch::random_in_bounds(mesh, 200 * BATCH, seed);
        let mut counts = [0usize; 2];
        for k in 0..400 {
            let mut rays = Vec::with_capacity(BATCH);
            let mut tmax = [0.0f32; BATCH];
            for (i, t) in tmax.iter_mut().enumerate() {
                if k % 2 == 0 {
                    let ((a, na), (b, _)) = (on_mesh(&mut rng), on_mesh(&mut rng));
                    let o = a + na * (1e-3 * if rng.below(2) == 0 { 1.0 } else { -1.0 });
                    let d = (b - o).normalize_or_zero();
                    rays.push(Ray::new(o, d));
                    *t = (b - o).length() * (1.0 - 1e-4);
                } else {
                    rays.push(random.ray((k / 2) * BATCH + i));
                    *t = match rng.below(16) {
                        0 => f32::INFINITY,
                        1 => 0.0,
                        2 => -1.0,
                        3 => f32::NAN,
                        _ => rng.next_f32() * 4.0,
                    };
                }
            }
            let axis = |f: fn(&Ray) -> Vec3, a: usize| -> [f32; BATCH] { std::array::from_fn(|i| f(&rays[i])[a]) };
            let org = [0, 1, 2].map(|a| axis(|r| r.origin, a));
            let dir = [0, 1, 2].map(|a| axis(|r| r.dir, a));
            let keep = 1.0 - (k % 64) as f32 / 64.0;
            let live = (0..BATCH).fold(0u32, |m, i| m | (((rng.next_f32() < keep) as u32) << i));
            let got = p.occluded_batch(&accel.bvh, [&org[0], &org[1], &org[2]], [&dir[0], &dir[1], &dir[2]], &tmax, live);
            for (i, r) in rays.iter().enumerate() {
                let want = live & (1 << i) != 0 && accel.occluded(r, tmax[i]);
                assert_eq!(got & (1 << i) != 0, want, "batch {k}, lane {i}: {r:?}, tmax {}", tmax[i]);
                if live & (1 << i) != 0 {
                    counts[want as usize] += 1;
                }
            }
        }
        counts
    }

    /// `occluded_batch` answers every live lane as `Bvh::occluded` does and no other.
    #[test]
    fn occluded_batch_equals_bvh_queries() {
        let scene =
            crate::scene::Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.toml")).unwrap();
        let [free, blocked] = check_occluded(&scene.mesh, 8);
        let mut rng = Pcg32::new(9, 0);
        let mut soup = Mesh::default();
        for _ in 0..40 {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0;
            let p: Vec<Vec3> = (0..3).map(|_| c + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5).collect();
            soup.append(&p, &[], &[], &[[0, 1, 2]], 0);
        }
        let [free2, blocked2] = check_occluded(&soup, 10);
        if has_avx512() {
            assert!(
                free > 1_500 && blocked > 1_500 && free2 > 1_500 && blocked2 > 1_500,
                "{free}/{blocked}, soup {free2}/{blocked2} free/blocked"
            );
        }
    }

    /// The packet query answers as the BVH does, bit for bit: on the Cornell box's camera rays
    /// (a quarter aimed at shared edges, where the f64 fallback decides) and random rays, and
    /// on a soup of random triangles. Fails only on a CPU with AVX-512 F; elsewhere there is
    /// no packet query to check.
    #[test]
    fn packets_equal_bvh_queries() {
        let scene =
            crate::scene::Scene::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.toml")).unwrap();
        let mut hits = check(&scene.mesh, &RayBatch::camera(&scene.mesh, 40_000, 1));
        hits += check(&scene.mesh, &RayBatch::random_in_bounds(&scene.mesh, 40_000, 2));
        let mut rng = Pcg32::new(3, 0);
        let mut soup = Mesh::default();
        for _ in 0..40 {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0;
            let p: Vec<Vec3> = (0..3).map(|_| c + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5).collect();
            soup.append(&p, &[], &[], &[[0, 1, 2]], 0);
        }
        hits += check(&soup, &RayBatch::random_in_bounds(&soup, 40_000, 4));
        // Overlapping triangles in one plane: hits at exactly the same distance, which the
        // clusters' order (not the index order) meets, so only the rule for ties keeps the
        // BVH's answer.
        let mut flat = Mesh::default();
        for _ in 0..40 {
            let p: Vec<Vec3> = (0..3).map(|_| Vec3::new(rng.next_f32() * 4.0, rng.next_f32() * 4.0, 1.0)).collect();
            flat.append(&p, &[], &[], &[[0, 1, 2]], 0);
        }
        let mut down = RayBatch::default();
        for _ in 0..40_000 {
            let o = Vec3::new(rng.next_f32() * 4.0, rng.next_f32() * 4.0, 2.0 + rng.next_f32());
            let target = Vec3::new(rng.next_f32() * 4.0, rng.next_f32() * 4.0, 1.0);
            down.push(o, (target - o).normalize(), f32::INFINITY);
        }
        hits += check(&flat, &down);
        if has_avx512() {
            assert!(hits > 30_000, "only {hits} hits");
        }
    }
}
