//! The AVX2 and FMA paths of the BVH query, chosen at run time: the eight children of a node
//! tested in one 256-bit operation and leaves two `Tri4` blocks at a time. The leaf test has
//! exactly the SSE2 path's floating-point operations; the node test has its own (one fused
//! multiply-add per plane), conservative as the SSE2 one is, so both visit every box a ray
//! touches and the closest hit, found by the same triangle test and the same rule for ties,
//! is the same bit for bit.

use super::tri4::{closest_lane, ties, tri4_test};
use super::{HitRec, Node, NodeTest, Probe, RayData, Tri4, ANY_HIT, W};
use std::arch::x86_64::*;

/// Proof that this CPU has AVX2, FMA and POPCNT: only `detect` makes one. `tri8`: leaves are
/// tested two `Tri4` blocks at a time (`tri8_test`), else one at a time. `avx512`: the CPU
/// also has AVX-512 F and VL, and queries run as `Bvh::query_avx512`.
#[derive(Clone, Copy)]
pub(super) struct Avx2 {
    pub(super) tri8: bool,
    pub(super) avx512: bool,
}

impl Avx2 {
    pub(super) fn detect() -> Option<Avx2> {
        (is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") && is_x86_feature_detected!("popcnt")).then(|| Avx2 {
            tri8: !splits_256_bit_operations(),
            avx512: is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl"),
        })
    }
}

/// Whether this CPU executes each 256-bit operation as two 128-bit halves: AMD's first Zen
/// generation and Zen+ (family 17h, models below 30h). There two `Tri4` blocks tested in one
/// pass of 256-bit operations (`tri8_test`, paired by 128-bit inserts) gain nothing on
/// testing them one at a time, and lose the exit after a missed first block: one at a time
/// traced the displaced sphere's camera rays 3–4 % faster and the Cornell box's 4 % faster in
/// one process (`bvh_ab e 5 5:tri4`, docs/journal/performance.md).
fn splits_256_bit_operations() -> bool {
    let (v, l) = (__cpuid(0), __cpuid(1).eax);
    // "AuthenticAMD" in EBX, EDX, ECX.
    let amd = (v.ebx, v.edx, v.ecx) == (0x6874_7541, 0x6974_6e65, 0x444d_4163);
    let family = ((l >> 8) & 0xf) + ((l >> 20) & 0xff);
    let model = ((l >> 4) & 0xf) | ((l >> 12) & 0xf0);
    amd && family == 0x17 && model < 0x30
}

impl NodeTest for Avx2 {
    /// `super::node_test` with all eight children in one 256-bit register, each plane's
    /// distance as fma(p, inv, c) rather than (p − o)·inv: one operation fewer on the way from
    /// a node's load to its mask, and distances that differ from the SSE2 test's by roundings,
    /// which `FMA_WIDEN` covers (its comment has the argument), so the test stays conservative.
    /// Not a `#[target_feature]` function itself, which Rust may not inline: it is inlined
    /// into `Bvh::query_avx2`, which has the features, and only compiled there.
    #[inline(always)]
    fn node_test(self, node: &Node, r: &RayData, tmax: f32) -> (u32, [f32; W]) {
        let mut tnear = [0.0f32; W];
        // SAFETY: `self` exists only where `detect` found AVX2, FMA and POPCNT on this CPU; the
        // loads read one plane (8 floats, `plane`) and the store writes `tnear` (8 floats).
        let mask = unsafe {
            let plane = |p: usize| _mm256_loadu_ps(plane(&node.b[p]).as_ptr());
            // Per axis, the plane the ray enters by and the one it leaves by, picked by the
            // sign of its reciprocal direction (a blend on the sign bit): the same values as the
            // minimum and maximum of the two planes' distances (rounding is monotonic), with one
            // product per plane instead of two and a blend instead of a min on the way to the
            // mask. Empty slots' inverted boxes still give an entry past the exit.
            // A macro: this closure was not inlined (a call per axis and visit).
            macro_rules! t {
                ($axis:literal) => {{
                    let (lo, hi) = (plane($axis), plane($axis + 3));
                    let (il, ih) = (_mm256_set1_ps(r.inv_lo[$axis].x), _mm256_set1_ps(r.inv_hi[$axis].x));
                    let (cl, ch) = (_mm256_set1_ps(r.c_lo[$axis].x), _mm256_set1_ps(r.c_hi[$axis].x));
                    (_mm256_fmadd_ps(_mm256_blendv_ps(lo, hi, il), il, cl), _mm256_fmadd_ps(_mm256_blendv_ps(hi, lo, il), ih, ch))
                }};
            }
            let zero = _mm256_setzero_ps();
            let ((xn, xf), (yn, yf), (zn, zf)) = (t!(0), t!(1), t!(2));
            let tn = _mm256_max_ps(_mm256_max_ps(xn, yn), _mm256_max_ps(zn, zero));
            let tf = _mm256_min_ps(_mm256_min_ps(xf, yf), _mm256_min_ps(zf, _mm256_set1_ps(tmax)));
            _mm256_storeu_ps(tnear.as_mut_ptr(), tn);
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(tn, tf)) as u32 & node.valid
        };
        (mask, tnear)
    }

    /// `NodeTest::below` by one integer compare: the distances are not negative, so their bits
    /// order as integers do, and with the lane in the low three bits no two keys are equal
    /// (distances within eight units in the last place are ordered by lane, the higher below:
    /// the order of visits, not the hits, may differ from the SSE2 path's).
    #[inline(always)]
    fn below(self, tnear: &[f32; W], c: usize) -> u32 {
        // SAFETY: as in `node_test`; the load reads `tnear` (8 floats).
        unsafe {
            let keys = _mm256_or_si256(
                _mm256_and_si256(_mm256_castps_si256(_mm256_loadu_ps(tnear.as_ptr())), _mm256_set1_epi32(!7)),
                _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            );
            // Lane c's key picked from the keys in a register, not rebuilt from `tnear[c]` read
            // back through memory.
            let key = _mm256_permutevar8x32_epi32(keys, _mm256_set1_epi32(c as i32));
            _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(keys, key))) as u32
        }
    }

    #[inline(always)]
    fn leaf_test<const ANY: bool, P: Probe>(
        self,
        blocks: &[Tri4],
        r: &RayData,
        tmax: &mut f32,
        best: &mut Option<HitRec>,
        probe: &mut P,
    ) -> bool {
        if !self.tri8 {
            return super::leaf_test_tri4::<ANY, P>(blocks, r, tmax, best, probe);
        }
        let mut pairs = blocks.chunks_exact(2);
        for pair in &mut pairs {
            probe.block();
            probe.block();
            let tie_id = best.map_or(0, |h| h.1);
            // SAFETY: as in `node_test`.
            if let Some(h) = unsafe { tri8_test::<ANY>(&pair[0], &pair[1], r, *tmax, tie_id) } {
                *tmax = h.0;
                *best = Some(h);
                if ANY {
                    return true;
                }
            }
        }
        super::leaf_test_tri4::<ANY, P>(pairs.remainder(), r, tmax, best, probe)
    }
}

/// `tri4_test(a)` and then `tri4_test(b)` against the closer hit (with `ANY`: whether
/// either has a hit, `ANY_HIT`), in one pass of 256-bit operations: lanes 0..4 are `a`'s triangles,
/// 4..8 `b`'s, and every lane computes exactly `tri4_test`'s operations, so the result is
/// bit-identical to the two `Tri4` tests (which remain the path where an edge function
/// rounds to zero): the closest of the eight hits, of equal distances the lowest index, which
/// the sequence gives too.
///
/// # Safety
/// Only with AVX2 (an `Avx2` exists).
#[inline(always)]
unsafe fn tri8_test<const ANY: bool>(a: &Tri4, b: &Tri4, r: &RayData, tmax: f32, tie_id: u32) -> Option<HitRec> {
    // SAFETY: the caller has checked AVX2; the loads read whole `Vec4`s of `a` and `b`
    // and the stores write arrays of `W` floats.
    unsafe {
        let [kx, ky, kz] = r.k;
        // Macros, not closures: a closure is a function of its own, compiled without
        // `query_avx2`'s target features unless inlined (every intrinsic then a call).
        macro_rules! splat {
            ($v:expr) => {
                _mm256_set1_ps($v.x)
            };
        }
        let (ox, oy, oz) = (splat!(r.o[kx]), splat!(r.o[ky]), splat!(r.o[kz]));
        let (sx, sy, sz) = (splat!(r.s[0]), splat!(r.s[1]), splat!(r.s[2]));
        macro_rules! load {
            ($vtx:expr, $axis:expr) => {
                _mm256_set_m128(_mm_loadu_ps(b.v[$vtx][$axis].as_ref().as_ptr()), _mm_loadu_ps(a.v[$vtx][$axis].as_ref().as_ptr()))
            };
        }
        macro_rules! sheared {
            ($vtx:expr) => {{
                let az = _mm256_sub_ps(load!($vtx, kz), oz);
                let x = _mm256_sub_ps(_mm256_sub_ps(load!($vtx, kx), ox), _mm256_mul_ps(sx, az));
                let y = _mm256_sub_ps(_mm256_sub_ps(load!($vtx, ky), oy), _mm256_mul_ps(sy, az));
                (x, y, _mm256_mul_ps(sz, az))
            }};
        }
        let (ax, ay, az) = sheared!(0);
        let (bx, by, bz) = sheared!(1);
        let (cx, cy, cz) = sheared!(2);
        let u = _mm256_sub_ps(_mm256_mul_ps(cx, by), _mm256_mul_ps(cy, bx));
        let v = _mm256_sub_ps(_mm256_mul_ps(ax, cy), _mm256_mul_ps(ay, cx));
        let w = _mm256_sub_ps(_mm256_mul_ps(bx, ay), _mm256_mul_ps(by, ax));
        let zero = _mm256_setzero_ps();
        let eq0 = _mm256_or_ps(
            _mm256_or_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(u, zero), _mm256_cmp_ps::<_CMP_EQ_OQ>(v, zero)),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(w, zero),
        );
        if _mm256_movemask_ps(eq0) != 0 {
            let ha = tri4_test(a, r, tmax, tie_id);
            if ANY && ha.is_some() {
                return ha;
            }
            let hb = tri4_test(b, r, ha.map_or(tmax, |h| h.0), ha.map_or(tie_id, |h| h.1));
            return hb.or(ha);
        }
        // As in `tri4_fast`: lanes whose edge functions' sign bits differ are missed, and most
        // pairs are missed so in every lane.
        let apart = _mm256_or_ps(_mm256_xor_ps(u, v), _mm256_xor_ps(u, w));
        if _mm256_movemask_ps(apart) == 0xff {
            return None;
        }
        macro_rules! gt {
            ($x:expr) => {
                _mm256_cmp_ps::<_CMP_GT_OQ>($x, zero)
            };
        }
        let det = _mm256_add_ps(_mm256_add_ps(u, v), w);
        let t_scaled = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(u, az), _mm256_mul_ps(v, bz)), _mm256_mul_ps(w, cz));
        let sign = _mm256_set1_ps(-0.0);
        let dsign = _mm256_and_ps(det, sign);
        let ts = _mm256_xor_ps(t_scaled, dsign);
        let dabs = _mm256_xor_ps(det, dsign);
        let tmax8 = _mm256_set1_ps(tmax);
        // As in `tri4_fast`: the division only on the path of a possible hit, and no test of
        // `det` itself, nonzero in the lanes not `apart`.
        let tw = _mm256_set1_ps(tmax * crate::geometry::triangle::RANGE_WIDEN);
        let ok = _mm256_blendv_ps(_mm256_and_ps(gt!(ts), _mm256_cmp_ps::<_CMP_LT_OQ>(ts, _mm256_mul_ps(tw, dabs))), zero, apart);
        if _mm256_movemask_ps(ok) == 0 {
            return None;
        }
        let t = _mm256_div_ps(t_scaled, det);
        let ahead = _mm256_and_ps(ok, gt!(t));
        let mut m = _mm256_movemask_ps(_mm256_and_ps(ahead, _mm256_cmp_ps::<_CMP_LT_OQ>(t, tmax8))) as u32;
        let ids = [a.id[0], a.id[1], a.id[2], a.id[3], b.id[0], b.id[1], b.id[2], b.id[3]];
        if !ANY {
            m |= ties(&ids, _mm256_movemask_ps(_mm256_and_ps(ahead, _mm256_cmp_ps::<_CMP_EQ_OQ>(t, tmax8))) as u32, tie_id);
        }
        if m == 0 {
            return None;
        }
        if ANY {
            return Some(ANY_HIT);
        }
        let mut ta = [0.0f32; W];
        _mm256_storeu_ps(ta.as_mut_ptr(), t);
        let lane = closest_lane(&ta, &ids, m);
        let mut da = [0.0f32; W];
        let mut va = [0.0f32; W];
        let mut wa = [0.0f32; W];
        _mm256_storeu_ps(da.as_mut_ptr(), det);
        _mm256_storeu_ps(va.as_mut_ptr(), v);
        _mm256_storeu_ps(wa.as_mut_ptr(), w);
        let inv = 1.0 / da[lane];
        let id = ids[lane];
        Some((ta[lane], id, va[lane] * inv, wa[lane] * inv))
    }
}

/// The eight floats of one plane of a node.
#[inline(always)]
fn plane(p: &[glam::Vec4; 2]) -> &[f32; W] {
    // SAFETY: `Vec4` is four `f32`s without padding (`repr(C)` or a 16-byte SIMD type of
    // the same layout), so `[Vec4; 2]` is exactly `[f32; 8]`, and f32's alignment is lower.
    unsafe { &*(p as *const [glam::Vec4; 2] as *const [f32; W]) }
}
