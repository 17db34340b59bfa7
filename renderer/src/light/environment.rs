//! The environment light: a constant colour, or an importance-sampled lat-long map.
//!
//! # Direction ↔ texture mapping (y up)
//!
//! A lat-long map of `W × H` texels covers the sphere with `u` along the azimuth φ and `v` along
//! the polar angle θ measured from +Y; row 0 (v = 0) is the zenith (+Y), the bottom row is −Y.
//! For a unit direction `d = (x, y, z)` in the map's own frame:
//!
//! ```text
//! θ = acos(y),            v = θ / π            ∈ [0, 1]
//! φ = atan2(x, −z),       u = φ / 2π mod 1     ∈ [0, 1)
//! d = (sin θ · sin φ,  cos θ,  −sin θ · cos φ)      (inverse)
//! ```
//!
//! so the left edge of the image (u = 0) looks toward −Z, u = ¼ toward +X, the image centre
//! (u = ½) toward +Z and u = ¾ toward −X. Texel `(i, j)` covers u ∈ [i/W, (i+1)/W),
//! v ∈ [j/H, (j+1)/H).
//!
//! `rotation_deg` rotates the map about +Y (right-handed: a positive angle turns +Z toward +X):
//! `d_world = R_y(α) · d_map` with `R_y(α)(x, y, z) = (x cos α + z sin α, y, −x sin α + z cos α)`.
//! Radiance is the texel value times `scale`.
//!
//! # Lookup and sampling
//!
//! Radiance is looked up bilinearly (wrapping in u, clamped in v so the poles never blend with
//! the opposite pole). Directions are sampled from a piecewise-constant 2D distribution over the
//! texels with weight `luminance × sin θ_centre` (pbrt's scheme), where the luminance is the
//! mean of the bilinear reconstruction over the texel (¾ own value, ⅛ per neighbour, per axis).
//! Bilinear filtering spreads a texel into its neighbours; weighting by the filtered mean keeps
//! the pdf proportional to the energy actually seen and positive wherever the radiance is
//! positive, so a one-texel sun is found by light sampling in full. The solid-angle density is
//! `pdf_uv / (2π² sin θ)` with `pdf_uv` the value of the texel cell containing the direction;
//! [`EnvLight::pdf`] evaluates exactly that, and `sample` reports `pdf(wi)` of the direction it
//! returns, so the two agree bit for bit.
//!
//! Negative, NaN or infinite texels (and a negative or non-finite `scale`) count as 0.

use super::distribution::Distribution2D;
use super::{Environment, EnvironmentView};
use crate::math::PI;
use crate::sampling::{square_to_uniform_sphere, UNIFORM_SPHERE_PDF};
use glam::{Vec2, Vec3};

/// The environment after sanitising, ready to sample.
pub(crate) enum EnvLight {
    Black,
    Constant(Vec3),
    Map(Box<EnvMap>),
}

pub(crate) struct EnvMap {
    width: usize,
    height: usize,
    /// Sanitised texels, `scale` applied.
    texels: Vec<Vec3>,
    cos_rot: f32,
    sin_rot: f32,
    dist: Distribution2D,
    /// Mean luminance over the sphere (solid-angle weighted).
    mean_luminance: f64,
}

/// Rec. 709 luminance in f64: texels near f32::MAX would overflow the f32 weighted sum.
fn luminance64(t: Vec3) -> f64 {
    0.2126 * t.x as f64 + 0.7152 * t.y as f64 + 0.0722 * t.z as f64
}

/// Keeps a radiance finite and non-negative.
fn sanitize(c: Vec3) -> Vec3 {
    let f = |x: f32| if x.is_finite() && x > 0.0 { x } else { 0.0 };
    Vec3::new(f(c.x), f(c.y), f(c.z))
}

impl EnvLight {
    pub fn new(env: Environment) -> EnvLight {
        match env {
            Environment::Constant(c) => {
                let c = sanitize(c);
                if c.max_element() > 0.0 {
                    EnvLight::Constant(c)
                } else {
                    EnvLight::Black
                }
            }
            Environment::Map { image, rotation_deg, scale } => {
                let (w, h) = (image.width as usize, image.height as usize);
                if w == 0 || h == 0 || image.texels.len() != w * h {
                    return EnvLight::Black;
                }
                let scale = if scale.is_finite() && scale > 0.0 { scale } else { 0.0 };
                let texels: Vec<Vec3> = image.texels.iter().map(|&t| (sanitize(t) * scale).min(Vec3::splat(f32::MAX))).collect();
                let mut lum: Vec<f32> = texels.iter().map(|&t| luminance64(t).min(f32::MAX as f64) as f32).collect();
                let sin_row = |y: usize| ((y as f64 + 0.5) / h as f64 * std::f64::consts::PI).sin();
                // Σ L sin θ ΔθΔφ / 4π with Δθ = π/H, Δφ = 2π/W.
                let mut acc = 0.0f64;
                for y in 0..h {
                    acc += texels[y * w..(y + 1) * w].iter().map(|&t| luminance64(t)).sum::<f64>() * sin_row(y);
                }
                let mean_luminance =
                    acc * (std::f64::consts::PI / h as f64) * (2.0 * std::f64::consts::PI / w as f64) / (4.0 * std::f64::consts::PI);
                // Mean of the bilinear reconstruction over each texel: per axis the texel keeps ¾ of
                // its own value and gets ⅛ of each neighbour's (wrapping in u, clamped in v).
                // f32 buffers, reused, keep an 8k map's transient memory at 8 bytes per texel.
                let mut across = vec![0.0f32; w * h];
                for y in 0..h {
                    let row = &lum[y * w..(y + 1) * w];
                    for x in 0..w {
                        let (l, r) = (row[(x + w - 1) % w] as f64, row[(x + 1) % w] as f64);
                        across[y * w + x] = (0.75 * row[x] as f64 + 0.125 * (l + r)).min(f32::MAX as f64) as f32;
                    }
                }
                for y in 0..h {
                    let (up, down) = (y.saturating_sub(1), (y + 1).min(h - 1));
                    for x in 0..w {
                        let (a, b) = (across[up * w + x] as f64, across[down * w + x] as f64);
                        let m = 0.75 * across[y * w + x] as f64 + 0.125 * (a + b);
                        lum[y * w + x] = (m * sin_row(y)).min(f32::MAX as f64) as f32;
                    }
                }
                drop(across);
                let Some(dist) = Distribution2D::new(&lum, w, h) else {
                    return EnvLight::Black;
                };
                let rot = if rotation_deg.is_finite() { (rotation_deg as f64).to_radians() } else { 0.0 };
                EnvLight::Map(Box::new(EnvMap {
                    width: w,
                    height: h,
                    texels,
                    cos_rot: rot.cos() as f32,
                    sin_rot: rot.sin() as f32,
                    dist,
                    mean_luminance,
                }))
            }
        }
    }

    pub fn view(&self) -> EnvironmentView<'_> {
        match self {
            EnvLight::Black => EnvironmentView::Black,
            EnvLight::Constant(c) => EnvironmentView::Constant(*c),
            EnvLight::Map(m) => {
                EnvironmentView::Map { width: m.width, height: m.height, texels: &m.texels, cos_rot: m.cos_rot, sin_rot: m.sin_rot }
            }
        }
    }

    pub fn is_black(&self) -> bool {
        matches!(self, EnvLight::Black)
    }

    /// Power estimate of an environment around a scene of radius `r`: 4π · πr² · mean luminance.
    pub fn power(&self, r: f32) -> f64 {
        let mean = match self {
            EnvLight::Black => 0.0,
            EnvLight::Constant(c) => luminance64(*c),
            EnvLight::Map(m) => m.mean_luminance,
        };
        let r = r as f64;
        4.0 * std::f64::consts::PI * std::f64::consts::PI * r * r * mean
    }

    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match self {
            EnvLight::Black => Vec3::ZERO,
            EnvLight::Constant(c) => *c,
            EnvLight::Map(m) => m.lookup(dir),
        }
    }

    /// `radiance(dir)` and, if `want_pdf`, `pdf(dir)` (else 0), the direction's texture
    /// coordinates found once for both: each costs an atan2 and an acos.
    pub fn radiance_pdf(&self, dir: Vec3, want_pdf: bool) -> (Vec3, f32) {
        match self {
            EnvLight::Black => (Vec3::ZERO, 0.0),
            EnvLight::Constant(c) => (*c, if want_pdf { UNIFORM_SPHERE_PDF } else { 0.0 }),
            EnvLight::Map(m) => match m.uv_of(dir) {
                None => (Vec3::ZERO, 0.0),
                Some((uv, sin_theta)) => (m.lookup_uv(uv), if want_pdf { m.pdf_uv(uv, sin_theta) } else { 0.0 }),
            },
        }
    }

    /// Solid-angle density of `sample`, selection not included.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self {
            EnvLight::Black => 0.0,
            EnvLight::Constant(_) => UNIFORM_SPHERE_PDF,
            EnvLight::Map(m) => m.pdf(dir),
        }
    }

    /// A world direction, its density `self.pdf(wi)` and `self.radiance(wi)`; `None` if that
    /// density is 0.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32, Vec3)> {
        match self {
            EnvLight::Black => None,
            EnvLight::Constant(c) => Some((square_to_uniform_sphere(u), UNIFORM_SPHERE_PDF, *c)),
            EnvLight::Map(m) => {
                let uv = m.dist.sample(u);
                let wi = m.to_world(uv_to_dir(uv));
                let (radiance, pdf) = self.radiance_pdf(wi, true);
                (pdf > 0.0).then_some((wi, pdf, radiance))
            }
        }
    }
}

/// Map-frame direction of texture coordinates (see the module docs).
pub fn uv_to_dir(uv: Vec2) -> Vec3 {
    let phi = 2.0 * PI * uv.x;
    let theta = PI * uv.y;
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(st * sp, ct, -st * cp)
}

/// Texture coordinates of a unit map-frame direction, and sin θ.
pub fn dir_to_uv(d: Vec3) -> (Vec2, f32) {
    let theta = d.y.clamp(-1.0, 1.0).acos();
    let mut u = d.x.atan2(-d.z) * (0.5 / PI);
    if u < 0.0 {
        u += 1.0;
    }
    // u = 1 − tiny can round to 1.0; it belongs to the last column.
    let u = if u < 1.0 { u } else { 0.0 };
    let sin_theta = (d.x * d.x + d.z * d.z).sqrt();
    (Vec2::new(u, theta / PI), sin_theta)
}

impl EnvMap {
    fn to_world(&self, d: Vec3) -> Vec3 {
        let (c, s) = (self.cos_rot, self.sin_rot);
        Vec3::new(d.x * c + d.z * s, d.y, -d.x * s + d.z * c)
    }

    /// Unit map-frame direction of a world direction; `None` for zero or non-finite input.
    fn to_map(&self, d: Vec3) -> Option<Vec3> {
        let d = d.normalize_or_zero();
        if d == Vec3::ZERO || !d.is_finite() {
            return None;
        }
        let (c, s) = (self.cos_rot, self.sin_rot);
        Some(Vec3::new(d.x * c - d.z * s, d.y, d.x * s + d.z * c))
    }

    fn texel(&self, x: i64, y: i64) -> Vec3 {
        // Lookups ask for columns −1 to W: a wrap by one width spares the division.
        let w = self.width as i64;
        let x = if x < 0 {
            x + w
        } else if x >= w {
            x - w
        } else {
            x
        };
        let x = if (0..w).contains(&x) { x as usize } else { x.rem_euclid(w) as usize };
        let y = y.clamp(0, self.height as i64 - 1) as usize;
        self.texels[y * self.width + x]
    }

    /// Texture coordinates and sin θ of a world direction (`None` for zero or non-finite).
    fn uv_of(&self, dir: Vec3) -> Option<(Vec2, f32)> {
        self.to_map(dir).map(dir_to_uv)
    }

    fn lookup(&self, dir: Vec3) -> Vec3 {
        self.uv_of(dir).map_or(Vec3::ZERO, |(uv, _)| self.lookup_uv(uv))
    }

    fn lookup_uv(&self, uv: Vec2) -> Vec3 {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let b = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        let c = a.lerp(b, fy);
        // Lerping two texels near f32::MAX may overflow.
        if c.is_finite() {
            c
        } else {
            Vec3::splat(f32::MAX).min(c.max(Vec3::ZERO))
        }
    }

    fn pdf(&self, dir: Vec3) -> f32 {
        self.uv_of(dir).map_or(0.0, |(uv, sin_theta)| self.pdf_uv(uv, sin_theta))
    }

    fn pdf_uv(&self, uv: Vec2, sin_theta: f32) -> f32 {
        if !(sin_theta > 0.0) {
            return 0.0;
        }
        let pdf = self.dist.pdf(uv) / (2.0 * PI * PI * sin_theta);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }
}
