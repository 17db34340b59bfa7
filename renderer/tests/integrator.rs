//! Integrator correctness: furnace tests, unbiasedness (1/spp convergence) and determinism across
//! thread counts. The hard cases that must stay finite are in hard_cases.rs.

mod common;

use common::*;
use glam::{Mat4, Vec3};
use renderer::film::BufferRequest;
use renderer::light::Environment;
use renderer::scene::primitives::{cube, quad, sphere};
use renderer::scene::MaterialKind;

/// Mean of channel-averaged radiance over `pixels`, with its standard error from the frame's
/// own variance-of-the-mean buffer (pixels are independent, so variances add).
fn mean_and_se(frame: &renderer::film::Frame, pixels: &[usize]) -> (f64, f64) {
    let (mut m, mut v) = (0.0f64, 0.0f64);
    for &i in pixels {
        for c in 0..3 {
            m += frame.radiance.mean[i * 3 + c] as f64 / 3.0;
            v += frame.radiance.var[i * 3 + c] as f64 / 9.0;
        }
    }
    let n = pixels.len() as f64;
    // Channels of a pixel are correlated; summing var/9 per channel underestimates the
    // variance of their mean by at most 3×, so we use the upper bound 3·Σvar/9.
    (m / n, (3.0 * v).sqrt() / n)
}

/// Pixels whose centre ray passes within `r` (in pixels) of the image centre.
fn disk_pixels(w: u32, h: u32, r: f32) -> Vec<usize> {
    (0..(w * h) as usize)
        .filter(|&i| {
            let (x, y) = ((i as u32 % w) as f32 + 0.5 - w as f32 / 2.0, (i as u32 / w) as f32 + 0.5 - h as f32 / 2.0);
            x * x + y * y < r * r
        })
        .collect()
}

#[test]
fn furnace_white_diffuse_sphere_is_one() {
    // A white Lambertian convex polyhedron in a unit environment reflects exactly what it
    // receives: every path returns 1 after one bounce, so the expected pixel value is 1.
    let cam = camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 40.0, 32, 32);
    let s = scene(vec![(flat(sphere(1.0, 48)), Mat4::IDENTITY, lambert(1.0))], Environment::Constant(Vec3::ONE), cam, vec![]);
    let f = render(&s, 64, 1, 5, BufferRequest::RADIANCE_ONLY);
    let sphere_px = disk_pixels(32, 32, 8.0);
    let (m, se) = mean_and_se(&f, &sphere_px);
    // 4 standard errors: a false failure has probability < 1e-4; a 1 % energy error is
    // ~20 standard errors at this sample count, so real bugs fail.
    assert!((m - 1.0).abs() < 4.0 * se + 1e-4, "diffuse furnace mean {m} ± {se}");
    assert!(se < 0.003, "test too noisy to detect a 1% error: se {se}");
    // Background pixels see the environment directly: exactly 1.
    let corner = 0;
    assert!((f.radiance.mean[corner] - 1.0).abs() < 1e-6);
}

#[test]
fn furnace_glass_sphere_is_one() {
    // Smooth IOR-1.5 glass loses and gains no energy: reflection + transmission = 1 at every
    // interface and the η² radiance scaling cancels between entering and leaving. 16 bounces
    // let all but a negligible fraction of internally reflected energy out (F ≤ 0.1 inside
    // away from the silhouette, 0.1^8 ≈ 1e-8 left after 16 interfaces); we test the inner disk.
    let cam = camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 40.0, 32, 32);
    let glass = with_kind(MaterialKind::Dielectric { ior: 1.5, roughness: 0.0, tint: Vec3::ONE, dist: Default::default() });
    let s = scene(vec![(flat(sphere(1.0, 48)), Mat4::IDENTITY, glass)], Environment::Constant(Vec3::ONE), cam, vec![]);
    let f = render(&s, 64, 2, 16, BufferRequest::RADIANCE_ONLY);
    let inner = disk_pixels(32, 32, 6.0);
    let (m, se) = mean_and_se(&f, &inner);
    assert!((m - 1.0).abs() < 4.0 * se + 2e-3, "glass furnace mean {m} ± {se}");
}

#[test]
fn convergence_is_one_over_spp() {
    // An unbiased estimator's relMSE against the truth falls as 1/spp; a biased one flattens
    // out. Reference: 4096 spp with another seed, whose own error adds ≤ 256/4096 = 6 % at the
    // 256-spp point and so shifts the fitted slope by < 0.02 — far inside the ±20 % band.
    let cam = camera(Vec3::new(0.0, 1.0, 3.4), Vec3::new(0.0, 1.0, 0.0), 40.0, 24, 24);
    let box_ = vec![
        (quad(), Mat4::from_translation(Vec3::new(0.0, 0.0, 0.0)) * Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2), lambert(0.7)),
        (quad(), Mat4::from_translation(Vec3::new(0.0, 1.0, -1.0)), lambert(0.7)),
        (
            quad(),
            Mat4::from_translation(Vec3::new(-1.0, 1.0, 0.0)) * Mat4::from_rotation_y(std::f32::consts::FRAC_PI_2),
            with_kind(MaterialKind::Lambert { albedo: renderer::scene::ColorParam::Const(Vec3::new(0.7, 0.1, 0.1)) }),
        ),
        (quad(), Mat4::from_translation(Vec3::new(0.0, 2.0, 0.0)) * Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2), lambert(0.7)),
        (
            quad(),
            Mat4::from_translation(Vec3::new(0.0, 1.99, 0.0))
                * Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2)
                * Mat4::from_scale(Vec3::splat(0.3)),
            emitter(Vec3::splat(15.0)),
        ),
        (
            cube(),
            Mat4::from_translation(Vec3::new(0.3, 0.3, -0.2)) * Mat4::from_scale(Vec3::splat(0.3)),
            with_kind(MaterialKind::Conductor {
                eta: Vec3::new(0.2, 0.9, 1.1),
                k: Vec3::new(3.9, 2.4, 2.2),
                roughness: 0.2,
                specular_tint: renderer::scene::ColorParam::Const(Vec3::ONE),
                dist: Default::default(),
            }),
        ),
    ];
    let s = scene(box_, Environment::Constant(Vec3::splat(0.2)), cam, vec![]);
    let reference = render(&s, 4096, 999, 5, BufferRequest::RADIANCE_ONLY);
    let rel_mse = |spp: u32| -> f64 {
        let f = render(&s, spp, 7, 5, BufferRequest::RADIANCE_ONLY);
        let mut e = 0.0f64;
        for (x, y) in f.radiance.mean.iter().zip(&reference.radiance.mean) {
            e += ((x - y) as f64).powi(2) / ((*y as f64).powi(2) + 0.01);
        }
        e / f.radiance.mean.len() as f64
    };
    let spps = [4u32, 16, 64, 256];
    let pts: Vec<(f64, f64)> = spps.iter().map(|&s| ((s as f64).ln(), rel_mse(s).ln())).collect();
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
    assert!((-1.2..=-0.8).contains(&slope), "log-log slope of relMSE vs spp is {slope}, expected −1 ± 20 %");
}

#[test]
fn same_seed_same_bytes_on_one_and_two_threads() {
    let cam = camera(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, 45.0, 40, 24);
    let s = scene(
        vec![
            (
                sphere(0.5, 24),
                Mat4::IDENTITY,
                with_kind(MaterialKind::Plastic {
                    albedo: renderer::scene::ColorParam::Const(Vec3::new(0.2, 0.5, 0.8)),
                    ior: 1.5,
                    roughness: 0.1,
                    dist: Default::default(),
                    nonlinear: true,
                }),
            ),
            (
                quad(),
                Mat4::from_translation(Vec3::new(0.0, -0.5, 0.0))
                    * Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2)
                    * Mat4::from_scale(Vec3::splat(3.0)),
                lambert(0.5),
            ),
            (
                quad(),
                Mat4::from_translation(Vec3::new(0.0, 2.0, 0.0))
                    * Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2)
                    * Mat4::from_scale(Vec3::splat(0.5)),
                emitter(Vec3::splat(8.0)),
            ),
        ],
        Environment::Constant(Vec3::splat(0.1)),
        cam,
        vec![],
    );
    let dir = std::env::temp_dir().join(format!("pixguide-determinism-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut files = Vec::new();
    let mut frames = Vec::new();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let f = pool.install(|| render(&s, 8, 42, 5, BufferRequest::ALL));
        let exr = dir.join(format!("t{threads}.exr"));
        let st = dir.join(format!("t{threads}.safetensors"));
        renderer::film::exr_io::write_frame(&f, &exr).unwrap();
        f.descriptors.as_ref().unwrap().write_safetensors(&st).unwrap();
        files.push((std::fs::read(&exr).unwrap(), std::fs::read(&st).unwrap()));
        frames.push(f);
    }
    let diff = frames[0].radiance.mean.iter().zip(&frames[1].radiance.mean).filter(|(a, b)| a != b).count();
    assert_eq!(diff, 0, "radiance differs between 1 and 2 threads in {diff} values");
    assert!(files[0].0 == files[1].0, "EXR differs between 1 and 2 threads");
    assert!(files[0].1 == files[1].1, "descriptors differ between 1 and 2 threads");
    // And a different seed must change the image (the comparison above can fail).
    let other = render(&s, 8, 43, 5, BufferRequest::RADIANCE_ONLY);
    let same = render(&s, 8, 42, 5, BufferRequest::RADIANCE_ONLY);
    assert_ne!(other.radiance.mean, same.radiance.mean);
    std::fs::remove_dir_all(&dir).ok();
}
