//! Pinhole camera.

use crate::math::Ray;
use glam::{Vec2, Vec3};

/// The image extent a field of view spans (Mitsuba's `fov_axis`). The angle along this extent
/// is what a camera keeps when its image size changes (`--size`): a Mitsuba camera with the
/// default axis `X` keeps its horizontal view, ours (`Y`) its vertical one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FovAxis {
    /// Horizontal.
    X,
    /// Vertical.
    Y,
    /// The image diagonal.
    Diagonal,
    /// The shorter side of the image (horizontal for a square one).
    Smaller,
    /// The longer side of the image (horizontal for a square one).
    Larger,
}

impl FovAxis {
    /// Mitsuba's names (`x`, `y`, `diagonal`, `smaller`, `larger`; case-insensitive, as in Mitsuba 3).
    pub fn parse(s: &str) -> Option<FovAxis> {
        Some(match s.trim().to_ascii_lowercase().as_str() {
            "x" => FovAxis::X,
            "y" => FovAxis::Y,
            "diagonal" => FovAxis::Diagonal,
            "smaller" => FovAxis::Smaller,
            "larger" => FovAxis::Larger,
            _ => return None,
        })
    }

    /// Length in pixels of the extent the field of view spans on a `width` × `height` image.
    #[inline]
    pub fn span(self, width: f32, height: f32) -> f32 {
        match self {
            FovAxis::X => width,
            FovAxis::Y => height,
            FovAxis::Diagonal => (width * width + height * height).sqrt(),
            // Mitsuba 3 resolves these with aspect = w/h: smaller is y iff aspect > 1.
            FovAxis::Smaller => {
                if width > height {
                    height
                } else {
                    width
                }
            }
            FovAxis::Larger => {
                if width > height {
                    width
                } else {
                    height
                }
            }
        }
    }
}

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors of the camera frame: right, up, forward (looking direction).
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
    /// The extent the field of view spans; its angle is kept when `width`/`height` change.
    pub fov_axis: FovAxis,
    /// tan(fov / 2) along `fov_axis`. The angles along the other extents follow from the image
    /// size (`tan_half_extent`), so setting `width`/`height` directly is a correct resize.
    pub tan_half_fov: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// A camera with a vertical field of view (`FovAxis::Y`).
    /// `up` need not be orthogonal to the view direction, only not parallel to it.
    /// Returns `None` for a degenerate set-up (target == position, up ∥ view, fov ∉ (0,180)).
    pub fn look_at(position: Vec3, target: Vec3, up: Vec3, vfov_deg: f32, width: u32, height: u32) -> Option<Camera> {
        Camera::look_at_axis(position, target, up, vfov_deg, FovAxis::Y, width, height)
    }

    /// Like `look_at`, with the field of view `fov_deg` measured along `axis`.
    pub fn look_at_axis(position: Vec3, target: Vec3, up: Vec3, fov_deg: f32, axis: FovAxis, width: u32, height: u32) -> Option<Camera> {
        let forward = (target - position).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        if forward == Vec3::ZERO || right == Vec3::ZERO || !(fov_deg > 0.0 && fov_deg < 180.0) {
            return None;
        }
        let up = right.cross(forward);
        Some(Camera { position, right, up, forward, fov_axis: axis, tan_half_fov: (fov_deg.to_radians() * 0.5).tan(), width, height })
    }

    /// Scale of the film's [-1, 1] coordinates to tangents, horizontally and vertically:
    /// multiplying `tan_half_fov` by these gives the tangents of the half-angles the image spans.
    #[inline]
    fn extent_scale(&self) -> Vec2 {
        let (w, h) = (self.width as f32, self.height as f32);
        let span = self.fov_axis.span(w, h);
        // For `Y` this is (w/h, 1) exactly, the factors this camera always used.
        Vec2::new(w / span, h / span)
    }

    /// tan of the half-angles the image spans: (horizontal, vertical).
    pub fn tan_half_extent(&self) -> Vec2 {
        self.tan_half_fov * self.extent_scale()
    }

    /// tan(vertical fov / 2) at the current image size.
    pub fn tan_half_vfov(&self) -> f32 {
        self.tan_half_extent().y
    }

    /// Primary ray through film position `film` in pixels (x right, y down; (0,0) is the top-left corner).
    #[inline]
    pub fn ray(&self, film: Vec2) -> Ray {
        self.ray_maker().ray(film)
    }

    /// What `ray` computes once per camera, for many rays in a loop: a loop over `ray` itself
    /// branches on `fov_axis` and divides twice for every ray, and does not vectorise.
    #[inline]
    pub fn ray_maker(&self) -> RayMaker {
        RayMaker {
            position: self.position,
            right: self.right,
            up: self.up,
            forward: self.forward,
            tan_half_fov: self.tan_half_fov,
            scale: self.extent_scale(),
            width: self.width as f32,
            height: self.height as f32,
        }
    }
}

/// A camera's primary rays (`Camera::ray_maker`), with exactly `Camera::ray`'s operations.
#[derive(Clone, Copy, Debug)]
pub struct RayMaker {
    position: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    tan_half_fov: f32,
    scale: Vec2,
    width: f32,
    height: f32,
}

impl RayMaker {
    #[inline(always)]
    pub fn ray(&self, film: Vec2) -> Ray {
        let s = self.scale;
        let sx = (2.0 * film.x / self.width - 1.0) * self.tan_half_fov * s.x;
        let sy = (1.0 - 2.0 * film.y / self.height) * self.tan_half_fov * s.y;
        let dir = (self.forward + sx * self.right + sy * self.up).normalize();
        Ray::new(self.position, dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(axis: FovAxis, fov_deg: f32, w: u32, h: u32) -> Camera {
        Camera::look_at_axis(Vec3::ZERO, -Vec3::Z, Vec3::Y, fov_deg, axis, w, h).unwrap()
    }

    /// tan of the half-angle between the view axis and the ray through a film point.
    fn tan_to(c: &Camera, film: Vec2) -> Vec2 {
        let d = c.ray(film).dir;
        Vec2::new(d.dot(c.right), d.dot(c.up)) / d.dot(c.forward)
    }

    #[test]
    fn each_fov_axis_spans_its_extent() {
        let t = 30f32.to_radians().tan(); // fov 60°
        for (w, h) in [(320u32, 180u32), (180, 320), (200, 200)] {
            let (wf, hf) = (w as f32, h as f32);
            let diag = (wf * wf + hf * hf).sqrt();
            // Expected tan of the half-angle to the right edge and to the top edge.
            let cases = [
                (FovAxis::X, Vec2::new(t, t * hf / wf)),
                (FovAxis::Y, Vec2::new(t * wf / hf, t)),
                (FovAxis::Diagonal, Vec2::new(t * wf / diag, t * hf / diag)),
                (FovAxis::Smaller, if w > h { Vec2::new(t * wf / hf, t) } else { Vec2::new(t, t * hf / wf) }),
                (FovAxis::Larger, if w > h { Vec2::new(t, t * hf / wf) } else { Vec2::new(t * wf / hf, t) }),
            ];
            for (axis, want) in cases {
                let c = cam(axis, 60.0, w, h);
                let right_edge = tan_to(&c, Vec2::new(wf, hf / 2.0)).x;
                let top_edge = tan_to(&c, Vec2::new(wf / 2.0, 0.0)).y;
                let got = Vec2::new(right_edge, top_edge);
                assert!((got - want).abs().max_element() < 1e-5, "{axis:?} {w}x{h}: {got} vs {want}");
                assert!((c.tan_half_extent() - want).abs().max_element() < 1e-6, "{axis:?} {w}x{h}");
                if axis != FovAxis::Diagonal {
                    // The corner is where both extents meet.
                    let corner = tan_to(&c, Vec2::new(wf, 0.0));
                    assert!((corner - want).abs().max_element() < 1e-5, "{axis:?} {w}x{h} corner {corner}");
                } else {
                    let corner = tan_to(&c, Vec2::new(wf, 0.0));
                    assert!((corner.length() - t).abs() < 1e-5, "diagonal {w}x{h}: corner {corner}");
                }
            }
        }
    }

    #[test]
    fn resizing_keeps_the_angle_along_the_axis() {
        for axis in [FovAxis::X, FovAxis::Y, FovAxis::Diagonal, FovAxis::Smaller, FovAxis::Larger] {
            let mut resized = cam(axis, 50.0, 176, 128);
            resized.width = 320;
            resized.height = 180;
            let direct = cam(axis, 50.0, 320, 180);
            for film in [Vec2::new(0.0, 0.0), Vec2::new(320.0, 180.0), Vec2::new(13.5, 170.25), Vec2::new(160.0, 90.0)] {
                assert_eq!(resized.ray(film).dir, direct.ray(film).dir, "{axis:?} at {film}");
            }
        }
    }

    #[test]
    fn fov_axis_names() {
        assert_eq!(FovAxis::parse("x"), Some(FovAxis::X));
        assert_eq!(FovAxis::parse("Y"), Some(FovAxis::Y));
        assert_eq!(FovAxis::parse("diagonal"), Some(FovAxis::Diagonal));
        assert_eq!(FovAxis::parse("smaller"), Some(FovAxis::Smaller));
        assert_eq!(FovAxis::parse("larger"), Some(FovAxis::Larger));
        assert_eq!(FovAxis::parse("z"), None);
    }
}
