//! Per-shot randomisation for training data (issue 4, method.md §7.1): camera, material
//! parameters and environment, all drawn from one seed so a shot can be regenerated exactly.
//!
//! What is never randomised, because physical correctness depends on it: the specular
//! reflectance of conductors (their complex IOR), the IOR and tint of glass, and emitters.

use crate::camera::Camera;
use crate::light::{Environment, Lights};
use crate::math::Ray;
use crate::rng::Pcg32;
use crate::scene::{ColorParam, Material, MaterialKind, Scene};
use crate::sky::{bake, SkyParams};
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
}

impl Original {
    pub fn of(scene: &Scene) -> Original {
        let fov_deg = 2.0 * scene.camera.tan_half_fov.atan().to_degrees();
        let has_environment = scene.lights.env_radiance(Vec3::Y).max_element() > 0.0
            || scene.lights.env_radiance(Vec3::X).max_element() > 0.0;
        Original { camera: scene.camera.clone(), fov_deg, materials: scene.materials.clone(), has_environment }
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
        MaterialKind::Conductor { roughness, .. } => format!("conductor alpha {roughness:.4}"),
        MaterialKind::Dielectric { ior, roughness, .. } => format!("dielectric ior {ior:.3} alpha {roughness:.4}"),
    }
}

fn random_material(orig: &Material, rng: &mut Pcg32) -> Material {
    let mut m = orig.clone();
    if orig.is_emissive() {
        return m;
    }
    m.kind = match &orig.kind {
        MaterialKind::Dielectric { ior, tint, .. } => MaterialKind::Dielectric { ior: *ior, roughness: roughness(rng), tint: *tint },
        MaterialKind::Conductor { eta, k, specular_tint, .. } => MaterialKind::Conductor { eta: *eta, k: *k, roughness: roughness(rng), specular_tint: *specular_tint },
        MaterialKind::Lambert { albedo } | MaterialKind::Plastic { albedo, .. } => {
            let colour = Vec3::new(uniform(rng, 0.01, 1.0), uniform(rng, 0.01, 1.0), uniform(rng, 0.01, 1.0));
            // Keep textures half of the time: they carry the fine detail denoisers must keep.
            let albedo = match albedo {
                ColorParam::Texture { .. } if rng.next_f32() < 0.5 => albedo.clone(),
                _ => ColorParam::Const(colour),
            };
            if rng.next_f32() < 0.6 {
                MaterialKind::Lambert { albedo }
            } else {
                MaterialKind::Plastic { albedo, ior: uniform(rng, 1.3, 1.8), roughness: roughness(rng) }
            }
        }
    };
    m
}

/// Scores a camera by how much of a coarse 8×8 grid of its rays sees geometry far enough away;
/// cameras inside objects or pressed against walls score low.
fn camera_score(scene: &Scene, cam: &Camera) -> f32 {
    let mut score = 0.0;
    for j in 0..8 {
        for i in 0..8 {
            let film = glam::Vec2::new((i as f32 + 0.5) / 8.0 * cam.width as f32, (j as f32 + 0.5) / 8.0 * cam.height as f32);
            let ray: Ray = cam.ray(film);
            match scene.accel.intersect(&ray, f32::INFINITY) {
                Some(h) if h.t > 0.05 * scene.radius => {
                    // Seeing the back of a one-sided wall means we are outside a room.
                    let n = scene.mesh.geometric_normal(h.prim as usize);
                    score += if n.dot(ray.dir) < 0.0 { 1.0 } else { 0.3 };
                }
                Some(_) => {}
                None => score += 0.5,
            }
        }
    }
    score / 64.0
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
    let mut best = (camera_score(scene, &orig.camera), orig.camera.clone(), orig.camera.position, orig.camera.position + orig.camera.forward, orig.camera.up, orig.fov_deg);
    best.0 *= 0.8; // prefer new views when they are about as good
    for _ in 0..12 {
        let r3 = |rng: &mut Pcg32| Vec3::new(uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0), uniform(rng, -1.0, 1.0));
        let (eye, target) = if inside {
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

    scene.materials = orig.materials.iter().map(|m| random_material(m, &mut rng)).collect();
    let materials = scene.materials.iter().map(|m| format!("{}: {}", m.name, describe(&m.kind))).collect();

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
        let scale = uniform(&mut rng, 0.5, 2.0);
        let name = format!("sky elev {:.1} az {:.1} turbidity {:.2} sun/sky {:.2} scale {:.2}", p.sun_elevation_deg, p.sun_azimuth_deg, p.turbidity, p.sun_to_sky, scale);
        (Environment::Map { image: bake(&p), rotation_deg: rotation, scale }, name)
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
