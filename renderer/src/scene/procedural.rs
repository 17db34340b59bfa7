//! Procedural meshes for the scene library (docs/scene-format.md, "Procedural shapes"):
//!
//! - `lathe`: a surface of revolution about +Y from an (r, y) profile (vases, glasses, bowls,
//!   rods); profile corners sharper than [`CREASE_DEG`] keep separate normals on each side, so a
//!   cylinder's rim stays crisp while a smooth vase stays smooth;
//! - `heightfield`: a displaced grid over [-1,1]² in the XZ plane, facing +Y, with a seeded
//!   fractal value noise (terrain, rumpled cloth, rough stone);
//! - `grid`: an nx × ny × nz array of cubes or spheres (slats, bars, stacks, shelves of balls).
//!
//! Every generator validates its parameters and returns a message naming the bad one; the
//! caller adds the file and the shape index.

use super::primitives::{cube, sphere, TriMesh};
use glam::{Mat4, Vec2, Vec3};
use std::f32::consts::TAU;

/// Profile turns sharper than this (degrees) get split normals.
pub const CREASE_DEG: f32 = 30.0;
/// Largest grid of a heightfield per side and largest copy count of a `grid` (keeps a typo from
/// asking for billions of triangles).
pub const MAX_HEIGHTFIELD_SIDE: u32 = 2048;
pub const MAX_GRID_COPIES: u32 = 100_000;
/// Largest triangle count of one lathe or grid, about that of the finest sphere (4096 segments):
/// the copy and segment limits alone still allow a grid of 10⁵ fine spheres (10¹² triangles) or
/// a lathe of a long profile at 4096 segments.
pub const MAX_SHAPE_TRIANGLES: u64 = 1 << 24;

/// A surface of revolution of `profile` ((r, y) points, r ≥ 0) about +Y with `segments` slices.
/// Traverse the profile so that the surface lies on your right walking up/outward: the normal of
/// a profile segment (dr, dy) is (dy, −dr) in the (r, y) plane, i.e. points away from the axis
/// for a segment going up. Points on the axis (r = 0) close the surface there without
/// degenerate triangles. `v` runs along the profile's arc length, `u` around the axis.
pub fn lathe(profile: &[[f32; 2]], segments: u32) -> Result<TriMesh, String> {
    if profile.len() < 2 {
        return Err(format!("needs at least 2 points, has {}", profile.len()));
    }
    if !(3..=4096).contains(&segments) {
        return Err(format!("segments {segments} is outside 3..=4096"));
    }
    for (i, p) in profile.iter().enumerate() {
        if !p[0].is_finite() || !p[1].is_finite() {
            return Err(format!("point {i} {p:?} is not finite"));
        }
        if p[0] < 0.0 {
            return Err(format!("point {i} has a negative radius {}", p[0]));
        }
    }
    let triangles = (profile.len() as u64 - 1) * segments as u64 * 2;
    if triangles > MAX_SHAPE_TRIANGLES {
        return Err(format!("{} points at {segments} segments make {triangles} triangles (at most {MAX_SHAPE_TRIANGLES})", profile.len()));
    }
    let pts: Vec<Vec2> = profile.iter().map(|p| Vec2::new(p[0], p[1])).collect();
    let mut seg_normals = Vec::new();
    let mut lengths = vec![0.0f32];
    for (i, w) in pts.windows(2).enumerate() {
        let d = w[1] - w[0];
        if d.length() <= 1e-7 * (1.0 + w[0].length()) {
            return Err(format!("points {i} and {} coincide (a zero-length segment)", i + 1));
        }
        if w[0].x == 0.0 && w[1].x == 0.0 {
            return Err(format!("segment {i}..{} lies on the axis (it would have no area)", i + 1));
        }
        seg_normals.push(Vec2::new(d.y, -d.x).normalize());
        lengths.push(lengths[i] + d.length());
    }
    let total = *lengths.last().unwrap();
    let cos_crease = CREASE_DEG.to_radians().cos();
    let mut m = TriMesh::default();
    // Two rings per segment (its start and end), so each segment can carry its own normals at a
    // crease; smooth joints average the two segment normals.
    for (s, w) in pts.windows(2).enumerate() {
        let mut rows = [0u32; 2];
        for (e, (pi, p)) in [(s, w[0]), (s + 1, w[1])].into_iter().enumerate() {
            let other = if e == 0 { s.checked_sub(1) } else { (s + 1 < seg_normals.len()).then_some(s + 1) };
            let own = seg_normals[s];
            let n2 = match other {
                Some(o) if seg_normals[o].dot(own) >= cos_crease => (seg_normals[o] + own).normalize_or_zero(),
                _ => own,
            };
            let n2 = if n2 == Vec2::ZERO { own } else { n2 };
            rows[e] = m.positions.len() as u32;
            let v = lengths[pi] / total;
            for j in 0..=segments {
                let u = j as f32 / segments as f32;
                // φ from +X towards −Z, as the built-in sphere, so textures read left to right.
                let (sn, cs) = (u * TAU).sin_cos();
                let radial = Vec3::new(cs, 0.0, -sn);
                let pos = if j == segments { Vec3::new(p.x, p.y, 0.0) } else { radial * p.x + Vec3::Y * p.y };
                let pos = if p.x == 0.0 { Vec3::new(0.0, p.y, 0.0) } else { pos };
                m.positions.push(pos);
                m.normals.push((radial * n2.x + Vec3::Y * n2.y).normalize());
                m.uvs.push(Vec2::new(u, v));
            }
        }
        let (a0, b0) = (rows[0], rows[1]);
        for j in 0..segments {
            let (a, a1, b, b1) = (a0 + j, a0 + j + 1, b0 + j, b0 + j + 1);
            // Quad a, a1 (lower ring, increasing φ) and b, b1 (upper ring). φ increases towards
            // −Z, i.e. clockwise seen from +Y, so (a, a1, b) winds with the normal pointing away
            // from the axis for a rising profile.
            if w[0].x != 0.0 {
                m.triangles.push([a, a1, b]);
            }
            if w[1].x != 0.0 {
                m.triangles.push([a1, b1, b]);
            }
        }
    }
    Ok(m)
}

/// Parameters of a heightfield.
#[derive(Clone, Debug)]
pub struct HeightfieldParams {
    /// Quads along X and Z.
    pub resolution: [u32; 2],
    /// Largest displacement along +Y (the noise lies in [−1, 1]).
    pub amplitude: f32,
    /// Noise cells across the [-1,1] square for the first octave.
    pub frequency: f32,
    pub octaves: u32,
    pub seed: u32,
}

fn hash(x: i32, z: i32, seed: u32) -> f32 {
    let mut h = (x as u32).wrapping_mul(0x8da6b343) ^ (z as u32).wrapping_mul(0xd8163841) ^ seed.wrapping_mul(0xcb1ab31f);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2c1b3c6d);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297a2d39);
    h ^= h >> 15;
    (h >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
}

/// Smoothly interpolated lattice noise in [−1, 1].
fn value_noise(x: f32, z: f32, seed: u32) -> f32 {
    let (xi, zi) = (x.floor(), z.floor());
    let (fx, fz) = (x - xi, z - zi);
    let (sx, sz) = (fx * fx * (3.0 - 2.0 * fx), fz * fz * (3.0 - 2.0 * fz));
    let (xi, zi) = (xi as i32, zi as i32);
    let a = hash(xi, zi, seed) + (hash(xi + 1, zi, seed) - hash(xi, zi, seed)) * sx;
    let b = hash(xi, zi + 1, seed) + (hash(xi + 1, zi + 1, seed) - hash(xi, zi + 1, seed)) * sx;
    a + (b - a) * sz
}

/// Fractal noise normalised to [−1, 1] (each octave doubles the frequency, halves the amplitude).
pub fn fbm(x: f32, z: f32, octaves: u32, seed: u32) -> f32 {
    let (mut sum, mut amp, mut norm, mut f) = (0.0, 1.0, 0.0, 1.0);
    for o in 0..octaves {
        sum += amp * value_noise(x * f, z * f, seed.wrapping_add(o.wrapping_mul(7919)));
        norm += amp;
        amp *= 0.5;
        f *= 2.0;
    }
    sum / norm
}

/// A displaced grid over [-1,1]² in XZ facing +Y; uv (0, 0) at (−1, ·, −1).
pub fn heightfield(p: &HeightfieldParams) -> Result<TriMesh, String> {
    let [nx, nz] = p.resolution;
    if !(1..=MAX_HEIGHTFIELD_SIDE).contains(&nx) || !(1..=MAX_HEIGHTFIELD_SIDE).contains(&nz) {
        return Err(format!("resolution [{nx}, {nz}] is outside 1..={MAX_HEIGHTFIELD_SIDE} per side"));
    }
    if !p.amplitude.is_finite() || p.amplitude < 0.0 {
        return Err(format!("amplitude {} must be finite and ≥ 0", p.amplitude));
    }
    if !p.frequency.is_finite() || p.frequency <= 0.0 || p.frequency > 1e4 {
        return Err(format!("frequency {} must be in (0, 10000]", p.frequency));
    }
    if !(1..=12).contains(&p.octaves) {
        return Err(format!("octaves {} is outside 1..=12", p.octaves));
    }
    let mut m = TriMesh::default();
    for j in 0..=nz {
        for i in 0..=nx {
            let (u, v) = (i as f32 / nx as f32, j as f32 / nz as f32);
            let (x, z) = (u * 2.0 - 1.0, v * 2.0 - 1.0);
            let y = p.amplitude * fbm(u * p.frequency, v * p.frequency, p.octaves, p.seed);
            m.positions.push(Vec3::new(x, y, z));
            m.uvs.push(Vec2::new(u, v));
        }
    }
    let row = nx + 1;
    for j in 0..nz {
        for i in 0..nx {
            let a = j * row + i;
            // Seen from +Y with +X right, +Z points towards the viewer: (a, a+row, a+1) winds
            // counter-clockwise, normal +Y.
            m.triangles.push([a, a + row, a + 1]);
            m.triangles.push([a + 1, a + row, a + row + 1]);
        }
    }
    m.normals = vertex_normals(&m);
    Ok(m)
}

/// Area-weighted vertex normals from the winding (a vertex no triangle touches gets +Y).
pub fn vertex_normals(m: &TriMesh) -> Vec<Vec3> {
    let mut n = vec![Vec3::ZERO; m.positions.len()];
    for t in &m.triangles {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        let w = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += w;
        }
    }
    n.into_iter().map(|v| v.try_normalize().unwrap_or(Vec3::Y)).collect()
}

/// The element a `grid` repeats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridElement {
    Cube,
    Sphere,
}

/// `count` copies of `element` (the unit cube [-1,1]³ or unit sphere, scaled by
/// `element_scale`) at `spacing` apart, centred on the origin.
pub fn grid(element: GridElement, count: [u32; 3], spacing: Vec3, element_scale: Vec3, segments: u32) -> Result<TriMesh, String> {
    if count.contains(&0) {
        return Err(format!("count {count:?} has a zero entry"));
    }
    let copies = count.iter().map(|&c| c as u64).product::<u64>();
    if copies > MAX_GRID_COPIES as u64 {
        return Err(format!("count {count:?} makes {copies} copies (at most {MAX_GRID_COPIES})"));
    }
    if !spacing.is_finite() {
        return Err(format!("spacing {spacing} is not finite"));
    }
    if !element_scale.is_finite() || element_scale.min_element() <= 0.0 {
        return Err(format!("element_scale {element_scale} must be positive and finite"));
    }
    let base = match element {
        GridElement::Cube => cube(),
        GridElement::Sphere => sphere(1.0, segments),
    }
    .transformed(&Mat4::from_scale(element_scale));
    let triangles = copies * base.triangles.len() as u64;
    if triangles > MAX_SHAPE_TRIANGLES {
        return Err(format!(
            "count {count:?} of {} triangles each makes {triangles} triangles (at most {MAX_SHAPE_TRIANGLES})",
            base.triangles.len()
        ));
    }
    let mut out = TriMesh::default();
    let c = Vec3::new(count[0] as f32 - 1.0, count[1] as f32 - 1.0, count[2] as f32 - 1.0) * 0.5;
    for k in 0..count[2] {
        for j in 0..count[1] {
            for i in 0..count[0] {
                let off = (Vec3::new(i as f32, j as f32, k as f32) - c) * spacing;
                let first = out.positions.len() as u32;
                out.positions.extend(base.positions.iter().map(|&p| p + off));
                out.normals.extend_from_slice(&base.normals);
                out.uvs.extend_from_slice(&base.uvs);
                out.triangles.extend(base.triangles.iter().map(|t| t.map(|v| v + first)));
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// Welds vertices by position and counts directed edges: a closed, consistently wound
    /// surface has every edge exactly once in each direction.
    fn is_watertight(m: &TriMesh) -> Result<(), String> {
        let key = |p: Vec3| ((p.x * 1e5).round() as i64, (p.y * 1e5).round() as i64, (p.z * 1e5).round() as i64);
        type Vertex = (i64, i64, i64);
        let mut edges: HashMap<(Vertex, Vertex), i32> = HashMap::new();
        for t in &m.triangles {
            for e in 0..3 {
                let (a, b) = (key(m.positions[t[e] as usize]), key(m.positions[t[(e + 1) % 3] as usize]));
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            if n != 1 || edges.get(&(b, a)).copied() != Some(1) {
                return Err(format!("edge {a:?}->{b:?} used {n} times, reverse {:?}", edges.get(&(b, a))));
            }
        }
        Ok(())
    }

    fn winding_normal(m: &TriMesh, t: [u32; 3]) -> Vec3 {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        (b - a).cross(c - a)
    }

    /// No zero-area triangle, and every winding normal agrees with its vertex normals.
    fn check_triangles(m: &TriMesh) {
        assert!(!m.triangles.is_empty());
        assert_eq!(m.normals.len(), m.positions.len());
        for &t in &m.triangles {
            let ng = winding_normal(m, t);
            assert!(ng.length() > 1e-9, "degenerate triangle {t:?}");
            for &i in &t {
                let n = m.normals[i as usize];
                assert!((n.length() - 1.0).abs() < 1e-4, "normal {n} not unit");
                assert!(ng.normalize().dot(n) > 0.0, "triangle {t:?} winds against normal {n}");
            }
        }
    }

    fn closed_cylinder() -> TriMesh {
        lathe(&[[0.0, -1.0], [1.0, -1.0], [1.0, 1.0], [0.0, 1.0]], 32).unwrap()
    }

    #[test]
    fn lathe_closed_profile_is_watertight_and_outward() {
        let m = closed_cylinder();
        check_triangles(&m);
        is_watertight(&m).unwrap();
        // Outward: the normals at the side point away from the axis, the caps along ±Y
        // (the rim is a 90° crease, so nothing is averaged there).
        for (p, n) in m.positions.iter().zip(&m.normals) {
            if p.y.abs() < 0.999 {
                assert!((n.dot(Vec3::new(p.x, 0.0, p.z).normalize()) - 1.0).abs() < 1e-5);
            }
        }
        let tops = m.positions.iter().zip(&m.normals).filter(|(p, n)| p.y > 0.999 && n.y > 0.999).count();
        assert!(tops > 32, "cap normals were smoothed across the rim");
        // Area of a 32-gon prism: 2·(32/2)·sin(2π/32) caps + 32·2·sin(π/32)·2 side.
        let n = 32.0f64;
        let expected = 2.0 * (n / 2.0) * (std::f64::consts::TAU / n).sin() + n * 2.0 * (std::f64::consts::PI / n).sin() * 2.0;
        assert!((m.area() - expected).abs() < 1e-4 * expected, "{} vs {expected}", m.area());
    }

    #[test]
    fn lathe_smooth_profile_averages_normals() {
        // A sphere-like profile: consecutive segments turn by 18°, under the crease angle, so the
        // shared rings must carry the same (averaged) normal on both sides.
        let pts: Vec<[f32; 2]> = (0..=10)
            .map(|i| {
                let t = std::f32::consts::PI * (i as f32 / 10.0 - 0.5);
                [t.cos().max(0.0), t.sin()]
            })
            .collect();
        let mut pts = pts;
        pts[0][0] = 0.0;
        pts[10][0] = 0.0;
        let m = lathe(&pts, 24).unwrap();
        check_triangles(&m);
        is_watertight(&m).unwrap();
        for (p, n) in m.positions.iter().zip(&m.normals) {
            // On a sphere the normal is the position; averaging two chords' normals gets within
            // half the 18° turn of it.
            assert!(n.dot(p.normalize()) > (9.5f32).to_radians().cos(), "{p} {n}");
        }
    }

    #[test]
    fn lathe_rejects_bad_profiles() {
        assert!(lathe(&[[1.0, 0.0]], 8).unwrap_err().contains("at least 2"));
        assert!(lathe(&[[-1.0, 0.0], [1.0, 1.0]], 8).unwrap_err().contains("negative radius"));
        assert!(lathe(&[[1.0, 0.0], [1.0, 0.0]], 8).unwrap_err().contains("coincide"));
        assert!(lathe(&[[0.0, 0.0], [0.0, 1.0]], 8).unwrap_err().contains("on the axis"));
        assert!(lathe(&[[1.0, f32::NAN], [1.0, 1.0]], 8).unwrap_err().contains("finite"));
        assert!(lathe(&[[1.0, 0.0], [1.0, 1.0]], 2).unwrap_err().contains("segments"));
    }

    /// Each parameter within its own limit, together billions of triangles: refused before
    /// anything is allocated (without the limit, this grid of spheres would build 4·10⁸ triangles,
    /// tens of GB).
    #[test]
    fn shapes_beyond_the_triangle_limit_are_refused() {
        let e = grid(GridElement::Sphere, [100_000, 1, 1], Vec3::splat(2.5), Vec3::ONE, 64).unwrap_err();
        assert!(e.contains("count [100000, 1, 1]") && e.contains("at most 16777216"), "{e}");
        let profile: Vec<[f32; 2]> = (0..3000).map(|i| [1.0, i as f32]).collect();
        let e = lathe(&profile, 4096).unwrap_err();
        assert!(e.contains("3000 points") && e.contains("at most 16777216"), "{e}");
        // As many copies of a cube (1.2·10⁶ triangles) are fine.
        assert!(grid(GridElement::Cube, [100_000, 1, 1], Vec3::splat(2.5), Vec3::ONE, 64).is_ok());
    }

    #[test]
    fn heightfield_faces_up_and_stays_within_amplitude() {
        let p = HeightfieldParams { resolution: [16, 12], amplitude: 0.3, frequency: 3.0, octaves: 4, seed: 7 };
        let m = heightfield(&p).unwrap();
        check_triangles(&m);
        assert_eq!(m.triangles.len(), 2 * 16 * 12);
        let (lo, hi) = m.positions.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p.y), hi.max(p.y)));
        assert!(lo >= -0.3 - 1e-6 && hi <= 0.3 + 1e-6, "{lo}..{hi}");
        assert!(hi - lo > 0.05, "the surface is flat: {lo}..{hi}");
        // Another seed gives another surface.
        let other = heightfield(&HeightfieldParams { seed: 8, ..p.clone() }).unwrap();
        assert!(m.positions.iter().zip(&other.positions).any(|(a, b)| (a.y - b.y).abs() > 1e-3));
        assert!(heightfield(&HeightfieldParams { resolution: [0, 4], ..p.clone() }).is_err());
        assert!(heightfield(&HeightfieldParams { amplitude: f32::INFINITY, ..p.clone() }).is_err());
        assert!(heightfield(&HeightfieldParams { frequency: 0.0, ..p }).is_err());
    }

    #[test]
    fn grid_copies_are_closed_and_placed() {
        let m = grid(GridElement::Cube, [3, 1, 2], Vec3::new(3.0, 0.0, 4.0), Vec3::new(1.0, 0.1, 1.0), 16).unwrap();
        check_triangles(&m);
        assert_eq!(m.triangles.len(), 6 * 12);
        let (lo, hi) = m.positions.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        assert!((lo - Vec3::new(-4.0, -0.1, -3.0)).abs().max_element() < 1e-5, "{lo}");
        assert!((hi - Vec3::new(4.0, 0.1, 3.0)).abs().max_element() < 1e-5, "{hi}");
        let s = grid(GridElement::Sphere, [2, 2, 1], Vec3::splat(3.0), Vec3::ONE, 12).unwrap();
        check_triangles(&s);
        is_watertight(&s).unwrap();
        assert!(grid(GridElement::Cube, [0, 1, 1], Vec3::ONE, Vec3::ONE, 8).is_err());
        assert!(grid(GridElement::Cube, [1000, 1000, 1], Vec3::ONE, Vec3::ONE, 8).is_err());
        assert!(grid(GridElement::Cube, [1, 1, 1], Vec3::ONE, Vec3::new(1.0, 0.0, 1.0), 8).is_err());
    }

    /// The TOML wiring: good shapes load, and each bad parameter is an error naming the shape's
    /// field.
    #[test]
    fn toml_shapes_load_and_name_bad_fields() {
        let dir = std::env::temp_dir().join(format!("pixguide-procedural-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let head = "[camera]\nposition = [0, 1, 4]\ntarget = [0, 0, 0]\nresolution = [8, 8]\n[materials.m]\ntype = \"diffuse\"\nemission = [1, 1, 1]\n";
        let load = |name: &str, shape: &str| {
            let p = dir.join(name);
            std::fs::write(&p, format!("{head}[[shapes]]\nmaterial = \"m\"\n{shape}")).unwrap();
            crate::scene::toml_format::load(&p).map(|d| d.mesh.triangles.len()).map_err(|e| e.to_string())
        };
        assert_eq!(load("a.toml", "type = \"grid\"\ncount = [2, 3, 1]\n").unwrap(), 6 * 12);
        assert!(load("b.toml", "type = \"lathe\"\nprofile = [[0, 0], [1, 0], [0, 1]]\nsegments = 8\n").unwrap() == 16);
        assert!(load("c.toml", "type = \"heightfield\"\nresolution = [4, 4]\n").unwrap() == 32);
        let e = load("d.toml", "type = \"lathe\"\nprofile = [[1, 0]]\n").unwrap_err();
        assert!(e.contains("shapes[0].profile") && e.contains("at least 2"), "{e}");
        let e = load("e.toml", "type = \"grid\"\ncount = [1, 1, 1]\namplitude = 2\n").unwrap_err();
        assert!(e.contains("shapes[0].amplitude"), "{e}");
        let e = load("f.toml", "type = \"grid\"\ncount = [1, 1, 1]\nelement = \"cone\"\n").unwrap_err();
        assert!(e.contains("shapes[0].element") && e.contains("cone"), "{e}");
        let e = load("g.toml", "type = \"heightfield\"\nfrequency = -1\n").unwrap_err();
        assert!(e.contains("shapes[0]") && e.contains("frequency"), "{e}");
        let e = load("h.toml", "type = \"grid\"\n").unwrap_err();
        assert!(e.contains("shapes[0].count"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
