//! A procedural daylight environment: Preetham et al.'s analytic sky (1999) plus a sun disk,
//! baked into a lat-long map with the direction convention of `light::environment`
//! (u = φ/2π with d = (sin θ sin φ, cos θ, −sin θ cos φ), v = θ/π from +Y).
//!
//! Units are relative: the sky's zenith luminance is 1 and the sun disk's radiance is chosen so
//! that the sun's irradiance on a horizontal plane is `sun_to_sky` times the sky's.

use crate::math::{luminance, PI};
use crate::texture::Texture;
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct SkyParams {
    pub width: u32,
    pub height: u32,
    /// Sun elevation above the horizon in degrees (> 0 for the Preetham model to be valid).
    pub sun_elevation_deg: f32,
    /// Sun azimuth φ in degrees in the map's convention (0 = −Z, 90 = +X).
    pub sun_azimuth_deg: f32,
    /// Atmospheric turbidity, 2 (very clear) … 10 (hazy).
    pub turbidity: f32,
    /// Angular radius of the sun disk in degrees. The real sun is 0.27°; a larger disk keeps
    /// a few texels lit so importance sampling finds it and shadows stay soft enough to denoise.
    pub sun_radius_deg: f32,
    /// Sun irradiance / sky irradiance on a horizontal plane.
    pub sun_to_sky: f32,
    /// Albedo of the ground below the horizon (lit by the sky's average).
    pub ground_albedo: Vec3,
}

impl Default for SkyParams {
    fn default() -> Self {
        SkyParams {
            width: 512,
            height: 256,
            sun_elevation_deg: 35.0,
            sun_azimuth_deg: 40.0,
            turbidity: 3.0,
            sun_radius_deg: 1.5,
            sun_to_sky: 4.0,
            ground_albedo: Vec3::splat(0.3),
        }
    }
}

fn dir(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos())
}

/// Perez et al. luminance distribution F(θ, γ).
fn perez(theta: f32, gamma: f32, c: [f32; 5]) -> f32 {
    let cos_t = theta.cos().max(0.01);
    (1.0 + c[0] * (c[1] / cos_t).exp()) * (1.0 + c[2] * (c[3] * gamma).exp() + c[4] * gamma.cos().powi(2))
}

fn xyy_to_linear_srgb(x: f32, y: f32, lum: f32) -> Vec3 {
    let y_ = y.max(1e-6);
    let (cx, cy, cz) = (x / y_ * lum, lum, (1.0 - x - y) / y_ * lum);
    Vec3::new(3.2406 * cx - 1.5372 * cy - 0.4986 * cz, -0.9689 * cx + 1.8758 * cy + 0.0415 * cz, 0.0557 * cx - 0.2040 * cy + 1.0570 * cz)
        .max(Vec3::ZERO)
}

/// The sky radiance (zenith luminance 1) in direction (θ, γ) for sun zenith angle `theta_s`.
fn preetham(theta: f32, gamma: f32, theta_s: f32, t: f32) -> Vec3 {
    let cy = [0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771, -0.0670 * t + 0.3703];
    let cx = [-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989, -0.0033 * t + 0.0452];
    let cyy = [-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537, -0.0109 * t + 0.0529];
    let (t2, ts, ts2, ts3) = (t * t, theta_s, theta_s * theta_s, theta_s * theta_s * theta_s);
    let zx = (0.00166 * ts3 - 0.00375 * ts2 + 0.00209 * ts) * t2
        + (-0.02903 * ts3 + 0.06377 * ts2 - 0.03202 * ts + 0.00394) * t
        + (0.11693 * ts3 - 0.21196 * ts2 + 0.06052 * ts + 0.25886);
    let zy = (0.00275 * ts3 - 0.00610 * ts2 + 0.00317 * ts) * t2
        + (-0.04214 * ts3 + 0.08970 * ts2 - 0.04153 * ts + 0.00516) * t
        + (0.15346 * ts3 - 0.26756 * ts2 + 0.06670 * ts + 0.26688);
    let lum = perez(theta, gamma, cy) / perez(0.0, theta_s, cy);
    let x = zx * perez(theta, gamma, cx) / perez(0.0, theta_s, cx);
    let y = zy * perez(theta, gamma, cyy) / perez(0.0, theta_s, cyy);
    xyy_to_linear_srgb(x, y, lum)
}

/// Bakes the sky and sun into a lat-long texture.
pub fn bake(p: &SkyParams) -> Texture {
    let (w, h) = (p.width.max(8) as usize, p.height.max(4) as usize);
    let elev = p.sun_elevation_deg.clamp(0.5, 90.0).to_radians();
    let theta_s = PI / 2.0 - elev;
    let sun = dir(theta_s, p.sun_azimuth_deg.to_radians());
    let t = p.turbidity.clamp(1.7, 10.0);
    // Texel index, centre direction and solid angle of every texel of the map.
    let texel_dirs: Vec<(usize, Vec3, f32)> = (0..h)
        .flat_map(|j| {
            let theta = (j as f32 + 0.5) / h as f32 * PI;
            let d_omega = (2.0 * PI / w as f32) * (PI / h as f32) * theta.sin();
            (0..w).map(move |i| (j * w + i, dir(theta, (i as f32 + 0.5) / w as f32 * 2.0 * PI), d_omega))
        })
        .collect();
    let mut texels = vec![Vec3::ZERO; w * h];
    let mut sky_irradiance = 0.0f64;
    for &(k, d, d_omega) in texel_dirs.iter().filter(|t| t.1.y > 0.0) {
        let gamma = d.dot(sun).clamp(-1.0, 1.0).acos();
        let c = preetham(d.y.clamp(-1.0, 1.0).acos(), gamma, theta_s, t);
        texels[k] = c;
        sky_irradiance += (luminance(c) * d.y * d_omega) as f64;
    }
    // Ground: a grey Lambertian plane lit by sky and sun (radiance = albedo·E/π).
    let ground = p.ground_albedo * (sky_irradiance as f32 * (1.0 + p.sun_to_sky.max(0.0)) / PI);
    // Sun disk radiance so that its horizontal irradiance is sun_to_sky × the sky's.
    let cos_r = p.sun_radius_deg.max(0.05).to_radians().cos();
    let mut sun_texels = Vec::new();
    let mut sun_irr_unit = 0.0f64;
    for &(k, d, d_omega) in &texel_dirs {
        if d.y <= 0.0 {
            texels[k] = ground;
        } else if d.dot(sun) >= cos_r {
            sun_texels.push(k);
            sun_irr_unit += (d.y * d_omega) as f64;
        }
    }
    if sun_irr_unit > 0.0 {
        let sun_colour = preetham(theta_s, 0.0, theta_s, t);
        let sun_colour = sun_colour / luminance(sun_colour).max(1e-6);
        let radiance = (p.sun_to_sky as f64 * sky_irradiance / sun_irr_unit) as f32;
        for k in sun_texels {
            texels[k] += sun_colour * radiance;
        }
    }
    Texture { width: w as u32, height: h as u32, texels }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sun_is_where_asked_and_ratio_holds() {
        let p = SkyParams { width: 256, height: 128, ..Default::default() };
        let t = bake(&p);
        assert!(t.texels.iter().all(|c| c.is_finite() && c.min_element() >= 0.0));
        let (k, _) = t.texels.iter().enumerate().max_by(|a, b| luminance(*a.1).total_cmp(&luminance(*b.1))).unwrap();
        let (i, j) = (k % 256, k / 256);
        let (theta, phi) = ((j as f32 + 0.5) / 128.0 * PI, (i as f32 + 0.5) / 256.0 * 2.0 * PI);
        // The brightest texel lies inside the sun disk (radius 1.5° + one texel ≈ 1.4°).
        let want = dir(PI / 2.0 - p.sun_elevation_deg.to_radians(), p.sun_azimuth_deg.to_radians());
        assert!(dir(theta, phi).dot(want) > (3.0f32).to_radians().cos());
        // Horizontal irradiance: sun / sky = sun_to_sky by construction (discretised the same way).
        let (mut sky, mut total) = (0.0f64, 0.0f64);
        let sun_cos = p.sun_radius_deg.to_radians().cos();
        for j in 0..128 {
            let theta = (j as f32 + 0.5) / 128.0 * PI;
            let dw = (2.0 * PI / 256.0) * (PI / 128.0) * theta.sin();
            for i in 0..256 {
                let d = dir(theta, (i as f32 + 0.5) / 256.0 * 2.0 * PI);
                if d.y > 0.0 {
                    let e = (luminance(t.texels[j * 256 + i]) * d.y * dw) as f64;
                    total += e;
                    if d.dot(want) < sun_cos {
                        sky += e;
                    }
                }
            }
        }
        let ratio = (total - sky) / sky;
        assert!((ratio - p.sun_to_sky as f64).abs() < 0.05 * p.sun_to_sky as f64, "sun/sky ratio {ratio}");
    }
}
