//! Watertight ray/triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)).
//!
//! The ray is sheared so that it runs along +Z through the origin; each edge function is then a
//! 2D cross product of the sheared vertices. Because a shared edge produces the same edge function
//! (up to sign) for both triangles that use it, no ray can slip between two triangles sharing an
//! edge. When an edge function rounds to exactly zero the ray passes (numerically) through the edge
//! and the three functions are recomputed in f64, which is exact for products of f32 values, so the
//! tie is broken consistently by both neighbours.

use glam::{Vec3, Vec3A};

/// Per-ray constants of the shear transform, as three row vectors: the sheared coordinates of
/// a point relative to the origin are its dot products with `mx`, `my`, `mz`. Each row has one
/// 1 (or `sz`), at most one shear factor and a zero, so every dot product equals the paper's
/// `a[kx] - sx * a[kz]` exactly (adding a zero product is exact); it is computed in SIMD
/// without branching on the axis permutation.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    pub origin: Vec3A,
    pub mx: Vec3A,
    pub my: Vec3A,
    pub mz: Vec3A,
}

impl RayShear {
    /// `None` for a zero or non-finite direction or origin, which can hit nothing.
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Option<RayShear> {
        if !origin.is_finite() || !dir.is_finite() {
            return None;
        }
        let ([kx, ky, kz], [sx, sy, sz]) = shear_axes(dir)?;
        let mut mx = Vec3A::ZERO;
        mx[kx] = 1.0;
        mx[kz] = -sx;
        let mut my = Vec3A::ZERO;
        my[ky] = 1.0;
        my[kz] = -sy;
        let mut mz = Vec3A::ZERO;
        mz[kz] = sz;
        Some(RayShear { origin: origin.into(), mx, my, mz })
    }
}

/// The shear of Woop et al. for a finite direction `dir`: the axes `[kx, ky, kz]` and the
/// factors `[sx, sy, sz]` (`sz = 1/dir[kz]`, `sx = dir[kx]·sz`, `sy = dir[ky]·sz`). kz is the
/// dominant axis; kx and ky are the others, swapped for a negative dominant component so the
/// winding (and thus the sign of the edge functions) is preserved. `None` for a zero
/// direction. This file's `RayShear` shears with it; the BVH's `RayData::new` computes the same
/// axes and factors by selects (a test there holds them equal bit for bit).
#[inline(always)]
pub fn shear_axes(dir: Vec3) -> Option<([usize; 3], [f32; 3])> {
    let [kx, ky, kz] = shear_perm(dir)?;
    let d = dir.to_array();
    let sz = 1.0 / d[kz];
    Some(([kx, ky, kz], [d[kx] * sz, d[ky] * sz, sz]))
}

/// The axes `[kx, ky, kz]` of `shear_axes`.
#[inline(always)]
fn shear_perm(dir: Vec3) -> Option<[usize; 3]> {
    // Arrays, not `Vec3`'s `Index` (a `match` on the axis): indexed by a computed axis, that
    // compiled to compare-and-branch chains on the ray's direction, mispredicted per ray.
    let d = dir.to_array();
    let a = dir.abs().to_array();
    let kz = if a[0] > a[1] {
        if a[0] > a[2] {
            0
        } else {
            2
        }
    } else if a[1] > a[2] {
        1
    } else {
        2
    };
    if a[kz] == 0.0 {
        return None;
    }
    let mut kx = (kz + 1) % 3;
    let mut ky = (kx + 1) % 3;
    if d[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    Some([kx, ky, kz])
}

/// Factor on `tmax` in the range test made before the division (`t_scaled` against
/// `tmax · |det|`). That test only spares the division; whether a triangle is hit is decided on
/// the divided t. Unwidened, the rounding of `tmax · |det|` could reject a triangle whose t
/// rounds below `tmax`, so which of two triangles hit at nearly the same distance a query
/// reported depended on the order it tested them in. Widened by 2^-20 (above the 2^-23 that
/// the two roundings can take off) it rejects only triangles at or beyond `tmax`, and every
/// query — BVH traversal in any order, the packet query — reports the same hit: the closest,
/// and of hits at exactly the same distance the lowest triangle index.
pub const RANGE_WIDEN: f32 = 1.0 + 1.0 / (1 << 20) as f32;

/// Intersection of the sheared ray with triangle (p0, p1, p2): `(t, b1, b2)` with t in (0, tmax),
/// where b1, b2 are the weights of p1 and p2.
#[inline(always)]
pub fn intersect(r: &RayShear, p0: Vec3A, p1: Vec3A, p2: Vec3A, tmax: f32) -> Option<(f32, f32, f32)> {
    let a = p0 - r.origin;
    let b = p1 - r.origin;
    let c = p2 - r.origin;
    let s = |p: Vec3A| [p.dot(r.mx), p.dot(r.my), p.dot(r.mz)];
    intersect_sheared(s(a), s(b), s(c), tmax)
}

/// The test on already sheared vertices `[x, y, z]` (relative to the ray origin, z scaled by
/// 1/d_kz): `x = a_kx − sx·a_kz`, `y = a_ky − sy·a_kz`, `z = sz·a_kz`. The BVH's four-wide
/// test performs the same operations lane by lane and falls back to this function when an edge
/// function rounds to zero.
#[inline(always)]
pub fn intersect_sheared(a: [f32; 3], b: [f32; 3], c: [f32; 3], tmax: f32) -> Option<(f32, f32, f32)> {
    let [ax, ay, az] = a;
    let [bx, by, bz] = b;
    let [cx, cy, cz] = c;
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // Products of two f32 are exact in f64, so the sign of each edge function is exact here
        // and both triangles sharing the edge see the same (opposite-signed) value.
        let (ax, ay, bx, by, cx, cy) = (ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64);
        u = (cx * by - cy * bx) as f32;
        v = (ax * cy - ay * cx) as f32;
        w = (bx * ay - by * ax) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let t_scaled = u * az + v * bz + w * cz;
    // Compare before dividing (sign-aware) so a back-facing det never flips the range test;
    // widened so that it keeps every triangle whose divided t is below tmax (see `RANGE_WIDEN`).
    let (ts, d) = if det < 0.0 { (-t_scaled, -det) } else { (t_scaled, det) };
    if !(ts > 0.0) || !(ts < tmax * RANGE_WIDEN * d) {
        return None;
    }
    let t = t_scaled / det;
    if !(t > 0.0 && t < tmax) {
        return None;
    }
    let inv = 1.0 / det;
    Some((t, v * inv, w * inv))
}

/// True when the triangle can never be hit: a non-finite vertex or exactly collinear vertices.
/// The cross product is taken in f64 so tiny but valid triangles (whose f32 cross product would
/// underflow) are kept.
pub fn is_degenerate(p0: Vec3, p1: Vec3, p2: Vec3) -> bool {
    if !(p0.is_finite() && p1.is_finite() && p2.is_finite()) {
        return true;
    }
    let (a, b, c) = (p0.as_dvec3(), p1.as_dvec3(), p2.as_dvec3());
    (b - a).cross(c - a) == glam::DVec3::ZERO
}
