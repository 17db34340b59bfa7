//! Leaf blocks of four triangles side by side (`Tri4`) and their test: Woop et al.'s watertight
//! test (see `triangle.rs`) four lanes at a time with exactly the scalar version's
//! floating-point operations, and the scalar test for a block in which an edge function
//! rounds to zero.

use super::{triangle, HitRec, RayData, ANY_HIT};
use glam::{Vec3, Vec4};

/// Four triangles side by side: `v[vertex][axis]`, lane i being triangle i. A leaf with fewer
/// than four triangles repeats its last one (the duplicate finds the same hit).
#[derive(Clone, Copy)]
#[repr(C, align(16))]
pub(super) struct Tri4 {
    pub(super) v: [[Vec4; 3]; 3],
    /// Original triangle index (into `Mesh::triangles`) of each lane.
    pub(super) id: [u32; 4],
}

/// Closest of the four triangles of `blk` hit in (0, tmax), or at exactly `tmax` with an index
/// below `tie_id` (the closest hit so far; 0 where there is none): (t, triangle index, b1, b2).
/// Of equal distances the lowest index wins, so the closest hit of a whole query does not depend
/// on the order the blocks are tested in (see `triangle::RANGE_WIDEN`). Exactly the
/// floating-point operations of `triangle::intersect`, four lanes at a time.
#[inline(always)]
pub(super) fn tri4_test(blk: &Tri4, r: &RayData, tmax: f32, tie_id: u32) -> Option<HitRec> {
    match tri4_fast::<false>(blk, r, tmax, tie_id) {
        Tri4Result::Miss => None,
        Tri4Result::Hit(h) => Some(h),
        Tri4Result::EdgeZero => tri4_scalar(blk, r, tmax, tie_id),
    }
}

/// What the vector part of `tri4_test` found.
pub(super) enum Tri4Result {
    Miss,
    Hit(HitRec),
    /// An edge function rounded to zero: the ray passes (numerically) through an edge or
    /// vertex; the scalar test (`tri4_scalar`) resolves it exactly, consistently with the
    /// neighbour.
    EdgeZero,
}

/// `tri4_test` without its scalar fallback. Kept apart so that a caller handles the two
/// outcomes on separate paths: merged with the out-of-line fallback's result (returned through
/// memory), the hit record was assembled in memory by four scalar stores and reloaded at once
/// by `*best = Some(h)`, a failed store-to-load forward on every leaf hit.
///
/// With `ANY` a hit is `ANY_HIT`: an any-hit query only asks whether there is one, so the
/// closest lane, its division and its barycentrics are skipped.
#[inline(always)]
pub(super) fn tri4_fast<const ANY: bool>(blk: &Tri4, r: &RayData, tmax: f32, tie_id: u32) -> Tri4Result {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.s;
    let sheared = |v: &[Vec4; 3]| {
        let az = v[kz] - r.o[kz];
        (v[kx] - r.o[kx] - sx * az, v[ky] - r.o[ky] - sy * az, sz * az)
    };
    let (ax, ay, az) = sheared(&blk.v[0]);
    let (bx, by, bz) = sheared(&blk.v[1]);
    let (cx, cy, cz) = sheared(&blk.v[2]);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let zero = Vec4::ZERO;
    if (u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero)).any() {
        return Tri4Result::EdgeZero;
    }
    // A lane is missed by the ray's line where two of its edge functions (none zero, checked
    // above) have opposite signs: their sign bits decide. Most blocks are missed so in every
    // lane and skip the rest of the test.
    let (su, sv, sw) = (u.is_negative_bitmask(), v.is_negative_bitmask(), w.is_negative_bitmask());
    let apart = (su ^ sv) | (su ^ sw);
    if apart == 0xf {
        return Tri4Result::Miss;
    }
    // In the other lanes u, v and w are nonzero and of one sign, so their sum `det` is nonzero
    // too; a NaN fails the comparisons of `ts`, and where `det` overflowed t is 0 or NaN below
    // and fails `t > 0`.
    let det = u + v + w;
    let t_scaled = u * az + v * bz + w * cz;
    let ts = Vec4::select(det.cmplt(zero), -t_scaled, t_scaled);
    let dabs = det.abs();
    let tmax4 = Vec4::splat(tmax);
    // The division only on the path of a possible hit.
    let tw = Vec4::splat(tmax * triangle::RANGE_WIDEN);
    let ok = (ts.cmpgt(zero) & ts.cmplt(tw * dabs)).bitmask() & !apart;
    if ok == 0 {
        return Tri4Result::Miss;
    }
    let t = t_scaled / det;
    let ahead = ok & t.cmpgt(zero).bitmask();
    let mut m = ahead & t.cmplt(tmax4).bitmask();
    if !ANY {
        m |= ties(&blk.id, ahead & t.cmpeq(tmax4).bitmask(), tie_id);
    }
    if m == 0 {
        return Tri4Result::Miss;
    }
    if ANY {
        return Tri4Result::Hit(ANY_HIT);
    }
    let ta = t.to_array();
    let lane = closest_lane(&ta, &blk.id, m);
    let inv = 1.0 / det.to_array()[lane];
    Tri4Result::Hit((ta[lane], blk.id[lane], v.to_array()[lane] * inv, w.to_array()[lane] * inv))
}

/// The lane set in `m` (bit i: lane i) with the smallest `t`; of equal ones the one with the
/// lowest triangle index `id`.
#[inline(always)]
pub(super) fn closest_lane(t: &[f32], id: &[u32], mut m: u32) -> usize {
    let mut lane = m.trailing_zeros() as usize;
    m &= m - 1;
    while m != 0 {
        let l = m.trailing_zeros() as usize;
        m &= m - 1;
        if t[l] < t[lane] || (t[l] == t[lane] && id[l] < id[lane]) {
            lane = l;
        }
    }
    lane
}

/// Of the lanes in `eq` (hit at exactly the closest distance so far), those whose triangle
/// index is below `tie_id`, the closest hit's.
#[inline(always)]
pub(super) fn ties(id: &[u32], mut eq: u32, tie_id: u32) -> u32 {
    let mut m = 0;
    while eq != 0 {
        let l = eq.trailing_zeros();
        eq &= eq - 1;
        if id[l as usize] < tie_id {
            m |= 1 << l;
        }
    }
    m
}

/// `tri4_test` one lane at a time through the scalar watertight test (which recomputes edge
/// functions that round to zero in f64).
#[inline(never)]
pub(super) fn tri4_scalar(blk: &Tri4, r: &RayData, mut tmax: f32, mut tie_id: u32) -> Option<HitRec> {
    let [kx, ky, kz] = r.k;
    let [sx, sy, sz] = r.ss;
    let o = Vec3::new(r.o[0].x, r.o[1].x, r.o[2].x);
    let mut best = None;
    for lane in 0..4 {
        let p = |vtx: usize| Vec3::new(blk.v[vtx][0][lane], blk.v[vtx][1][lane], blk.v[vtx][2][lane]) - o;
        let sheared = |a: Vec3| {
            let az = a[kz];
            [a[kx] - sx * az, a[ky] - sy * az, sz * az]
        };
        // Up to and including tmax, then the rule on ties.
        if let Some((t, b1, b2)) = triangle::intersect_sheared(sheared(p(0)), sheared(p(1)), sheared(p(2)), tmax.next_up()) {
            if t < tmax || blk.id[lane] < tie_id {
                tmax = t;
                tie_id = blk.id[lane];
                best = Some((t, blk.id[lane], b1, b2));
            }
        }
    }
    best
}
