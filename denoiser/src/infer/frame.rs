//! From a rendered [`Frame`] to a denoised one in one call, so that a program that renders and
//! then denoises needs nothing of the binary (`pixguide render --denoise`, `pixguide denoise`,
//! denoiser/examples/render_and_denoise.rs). `pixguide eval` calls the two stages itself: it
//! prepares a frame once for several models.

use std::time::Instant;

use film::{Frame, PixelBuffer};

use super::{Denoised, InferError, InferOptions};
use crate::method::Method;
use crate::preprocess::{self, PrepareError};
use crate::weights::Loaded;

/// The result of [`denoise_frame`] with the time spent before the networks.
pub struct FrameRun {
    pub denoised: Denoised,
    /// Preprocessing (method.md §2, §4.1) seconds.
    pub prepare_s: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("the {0} model needs per-sample path descriptors, and the frame has none")]
    MissingDescriptors(Method),
    #[error(transparent)]
    Prepare(#[from] PrepareError),
    #[error(transparent)]
    Infer(#[from] InferError),
}

/// Preprocesses and denoises a frame in memory on `device`. The descriptors move from the frame
/// into the prepared image (they are the largest buffer; inference normalises them as it reads
/// them), so `frame.descriptors` is `None` afterwards.
pub fn denoise_frame(
    frame: &mut Frame,
    loaded: &Loaded,
    opts: &InferOptions,
    device: &burn::tensor::Device,
) -> Result<FrameRun, FrameError> {
    let t = Instant::now();
    if loaded.method.needs_descriptors() && frame.descriptors.is_none() {
        return Err(FrameError::MissingDescriptors(loaded.method));
    }
    let prepared = preprocess::prepare_for_inference(frame)?;
    let prepare_s = t.elapsed().as_secs_f64();
    let denoised = super::denoise(&loaded.model, &loaded.config, &prepared, &frame.radiance.mean, opts, device)?;
    Ok(FrameRun { denoised, prepare_s })
}

/// A frame holding only the denoised radiance (variance 0: it is no longer a sample mean), for
/// `film::exr_io::write_frame`.
pub fn denoised_frame(d: &Denoised, spp: u32) -> Frame {
    let n = d.width * d.height;
    let mut radiance = PixelBuffer::new(3, n);
    radiance.mean.copy_from_slice(&d.radiance);
    Frame {
        width: d.width as u32,
        height: d.height as u32,
        spp,
        radiance,
        diffuse: None,
        specular: None,
        albedo: None,
        normal: None,
        depth: None,
        depth_scale: 1.0,
        descriptors: None,
        nonfinite_samples: 0,
    }
}
