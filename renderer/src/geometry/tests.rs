use super::*;
use crate::rng::Pcg32;

fn rand3(rng: &mut Pcg32) -> Vec3 {
    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
}

fn mesh_from(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
    let material = vec![0; triangles.len()];
    Mesh { positions, normals: Vec::new(), uvs: Vec::new(), triangles, material }
}

/// A grid of n×n quads over [0,1]² (two triangles per quad, alternating diagonals), with a
/// height field so edges are neither axis-aligned nor coplanar. Its slope stays below 0.25, so
/// a ray steeper than that can have no silhouette edge to graze past.
fn grid(n: u32, scale: f32, offset: Vec3) -> Mesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
            let z = 0.03 * (7.0 * x).sin() * (5.0 * y).cos();
            positions.push(offset + scale * Vec3::new(x, y, z));
        }
    }
    let mut triangles = Vec::new();
    let idx = |i: u32, j: u32| j * (n + 1) + i;
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            } else {
                triangles.push([a, b, d]);
                triangles.push([b, c, d]);
            }
        }
    }
    mesh_from(positions, triangles)
}

fn brute_force(mesh: &Mesh, ray: &Ray, tmax: f32) -> Option<(f32, u32)> {
    let shear = triangle::RayShear::new(ray.origin, ray.dir)?;
    let mut best: Option<(f32, u32)> = None;
    for i in 0..mesh.triangles.len() {
        let [p0, p1, p2] = mesh.triangle(i);
        if triangle::is_degenerate(p0, p1, p2) {
            continue;
        }
        let limit = best.map_or(tmax, |b| b.0);
        if let Some((t, _, _)) = triangle::intersect(&shear, p0.into(), p1.into(), p2.into(), limit) {
            best = Some((t, i as u32));
        }
    }
    best
}

#[test]
fn closest_hit_matches_brute_force() {
    let mut rng = Pcg32::new(1, 0);
    // Random soup (many overlaps, so "closest" matters) plus a grid (shared edges).
    let mut mesh = grid(6, 1.0, Vec3::ZERO);
    for _ in 0..300 {
        let c = rand3(&mut rng) * 1.2 - 0.1;
        let p: Vec<Vec3> = (0..3).map(|_| c + (rand3(&mut rng) - 0.5) * 0.3).collect();
        mesh.append(&p, &[], &[], &[[0, 1, 2]], 0);
    }
    let accel = Accel::build(&mesh);
    let mut hits = 0;
    for _ in 0..20_000 {
        let o = rand3(&mut rng) * 2.0 - 0.5;
        let d = (rand3(&mut rng) * 2.0 - 1.0).normalize();
        let ray = Ray::new(o, d);
        let tmax = if rng.next_f32() < 0.3 { rng.next_f32() } else { f32::INFINITY };
        let want = brute_force(&mesh, &ray, tmax);
        let got = accel.intersect(&ray, tmax);
        match (want, got) {
            (None, None) => {}
            (Some((t, prim)), Some(h)) => {
                hits += 1;
                // Same triangle test on both sides: t must agree exactly; the prim may differ
                // only when two triangles are hit at the same t (shared edge or vertex).
                assert_eq!(t, h.t, "ray {ray:?}");
                if prim != h.prim {
                    assert!(brute_force(&mesh_from(mesh.positions.clone(), vec![mesh.triangles[h.prim as usize]]), &ray, tmax).is_some());
                }
                assert!(h.bary.x >= 0.0 && h.bary.y >= 0.0 && h.bary.x + h.bary.y <= 1.0 + 1e-6);
                // The barycentric point must lie on the ray at t.
                let [p0, p1, p2] = mesh.triangle(h.prim as usize);
                let p = p0 * (1.0 - h.bary.x - h.bary.y) + p1 * h.bary.x + p2 * h.bary.y;
                assert!((p - ray.at(h.t)).length() < 1e-4, "{p} vs {}", ray.at(h.t));
            }
            (w, g) => panic!("ray {ray:?} tmax {tmax}: brute force {w:?}, accel {g:?}"),
        }
        assert_eq!(accel.occluded(&ray, tmax), got.is_some(), "occluded disagrees for {ray:?}");
    }
    // Enough hits that the comparison means something.
    assert!(hits > 2_000, "only {hits} hits");
}

#[test]
fn rays_through_shared_edges_and_vertices_never_miss() {
    let n = 16;
    let mut rng = Pcg32::new(2, 0);
    for &(scale, offset) in &[(1.0, Vec3::ZERO), (1e-3, Vec3::new(0.3e-3, -2e-3, 1e-3)), (1e4, Vec3::new(-3e4, 1e4, 5e3))] {
        let mesh = grid(n, scale, offset);
        let accel = Accel::build(&mesh);
        let mut misses = 0;
        let mut total = 0;
        // Targets: every interior vertex, every interior edge midpoint (the quad diagonals too),
        // seen from random eye points above and below the height field.
        let mut targets = Vec::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (mesh.positions[t[k] as usize], mesh.positions[t[(k + 1) % 3] as usize]);
                targets.push(a);
                targets.push(a + (b - a) * 0.5);
                targets.push(a + (b - a) * rng.next_f32());
            }
        }
        for &target in &targets {
            let rel = (target - offset) / scale;
            // Skip the outer boundary, where a ray can legitimately graze past.
            if rel.x < 1e-3 || rel.y < 1e-3 || rel.x > 1.0 - 1e-3 || rel.y > 1.0 - 1e-3 {
                continue;
            }
            for side in [1.0f32, -1.0] {
                // Slope of these rays ≥ 0.97 / 1.5 > 0.25: every one must cross the surface.
                let eye = offset + scale * Vec3::new(rng.next_f32() * 2.0 - 0.5, rng.next_f32() * 2.0 - 0.5, side * (1.0 + rng.next_f32()));
                let ray = Ray::new(eye, (target - eye).normalize());
                total += 2;
                if accel.intersect(&ray, f32::INFINITY).is_none() {
                    misses += 1;
                }
                if !accel.occluded(&ray, f32::INFINITY) {
                    misses += 1;
                }
            }
        }
        assert!(total > 6000);
        assert_eq!(misses, 0, "scale {scale}: {misses} of {total} queries let the ray slip through");
    }
}

#[test]
fn degenerate_triangles_are_never_hit() {
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let positions = vec![
        // 0-2: collinear
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        // 3: NaN vertex, 4: infinite vertex
        Vec3::new(nan, 0.0, 0.0),
        Vec3::new(inf, 1.0, 0.0),
        // 5-7: a valid triangle far away, so the BVH is not empty
        Vec3::new(10.0, 0.0, 0.0),
        Vec3::new(11.0, 0.0, 0.0),
        Vec3::new(10.0, 1.0, 0.0),
        // 8: a point off the collinear line
        Vec3::new(0.0, 2.0, 0.0),
    ];
    let triangles = vec![[0, 1, 2], [0, 0, 8], [0, 3, 8], [0, 4, 8], [5, 6, 7], [0, 8, 99]];
    let mesh = mesh_from(positions, triangles);
    let accel = Accel::build(&mesh);
    let mut rng = Pcg32::new(3, 0);
    for _ in 0..20_000 {
        // Rays aimed at the degenerate ones' supports (the segment 0-2 and the region around 0-8).
        let target = Vec3::new(rng.next_f32() * 2.0, rng.next_f32() * 2.0, 0.0);
        let o = target + Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 1.0);
        let ray = Ray::new(o, (target - o).normalize());
        assert!(accel.intersect(&ray, f32::INFINITY).is_none(), "hit a degenerate triangle with {ray:?}");
        assert!(!accel.occluded(&ray, f32::INFINITY));
    }
    // The valid one still works.
    let ray = Ray::new(Vec3::new(10.2, 0.2, 1.0), Vec3::NEG_Z);
    assert_eq!(accel.intersect(&ray, f32::INFINITY).map(|h| h.prim), Some(4));
    // A mesh of only degenerate triangles builds and hits nothing.
    let only_bad = mesh_from(vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0], vec![[0, 1, 2]]);
    let accel = Accel::build(&only_bad);
    assert!(accel.intersect(&Ray::new(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z), f32::INFINITY).is_none());
}

#[test]
fn tmax_is_an_open_bound() {
    let mesh = grid(4, 1.0, Vec3::ZERO);
    let accel = Accel::build(&mesh);
    let mut rng = Pcg32::new(4, 0);
    let mut checked = 0;
    for _ in 0..2000 {
        let o = Vec3::new(rng.next_f32(), rng.next_f32(), 2.0);
        let target = Vec3::new(rng.next_f32(), rng.next_f32(), 0.0);
        let ray = Ray::new(o, (target - o).normalize());
        let Some(h) = accel.intersect(&ray, f32::INFINITY) else { continue };
        checked += 1;
        assert!(accel.intersect(&ray, h.t).is_none(), "hit at exactly tmax");
        assert!(!accel.occluded(&ray, h.t));
        let above = h.t * (1.0 + 1e-6);
        assert_eq!(accel.intersect(&ray, above).map(|x| x.t), Some(h.t));
        assert!(accel.occluded(&ray, above));
        assert!(accel.intersect(&ray, 0.0).is_none() && !accel.occluded(&ray, 0.0));
        assert!(accel.intersect(&ray, -1.0).is_none() && !accel.occluded(&ray, f32::NAN));
    }
    assert!(checked > 1500);
}

#[test]
fn bad_rays_hit_nothing() {
    let mesh = grid(4, 1.0, Vec3::ZERO);
    let accel = Accel::build(&mesh);
    for (o, d) in [
        (Vec3::new(0.5, 0.5, 1.0), Vec3::ZERO),
        (Vec3::new(0.5, 0.5, f32::NAN), Vec3::NEG_Z),
        (Vec3::new(0.5, 0.5, 1.0), Vec3::new(0.0, f32::INFINITY, -1.0)),
    ] {
        assert!(accel.intersect(&Ray::new(o, d), f32::INFINITY).is_none());
        assert!(!accel.occluded(&Ray::new(o, d), f32::INFINITY));
    }
    // An exactly axis-parallel ray still finds the surface.
    assert!(accel.intersect(&Ray::new(Vec3::new(0.3, 0.6, 1.0), Vec3::NEG_Z), f32::INFINITY).is_some());
}

/// Rays spawned from points on a triangle (computed by barycentric interpolation, as
/// `Scene::surface` does) never re-hit it, on either side, at scene scales 1e-3, 1 and 1e4;
/// and a shadow ray between two facing parallel quads a small gap apart sees neither quad.
#[test]
fn offset_origin_avoids_self_hits_and_leaks() {
    let mut rng = Pcg32::new(5, 0);
    for &scale in &[1e-3f32, 1.0, 1e4] {
        // A tilted triangle at a generic position, and one through the origin.
        for &centre in &[Vec3::new(0.37, -0.61, 0.23), Vec3::ZERO] {
            let p0 = scale * (centre + Vec3::new(-0.5, -0.3, 0.1));
            let p1 = scale * (centre + Vec3::new(0.6, -0.2, -0.3));
            let p2 = scale * (centre + Vec3::new(0.1, 0.7, 0.4));
            let mesh = mesh_from(vec![p0, p1, p2], vec![[0, 1, 2]]);
            let accel = Accel::build(&mesh);
            let ng = mesh.geometric_normal(0);
            let extent = p0.abs().max(p1.abs()).max(p2.abs()).max_element();
            for _ in 0..20_000 {
                let (mut b1, mut b2) = (rng.next_f32(), rng.next_f32());
                if b1 + b2 > 1.0 {
                    (b1, b2) = (1.0 - b1, 1.0 - b2);
                }
                let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
                let mut d = (rand3(&mut rng) * 2.0 - 1.0).normalize();
                // Grazing directions are the hard case: make a third of them nearly tangent.
                if rng.next_f32() < 0.33 {
                    d = (d - ng * d.dot(ng) * 0.999).normalize();
                }
                if d.dot(ng).abs() < 1e-6 {
                    continue;
                }
                let o = offset_ray_origin(p, ng, d, extent);
                let ray = Ray::new(o, d);
                assert!(accel.intersect(&ray, f32::INFINITY).is_none(), "scale {scale}: self-hit from {p} dir {d}");
            }
        }
        // Facing quads z = 0 (normal +z) and z = gap (normal -z), gap = 1e-3 of the scene scale.
        let gap = 1e-3 * scale;
        let base = Vec3::new(0.2, 0.4, 0.3) * scale;
        let q = |z: f32| {
            [
                base + Vec3::new(0.0, 0.0, z),
                base + Vec3::new(scale, 0.0, z),
                base + Vec3::new(scale, scale, z),
                base + Vec3::new(0.0, scale, z),
            ]
        };
        let (lo, hi) = (q(0.0), q(gap));
        let mut positions = lo.to_vec();
        positions.extend_from_slice(&hi);
        let mesh = mesh_from(positions, vec![[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]]);
        let accel = Accel::build(&mesh);
        for _ in 0..5_000 {
            let a = base + Vec3::new(rng.next_f32() * 0.8 + 0.1, rng.next_f32() * 0.8 + 0.1, 0.0) * scale;
            let b = base + Vec3::new(rng.next_f32() * 0.8 + 0.1, rng.next_f32() * 0.8 + 0.1, 0.0) * scale + Vec3::Z * gap;
            let ext = |v: &[Vec3; 4]| v.iter().map(|p| p.abs().max_element()).fold(0.0, f32::max);
            let oa = offset_ray_origin(a, Vec3::Z, b - a, ext(&lo));
            let ob = offset_ray_origin(b, Vec3::NEG_Z, oa - b, ext(&hi));
            // Both origins must stay inside the gap (no leaking out of it).
            assert!(oa.z > a.z && oa.z < b.z && ob.z < b.z && ob.z > a.z, "scale {scale}: offsets leave the gap");
            let d = ob - oa;
            let dist = d.length();
            let ray = Ray::new(oa, d / dist);
            assert!(!accel.occluded(&ray, dist * (1.0 - 1e-4)), "scale {scale}: falsely occluded");
            // And the unshortened ray beyond b does hit the upper quad (it is not tunnelled past).
            let through = Ray::new(oa, (b - oa).normalize());
            let h = accel.intersect(&through, f32::INFINITY);
            assert!(h.is_some_and(|h| h.prim >= 2), "scale {scale}: ray towards b missed the upper quad");
        }
    }
}

/// The AVX2 node test (used where the CPU has AVX2 and FMA), with leaves tested two blocks at a
/// time (the default) or one, and the SSE2 one (the x86-64 baseline, and what every other CPU
/// runs) give identical answers: same t, triangle and
/// barycentrics bit for bit, and the same shadow-ray answers, on camera rays (a quarter aimed at
/// shared edges), random rays, short segments and axis-parallel rays, over a displaced sphere and a triangle soup.
#[test]
fn avx2_and_sse2_node_tests_agree() {
    use crate::bench::{displaced_sphere, RayBatch, SphereStyle};
    let mut soup = grid(8, 1.0, Vec3::ZERO);
    let mut rng = Pcg32::new(9, 0);
    for _ in 0..2000 {
        let c = rand3(&mut rng) * 1.2 - 0.1;
        let p: Vec<Vec3> = (0..3).map(|_| c + (rand3(&mut rng) - 0.5) * 0.2).collect();
        soup.append(&p, &[], &[], &[[0, 1, 2]], 0);
    }
    for mesh in [displaced_sphere(120, 120, SphereStyle::CrossCheck), soup] {
        let mut accel = Accel::build(&mesh);
        let mut batch = RayBatch::camera(&mesh, 20_000, 3);
        let rnd = RayBatch::random_in_bounds(&mesh, 20_000, 4);
        for i in 0..rnd.len() {
            // Every third random ray a short segment, so tmax culls.
            let tmax = if i % 3 == 0 { rnd.tmax[i].min(rng.next_f32()) } else { rnd.tmax[i] };
            batch.push(rnd.origins[i], rnd.dirs[i], tmax);
        }
        // Axis-parallel rays, the other components +0.0 or −0.0: the AVX2 test picks each axis's
        // entry plane by the sign of the clamped reciprocal, the SSE2 one by a min.
        for i in 0..3000 {
            let z = |bit: usize| if i >> bit & 1 == 0 { 0.0 } else { -0.0 };
            let mut d = Vec3::new(z(2), z(3), z(4));
            d[i % 3] = if i >> 5 & 1 == 0 { 1.0 } else { -1.0 };
            batch.push(rnd.origins[i], d, rnd.tmax[i]);
        }
        let run = |accel: &Accel| {
            (0..batch.len())
                .map(|i| {
                    let (ray, tmax) = (batch.ray(i), batch.tmax[i]);
                    let h = accel.intersect(&ray, tmax).map(|h| (h.t.to_bits(), h.prim, h.bary.x.to_bits(), h.bary.y.to_bits()));
                    (h, accel.occluded(&ray, tmax))
                })
                .collect::<Vec<_>>()
        };
        accel.set_avx2(false);
        let sse2 = run(&accel);
        let hits = sse2.iter().filter(|h| h.0.is_some()).count();
        assert!(hits > batch.len() / 4, "only {hits} hits");
        if !accel.set_avx2(true) {
            eprintln!("this CPU has no AVX2 and FMA: only the SSE2 node test ran");
            return;
        }
        // With AVX-512 where the CPU has it (the same query, more registers), and without.
        let with_512 = accel.set_avx512(true);
        for avx512 in if with_512 { vec![true, false] } else { vec![false] } {
            accel.set_avx512(avx512);
            for tri8 in [true, false] {
                accel.set_tri8(tri8);
                let avx2 = run(&accel);
                for (i, (a, b)) in sse2.iter().zip(&avx2).enumerate() {
                    assert_eq!(a, b, "avx512 {avx512}, tri8 {tri8}, ray {i}: {:?} tmax {}", batch.ray(i), batch.tmax[i]);
                }
            }
        }
    }
}

/// `offset_ray_origin` as it was before it became branch-free (with the wrapping integer
/// arithmetic of a release build spelled out), the reference the new one must match bit for bit.
fn offset_ray_origin_reference(p: Vec3, ng: Vec3, dir: Vec3, extent: f32) -> Vec3 {
    if !p.is_finite() || !ng.is_finite() {
        return p;
    }
    let n = if ng.dot(dir) < 0.0 { -ng } else { ng };
    let mag = p.abs().max_element().max(extent).max(MIN_MAGNITUDE);
    let mut out = p;
    for i in 0..3 {
        let pi = p[i];
        out[i] = if pi.abs() < mag * ORIGIN_FRACTION {
            pi + FLOAT_SCALE * mag * n[i]
        } else {
            let steps = (INT_SCALE * n[i]) as i32;
            let bits = pi.to_bits() as i32;
            let stepped = f32::from_bits(if pi < 0.0 { bits.wrapping_sub(steps) } else { bits.wrapping_add(steps) } as u32);
            if stepped.is_finite() {
                stepped
            } else {
                pi
            }
        };
    }
    out
}

#[test]
fn offset_origin_is_bit_identical_to_the_branching_version() {
    let specials = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        1e-45,
        -1e-45,
        1e-8,
        3e-10,
        1.0 / 32.0,
        -1.0 / 32.0,
        0.5,
        1e4,
        -1e4,
        f32::MAX,
        f32::MIN,
        f32::MAX / 2.0,
        1e30,
        -1e30,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        -f32::NAN,
        f32::from_bits(0x7f7f_ff00),
        f32::from_bits(0xff7f_ffff),
    ];
    let mut rng = Pcg32::new(14, 2);
    // Random values over the whole f32 range (any bit pattern, NaNs and infinities included)
    // and over scene-like ranges, with unit and non-unit normals.
    let value = |rng: &mut Pcg32| match rng.below(4) {
        0 => f32::from_bits(rng.next_u32()),
        1 => specials[rng.below(specials.len() as u32) as usize],
        2 => (rng.next_f32() - 0.5) * 2f32.powi(rng.below(40) as i32 - 20),
        _ => (rng.next_f32() * 2.0 - 1.0) * 10.0,
    };
    let mut checked = 0;
    for _ in 0..2_000_000 {
        let p = Vec3::new(value(&mut rng), value(&mut rng), value(&mut rng));
        let ng = if rng.below(2) == 0 {
            Vec3::new(value(&mut rng), value(&mut rng), value(&mut rng))
        } else {
            (rand3(&mut rng) - 0.5).normalize_or_zero()
        };
        let dir = Vec3::new(value(&mut rng), value(&mut rng), value(&mut rng));
        let extent = if rng.below(2) == 0 { value(&mut rng).abs() } else { 0.0 };
        let (new, old) = (offset_ray_origin(p, ng, dir, extent), offset_ray_origin_reference(p, ng, dir, extent));
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        assert_eq!(bits(new), bits(old), "p {p:?} ng {ng:?} dir {dir:?}");
        checked += (p.is_finite() && ng.is_finite()) as u32;
    }
    // The non-finite guard must not have hidden the offset arithmetic itself.
    assert!(checked > 100_000, "only {checked} finite inputs");
}

/// A direction component of exactly −0.0 is as parallel to its axis as +0.0: the ray must find
/// what the same ray with +0.0 finds. (Box planes were ordered by `d < 0`, false for −0.0,
/// while the clamped reciprocal kept the sign: −1e20 with the planes of a positive direction,
/// so every box the origin lay within on that axis was culled.)
#[test]
fn negative_zero_direction_components_hit_like_positive_zero() {
    let mesh = grid(8, 2.0, Vec3::new(-1.0, -1.0, 0.0));
    let accels = [true, false].map(|isa| {
        let mut a = Accel::build(&mesh);
        a.set_avx2(isa);
        (isa, a)
    });
    let mut rng = Pcg32::new(17, 0);
    let mut hits = 0;
    for _ in 0..2000 {
        let o = Vec3::new(rng.next_f32() * 1.4 - 0.7, rng.next_f32() * 1.4 - 0.7, 0.5 + rng.next_f32());
        let lateral = rng.next_f32() * 0.2 - 0.1;
        for axis in 0..2 {
            for (isa, a) in &accels {
                let mut pos = Vec3::new(lateral, lateral, -1.0);
                pos[axis] = 0.0;
                let mut neg = pos;
                neg[axis] = -0.0;
                let want = a.intersect(&Ray::new(o, pos), f32::INFINITY).map(|h| (h.t, h.prim));
                let got = a.intersect(&Ray::new(o, neg), f32::INFINITY).map(|h| (h.t, h.prim));
                assert!(want.is_some(), "the grid lies below every origin: {o} {pos}");
                assert_eq!(want, got, "origin {o}, direction {neg:?} (avx2 {isa})");
                assert!(a.occluded(&Ray::new(o, neg), f32::INFINITY));
                hits += 1;
            }
        }
    }
    assert_eq!(hits, 8000);
}

/// Rays spawned from points within 1e-3 of the world origin on a tilted triangle through it,
/// whose vertices lie at distance ~1: neither the BVH nor the packet query may find the triangle
/// again. The hit point's error is relative to the vertices (~1e-7 here), so an offset relative
/// to |p| alone (~1e-11 for |p| ~ 1e-6) let the triangle be re-hit.
#[test]
fn offset_origin_near_the_world_origin_avoids_self_hits() {
    let (v0, v1, v2) = (Vec3::new(-1.0, -0.8, 0.3), Vec3::new(1.1, -0.5, -0.4), Vec3::new(0.2, 0.9, 0.5));
    let q = v0 * 0.4 + v1 * 0.3 + v2 * 0.3;
    let (p0, p1, p2) = (v0 - q, v1 - q, v2 - q);
    let mesh = mesh_from(vec![p0, p1, p2], vec![[0, 1, 2]]);
    let accel = Accel::build(&mesh);
    let ng = mesh.geometric_normal(0);
    let extent = p0.abs().max(p1.abs()).max(p2.abs()).max_element();
    let mut rng = Pcg32::new(77, 1);
    let (mut rays, mut hits) = (Vec::new(), 0);
    for _ in 0..40_000 {
        let eps = 10f32.powi(-(3 + rng.below(5) as i32));
        let b1 = 0.3 + (rng.next_f32() - 0.5) * eps;
        let b2 = 0.3 + (rng.next_f32() - 0.5) * eps;
        let p = p0 * (1.0 - b1 - b2) + p1 * b1 + p2 * b2;
        let mut d = (rand3(&mut rng) * 2.0 - 1.0).normalize();
        if rng.next_f32() < 0.5 {
            d = (d - ng * d.dot(ng) * 0.99).normalize();
        }
        if d.dot(ng).abs() < 1e-6 {
            continue;
        }
        let ray = Ray::new(offset_ray_origin(p, ng, d, extent), d);
        hits += accel.intersect(&ray, f32::INFINITY).is_some() as usize;
        rays.push(ray);
    }
    // The packet query, where this CPU has one (AVX-512).
    let mut out = [None; super::packet::WIDTH];
    for chunk in rays.chunks(super::packet::WIDTH) {
        accel.intersect_live(chunk, &[true; super::packet::WIDTH][..chunk.len()], f32::INFINITY, &mut out[..chunk.len()]);
        hits += out[..chunk.len()].iter().filter(|h| h.is_some()).count();
    }
    assert!(rays.len() > 30_000);
    assert_eq!(hits, 0, "self-hits near the world origin");
}

/// Rays that start a hair's breadth from a flat box and run along it, far from the world
/// origin, to targets near the box's edges: the slab distance to the flat side is tiny next to
/// the origin's magnitude, so a node test that rounds the origin's term on its own (as a fused
/// p·inv − fl(o·inv) would, docs/journal/performance.md) culls some of them unless the boxes
/// are widened for it. Every ray must hit what the brute-force test hits, with the same t, on
/// the AVX2 path (where the CPU has it) and the SSE2 one, rays from a million units away too.
#[test]
fn rays_along_a_flat_box_far_from_the_world_origin_hit() {
    let mut rng = Pcg32::new(17, 0);
    // A unit quad in the plane x = 100 (its box is flat in x), y and z in [100, 101].
    let c = Vec3::new(100.0, 100.0, 100.0);
    let positions = vec![c, c + Vec3::Y, c + Vec3::Y + Vec3::Z, c + Vec3::Z];
    let mesh = mesh_from(positions, vec![[0, 1, 2], [0, 2, 3]]);
    let mut accel = Accel::build(&mesh);
    let mut rays = Vec::new();
    // A coordinate on the quad within 1e-3 of an edge, where the y and z slabs bound the hit.
    let edge = |rng: &mut Pcg32| if rng.next_f32() < 0.5 { rng.next_f32() * 1e-3 } else { 1.0 - rng.next_f32() * 1e-3 };
    for i in 0..20_000 {
        let (ty, tz) = match i % 3 {
            0 => (edge(&mut rng), rng.next_f32()),
            1 => (rng.next_f32(), edge(&mut rng)),
            _ => (edge(&mut rng), edge(&mut rng)),
        };
        let target = c + Vec3::new(0.0, ty, tz);
        // An origin 1e-7 to 1e-2 off the plane, on either side, 0.5 to 2 away along it.
        let eps = 10f32.powf(-7.0 + 5.0 * rng.next_f32()) * if rng.next_f32() < 0.5 { 1.0 } else { -1.0 };
        let along = (rand3(&mut rng) * 2.0 - 1.0) * Vec3::new(0.0, 1.0, 1.0);
        let along = along.normalize_or(Vec3::Y) * (0.5 + 1.5 * rng.next_f32());
        let o = target - along + Vec3::new(eps, 0.0, 0.0);
        rays.push((o, target - o));
    }
    // From far away.
    for _ in 0..2_000 {
        let target = c + Vec3::new(0.0, rng.next_f32(), rng.next_f32());
        let o = target + (rand3(&mut rng) * 2.0 - 1.0).normalize_or(Vec3::X) * 1e6;
        rays.push((o, target - o));
    }
    let run = |accel: &Accel| {
        let mut hits = 0;
        for &(o, d) in &rays {
            let ray = Ray::new(o, d);
            let want = brute_force(&mesh, &ray, f32::INFINITY);
            let got = accel.intersect(&ray, f32::INFINITY);
            assert_eq!(want.map(|w| w.0), got.map(|h| h.t), "ray {ray:?}");
            assert_eq!(accel.occluded(&ray, f32::INFINITY), got.is_some(), "occluded disagrees for {ray:?}");
            hits += got.is_some() as usize;
        }
        hits
    };
    let hits = run(&accel);
    // Every ray is aimed at the quad, but an origin less than half an ulp of 100 (3.8e-6) off
    // the plane rounds onto it, and a ray in the quad's plane is missed by both tests (about
    // 6,300 of the 22,000).
    assert!(hits > rays.len() / 3, "only {hits} of {} rays hit", rays.len());
    accel.set_avx2(false);
    assert_eq!(run(&accel), hits);
}

/// Triangles so large that a ray's edge functions overflow (to infinity, or to NaN as the
/// difference of two infinite products) and their sum `det` with them: the vector tests, which
/// decide most misses by the edge functions' sign bits and do not test `det` itself, must still
/// hit exactly what the scalar test hits, on every path.
#[test]
fn triangles_whose_edge_functions_overflow_hit_what_brute_force_hits() {
    let mut rng = Pcg32::new(23, 0);
    let mut mesh = mesh_from(Vec::new(), Vec::new());
    // Products of sheared coordinates reach 1e34 to 1e40 (f32 overflows at 3.4e38).
    let scales = [1e17f32, 1e18, 1e19, 4e19, 1e20];
    for i in 0..400 {
        let s = scales[i % scales.len()];
        let c = (rand3(&mut rng) * 2.0 - 1.0) * s;
        let p: Vec<Vec3> = (0..3).map(|_| c + (rand3(&mut rng) - 0.5) * s).collect();
        mesh.append(&p, &[], &[], &[[0, 1, 2]], 0);
    }
    let mut accel = Accel::build(&mesh);
    let mut rays = Vec::new();
    for i in 0..20_000 {
        // Aimed at a point inside a random triangle of the ray's scale, from up to that scale away.
        let k = rng.next_u32() as usize % mesh.triangles.len();
        let [p0, p1, p2] = mesh.triangle(k);
        let (b1, b2) = (rng.next_f32(), rng.next_f32());
        let (b1, b2) = if b1 + b2 > 1.0 { (1.0 - b1, 1.0 - b2) } else { (b1, b2) };
        let target = p0 + (p1 - p0) * b1 + (p2 - p0) * b2;
        let o = target + (rand3(&mut rng) * 2.0 - 1.0) * scales[i % scales.len()];
        rays.push((o, target - o));
    }
    let run = |accel: &Accel| {
        rays.iter()
            .map(|&(o, d)| {
                let ray = Ray::new(o, d);
                let got = accel.intersect(&ray, f32::INFINITY);
                assert_eq!(brute_force(&mesh, &ray, f32::INFINITY).map(|w| w.0.to_bits()), got.map(|h| h.t.to_bits()), "ray {ray:?}");
                assert_eq!(accel.occluded(&ray, f32::INFINITY), got.is_some(), "occluded disagrees for {ray:?}");
                got.map(|h| (h.t.to_bits(), h.prim))
            })
            .collect::<Vec<_>>()
    };
    accel.set_avx2(false);
    let sse2 = run(&accel);
    let hits = sse2.iter().filter(|h| h.is_some()).count();
    // Most rays are aimed at a triangle; those of the largest scales miss where it overflows.
    assert!(hits > rays.len() / 4, "only {hits} of {} rays hit", rays.len());
    if accel.set_avx2(true) {
        for tri8 in [true, false] {
            accel.set_tri8(tri8);
            assert_eq!(run(&accel), sse2, "tri8 {tri8}");
        }
    }
}
