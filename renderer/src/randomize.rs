//! Per-shot randomisation for training data (method.md §7.1): camera, material
//! parameters and textures, emitters' strength and colour, and the environment, all drawn from
//! one seed so a shot can be regenerated exactly.
//!
//! What is never randomised, because physical correctness depends on it: the complex IOR of
//! conductors (a tint, textured or not, only scales their Fresnel reflectance) and the IOR and
//! tint of glass. Emitters keep their shape and place; only their radiance is scaled and tinted.

use crate::camera::Camera;
use crate::light::{Environment, Lights};
use crate::math::luminance;
use crate::math::Ray;
use crate::rng::Pcg32;
use crate::scene::{ColorParam, Material, MaterialKind, Scene};
use crate::sky::{bake, SkyParams};
use crate::texture::Texture;
use glam::Vec3;
use serde::Serialize;

/// What a shot changed, recorded as one JSON line beside its files.
#[derive(Clone, Debug, Serialize)]
pub struct ShotParams {
    pub scene: String,
    pub shot: u32,
    pub seed: u64,
    pub camera_position: [f32; 3],
    pub camera_target: [f32; 3],
    pub camera_up: [f32; 3],
    pub fov_deg: f32,
    pub environment: String,
    pub environment_rotation_deg: f32,
    pub materials: Vec<String>,
}

/// The scene's state before any shot touched it, to restore between shots.
pub struct Original {
    camera: Camera,
    fov_deg: f32,
    materials: Vec<Material>,
    has_environment: bool,
    /// E_h/π of the scene's own environment: random skies keep the exposure the scene's author
    /// chose (a dim fill around an area-lit set, a bright sky seen through blinds, daylight).
    env_white: f32,
}

impl Original {
    pub fn of(scene: &Scene) -> Original {
        let fov_deg = 2.0 * scene.camera.tan_half_vfov().atan().to_degrees();
        let has_environment =
            scene.lights.env_radiance(Vec3::Y).max_element() > 0.0 || scene.lights.env_radiance(Vec3::X).max_element() > 0.0;
        // E_h/π of the environment by the midpoint rule on a 32 × 64 (θ, φ) grid of the upper
        // hemisphere; a sun disk of 1.5° falls between grid points now and then, so this is
        // only a level, good to some ten per cent, which is all an exposure range needs.
        let (nt, np) = (32, 64);
        let mut e = 0.0f64;
        for j in 0..nt {
            let theta = (j as f32 + 0.5) / nt as f32 * std::f32::consts::FRAC_PI_2;
            for i in 0..np {
                let phi = (i as f32 + 0.5) / np as f32 * std::f32::consts::TAU;
                let d = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                let d_omega = std::f32::consts::FRAC_PI_2 / nt as f32 * std::f32::consts::TAU / np as f32 * theta.sin();
                e += (luminance(scene.lights.env_radiance(d)) * theta.cos() * d_omega) as f64;
            }
        }
        let env_white = (e as f32) / crate::math::PI;
        Original { camera: scene.camera.clone(), fov_deg, materials: scene.materials.clone(), has_environment, env_white }
    }
}

/// Irradiance (luminance) on an upward-facing horizontal plane from the upper hemisphere of a
/// lat-long map in `light::environment`'s convention (row j at θ = (j + ½)/h·π from +Y).
pub fn horizontal_irradiance(map: &Texture) -> f32 {
    let (w, h) = (map.width as usize, map.height as usize);
    let mut e = 0.0f64;
    for j in 0..h {
        let theta = (j as f64 + 0.5) / h as f64 * std::f64::consts::PI;
        if theta >= std::f64::consts::FRAC_PI_2 {
            break;
        }
        let d_omega = (std::f64::consts::TAU / w as f64) * (std::f64::consts::PI / h as f64) * theta.sin();
        let row: f64 = map.texels[j * w..(j + 1) * w].iter().map(|&c| luminance(c) as f64).sum();
        e += row * theta.cos() * d_omega;
    }
    e as f32
}

/// Radiance a white Lambertian plane facing up should get from a randomised sky when the scene's
/// own environment gives no usable level: the sky map is scaled so that E_h/π lands in this
/// range (log-uniform). Otherwise the range is 0.6–1.5 × the scene's own E_h/π (clamped to
/// [`ENV_WHITE_LIMITS`]); the shipped outdoor scenes are authored at E_h/π ≈ 0.8, inside this. With albedos drawn in [0.01, 1]
/// (mean ≈ 0.5) a sunlit floor then sits at 0.2–0.7 and sun-facing walls (which can receive
/// several times E_h when the sun is low) rarely clip, while the old fixed scale of 0.5–2 on a
/// sky whose zenith luminance is 1 gave E_h/π ≈ 2–20 and blew out most outdoor shots.
pub const SKY_WHITE_RADIANCE: (f32, f32) = (0.45, 1.1);

/// Bounds on the scene's own E_h/π that random skies are scaled around: below, a scene lit by
/// its lamps with a near-black fill still gets a visible sky; above, a map that was already
/// blown out in the scene file does not pass its overexposure on.
pub const ENV_WHITE_LIMITS: (f32, f32) = (0.05, 6.0);

/// The environment scale that gives a white horizontal plane radiance `white` under `map`
/// (1 for a map with no light from above, where no scale can help).
pub fn sky_scale_for(map: &Texture, white: f32) -> f32 {
    let e = horizontal_irradiance(map);
    if e > 1e-9 && e.is_finite() {
        white * crate::math::PI / e
    } else {
        1.0
    }
}

fn uniform(rng: &mut Pcg32, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.next_f32()
}

/// GGX alpha drawn as in OptaGen: √α uniform in [√0.004, √0.6]; 30 % of surfaces stay smooth.
fn roughness(rng: &mut Pcg32) -> f32 {
    if rng.next_f32() < 0.3 {
        0.0
    } else {
        uniform(rng, 0.004f32.sqrt(), 0.6f32.sqrt()).powi(2)
    }
}

fn describe(kind: &MaterialKind) -> String {
    match kind {
        MaterialKind::Lambert { albedo: ColorParam::Const(a) } => format!("diffuse {:.3},{:.3},{:.3}", a.x, a.y, a.z),
        MaterialKind::Lambert { .. } => "diffuse textured".into(),
        MaterialKind::Plastic { ior, roughness, .. } => format!("plastic ior {ior:.3} alpha {roughness:.4}"),
        MaterialKind::Conductor { roughness, specular_tint: ColorParam::Const(_), .. } => format!("conductor alpha {roughness:.4}"),
        MaterialKind::Conductor { roughness, .. } => format!("conductor textured alpha {roughness:.4}"),
        MaterialKind::Dielectric { ior, roughness, .. } => format!("dielectric ior {ior:.3} alpha {roughness:.4}"),
    }
}

/// Relative linear-sRGB colour of a light between warm (t = −1, about 2700 K) and cool (t = 1,
/// about 8000 K) white, at unit luminance so that the tint changes no exposure.
fn light_tint(t: f32) -> Vec3 {
    let (warm, white, cool) = (Vec3::new(1.0, 0.6, 0.3), Vec3::ONE, Vec3::new(0.75, 0.85, 1.0));
    let c = if t < 0.0 { white.lerp(warm, -t) } else { white.lerp(cool, t) };
    c / luminance(c)
}

/// A texture of the scene for a surface that had none: 0 .. n picks one, None keeps the colour.
fn random_texture(rng: &mut Pcg32, n_textures: usize, p: f32) -> Option<u32> {
    let pick = rng.next_f32() < p;
    let k = (rng.next_f32() * n_textures as f32) as usize;
    (pick && n_textures > 0).then_some(k.min(n_textures.saturating_sub(1)) as u32)
}

fn random_material(orig: &Material, rng: &mut Pcg32, n_textures: usize) -> Material {
    let mut m = orig.clone();
    if orig.is_emissive() {
        // Half to twice the authored power: the exposure range a denoiser meets from lamps, with
        // the sky's own range (0.6–1.5×) for environment-lit scenes; 60 % of lights turn warm or cool.
        let scale = 0.5 * 4f32.powf(rng.next_f32());
        let t = uniform(rng, -1.0, 1.0);
        let tint = if rng.next_f32() < 0.6 { light_tint(t) } else { Vec3::ONE };
        m.emission = orig.emission * scale * tint;
        return m;
    }
    m.kind = match &orig.kind {
        MaterialKind::Dielectric { ior, tint, .. } => {
            MaterialKind::Dielectric { ior: *ior, roughness: roughness(rng), tint: *tint, dist: Default::default() }
        }
        MaterialKind::Conductor { eta, k, specular_tint, .. } => {
            // A third of untextured metals get one of the scene's textures as their tint,
            // lifted towards white (tarnish, inlay, engraving): textured conductors are in the
            // test scenes (veach-ajar's floor) and the training scenes had none.
            let specular_tint = match (specular_tint, random_texture(rng, n_textures, 0.35)) {
                (ColorParam::Const(c), Some(index)) => ColorParam::texture(index, *c * uniform(rng, 0.7, 1.0)),
                (t, _) => t.clone(),
            };
            MaterialKind::Conductor { eta: *eta, k: *k, roughness: roughness(rng), specular_tint, dist: Default::default() }
        }
        MaterialKind::Lambert { albedo } | MaterialKind::Plastic { albedo, .. } => {
            let colour = Vec3::new(uniform(rng, 0.01, 1.0), uniform(rng, 0.01, 1.0), uniform(rng, 0.01, 1.0));
            // Keep textures half of the time: they carry the fine detail denoisers must keep.
            let keep = rng.next_f32() < 0.5;
            let new_texture = random_texture(rng, n_textures, 0.25);
            let albedo = match (albedo, new_texture) {
                (ColorParam::Texture { .. } | ColorParam::Checkerboard { .. }, _) if keep => albedo.clone(),
                // A quarter of surfaces get a texture of the scene, tinted: more texture detail
                // on more shapes than the authors drew.
                (_, Some(index)) => ColorParam::texture(index, colour.max(Vec3::splat(0.2))),
                _ => ColorParam::Const(colour),
            };
            if rng.next_f32() < 0.6 {
                MaterialKind::Lambert { albedo }
            } else {
                MaterialKind::Plastic {
                    albedo,
                    ior: uniform(rng, 1.3, 1.8),
                    roughness: roughness(rng),
                    dist: Default::default(),
                    nonlinear: true,
                }
            }
        }
    };
    m
}

/// Scores a camera by how much of a coarse 8×8 grid of its rays sees geometry far enough away
/// (cameras inside objects or pressed against walls score low), times how many different
/// materials it sees (a view filled by one wall teaches a denoiser little).
fn camera_score(scene: &Scene, cam: &Camera) -> f32 {
    let mut score = 0.0;
    let mut seen: Vec<u32> = Vec::new();
    for j in 0..8 {
        for i in 0..8 {
            let film = glam::Vec2::new((i as f32 + 0.5) / 8.0 * cam.width as f32, (j as f32 + 0.5) / 8.0 * cam.height as f32);
            let ray: Ray = cam.ray(film);
            match scene.accel.intersect(&ray, f32::INFINITY) {
                Some(h) if h.t > 0.05 * scene.radius => {
                    // Seeing the back of a one-sided wall means we are outside a room.
                    let n = scene.mesh.geometric_normal(h.prim as usize);
                    score += if n.dot(ray.dir) < 0.0 { 1.0 } else { 0.3 };
                    let m = scene.mesh.material[h.prim as usize];
                    if !seen.contains(&m) {
                        seen.push(m);
                    }
                }
                Some(_) => {}
                None => score += 0.5,
            }
        }
    }
    // Up to four materials count; one material alone halves the score.
    let variety = 0.5 + 0.5 * (seen.len().min(4) as f32 - 1.0).max(0.0) / 3.0;
    score / 64.0 * variety
}

/// The point the scene's own camera looks at: its first hit along the view axis, or a point at
/// half the scene size ahead when the axis sees nothing.
fn original_target(scene: &Scene, cam: &Camera) -> Vec3 {
    let ray = Ray::new(cam.position, cam.forward);
    let t = scene.accel.intersect(&ray, f32::INFINITY).map_or(0.5 * scene.radius, |h| h.t);
    cam.position + cam.forward * t
}

/// Applies shot `shot`'s randomisation to `scene` (restoring `orig` first) and returns what it did.
pub fn randomize(scene: &mut Scene, orig: &Original, name: &str, shot: u32, seed: u64) -> ShotParams {
    let mut rng = Pcg32::new(crate::rng::mix64(seed ^ crate::rng::mix64(shot as u64 + 1)), crate::rng::mix64(name.len() as u64 + seed));
    let (lo, hi) = scene.mesh.bounds();
    let (centre, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    // Scenes without an environment (closed rooms, Cornell boxes) are lit from inside: treat
    // them as interiors even when their own camera stands outside the bounds (an open box).
    let inside = (orig.camera.position - centre).abs().cmple(half).all() || !orig.has_environment;
    let (w, h) = (orig.camera.width, orig.camera.height);

    // Camera: the original view is one candidate, so a scene never gets a worse view than its own.
    let mut best = (
        camera_score(scene, &orig.camera),
        orig.camera.clone(),
        orig.camera.position,
        orig.camera.position + orig.camera.forward,
        orig.camera.up,
        orig.fov_deg,
    );
    best.0 *= 0.8; // prefer new views when they are about as good
    let orig_target = original_target(scene, &orig.camera);
    for k in 0..12 {
        let r3 = |rng: &mut Pcg32| Vec3::new(uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0));
        let (eye, target) = if k % 3 != 2 {
            // Two candidates in three orbit the scene's own view: the author framed the content
            // there, while views drawn from the bounds alone mostly show floors and walls.
            let offset = orig.camera.position - orig_target;
            let dist = offset.length().max(1e-3);
            let turn = glam::Quat::from_axis_angle(Vec3::Y, uniform(&mut rng, -60.0, 60.0).to_radians());
            let dir = (turn * offset / dist + Vec3::Y * uniform(&mut rng, -0.3, 0.4)).normalize_or_zero();
            let target = orig_target + r3(&mut rng) * 0.15 * dist;
            (target + dir * dist * uniform(&mut rng, 0.6, 1.3), target)
        } else if inside {
            (centre + r3(&mut rng) * half * 0.7, centre + r3(&mut rng) * half * 0.7)
        } else {
            let eye = centre + r3(&mut rng) * half.max(Vec3::splat(half.max_element() * 0.5)) * 2.5;
            (eye, centre + r3(&mut rng) * half * 0.3)
        };
        let up = (Vec3::Y + r3(&mut rng) * 0.5).normalize_or_zero();
        let fov = orig.fov_deg * uniform(&mut rng, 0.8, 1.2);
        if let Some(cam) = Camera::look_at(eye, target, up, fov.clamp(10.0, 120.0), w, h) {
            let s = camera_score(scene, &cam);
            if s > best.0 {
                best = (s, cam, eye, target, up, fov);
            }
        }
    }
    let (_, cam, eye, target, up, fov) = best;
    scene.camera = cam;

    let n_textures = scene.textures.len();
    scene.materials = orig.materials.iter().map(|m| random_material(m, &mut rng, n_textures)).collect();
    let materials = scene
        .materials
        .iter()
        .map(|m| match m.is_emissive() {
            true => format!("{}: {} emission {:.3},{:.3},{:.3}", m.name, describe(&m.kind), m.emission.x, m.emission.y, m.emission.z),
            false => format!("{}: {}", m.name, describe(&m.kind)),
        })
        .collect();

    // Environment: a fresh procedural sky per shot (scenes without any environment keep none,
    // e.g. closed Cornell boxes, where it would only cost time).
    let rotation = uniform(&mut rng, 0.0, 360.0);
    let (env, env_name) = if orig.has_environment {
        let p = SkyParams {
            width: 256,
            height: 128,
            sun_elevation_deg: uniform(&mut rng, 5.0, 80.0),
            sun_azimuth_deg: uniform(&mut rng, 0.0, 360.0),
            turbidity: uniform(&mut rng, 2.0, 8.0),
            sun_to_sky: uniform(&mut rng, 1.0, 8.0),
            ..Default::default()
        };
        let image = bake(&p);
        // Around the scene's own level, within sane bounds; a scene whose environment has no
        // light from above (or an absurd amount) gets the default daylight range.
        let (lo, hi) = if orig.env_white.is_finite() && orig.env_white > 0.0 {
            let w = orig.env_white.clamp(ENV_WHITE_LIMITS.0, ENV_WHITE_LIMITS.1);
            (w * 0.6, w * 1.5)
        } else {
            SKY_WHITE_RADIANCE
        };
        let white = lo * (hi / lo).powf(rng.next_f32());
        let scale = sky_scale_for(&image, white);
        let name = format!(
            "sky elev {:.1} az {:.1} turbidity {:.2} sun/sky {:.2} scale {:.2}",
            p.sun_elevation_deg, p.sun_azimuth_deg, p.turbidity, p.sun_to_sky, scale
        );
        (Environment::Map { image, rotation_deg: rotation, scale }, name)
    } else {
        (Environment::Constant(Vec3::ZERO), "none".to_string())
    };
    scene.lights = Lights::build(&scene.mesh, &scene.materials, env);

    ShotParams {
        scene: name.to_string(),
        shot,
        seed,
        camera_position: eye.to_array(),
        camera_target: target.to_array(),
        camera_up: up.to_array(),
        fov_deg: fov,
        environment: env_name,
        environment_rotation_deg: rotation,
        materials,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn horizontal_irradiance_of_a_constant_sky_is_pi_l() {
        // A constant radiance L over the upper hemisphere gives E = πL; the midpoint rule over
        // 64 rows of θ is accurate to well under 0.1 %.
        let map = Texture { width: 32, height: 64, texels: vec![Vec3::splat(2.0); 32 * 64] };
        let e = horizontal_irradiance(&map);
        assert!((e - 2.0 * crate::math::PI).abs() < 1e-3 * e, "{e}");
        // Light from below the horizon does not count.
        let mut lower = map.clone();
        lower.texels[..32 * 32].fill(Vec3::ZERO);
        assert!(horizontal_irradiance(&lower) < 1e-6);
        assert_eq!(sky_scale_for(&lower, 0.8), 1.0);
    }

    #[test]
    fn scaled_skies_land_in_the_exposure_range() {
        // Whatever the sun's height and strength, the scale brings E_h/π of the scaled map to
        // the requested white radiance (exactly, up to float rounding).
        for (elev, ratio) in [(5.0, 1.0), (30.0, 4.0), (80.0, 8.0)] {
            let p = SkyParams { width: 128, height: 64, sun_elevation_deg: elev, sun_to_sky: ratio, ..Default::default() };
            let map = bake(&p);
            let s = sky_scale_for(&map, 0.7);
            let white = s * horizontal_irradiance(&map) / crate::math::PI;
            assert!((white - 0.7).abs() < 1e-3, "elev {elev}: {white}");
        }
    }
}

#[cfg(test)]
mod scene_tests {
    use super::*;
    use std::path::Path;

    #[test]
    fn random_skies_keep_the_scenes_exposure_and_cameras_see_content() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/metal-spheres-sky/scene.toml");
        let mut scene = Scene::load(&path).unwrap();
        let orig = Original::of(&scene);
        // The scene is authored at E_h/π ≈ 0.8 (scale 0.11 on a sky of E_h ≈ 22); the 32 × 64 grid
        // estimate is good to ~10 %, so 0.6–1.0 can only fail if the estimate is broken.
        assert!(orig.env_white > 0.6 && orig.env_white < 1.0, "{}", orig.env_white);
        for shot in 0..4 {
            let p = randomize(&mut scene, &orig, "metal-spheres-sky", shot, 7);
            let again = Original::of(&scene);
            // 0.6–1.5 × the original, with the estimate's ~10 % error on either side.
            let ratio = again.env_white / orig.env_white;
            assert!(ratio > 0.5 && ratio < 1.7, "shot {shot}: ratio {ratio} ({})", p.environment);
            assert!(camera_score(&scene, &scene.camera) > 0.2, "shot {shot} sees nothing");
        }
    }

    #[test]
    fn lights_change_power_and_colour_within_bounds_and_metals_get_textures() {
        let (mut textured_metals, mut lights) = (0, 0);
        // Sky-lit metals on marble, and lamp-lit metals on a textured table.
        for (name, shot) in (0..12).map(|k| ("metal-spheres-sky", k)).chain((0..4).map(|k| ("copper-bowls", k))) {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/{name}/scene.toml"));
            let mut scene = Scene::load(&path).unwrap();
            let orig = Original::of(&scene);
            randomize(&mut scene, &orig, name, shot, 3);
            for (m, o) in scene.materials.iter().zip(&orig.materials) {
                if o.is_emissive() {
                    // Power: 0.5–2× the authored luminance (the tint has unit luminance).
                    let r = luminance(m.emission) / luminance(o.emission);
                    assert!((0.5 - 1e-4..=2.0 + 1e-4).contains(&r), "{}: {r}", m.name);
                    lights += 1;
                }
                // A textured tint stays a reflectance: texels ≤ 1 times a scale ≤ 1.
                if let MaterialKind::Conductor { specular_tint: ColorParam::Texture { scale, index, .. }, .. } = &m.kind {
                    assert!(scale.max_element() <= 1.0 && (*index as usize) < scene.textures.len());
                    textured_metals += 1;
                }
            }
        }
        // 3 metals × 12 shots at 35 %: 12.6 expected; fewer than 3 has probability < 10⁻³.
        assert!(textured_metals >= 3, "{textured_metals}");
        assert!(lights >= 4, "copper-bowls' two lamps were not seen");
        for t in [-1.0, -0.3, 0.0, 0.5, 1.0] {
            let c = light_tint(t);
            assert!((luminance(c) - 1.0).abs() < 1e-5 && c.min_element() > 0.0, "{t}: {c}");
        }
    }
}
