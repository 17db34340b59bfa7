//! Materials as scenes describe them: a `MaterialKind` with colour parameters that may be
//! textured, plus emission. `Material::bsdf` turns one into a `Bsdf` at a surface point. Both
//! the scene loaders and the light structures (emissive triangles) use these, so they live here
//! rather than in `scene`.

use super::{Bsdf, Distribution, MIN_ALPHA};
use crate::texture::Texture;
use glam::{Affine2, Vec2, Vec3};

/// A colour that is constant or varies over a surface with its texture coordinates. Every
/// colour parameter of a material (albedo, a conductor's tint) is one of these, and
/// `ColorParam::eval` is the one place they are looked up.
#[derive(Clone, Debug)]
pub enum ColorParam {
    Const(Vec3),
    /// `textures[index]` times `scale`, bilinear and repeating, looked up at `to_uv(uv)`.
    Texture {
        index: u32,
        scale: Vec3,
        to_uv: Affine2,
    },
    /// Mitsuba's `checkerboard`: with (s, t) = `to_uv(uv)`, `color0` where the fractional parts
    /// of s and t are on the same side of ½ (both ≤ ½ or both > ½), else `color1`; so
    /// uv (0, 0) is `color0` and one period of the pattern spans one unit of s and t.
    Checkerboard {
        color0: Vec3,
        color1: Vec3,
        to_uv: Affine2,
    },
}

impl ColorParam {
    /// An image texture times `scale`, with the texture coordinates as they are.
    pub fn texture(index: u32, scale: Vec3) -> ColorParam {
        ColorParam::Texture { index, scale, to_uv: Affine2::IDENTITY }
    }

    /// The colour at texture coordinate `uv`.
    pub fn eval(&self, uv: Vec2, textures: &[Texture]) -> Vec3 {
        match self {
            ColorParam::Const(v) => *v,
            ColorParam::Texture { index, scale, to_uv } => textures[*index as usize].sample_bilinear(to_uv.transform_point2(uv)) * *scale,
            ColorParam::Checkerboard { color0, color1, to_uv } => {
                let p = to_uv.transform_point2(uv);
                if (p.x - p.x.floor() > 0.5) == (p.y - p.y.floor() > 0.5) {
                    *color0
                } else {
                    *color1
                }
            }
        }
    }

    /// Whether the colour varies over a surface.
    pub fn is_textured(&self) -> bool {
        !matches!(self, ColorParam::Const(_))
    }
}

/// The BSDF of a material, before texture lookups.
#[derive(Clone, Debug)]
pub enum MaterialKind {
    Lambert {
        albedo: ColorParam,
    },
    Conductor {
        eta: Vec3,
        k: Vec3,
        roughness: f32,
        specular_tint: ColorParam,
        dist: Distribution,
    },
    Dielectric {
        ior: f32,
        roughness: f32,
        tint: Vec3,
        dist: Distribution,
    },
    /// `nonlinear`: see `Bsdf::Plastic` (true in our formats; Mitsuba's `nonlinear`, default false).
    Plastic {
        albedo: ColorParam,
        ior: f32,
        roughness: f32,
        dist: Distribution,
        nonlinear: bool,
    },
}

/// A named material. `roughness` values above are GGX alpha. Non-zero `emission` makes every
/// triangle with this material an area light, emitting on the side of its geometric normal
/// (both sides if `two_sided_emission`).
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub kind: MaterialKind,
    pub emission: Vec3,
    pub two_sided_emission: bool,
    /// Reflect only on the front side (the winding normal's side), black from behind, as
    /// Mitsuba's BSDFs are unless wrapped in `twosided`. False (both sides alike) in our formats;
    /// transmissive BSDFs ignore it.
    pub one_sided: bool,
}

impl Material {
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// Emitted radiance leaving the surface with geometric normal `ng` in direction `w`.
    pub fn emitted(&self, ng: Vec3, w: Vec3) -> Vec3 {
        if self.two_sided_emission || ng.dot(w) > 0.0 {
            self.emission
        } else {
            Vec3::ZERO
        }
    }

    /// The BSDF at texture coordinate `uv`.
    pub fn bsdf(&self, uv: Vec2, textures: &[Texture]) -> Bsdf {
        let color = |c: &ColorParam| c.eval(uv, textures);
        let alpha = |r: f32| if r < MIN_ALPHA { 0.0 } else { r.min(1.0) };
        match &self.kind {
            MaterialKind::Lambert { albedo } => Bsdf::Lambert { albedo: color(albedo).clamp(Vec3::ZERO, Vec3::ONE) },
            MaterialKind::Conductor { eta, k, roughness, specular_tint, dist } => Bsdf::Conductor {
                eta: *eta,
                k: *k,
                alpha: alpha(*roughness),
                specular_tint: color(specular_tint).min(Vec3::ONE),
                dist: *dist,
            },
            MaterialKind::Dielectric { ior, roughness, tint, dist } => {
                Bsdf::Dielectric { eta: *ior, alpha: alpha(*roughness), tint: *tint, dist: *dist }
            }
            MaterialKind::Plastic { albedo, ior, roughness, dist, nonlinear } => Bsdf::Plastic {
                albedo: color(albedo).clamp(Vec3::ZERO, Vec3::ONE),
                eta: *ior,
                alpha: alpha(*roughness),
                dist: *dist,
                nonlinear: *nonlinear,
            },
        }
    }
}
