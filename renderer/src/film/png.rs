//! PNG previews. Tone mapping (documented in docs/formats.md): linear RGB × 2^exposure, then the
//! sRGB transfer curve, clipped to [0,1], 8 bits. Non-radiance buffers use their own mapping
//! (normals n·½+½, depth and variances normalised by their maximum).

use crate::{Error, Result};
use std::path::Path;

/// The sRGB opto-electronic transfer function on a linear value, clipped to [0,1].
pub fn srgb_encode(x: f32) -> f32 {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Interleaved RGB f32 → 8-bit sRGB with exposure (stops).
pub fn tonemap_rgb8(rgb: &[f32], exposure: f32) -> Vec<u8> {
    let k = 2f32.powf(exposure);
    rgb.iter().map(|&v| (srgb_encode(v * k) * 255.0 + 0.5) as u8).collect()
}

pub fn write_rgb8(path: &Path, width: u32, height: u32, rgb8: Vec<u8>) -> Result<()> {
    let img =
        image::RgbImage::from_raw(width, height, rgb8).ok_or_else(|| Error::image(path, "buffer size does not match the image size"))?;
    let tmp = path.with_extension("partial.png");
    img.save(&tmp).map_err(|e| Error::image(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// Writes linear radiance as a tone-mapped PNG.
pub fn write_radiance(path: &Path, width: u32, height: u32, rgb: &[f32], exposure: f32) -> Result<()> {
    write_rgb8(path, width, height, tonemap_rgb8(rgb, exposure))
}

/// Maps an arbitrary buffer of `channels` channels to displayable RGB in [0,1]: linear values are
/// scaled by the inverse of their 99th percentile (so one firefly does not blacken the picture).
pub fn normalised_rgb(values: &[f32], channels: usize, signed: bool) -> Vec<f32> {
    let n = values.len() / channels.max(1);
    let to_rgb = |i: usize| -> [f32; 3] {
        let p = &values[i * channels..(i + 1) * channels];
        match channels {
            1 => [p[0]; 3],
            _ => [p[0], p[1], p[2]],
        }
    };
    if signed {
        return (0..n).flat_map(|i| to_rgb(i).map(|v| (v * 0.5 + 0.5).clamp(0.0, 1.0))).collect();
    }
    let mut mags: Vec<f32> = values.iter().copied().filter(|v| v.is_finite()).map(f32::abs).collect();
    let scale = if mags.is_empty() {
        1.0
    } else {
        let k = ((mags.len() as f32 * 0.99) as usize).min(mags.len() - 1);
        let (_, p99, _) = mags.select_nth_unstable_by(k, f32::total_cmp);
        if *p99 > 0.0 {
            1.0 / *p99
        } else {
            1.0
        }
    };
    (0..n).flat_map(|i| to_rgb(i).map(|v| (v * scale).clamp(0.0, 1.0))).collect()
}
