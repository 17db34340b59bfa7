//! Frames to and from EXR files (the `film` crate's reader and writer), and textures to EXR.

pub use ::film::exr_io::*;

use crate::Result;
use std::path::Path;

/// Writes a linear RGB texture (e.g. an environment map) as a plain `R,G,B` f32 EXR.
pub fn write_rgb(path: &Path, tex: &crate::texture::Texture) -> Result<()> {
    let plane = |k: usize| tex.texels.iter().map(|c| c[k]).collect();
    Ok(write_rgb_planes(path, tex.width, tex.height, [plane(0), plane(1), plane(2)])?)
}
