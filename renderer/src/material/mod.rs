//! BSDFs: what the scenes need and no more (Lambert, conductor, dielectric, plastic).
//!
//! All directions are in the local shading frame (+Z = shading normal), pointing away from the
//! surface. `eval` returns f(wo, wi)·|cos θi| (the cosine is folded in), `pdf` the solid-angle
//! density with which `sample` produces `wi` (lobe-selection probability included), and `sample`
//! returns the weight f·|cos θi| / pdf. Delta lobes (smooth mirror, smooth glass, smooth coat)
//! are never returned by `eval`/`pdf`; their samples carry `Lobe::kind == Specular` and a `pdf`
//! equal to the discrete probability of choosing that lobe (so the path-descriptor "sampling
//! probability" stays finite).
//!
//! Sidedness: reflection-only BSDFs (Lambert, conductor, plastic) are two-sided: the integrator
//! flips the frame so that `wo.z > 0` before calling them. Dielectrics see the unflipped frame:
//! `wo.z > 0` means outside (the side the normal points to), and `eta` is interior/exterior IOR.

use crate::math::is_finite3;
use glam::{Vec2, Vec3};

mod conductor;
mod description;
mod dielectric;
pub mod fresnel;
mod lambert;
pub mod microfacet;
mod plastic;
#[cfg(test)]
mod tests;

use conductor::Conductor;
pub use description::{ColorParam, Material, MaterialKind};
use dielectric::Dielectric;
pub use microfacet::Distribution;
pub(crate) use plastic::mitsuba_nonlinear_albedo;
use plastic::Plastic;

/// What kind of lobe produced a sample; mirrors the renderer bitmask of method.md §1.1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LobeKind {
    Diffuse,
    Glossy,
    Specular,
}

/// A sampled lobe: kind, reflection or transmission, and its roughness (GGX alpha; 1 for
/// Lambert, 0 for smooth/delta lobes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobe {
    pub kind: LobeKind,
    pub transmission: bool,
    pub roughness: f32,
}

impl Lobe {
    /// The bounce-type bitmask of method.md §1.1: reflection 1, transmission 2, diffuse 4,
    /// glossy 8, specular 16.
    pub fn bitmask(&self) -> u32 {
        let dir = if self.transmission { 2 } else { 1 };
        let kind = match self.kind {
            LobeKind::Diffuse => 4,
            LobeKind::Glossy => 8,
            LobeKind::Specular => 16,
        };
        dir | kind
    }
}

/// One importance sample of a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Sampled incident direction, local frame, unit length.
    pub wi: Vec3,
    /// f·|cos θi| / pdf — finite and non-negative.
    pub weight: Vec3,
    /// f·|cos θi| of the sampled lobe (for delta lobes: weight·pdf).
    pub f_cos: Vec3,
    /// Solid-angle density (non-delta) or discrete lobe probability (delta lobes). > 0.
    pub pdf: f32,
    pub lobe: Lobe,
    /// Relative IOR crossed by a transmission sample (η_i/η_t), 1 for reflection; for radiance
    /// scaling and for MIS bookkeeping. η_i is the IOR on `wo`'s side (where the path arrives
    /// from), η_t the one on `wi`'s side: entering glass of IOR 1.5 from air gives 1/1.5. The
    /// radiance factor (η_i/η_t)² is already included in `weight` and `f_cos`.
    pub eta: f32,
}

/// A BSDF with its texture lookups already resolved at a hit point.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    /// Lambertian reflector, albedo in [0,1].
    Lambert { albedo: Vec3 },
    /// Metal with complex IOR (eta, k) per RGB channel; `alpha` is the roughness of the
    /// microfacet distribution `dist` (GGX or Beckmann), 0 = smooth.
    Conductor { eta: Vec3, k: Vec3, alpha: f32, specular_tint: Vec3, dist: Distribution },
    /// Glass with IOR `eta` = interior/exterior; `alpha` roughness of `dist` (0 = smooth);
    /// `tint` multiplies transmission and reflection (1 = clear).
    Dielectric { eta: f32, alpha: f32, tint: Vec3, dist: Distribution },
    /// Lambertian base under a dielectric coat of IOR `eta` and roughness `alpha` of `dist`
    /// (0 = smooth); `nonlinear` picks how the base's inter-reflections scale its albedo
    /// (plastic.rs; true for our scenes, false for Mitsuba's default plastic).
    Plastic { albedo: Vec3, eta: f32, alpha: f32, dist: Distribution, nonlinear: bool },
}

/// The contribution of `eval` split into the diffuse lobe and everything else (method.md §1.3:
/// at the first diffuse vertex only the diffuse lobe counts as "diffuse" radiance).
#[derive(Clone, Copy, Debug, Default)]
pub struct SplitEval {
    pub diffuse: Vec3,
    pub other: Vec3,
}

impl SplitEval {
    pub fn total(&self) -> Vec3 {
        self.diffuse + self.other
    }
}

impl Bsdf {
    /// Sample a direction. `u_lobe` picks a lobe, `u` drives the warp. `None` when the sample
    /// carries no energy (e.g. below the hemisphere); never a NaN.
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if !is_finite3(wo) || !u_lobe.is_finite() || !crate::math::vec2_finite(u) {
            return None;
        }
        let s = match self.resolved() {
            Resolved::Lambert(albedo) => lambert::sample(albedo, wo, u),
            Resolved::Conductor(c) => c.sample(wo, u),
            Resolved::Dielectric(d) => d.sample(wo, u_lobe, u),
            Resolved::Plastic(p) => p.sample(wo, u_lobe, u),
        }?;
        // Last line of defence: a sample that is not finite, has no density or carries negative
        // weight would poison the image; dropping it only loses a (measure-zero) bit of energy.
        let ok = s.pdf > 0.0
            && s.pdf.is_finite()
            && is_finite3(s.weight)
            && is_finite3(s.f_cos)
            && is_finite3(s.wi)
            && s.weight.min_element() >= 0.0
            && s.f_cos.min_element() >= 0.0
            && s.eta.is_finite()
            && s.eta > 0.0
            && s.wi != Vec3::ZERO;
        ok.then_some(s)
    }

    /// f(wo, wi)·|cos θi| of the non-delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_split(wo, wi).total()
    }

    /// `eval`, split into the diffuse lobe's part and the rest.
    pub fn eval_split(&self, wo: Vec3, wi: Vec3) -> SplitEval {
        if !is_finite3(wo) || !is_finite3(wi) {
            return SplitEval::default();
        }
        let split = match self.resolved() {
            Resolved::Lambert(albedo) => SplitEval { diffuse: lambert::eval(albedo, wo, wi), other: Vec3::ZERO },
            Resolved::Conductor(c) => SplitEval { diffuse: Vec3::ZERO, other: c.eval(wo, wi) },
            Resolved::Dielectric(d) => SplitEval { diffuse: Vec3::ZERO, other: d.eval(wo, wi) },
            Resolved::Plastic(p) => p.eval_split(wo, wi),
        };
        let clean = |v: Vec3| if is_finite3(v) { v.max(Vec3::ZERO) } else { Vec3::ZERO };
        SplitEval { diffuse: clean(split.diffuse), other: clean(split.other) }
    }

    /// Solid-angle density of `sample` producing `wi` through its non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if !is_finite3(wo) || !is_finite3(wi) {
            return 0.0;
        }
        let p = match self.resolved() {
            Resolved::Lambert(_) => lambert::pdf(wo, wi),
            Resolved::Conductor(c) => c.pdf(wo, wi),
            Resolved::Dielectric(d) => d.pdf(wo, wi),
            Resolved::Plastic(p) => p.pdf(wo, wi),
        };
        if p.is_finite() && p > 0.0 {
            p
        } else {
            0.0
        }
    }

    /// True when every lobe is a delta (no point in next-event estimation).
    pub fn is_delta(&self) -> bool {
        match *self {
            Bsdf::Lambert { .. } | Bsdf::Plastic { .. } => false,
            Bsdf::Conductor { alpha, .. } => !(alpha >= MIN_ALPHA),
            // An index-matched dielectric is a pass-through (a delta transmission) at any alpha.
            Bsdf::Dielectric { .. } => match self.resolved() {
                Resolved::Dielectric(d) => d.pass_through() || !(d.alpha >= MIN_ALPHA),
                _ => unreachable!(),
            },
        }
    }

    /// Whether the BSDF has a diffuse lobe (decides where "diffuse" radiance starts).
    pub fn has_diffuse(&self) -> bool {
        matches!(self, Bsdf::Lambert { .. } | Bsdf::Plastic { .. })
    }

    /// True for BSDFs that transmit (the integrator must not flip their frame).
    pub fn is_transmissive(&self) -> bool {
        matches!(self, Bsdf::Dielectric { .. })
    }

    /// The albedo reported in G-buffers, in [0,1]: diffuse albedo for Lambert and plastic, the
    /// normal-incidence reflectance for conductors, the tint for dielectrics.
    pub fn albedo(&self) -> Vec3 {
        match self.resolved() {
            Resolved::Lambert(albedo) => albedo,
            Resolved::Conductor(c) => c.albedo(),
            Resolved::Dielectric(d) => d.tint.min(Vec3::ONE),
            Resolved::Plastic(p) => p.albedo(),
        }
    }

    /// The parameters with bad values made harmless (the scene loader should already have
    /// rejected them; this keeps a texture NaN or a stray negative from reaching the maths):
    /// colours non-finite → 0, albedos clamped to [0, 1], tints ≥ 0, alpha in [0, 1], a
    /// non-positive or non-finite dielectric IOR becomes 1 (pass-through).
    fn resolved(&self) -> Resolved {
        let colour = |v: Vec3| if is_finite3(v) { v.max(Vec3::ZERO) } else { Vec3::ZERO };
        let alpha = |a: f32| if a.is_finite() { a.clamp(0.0, 1.0) } else { 0.0 };
        match *self {
            Bsdf::Lambert { albedo } => Resolved::Lambert(colour(albedo).min(Vec3::ONE)),
            Bsdf::Conductor { eta, k, alpha: a, specular_tint, dist } => Resolved::Conductor(Conductor {
                eta: if is_finite3(eta) { eta } else { Vec3::ONE },
                k: colour(k),
                alpha: alpha(a),
                tint: colour(specular_tint),
                dist,
            }),
            Bsdf::Dielectric { eta, alpha: a, tint, dist } => Resolved::Dielectric(Dielectric {
                eta: if eta.is_finite() && eta > 0.0 { eta } else { 1.0 },
                alpha: alpha(a),
                tint: colour(tint),
                dist,
            }),
            Bsdf::Plastic { albedo, eta, alpha, dist, nonlinear } => {
                Resolved::Plastic(Plastic::new(colour(albedo), eta, alpha, dist, nonlinear))
            }
        }
    }

    /// A representative roughness for path descriptors (GGX alpha; Lambert 1, smooth 0).
    pub fn roughness(&self) -> f32 {
        match *self {
            Bsdf::Lambert { .. } => 1.0,
            Bsdf::Conductor { alpha, .. } | Bsdf::Dielectric { alpha, .. } | Bsdf::Plastic { alpha, .. } => alpha,
        }
    }
}

/// `Bsdf` with sanitised parameters, dispatched to the per-material implementations.
enum Resolved {
    Lambert(Vec3),
    Conductor(Conductor),
    Dielectric(Dielectric),
    Plastic(Plastic),
}

/// Below this GGX alpha a lobe is treated as perfectly smooth (a delta). Rough GGX with alpha
/// under ~1e-3 is numerically indistinguishable from a mirror and its pdf overflows f32.
pub const MIN_ALPHA: f32 = 1e-3;
