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

use glam::{Vec2, Vec3};

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
    /// scaling and for MIS bookkeeping.
    pub eta: f32,
}

/// A BSDF with its texture lookups already resolved at a hit point.
#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    /// Lambertian reflector, albedo in [0,1].
    Lambert { albedo: Vec3 },
    /// Metal with complex IOR (eta, k) per RGB channel; `alpha` is GGX roughness, 0 = smooth.
    Conductor { eta: Vec3, k: Vec3, alpha: f32, specular_tint: Vec3 },
    /// Glass with IOR `eta` = interior/exterior; `alpha` GGX roughness (0 = smooth);
    /// `tint` multiplies transmission and reflection (1 = clear).
    Dielectric { eta: f32, alpha: f32, tint: Vec3 },
    /// Lambertian base under a dielectric coat of IOR `eta` and GGX roughness `alpha` (0 = smooth).
    Plastic { albedo: Vec3, eta: f32, alpha: f32 },
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
        let _ = (wo, u_lobe, u);
        todo!("material helper")
    }

    /// f(wo, wi)·|cos θi| of the non-delta lobes.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_split(wo, wi).total()
    }

    /// `eval`, split into the diffuse lobe's part and the rest.
    pub fn eval_split(&self, wo: Vec3, wi: Vec3) -> SplitEval {
        let _ = (wo, wi);
        todo!("material helper")
    }

    /// Solid-angle density of `sample` producing `wi` through its non-delta lobes.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let _ = (wo, wi);
        todo!("material helper")
    }

    /// True when every lobe is a delta (no point in next-event estimation).
    pub fn is_delta(&self) -> bool {
        match *self {
            Bsdf::Lambert { .. } | Bsdf::Plastic { .. } => false,
            Bsdf::Conductor { alpha, .. } | Bsdf::Dielectric { alpha, .. } => alpha < MIN_ALPHA,
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
        todo!("material helper")
    }

    /// A representative roughness for path descriptors (GGX alpha; Lambert 1, smooth 0).
    pub fn roughness(&self) -> f32 {
        match *self {
            Bsdf::Lambert { .. } => 1.0,
            Bsdf::Conductor { alpha, .. } | Bsdf::Dielectric { alpha, .. } | Bsdf::Plastic { alpha, .. } => alpha,
        }
    }
}

/// Below this GGX alpha a lobe is treated as perfectly smooth (a delta). Rough GGX with alpha
/// under ~1e-3 is numerically indistinguishable from a mirror and its pdf overflows f32.
pub const MIN_ALPHA: f32 = 1e-3;
