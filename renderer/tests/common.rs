//! Scene-building helpers shared by the integration tests.
#![allow(dead_code)]

use glam::{Mat4, Vec3};
use renderer::camera::Camera;
use renderer::film::{BufferRequest, Frame};
use renderer::geometry::Mesh;
use renderer::integrator::{self, RenderOptions};
use renderer::light::Environment;
use renderer::scene::primitives::TriMesh;
use renderer::scene::{ColorParam, Material, MaterialKind, RenderSettings, Scene, SceneDescription};
use renderer::texture::Texture;

pub fn lambert(albedo: f32) -> Material {
    Material {
        name: "lambert".into(),
        kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::splat(albedo)) },
        emission: Vec3::ZERO,
        two_sided_emission: false,
        one_sided: false,
    }
}

pub fn emitter(emission: Vec3) -> Material {
    Material {
        name: "light".into(),
        kind: MaterialKind::Lambert { albedo: ColorParam::Const(Vec3::ZERO) },
        emission,
        two_sided_emission: false,
        one_sided: false,
    }
}

pub fn with_kind(kind: MaterialKind) -> Material {
    Material { name: "m".into(), kind, emission: Vec3::ZERO, two_sided_emission: false, one_sided: false }
}

/// A scene from (mesh, transform, material) triples.
pub fn scene(shapes: Vec<(TriMesh, Mat4, Material)>, env: Environment, camera: Camera, textures: Vec<Texture>) -> Scene {
    let mut mesh = Mesh::default();
    let mut materials = Vec::new();
    for (m, xf, mat) in shapes {
        let m = m.transformed(&xf);
        mesh.append(&m.positions, &m.normals, &m.uvs, &m.triangles, materials.len() as u32);
        materials.push(mat);
    }
    let desc = SceneDescription { camera, settings: RenderSettings::default(), mesh, materials, textures, environment: env };
    Scene::new("test-scene", desc).expect("test scene builds")
}

pub fn camera(pos: Vec3, target: Vec3, fov: f32, w: u32, h: u32) -> Camera {
    Camera::look_at(pos, target, Vec3::Y, fov, w, h).unwrap()
}

pub fn render(scene: &Scene, spp: u32, seed: u64, max_bounces: u32, request: BufferRequest) -> Frame {
    let opts = RenderOptions { spp, seed, max_bounces, russian_roulette: false, request, crop: None, first_sample: 0 };
    let (frame, _) = integrator::render(scene, &opts, &|_| {}).expect("render succeeds");
    assert!(frame.all_finite(), "frame has non-finite values");
    frame
}

/// Flat-shaded copy (no vertex normals): makes a tessellated sphere an exact convex polyhedron.
pub fn flat(mut m: TriMesh) -> TriMesh {
    m.normals.clear();
    m
}
