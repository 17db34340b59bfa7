//! Plastic: a Lambertian base under a dielectric coat.
//!
//! Smooth coat (Mitsuba's `plastic`): a delta mirror lobe weighted by F(cos θo), plus the base
//! seen through the coat, ρ/(1 − ρ·F_dr,int) · (1 − F(cos θo))(1 − F(cos θi))/η² · cos θi/π,
//! where the 1/(1 − ρ F_dr,int) sums the light bouncing between base and coat.
//! Rough coat (in the style of Mitsuba's `roughplastic`): GGX or Beckmann reflection with
//! dielectric Fresnel, plus the same diffuse term with 1 − F replaced by 1 − E(cos θ), E the
//! directional albedo of the coat lobe (tabulated once per distribution), and F_dr,int by the
//! matching internal reflectance.
//!
//! That is the `nonlinear` form (Mitsuba's `nonlinear = true`; our TOML and glTF plastics). The
//! linear form, Mitsuba's default, divides by (1 − F_dr,int) instead of (1 − ρ·F_dr,int), so
//! that the diffuse colour stays close to ρ.
//!
//! Energy (nonlinear form): the internal reflectance is derived from the external one by the
//! reciprocity relation 1 − R_int = (1 − R_ext)/η², so for ρ = 1 the diffuse term carries
//! exactly 1 − E(cos θo) and coat + base never exceed 1 (up to the tabulation error of E, ~1e-4).
//! The coat IOR is clamped to [1, 3] (the table range) and alpha to [0, 1].

use super::fresnel;
use super::microfacet::{Distribution, Microfacet};
use super::{BsdfSample, Lobe, LobeKind, SplitEval, MIN_ALPHA};
use crate::math::INV_PI;
use crate::sampling::square_to_cosine_hemisphere;
use glam::{Vec2, Vec3};
use std::sync::OnceLock;

const ETA_MAX: f32 = 3.0;
const N_ETA: usize = 17;
const N_ALPHA: usize = 17;
const N_MU: usize = 33;
/// Midpoint grid per dimension over the visible-normal square for one tabulated E value: the
/// integrand F·G2/G1 is smooth there except along the horizon cut-off, giving ~1e-4 error.
const QUAD: usize = 32;
const N_FDR: usize = 1025;

struct Tables {
    /// E(μ, α, η), index [eta][alpha][mu]; μ nodes at (j/(N_MU−1))² to resolve grazing angles.
    e: Vec<f32>,
    /// 2∫E(μ)μ dμ of the μ-interpolant of `e`, index [eta][alpha].
    e_avg: Vec<f32>,
    /// Smooth-interface diffuse reflectance from outside, 2∫F(μ)μ dμ, over η on a fine grid.
    fdr_ext: Vec<f32>,
}

fn eta_node(i: usize, n: usize) -> f32 {
    1.0 + (ETA_MAX - 1.0) * i as f32 / (n - 1) as f32
}

/// Directional albedo of the GGX coat lobe (reflection only) for incidence cosine `mu`.
fn coat_albedo_quadrature(mu: f32, alpha: f32, eta: f32, dist: Distribution) -> f32 {
    if alpha < MIN_ALPHA {
        return fresnel::dielectric(mu, eta);
    }
    let mu = mu.max(1e-4);
    let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let ggx = Microfacet::new(alpha, dist);
    let g1 = ggx.g1(wo);
    let mut sum = 0.0f64;
    // Beckmann's visible normals are sampled by a numerical inversion, ~10x GGX's cost: a coarser
    // grid keeps its tables to a second or two (error ~5e-4).
    let quad = if dist == Distribution::Beckmann { QUAD / 2 } else { QUAD };
    for a in 0..quad {
        for b in 0..quad {
            let u = Vec2::new((a as f32 + 0.5) / quad as f32, (b as f32 + 0.5) / quad as f32);
            let m = ggx.sample_visible(wo, u);
            let wi = crate::math::reflect(wo, m);
            if wi.z > 0.0 {
                sum += (fresnel::dielectric(wo.dot(m), eta) * ggx.g2(wo, wi) / g1) as f64;
            }
        }
    }
    (sum / (quad * quad) as f64) as f32
}

fn tables(dist: Distribution) -> &'static Tables {
    static GGX: OnceLock<Tables> = OnceLock::new();
    static BECKMANN: OnceLock<Tables> = OnceLock::new();
    let cell = match dist {
        Distribution::Ggx => &GGX,
        Distribution::Beckmann => &BECKMANN,
    };
    cell.get_or_init(|| {
        let mut e = Vec::with_capacity(N_ETA * N_ALPHA * N_MU);
        let mut e_avg = Vec::with_capacity(N_ETA * N_ALPHA);
        // 3-point Gauss–Legendre per μ-segment: the interpolant is linear in x = √μ, so the
        // integrand 4·E(x)·x³ is a quartic per segment and this rule integrates it exactly.
        let gl = [(-0.774_596_7f64, 5.0 / 9.0), (0.0, 8.0 / 9.0), (0.774_596_7, 5.0 / 9.0)];
        for i in 0..N_ETA {
            let eta = eta_node(i, N_ETA);
            for j in 0..N_ALPHA {
                let alpha = j as f32 / (N_ALPHA - 1) as f32;
                let row: Vec<f32> = (0..N_MU)
                    .map(|k| {
                        let x = k as f32 / (N_MU - 1) as f32;
                        coat_albedo_quadrature(x * x, alpha, eta, dist)
                    })
                    .collect();
                let h = 1.0 / (N_MU - 1) as f64;
                let mut avg = 0.0f64;
                for k in 0..N_MU - 1 {
                    for (g, w) in gl {
                        let t = 0.5 * (g + 1.0);
                        let x = (k as f64 + t) * h;
                        let ev = row[k] as f64 * (1.0 - t) + row[k + 1] as f64 * t;
                        avg += 0.5 * h * w * 4.0 * ev * x * x * x;
                    }
                }
                e.extend_from_slice(&row);
                e_avg.push(avg as f32);
            }
        }
        // Simpson over μ; F(μ) is smooth for η ≥ 1 seen from outside (no critical angle).
        let fdr_ext = (0..N_FDR)
            .map(|i| {
                let eta = eta_node(i, N_FDR);
                let n = 2048;
                let mut s = 0.0f64;
                for k in 0..=n {
                    let mu = k as f64 / n as f64;
                    let w = if k == 0 || k == n {
                        1.0
                    } else if k % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    s += w * fresnel::dielectric(mu as f32, eta) as f64 * mu;
                }
                (2.0 * s / (3.0 * n as f64)) as f32
            })
            .collect();
        Tables { e, e_avg, fdr_ext }
    })
}

/// The rough coat's internal reflectance as Mitsuba's `roughplastic` computes it (the linear
/// form's divisor): the cosine-weighted hemispherical average 2∫E(μ)μ dμ of the coat lobe's
/// directional albedo seen from inside (relative IOR 1/η, total internal reflection included),
/// rather than our reciprocity relation from the outside albedo (which books the energy the
/// single-scattering lobe loses as transmitted). Computed once per (η, α, distribution) and
/// cached: Mitsuba scenes have a handful of plastics.
fn mitsuba_internal_reflectance(eta: f32, alpha: f32, dist: Distribution) -> f32 {
    use std::collections::HashMap;
    use std::sync::RwLock;
    /// (η bits, α bits, Beckmann?) → the hemispherical average.
    type Key = (u32, u32, bool);
    static CACHE: OnceLock<RwLock<HashMap<Key, f32>>> = OnceLock::new();
    let cache = CACHE.get_or_init(|| RwLock::new(HashMap::new()));
    let key = (eta.to_bits(), alpha.to_bits(), dist == Distribution::Beckmann);
    if let Some(&v) = cache.read().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return v;
    }
    // Gauss–Legendre in x = √μ over 16 segments (the albedo changes fastest near grazing).
    let gl = [(-0.774_596_7f64, 5.0 / 9.0), (0.0, 8.0 / 9.0), (0.774_596_7, 5.0 / 9.0)];
    let segments = 16;
    let h = 1.0 / segments as f64;
    let mut avg = 0.0f64;
    for k in 0..segments {
        for (g, w) in gl {
            let x = (k as f64 + 0.5 * (g + 1.0)) * h;
            let mu = x * x;
            // 2∫E(μ)μ dμ = ∫ 4 E(x²) x³ dx.
            avg += 0.5 * h * w * 4.0 * coat_albedo_quadrature(mu as f32, alpha, 1.0 / eta, dist) as f64 * x * x * x;
        }
    }
    let v = (avg as f32).clamp(0.0, 1.0);
    cache.write().unwrap_or_else(|e| e.into_inner()).insert(key, v);
    v
}

/// The diffuse reflectance ρ′ that makes Mitsuba's nonlinear `roughplastic` reflect the diffuse
/// energy our nonlinear rough plastic of albedo ρ does (the scene exporter's stand-in: Mitsuba
/// has no plastic with our internal reflectance). Both compute the diffuse term as
/// ρ/(1 − ρ R_int) times the same coat transmittances; only R_int differs (ours by reciprocity
/// from the outside albedo, Mitsuba's its single-scattering inside albedo), so with
/// k = ρ/(1 − ρ R_ours), ρ′ = k/(1 + k R_Mitsuba) gives ρ′/(1 − ρ′ R_Mitsuba) = k. A smooth coat
/// keeps ρ: both take the smooth interface's internal reflectance (Mitsuba by a fit, ours exact).
pub(crate) fn mitsuba_nonlinear_albedo(albedo: Vec3, eta: f32, alpha: f32, dist: Distribution) -> Vec3 {
    let p = Plastic::new(albedo, eta, alpha, dist, true);
    if p.smooth() {
        return p.albedo;
    }
    let (r_ours, r_mitsuba) = (p.internal_reflectance(), mitsuba_internal_reflectance(p.eta, p.alpha, dist));
    let k = p.albedo / (Vec3::ONE - p.albedo * r_ours).max(Vec3::splat(1e-6));
    k / (Vec3::ONE + k * r_mitsuba)
}

/// Cell index and fraction of coordinate `x` on a grid of `n` nodes spaced 1 apart.
fn cell(x: f32, n: usize) -> (usize, f32) {
    let x = x.clamp(0.0, (n - 1) as f32);
    let i = (x as usize).min(n - 2);
    (i, x - i as f32)
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

#[derive(Clone, Copy, Debug)]
pub struct Plastic {
    albedo: Vec3,
    eta: f32,
    alpha: f32,
    dist: Distribution,
    nonlinear: bool,
}

impl Plastic {
    pub fn new(albedo: Vec3, eta: f32, alpha: f32, dist: Distribution, nonlinear: bool) -> Self {
        let eta = if eta.is_finite() { eta.clamp(1.0, ETA_MAX) } else { 1.5 };
        let alpha = if alpha.is_finite() { alpha.clamp(0.0, 1.0) } else { 0.0 };
        Plastic { albedo: albedo.clamp(Vec3::ZERO, Vec3::ONE), eta, alpha, dist, nonlinear }
    }

    fn smooth(&self) -> bool {
        self.alpha < MIN_ALPHA
    }

    fn eta_coord(&self) -> f32 {
        (self.eta - 1.0) / (ETA_MAX - 1.0)
    }

    /// Energy reflected by the coat for incidence cosine `mu`.
    fn coat_energy(&self, mu: f32) -> f32 {
        if self.smooth() {
            return fresnel::dielectric(mu, self.eta);
        }
        let t = tables(self.dist);
        let (i, fi) = cell(self.eta_coord() * (N_ETA - 1) as f32, N_ETA);
        let (j, fj) = cell(self.alpha * (N_ALPHA - 1) as f32, N_ALPHA);
        let (k, fk) = cell(mu.clamp(0.0, 1.0).sqrt() * (N_MU - 1) as f32, N_MU);
        let at = |i: usize, j: usize| {
            let base = (i * N_ALPHA + j) * N_MU + k;
            lerp(t.e[base], t.e[base + 1], fk)
        };
        let v = lerp(lerp(at(i, j), at(i, j + 1), fj), lerp(at(i + 1, j), at(i + 1, j + 1), fj), fi);
        v.clamp(0.0, 1.0)
    }

    /// Diffuse reflectance of the coat seen from inside (light trying to leave the base layer).
    fn internal_reflectance(&self) -> f32 {
        if !self.nonlinear && !self.smooth() {
            return mitsuba_internal_reflectance(self.eta, self.alpha, self.dist);
        }
        let t = tables(self.dist);
        let ext = if self.smooth() {
            let (i, f) = cell(self.eta_coord() * (N_FDR - 1) as f32, N_FDR);
            // Biased low by a hair: underestimating R_int can only lower the diffuse energy.
            lerp(t.fdr_ext[i], t.fdr_ext[i + 1], f) - 1e-5
        } else {
            let (i, fi) = cell(self.eta_coord() * (N_ETA - 1) as f32, N_ETA);
            let (j, fj) = cell(self.alpha * (N_ALPHA - 1) as f32, N_ALPHA);
            let at = |i: usize, j: usize| t.e_avg[i * N_ALPHA + j];
            lerp(lerp(at(i, j), at(i, j + 1), fj), lerp(at(i + 1, j), at(i + 1, j + 1), fj), fi)
        };
        (1.0 - (1.0 - ext.clamp(0.0, 1.0)) / (self.eta * self.eta)).clamp(0.0, 1.0)
    }

    /// ρ/(1 − ρ R_int)/η²: base albedo with inter-reflections, and the solid-angle compression.
    /// Linear (`nonlinear` false, Mitsuba's default): ρ/(1 − R_int)/η², which keeps the diffuse
    /// colour close to ρ itself (Mitsuba's "preserve the texture colours") at the price of
    /// energy conservation: coat + base can reflect a little more than 1 for ρ near 1.
    fn diffuse_gain(&self, r_int: f32) -> Vec3 {
        let k = if self.nonlinear { self.albedo } else { Vec3::ONE };
        self.albedo / (Vec3::ONE - k * r_int).max(Vec3::splat(1e-6)) / (self.eta * self.eta)
    }

    /// Probability of sampling the coat lobe: its share of the estimated reflected energy.
    fn coat_probability(&self, wo: Vec3) -> f32 {
        let es = self.coat_energy(wo.z);
        let r_int = self.internal_reflectance();
        // Diffuse albedo for this wo: (1 − E_o)·ρ(1 − R_int)/(1 − ρ R_int), averaged over RGB.
        let ed = (1.0 - es) * (self.diffuse_gain(r_int) * (1.0 - r_int) * self.eta * self.eta).element_sum() / 3.0;
        if es + ed > 0.0 {
            es / (es + ed)
        } else {
            1.0
        }
    }

    fn coat_eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        let m = (wo + wi).normalize_or_zero();
        if self.smooth() || !(m.z > 0.0) {
            return 0.0;
        }
        let ggx = Microfacet::new(self.alpha, self.dist);
        fresnel::dielectric(wo.dot(m), self.eta) * ggx.d(m) * ggx.g2(wo, wi) / (4.0 * wo.z)
    }

    pub fn eval_split(&self, wo: Vec3, wi: Vec3) -> SplitEval {
        if !(wo.z > 0.0) || !(wi.z > 0.0) {
            return SplitEval::default();
        }
        let r_int = self.internal_reflectance();
        let t = (1.0 - self.coat_energy(wo.z)) * (1.0 - self.coat_energy(wi.z));
        SplitEval { diffuse: self.diffuse_gain(r_int) * (t * wi.z * INV_PI), other: Vec3::splat(self.coat_eval(wo, wi)) }
    }

    fn coat_pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let m = (wo + wi).normalize_or_zero();
        let cos_om = wo.dot(m);
        if self.smooth() || !(m.z > 0.0) || !(cos_om > 0.0) {
            return 0.0;
        }
        Microfacet::new(self.alpha, self.dist).pdf_visible(wo, m) / (4.0 * cos_om)
    }

    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if !(wo.z > 0.0) || !(wi.z > 0.0) {
            return 0.0;
        }
        let p = self.coat_probability(wo);
        (1.0 - p) * wi.z * INV_PI + p * self.coat_pdf(wo, wi)
    }

    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if !(wo.z > 0.0) {
            return None;
        }
        let p = self.coat_probability(wo);
        let coat = u_lobe < p;
        if coat && self.smooth() {
            let f = fresnel::dielectric(wo.z, self.eta);
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            let lobe = Lobe { kind: LobeKind::Specular, transmission: false, roughness: 0.0 };
            return Some(BsdfSample { wi, weight: Vec3::splat(f / p), f_cos: Vec3::splat(f), pdf: p, lobe, eta: 1.0 });
        }
        let (wi, lobe) = if coat {
            let m = Microfacet::new(self.alpha, self.dist).sample_visible(wo, u);
            (crate::math::reflect(wo, m), Lobe { kind: LobeKind::Glossy, transmission: false, roughness: self.alpha })
        } else {
            (square_to_cosine_hemisphere(u), Lobe { kind: LobeKind::Diffuse, transmission: false, roughness: 1.0 })
        };
        if !(wi.z > 0.0) {
            return None;
        }
        let f_cos = self.eval_split(wo, wi).total();
        let pdf = self.pdf(wo, wi);
        Some(BsdfSample { wi, weight: f_cos / pdf, f_cos, pdf, lobe, eta: 1.0 })
    }

    pub fn albedo(&self) -> Vec3 {
        self.albedo
    }
}
