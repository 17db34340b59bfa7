//! RGB textures in linear colour: albedo maps (decoded from sRGB) and environment maps.

use glam::{Vec2, Vec3};

/// A linear-RGB image, row 0 at the top (v = 0 is the top row, matching image files; OBJ/glTF
/// texture coordinates are flipped by their loaders to this convention).
#[derive(Clone, Debug)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub texels: Vec<Vec3>,
}

impl Texture {
    pub fn texel(&self, x: i64, y: i64) -> Vec3 {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        self.texels[y * self.width as usize + x]
    }

    /// Bilinear lookup with wrap-around (repeat) addressing.
    pub fn sample_bilinear(&self, uv: Vec2) -> Vec3 {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !x.is_finite() || !y.is_finite() {
            return self.texel(0, 0);
        }
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = x - x0;
        let fy = y - y0;
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let b = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }
}

impl Texture {
    /// Average texel (a constant stand-in where a material parameter cannot vary over a surface).
    pub fn mean(&self) -> Vec3 {
        if self.texels.is_empty() {
            return Vec3::ZERO;
        }
        let sum = self.texels.iter().fold(glam::DVec3::ZERO, |acc, t| acc + t.as_dvec3());
        (sum / self.texels.len() as f64).as_vec3()
    }
}

/// The sRGB transfer function inverted (IEC 61966-2-1): an encoded value in [0,1] to linear.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decoding_hits_known_points() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        // sRGB 0.5 is 0.214 linear (the familiar "middle grey is 21 %").
        assert!((srgb_to_linear(0.5) - 0.21404).abs() < 1e-4);
        // Continuous at the knee.
        assert!((srgb_to_linear(0.04045) - srgb_to_linear(0.040451)).abs() < 1e-5);
    }
}
