//! Frames: the film types live in the `film` crate, which the denoiser shares; they are
//! re-exported here at their old paths, beside what only the renderer's users need (tone-mapped
//! PNG previews, EXR files of textures).

pub use ::film::{channels, descriptors, BufferRequest, DescriptorFile, Descriptors, Frame, PixelBuffer, Precision, Welford};

pub mod exr_io;
pub mod png;
