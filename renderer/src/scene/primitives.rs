//! Built-in shapes as triangle meshes with unit normals and texture coordinates, plus the
//! triangle soup (`TriMesh`) every loader produces before it is appended to the scene mesh.
//!
//! Canonical shapes (place them with a shape's transform):
//! - `quad`: the square [-1,1]² in the XY plane, facing +Z (2 triangles, area 4);
//! - `cube`: [-1,1]³ with outward faces (12 triangles, area 24);
//! - `sphere`: radius r at the origin, a UV sphere with `segments` slices in φ and
//!   `segments / 2` stacks in θ (poles on ±Y);
//! - `disk`: radius r in the XY plane facing +Z, a fan of `segments` triangles.
//!
//! Texture coordinates follow `Texture`'s convention (v = 0 on the top row).

use glam::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::{PI, TAU};

/// An indexed triangle mesh with optional per-vertex normals and uvs (each empty or the same
/// length as `positions`).
#[derive(Clone, Debug, Default)]
pub struct TriMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// The mesh under an affine transform. Normals go through the inverse transpose; a mirroring
    /// transform (negative determinant) also reverses the winding, so the winding normal (which
    /// decides the emitting side of lights) keeps pointing the same way relative to the surface.
    pub fn transformed(&self, m: &Mat4) -> TriMesh {
        let positions = self.positions.iter().map(|&p| m.transform_point3(p)).collect();
        let linear = Mat3::from_mat4(*m);
        let det = linear.determinant();
        let normals = if self.normals.is_empty() || det == 0.0 || !det.is_finite() {
            // A singular transform has no normal transform; the geometric normal will do.
            Vec::new()
        } else {
            let nm = linear.inverse().transpose();
            self.normals.iter().map(|&n| nm.mul_vec3(n).normalize_or_zero()).collect()
        };
        let triangles = if det < 0.0 { self.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect() } else { self.triangles.clone() };
        TriMesh { positions, normals, uvs: self.uvs.clone(), triangles }
    }

    /// Total area of the triangles (degenerate ones contribute 0).
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|&[a, b, c]| {
                let (p0, p1, p2) = (self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]);
                0.5 * (p1 - p0).as_dvec3().cross((p2 - p0).as_dvec3()).length()
            })
            .sum()
    }
}

/// [-1,1]² in the XY plane facing +Z.
pub fn quad() -> TriMesh {
    let positions = vec![Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.0)];
    let uvs = vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)];
    TriMesh { positions, normals: vec![Vec3::Z; 4], uvs, triangles: vec![[0, 1, 2], [0, 2, 3]] }
}

/// [-1,1]³, each face its own four vertices so normals stay flat.
pub fn cube() -> TriMesh {
    let face = quad();
    let mut out = TriMesh::default();
    // Rotations taking +Z to each face normal; each face is the quad pushed out by one unit.
    let rotations = [
        Mat3::IDENTITY,
        Mat3::from_rotation_y(PI),
        Mat3::from_rotation_y(PI / 2.0),
        Mat3::from_rotation_y(-PI / 2.0),
        Mat3::from_rotation_x(-PI / 2.0),
        Mat3::from_rotation_x(PI / 2.0),
    ];
    for r in rotations {
        let base = out.positions.len() as u32;
        let n = r * Vec3::Z;
        out.positions.extend(face.positions.iter().map(|&p| r * p + n));
        out.normals.extend(std::iter::repeat_n(n, 4));
        out.uvs.extend_from_slice(&face.uvs);
        out.triangles.extend(face.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }
    out
}

/// UV sphere of radius `radius`: `segments` (≥ 3) slices around +Y and `max(segments/2, 2)`
/// stacks. Its vertices lie on the sphere, so its area is slightly below 4πr². A flat face of
/// angular half-sides (a, b) projects onto the sphere with area magnified by 1 + (a² + b²)/2 to
/// leading order; with a = Δθ/2, b = Δφ·sinθ/2 and sin²θ averaging 2/3 over the sphere, the
/// relative deficit is (Δθ² + ⅔Δφ²)/8, Δθ = π/stacks, Δφ = 2π/segments: 0.20 % for 64 segments.
pub fn sphere(radius: f32, segments: u32) -> TriMesh {
    let slices = segments.max(3);
    let stacks = (slices / 2).max(2);
    let mut m = TriMesh::default();
    for i in 0..=stacks {
        let v = i as f32 / stacks as f32;
        let theta = v * PI;
        for j in 0..=slices {
            let u = j as f32 / slices as f32;
            // φ runs from +X towards −Z so a texture reads left to right seen from outside.
            let phi = u * TAU;
            let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), -theta.sin() * phi.sin());
            // Exact poles: keep the top and bottom rows collapsed onto one point.
            let n = if i == 0 {
                Vec3::Y
            } else if i == stacks {
                -Vec3::Y
            } else {
                n
            };
            m.positions.push(n * radius);
            m.normals.push(n);
            m.uvs.push(Vec2::new(u, v));
        }
    }
    let row = slices + 1;
    for i in 0..stacks {
        for j in 0..slices {
            let a = i * row + j;
            let b = a + row;
            // Skip the zero-area triangles at the poles.
            if i != 0 {
                m.triangles.push([a, b, a + 1]);
            }
            if i != stacks - 1 {
                m.triangles.push([a + 1, b, b + 1]);
            }
        }
    }
    m
}

/// Disk of radius `radius` in the XY plane facing +Z, a fan of `segments` (≥ 3) triangles around
/// a centre vertex. Area = (n/2)·sin(2π/n)·r², below πr² by a relative (2π/n)²/6.
pub fn disk(radius: f32, segments: u32) -> TriMesh {
    let n = segments.max(3);
    let mut m = TriMesh::default();
    m.positions.push(Vec3::ZERO);
    m.normals.push(Vec3::Z);
    m.uvs.push(Vec2::new(0.5, 0.5));
    for j in 0..n {
        let phi = j as f32 / n as f32 * TAU;
        let (s, c) = phi.sin_cos();
        m.positions.push(Vec3::new(c * radius, s * radius, 0.0));
        m.normals.push(Vec3::Z);
        m.uvs.push(Vec2::new(0.5 + 0.5 * c, 0.5 - 0.5 * s));
    }
    for j in 0..n {
        m.triangles.push([0, 1 + j, 1 + (j + 1) % n]);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn winding_normal(m: &TriMesh, t: [u32; 3]) -> Vec3 {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        (b - a).cross(c - a).normalize_or_zero()
    }

    /// The winding normal must agree with the vertex normals (emission side and geometric normal).
    fn check_winding(m: &TriMesh) {
        for &t in &m.triangles {
            let ng = winding_normal(m, t);
            let ns = t.iter().map(|&i| m.normals[i as usize]).sum::<Vec3>();
            assert!(ng.dot(ns) > 0.0, "triangle {t:?} winds against its normals");
        }
    }

    #[test]
    fn windings_agree_with_normals() {
        check_winding(&quad());
        check_winding(&cube());
        check_winding(&sphere(1.0, 16));
        check_winding(&disk(1.0, 12));
    }

    #[test]
    fn mirrored_transform_keeps_winding_consistent() {
        let m = cube().transformed(&Mat4::from_scale(Vec3::new(-1.0, 2.0, 1.0)));
        check_winding(&m);
    }

    #[test]
    fn sphere_has_no_degenerate_triangles() {
        let s = sphere(1.0, 8);
        for &t in &s.triangles {
            assert!(winding_normal(&s, t) != Vec3::ZERO, "{t:?}");
        }
    }
}
