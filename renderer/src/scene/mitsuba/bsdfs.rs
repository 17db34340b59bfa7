//! `<bsdf>`: Mitsuba's BSDF types and their parameters (roughness, IORs by value or by name,
//! conductor presets, `twosided`) mapped to our materials.

use super::textures::Spectrum;
use super::{BsdfDef, Loader};
use crate::material::Distribution;
use crate::scene::MaterialKind;
use crate::Result;
use glam::Vec3;
use roxmltree::Node;

/// Named dielectrics of Mitsuba's IOR table (the ones scenes use), at 589 nm.
const IOR_NAMES: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.333),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

impl<'a, 'i> Loader<'a, 'i> {
    fn ior(&self, n: Node<'a, 'i>) -> Result<f32> {
        if n.tag_name().name() == "string" {
            let v = self.required(n, "value")?;
            return IOR_NAMES
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(v.trim()))
                .map(|&(_, x)| x)
                .ok_or_else(|| self.err(n, format!("unknown IOR name \"{v}\"")));
        }
        let x = self.float(n)?;
        if x <= 0.0 {
            return Err(self.err(n, format!("IOR {x} must be positive")));
        }
        Ok(x)
    }

    pub(super) fn bsdf(&mut self, n: Node<'a, 'i>, name: &str) -> Result<BsdfDef> {
        let ty = self.required(n, "type")?;
        if ty == "twosided" {
            // Shaded alike from both sides; a BSDF outside `twosided` is black from behind.
            let inner: Vec<_> = Self::elements(n).collect();
            return match inner.as_slice() {
                [one] if one.tag_name().name() == "bsdf" => self.bsdf(*one, name).map(|d| BsdfDef { two_sided: true, ..d }),
                [one] if one.tag_name().name() == "ref" => {
                    let id = self.required(*one, "id")?;
                    let d =
                        self.bsdfs.get(&id).cloned().ok_or_else(|| self.err(*one, format!("no <bsdf id=\"{id}\"> defined before this")))?;
                    Ok(BsdfDef { two_sided: true, ..d })
                }
                _ => Err(self.err(n, "twosided needs exactly one nested <bsdf> (two different sides are not supported)")),
            };
        }
        let mut alpha: Option<f32> = None;
        let (mut alpha_u, mut alpha_v) = (None, None);
        // Mitsuba's default microfacet distribution is Beckmann (0.6 and 3 alike).
        let mut dist = Distribution::Beckmann;
        let mut nonlinear = false;
        // Mitsuba's defaults: BK7 glass inside a dielectric, polypropylene (1.49) under a plastic
        // coat, air outside.
        let default_int = if ty.ends_with("plastic") { 1.49 } else { 1.5046f32 };
        let (mut int_ior, mut ext_ior) = (default_int, 1.000277f32);
        let mut reflectance: Option<Spectrum> = None;
        let mut specular: Option<Spectrum> = None;
        let mut transmittance: Option<Spectrum> = None;
        let (mut eta, mut k, mut preset, mut ext_eta) = (None, None, None, 1.0f32);
        for c in Self::elements(n) {
            let pname = c.attribute("name").unwrap_or("");
            match (ty.as_str(), pname) {
                (_, "alpha") => alpha = Some(self.float(c)?.max(0.0)),
                (_, "alphaU" | "alpha_u") => alpha_u = Some(self.float(c)?.max(0.0)),
                (_, "alphaV" | "alpha_v") => alpha_v = Some(self.float(c)?.max(0.0)),
                (_, "distribution") => {
                    let d = self.required(c, "value")?;
                    // Phong's exponent has no alpha at all; "as" (Ashikhmin–Shirley) is 0.5's
                    // anisotropic Phong.
                    dist = match d.as_str() {
                        "ggx" => Distribution::Ggx,
                        "beckmann" => Distribution::Beckmann,
                        _ => return Err(self.err(c, format!("microfacet distribution \"{d}\" is not supported (ggx, beckmann)"))),
                    };
                }
                ("diffuse" | "roughdiffuse", "reflectance")
                | ("plastic" | "roughplastic", "diffuseReflectance" | "diffuse_reflectance") => reflectance = Some(self.spectrum(c)?),
                (_, "specularReflectance" | "specular_reflectance") => specular = Some(self.spectrum(c)?),
                ("dielectric" | "roughdielectric", "specularTransmittance" | "specular_transmittance") => {
                    transmittance = Some(self.spectrum(c)?)
                }
                ("dielectric" | "roughdielectric" | "plastic" | "roughplastic", "intIOR" | "int_ior") => int_ior = self.ior(c)?,
                ("dielectric" | "roughdielectric" | "plastic" | "roughplastic", "extIOR" | "ext_ior") => ext_ior = self.ior(c)?,
                ("conductor" | "roughconductor", "eta") => eta = Some(self.color(c)?),
                ("conductor" | "roughconductor", "k") => k = Some(self.color(c)?),
                ("conductor" | "roughconductor", "material") => preset = Some(self.required(c, "value")?),
                ("conductor" | "roughconductor", "extEta" | "ext_eta") => ext_eta = self.ior(c)?,
                ("plastic" | "roughplastic", "nonlinear") => nonlinear = self.boolean(c)?,
                _ => return Err(self.err(c, format!("unsupported parameter of a \"{ty}\" BSDF"))),
            }
        }
        let roughness = match (alpha, alpha_u, alpha_v) {
            (Some(a), _, _) => a,
            (None, Some(u), Some(v)) => {
                if (u - v).abs() > 1e-3 {
                    self.warn(n, format!("anisotropic roughness ({u}, {v}) becomes isotropic {}", (u * v).sqrt()));
                }
                (u * v).sqrt()
            }
            (None, Some(a), None) | (None, None, Some(a)) => a,
            // Mitsuba's default roughness of the rough BSDFs.
            (None, None, None) => {
                if ty.starts_with("rough") {
                    0.1
                } else {
                    0.0
                }
            }
        };
        let roughness = if ty.starts_with("rough") { roughness } else { 0.0 };
        let specular_mean = |l: &Self, s: Option<Spectrum<'a, 'i>>, what: &str| -> Result<Vec3> {
            match s {
                None => Ok(Vec3::ONE),
                Some(s) => {
                    let (c, textured) = l.mean_color(s)?;
                    if textured {
                        l.warn(n, format!("a textured {what} becomes its mean {c}"));
                    }
                    Ok(c.min(Vec3::ONE))
                }
            }
        };
        let kind = match ty.as_str() {
            "diffuse" | "roughdiffuse" => {
                let albedo = self.color_param(reflectance.unwrap_or(Spectrum::Const(Vec3::splat(0.5))))?;
                MaterialKind::Lambert { albedo }
            }
            "plastic" | "roughplastic" => {
                let albedo = self.color_param(reflectance.unwrap_or(Spectrum::Const(Vec3::splat(0.5))))?;
                let s = specular_mean(self, specular, "specular reflectance")?;
                if (s - Vec3::ONE).abs().max_element() > 1e-3 {
                    self.warn(n, format!("plastic specularReflectance {s} is ignored (the coat reflects by Fresnel alone)"));
                }
                MaterialKind::Plastic { albedo, ior: int_ior / ext_ior, roughness, dist, nonlinear }
            }
            "dielectric" | "roughdielectric" => {
                let r = specular_mean(self, specular, "specular reflectance")?;
                let t = specular_mean(self, transmittance, "specular transmittance")?;
                if (r - t).abs().max_element() > 1e-3 {
                    self.warn(n, format!("reflectance {r} and transmittance {t} differ; both become {t}"));
                }
                MaterialKind::Dielectric { ior: int_ior / ext_ior, roughness, tint: t, dist }
            }
            "conductor" | "roughconductor" => {
                let (e, kk) = match (&preset, eta, k) {
                    // A perfect mirror (Mitsuba: η = 0, k = 1); k = 10⁴ gives F = 1 − 4·10⁻⁸.
                    (Some(p), None, None) if p == "none" => NONE_CONDUCTOR,
                    (Some(p), None, None) => {
                        let (_, e, kk) = MITSUBA3_CONDUCTORS.iter().find(|(m, _, _)| m.eq_ignore_ascii_case(p)).ok_or_else(|| {
                            let known: Vec<_> = MITSUBA3_CONDUCTORS.iter().map(|(m, _, _)| *m).collect();
                            self.err(
                                n,
                                format!("unknown conductor material \"{p}\" (known: {}, none; or give eta and k)", known.join(", ")),
                            )
                        })?;
                        (Vec3::from(*e), Vec3::from(*kk))
                    }
                    (None, Some(e), Some(kk)) => (e, kk),
                    // Mitsuba's default conductor is copper.
                    // Mitsuba 3's default conductor is that mirror (Mitsuba 0.6's was copper; Mitsuba 3
                    // renders 0.6 files with its own default too).
                    (None, None, None) => NONE_CONDUCTOR,
                    _ => return Err(self.err(n, "give either `material` or both `eta` and `k`")),
                };
                if e.min_element() <= 0.0 {
                    return Err(self.err(n, format!("eta {e} must be positive")));
                }
                let specular_tint = self.color_param(specular.unwrap_or(Spectrum::Const(Vec3::ONE)))?;
                MaterialKind::Conductor { eta: e / ext_eta, k: kk / ext_eta, roughness, specular_tint, dist }
            }
            other => return Err(self.err(n, format!("unsupported BSDF type \"{other}\""))),
        };
        Ok(BsdfDef { name: name.to_string(), kind, two_sided: false })
    }
}

/// Mitsuba's `material="none"`: a perfect mirror.
const NONE_CONDUCTOR: (Vec3, Vec3) = (Vec3::ONE, Vec3::splat(1e4));

/// RGB complex IOR (η, k) of Mitsuba's named conductors as Mitsuba 3.9's `scalar_rgb` variant
/// uses them (read back from it with `mi.traverse`): within ~1e-3 of our TOML presets
/// (`CONDUCTOR_PRESETS`, integrated from the same spectra), but a Mitsuba scene should render
/// as Mitsuba renders it. The other metals of Mitsuba's list are not tabulated (an error).
#[allow(clippy::excessive_precision)]
const MITSUBA3_CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("Ag", [0.155276, 0.116728, 0.138388], [4.82835, 3.12222, 2.1469]),
    ("Al", [1.6575, 0.880405, 0.521244], [9.22381, 6.2695, 4.837]),
    ("Au", [0.143036, 0.375307, 1.44205], [3.983, 2.38556, 1.60336]),
    ("Cr", [4.36967, 2.91651, 1.6549], [5.20655, 4.23131, 3.7547]),
    ("Cu", [0.201005, 0.92375, 1.10222], [3.91326, 2.45305, 2.14209]),
];
