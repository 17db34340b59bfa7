//! Loading images into linear-RGB [`Texture`]s: albedo textures and environment maps.
//!
//! 8- and 16-bit images (PNG, JPEG, ...) are sRGB-encoded by convention and are decoded to
//! linear; floating-point images (EXR, Radiance HDR) are already linear. Alpha is ignored.
//! Every error names the scene file, the field that referenced the image, and the image path.

use crate::texture::{srgb_to_linear, Texture};
use crate::{Error, Result};
use glam::Vec3;
use image::DynamicImage;
use std::path::Path;

/// Largest accepted image side; beyond it the image is surely a mistake (and would not fit).
const MAX_SIDE: u32 = 65536;

/// Reads and decodes an image file referenced by `field` of `scene_file`.
pub fn load_image(path: &Path, scene_file: &Path, field: &str) -> Result<Texture> {
    let fail = |msg: String| Error::scene(scene_file, field, format!("image '{}': {msg}", path.display()));
    let reader = image::ImageReader::open(path).map_err(|e| fail(format!("cannot open: {e}")))?;
    let reader = reader.with_guessed_format().map_err(|e| fail(format!("cannot read: {e}")))?;
    let img = reader.decode().map_err(|e| fail(format!("cannot decode: {e}")))?;
    to_texture(img).map_err(fail)
}

/// Decodes an image held in memory (e.g. embedded in a glTF file); `name` identifies it in errors.
pub fn decode_image(bytes: &[u8], name: &str, scene_file: &Path, field: &str) -> Result<Texture> {
    let fail = |msg: String| Error::scene(scene_file, field, format!("image {name}: {msg}"));
    let img = image::load_from_memory(bytes).map_err(|e| fail(format!("cannot decode: {e}")))?;
    to_texture(img).map_err(fail)
}

fn to_texture(img: DynamicImage) -> std::result::Result<Texture, String> {
    let (width, height) = (img.width(), img.height());
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(format!("unusable size {width}×{height}"));
    }
    let linear = matches!(img, DynamicImage::ImageRgb32F(_) | DynamicImage::ImageRgba32F(_));
    let rgb = img.into_rgb32f();
    let mut texels = Vec::with_capacity(width as usize * height as usize);
    for (x, y, p) in rgb.enumerate_pixels() {
        let c = Vec3::from(p.0);
        if !c.is_finite() {
            // A single NaN/Inf texel poisons every pixel that sees it (and the env-map CDF).
            return Err(format!("texel ({x}, {y}) is not finite ({c})"));
        }
        if c.min_element() < 0.0 {
            return Err(format!("texel ({x}, {y}) is negative ({c})"));
        }
        texels.push(if linear { c } else { c.map(srgb_to_linear) });
    }
    Ok(Texture { width, height, texels })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_images_stay_linear_and_8bit_is_srgb_decoded() {
        let mut f = image::Rgb32FImage::new(2, 1);
        f.put_pixel(1, 0, image::Rgb([0.5, 2.0, 0.25]));
        let t = to_texture(DynamicImage::ImageRgb32F(f)).unwrap();
        assert_eq!(t.texels[1], Vec3::new(0.5, 2.0, 0.25));

        let mut b = image::RgbImage::new(1, 1);
        b.put_pixel(0, 0, image::Rgb([255, 128, 0]));
        let t = to_texture(DynamicImage::ImageRgb8(b)).unwrap();
        assert!((t.texels[0].x - 1.0).abs() < 1e-6);
        assert!((t.texels[0].y - srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
        assert_eq!(t.texels[0].z, 0.0);
    }

    #[test]
    fn non_finite_texels_are_rejected() {
        let mut f = image::Rgb32FImage::new(3, 2);
        f.put_pixel(2, 1, image::Rgb([0.0, f32::NAN, 0.0]));
        let e = to_texture(DynamicImage::ImageRgb32F(f)).unwrap_err();
        assert!(e.contains("(2, 1)"), "{e}");
    }
}
