//! Pinhole camera.

use crate::math::Ray;
use glam::{Vec2, Vec3};

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: Vec3,
    /// Unit vectors of the camera frame: right, up, forward (looking direction).
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
    /// tan(vfov / 2).
    pub tan_half_fov: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// `up` need not be orthogonal to the view direction, only not parallel to it.
    /// Returns `None` for a degenerate set-up (target == position, up ∥ view, fov ∉ (0,180)).
    pub fn look_at(position: Vec3, target: Vec3, up: Vec3, vfov_deg: f32, width: u32, height: u32) -> Option<Camera> {
        let forward = (target - position).normalize_or_zero();
        let right = forward.cross(up).normalize_or_zero();
        if forward == Vec3::ZERO || right == Vec3::ZERO || !(vfov_deg > 0.0 && vfov_deg < 180.0) {
            return None;
        }
        let up = right.cross(forward);
        Some(Camera { position, right, up, forward, tan_half_fov: (vfov_deg.to_radians() * 0.5).tan(), width, height })
    }

    /// Primary ray through film position `film` in pixels (x right, y down; (0,0) is the top-left corner).
    pub fn ray(&self, film: Vec2) -> Ray {
        let aspect = self.width as f32 / self.height as f32;
        let sx = (2.0 * film.x / self.width as f32 - 1.0) * self.tan_half_fov * aspect;
        let sy = (1.0 - 2.0 * film.y / self.height as f32) * self.tan_half_fov;
        let dir = (self.forward + sx * self.right + sy * self.up).normalize();
        Ray::new(self.position, dir)
    }
}
