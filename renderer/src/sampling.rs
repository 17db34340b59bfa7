//! Warps from the unit square to directions and points, their densities, and MIS weights.

use crate::math::{INV_PI, PI};
use glam::{Vec2, Vec3};

/// Concentric (Shirley–Chiu) map of the unit square to the unit disk.
///
/// The angle is π/4 · q for |q| ≤ 1 in each octant pair, so its sine and cosine come from
/// `sin_cos_quarter` rather than libm's `sincosf` (5–8 % of the Cornell box render's samples
/// when it was a call per bounce); with selects instead of branches the wavefront's lane loops
/// vectorise it. (The second octant pair's cos(π/2 − a), sin(π/2 − a) are sin a, cos a.)
#[inline(always)]
pub fn square_to_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    let wide = o.x.abs() > o.y.abs();
    let (r, q) = if wide { (o.x, o.y) } else { (o.y, o.x) };
    let (s, c) = sin_cos_quarter((PI / 4.0) * (q / r));
    let d = if wide { Vec2::new(c, s) } else { Vec2::new(s, c) };
    // r is zero only at the centre (o = 0), where q / r is NaN.
    if r == 0.0 {
        Vec2::ZERO
    } else {
        r * d
    }
}

/// Sine and cosine of `a` for |a| ≤ π/4: Taylor polynomials through a⁹ and a¹⁰ (truncation
/// error below 2e-9 there), evaluated with plain multiplies and adds, which every CPU and every
/// lane of a vectorised loop rounds alike (no fused multiply-add: Rust never contracts).
#[inline(always)]
fn sin_cos_quarter(a: f32) -> (f32, f32) {
    let a2 = a * a;
    let s = a * (1.0 + a2 * (-1.0 / 6.0 + a2 * (1.0 / 120.0 + a2 * (-1.0 / 5040.0 + a2 * (1.0 / 362880.0)))));
    let c = 1.0 + a2 * (-0.5 + a2 * (1.0 / 24.0 + a2 * (-1.0 / 720.0 + a2 * (1.0 / 40320.0 + a2 * (-1.0 / 3628800.0)))));
    (s, c)
}

/// Cosine-weighted hemisphere around +Z; density `cos θ / π`.
// Always inlined: called in the wavefront's vectorised lane loops (integrator/wave.rs).
#[inline(always)]
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_disk_concentric(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * INV_PI
}

/// Uniform direction on the unit sphere; density `1 / 4π`.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform point on a triangle as barycentrics (b1, b2) (Heitz 2019's low-distortion map).
// Always inlined: the wavefront's vectorised lane loops (integrator/wave.rs) must hold no calls.
#[inline(always)]
pub fn square_to_triangle(u: Vec2) -> Vec2 {
    let (mut b0, mut b1);
    if u.x < u.y {
        b0 = u.x / 2.0;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.0;
        b0 = u.x - b1;
    }
    b0 = b0.clamp(0.0, 1.0);
    b1 = b1.clamp(0.0, 1.0);
    Vec2::new(b1, 1.0 - b0 - b1).max(Vec2::ZERO)
}

/// Power heuristic (β = 2) weight of strategy `a` against `b`, with densities in the same measure.
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let a = pdf_a * pdf_a;
    let b = pdf_b * pdf_b;
    if a == 0.0 {
        return 0.0;
    }
    if !b.is_finite() {
        return 0.0;
    }
    if !a.is_finite() {
        return 1.0;
    }
    a / (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The polynomial sine and cosine against f64's over the whole range they serve: within
    /// 2.5e-7 absolute (a few f32 ulps of values ≤ 1; truncation is below 2e-9, the rest is
    /// the rounding of eleven f32 operations).
    #[test]
    fn sin_cos_quarter_matches_libm() {
        let n = 100_000;
        let mut worst = 0.0f64;
        for i in 0..=n {
            let a = (PI / 4.0) * (2.0 * i as f32 / n as f32 - 1.0);
            let (s, c) = sin_cos_quarter(a);
            let (es, ec) = (a as f64).sin_cos();
            worst = worst.max((s as f64 - es).abs()).max((c as f64 - ec).abs());
        }
        assert!(worst < 2.5e-7, "worst error {worst:e}");
    }

    /// The concentric map against its definition in f64 (Shirley and Chiu 1997): the same
    /// point within 4e-7, never outside the unit disk by more than rounding, and the centre
    /// and the square's edges where they belong.
    #[test]
    fn concentric_map_matches_its_definition() {
        let reference = |u: Vec2| {
            let (x, y) = (2.0 * u.x as f64 - 1.0, 2.0 * u.y as f64 - 1.0);
            if x == 0.0 && y == 0.0 {
                return (0.0, 0.0);
            }
            let q = std::f64::consts::FRAC_PI_4;
            let (r, t) = if x.abs() > y.abs() { (x, q * (y / x)) } else { (y, 2.0 * q - q * (x / y)) };
            (r * t.cos(), r * t.sin())
        };
        let n = 300;
        for j in 0..=n {
            for i in 0..=n {
                let u = Vec2::new(i as f32 / n as f32, j as f32 / n as f32);
                let d = square_to_disk_concentric(u);
                let (ex, ey) = reference(u);
                assert!((d.x as f64 - ex).abs() < 4e-7 && (d.y as f64 - ey).abs() < 4e-7, "u {u}: {d} vs ({ex}, {ey})");
                assert!(d.length() <= 1.0 + 3e-7, "u {u}: {d} outside the disk");
            }
        }
        assert_eq!(square_to_disk_concentric(Vec2::splat(0.5)), Vec2::ZERO);
        assert_eq!(square_to_disk_concentric(Vec2::new(1.0, 0.5)), Vec2::new(1.0, 0.0));
    }
}
