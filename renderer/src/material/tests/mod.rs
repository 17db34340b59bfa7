//! BSDF tests, by topic: the χ² goodness of fit of `sample` against `pdf` (chi2.rs), energy
//! bounds (energy.rs), and sample/eval/pdf consistency, degenerate inputs, lobe bitmasks and
//! Fresnel reference values (invariants.rs). This file holds the BSDF configurations they share.

use super::*;

mod chi2;
mod energy;
mod invariants;

// ---------------------------------------------------------------------------------------------
// Test configurations.

const GOLD_ETA: Vec3 = Vec3::new(0.143, 0.374, 1.442);
const GOLD_K: Vec3 = Vec3::new(3.983, 2.385, 1.603);

/// wo with cos θ = `c` (negative: inside/below), at an azimuth away from any cell boundary.
fn wo_at(c: f32) -> Vec3 {
    let s = (1.0 - c * c).max(0.0).sqrt();
    let phi = 0.7f32;
    Vec3::new(s * phi.cos(), s * phi.sin(), c)
}

/// Incidence cosines: near grazing, intermediate, near normal.
const WO_COS: [f32; 3] = [0.05, 0.5, 0.93];

struct Config {
    name: String,
    bsdf: Bsdf,
    wo: Vec3,
}

fn conductor(alpha: f32) -> Bsdf {
    Bsdf::Conductor { eta: GOLD_ETA, k: GOLD_K, alpha, specular_tint: Vec3::ONE, dist: Default::default() }
}

fn chi2_configs(group: &str) -> Vec<Config> {
    let mut v = Vec::new();
    let mut push = |name: String, bsdf: Bsdf, signs: &[f32]| {
        for &c in &WO_COS {
            for &s in signs {
                v.push(Config { name: format!("{name} cos_o={}", c * s), bsdf, wo: wo_at(c * s) });
            }
        }
    };
    match group {
        "lambert" => push("lambert".into(), Bsdf::Lambert { albedo: Vec3::new(0.8, 0.5, 0.2) }, &[1.0]),
        "conductor" => {
            for alpha in [0.002, 0.05, 0.3, 1.0] {
                push(format!("conductor a={alpha}"), conductor(alpha), &[1.0]);
            }
            for alpha in [0.05, 0.3, 1.0] {
                let bsdf = Bsdf::Conductor { eta: GOLD_ETA, k: GOLD_K, alpha, specular_tint: Vec3::ONE, dist: Distribution::Beckmann };
                push(format!("beckmann conductor a={alpha}"), bsdf, &[1.0]);
            }
        }
        "dielectric_out" | "dielectric_in" => {
            let sign = if group == "dielectric_out" { 1.0 } else { -1.0 };
            for alpha in [0.002, 0.1, 0.5, 1.0] {
                // 1.05 stands for "nearly index-matched": at 1.01 the transmitted lobe is so
                // narrow that integrating the pdf over the cells alone takes minutes.
                for eta in [1.05, 1.33, 1.5, 2.4] {
                    let bsdf = Bsdf::Dielectric { eta, alpha, tint: Vec3::new(1.0, 0.9, 0.8), dist: Default::default() };
                    push(format!("dielectric a={alpha} eta={eta}"), bsdf, &[sign]);
                }
            }
        }
        "plastic" => {
            for alpha in [0.0, 0.1, 0.6, 1.0] {
                let bsdf = Bsdf::Plastic { albedo: Vec3::new(0.7, 0.4, 0.1), eta: 1.5, alpha, dist: Default::default(), nonlinear: true };
                push(format!("plastic a={alpha}"), bsdf, &[1.0]);
            }
        }
        _ => unreachable!(),
    }
    v
}

const CHI2_GROUPS: [&str; 5] = ["lambert", "conductor", "dielectric_out", "dielectric_in", "plastic"];

/// Every chi-square configuration run by the tests below, for the Šidák correction.
fn chi2_total_configs() -> usize {
    CHI2_GROUPS.iter().map(|g| chi2_configs(g).len()).sum()
}

fn is_delta_sample(s: &BsdfSample) -> bool {
    s.lobe.kind == LobeKind::Specular
}
