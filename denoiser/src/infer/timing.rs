//! Where an inference run's time goes: [`Timings`] per stage and network, and the forward pass
//! that books each network's time into it.

use burn::tensor::Tensor;

use crate::method::{MethodModel, MethodOutput, Part};
use crate::preprocess::InputTensors;

#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// Output tile side used.
    pub tile: usize,
    /// Cutting windows out of the prepared image and building tensors.
    pub gather_s: f64,
    /// Network forward passes (including reading results back); the sum of d_g, d_p, e, readback.
    pub forward_s: f64,
    /// D_G columns of both branches (KPCN on G-buffers).
    pub d_g_s: f64,
    /// Path-manifold modules plus the D_P columns (method p, guided) or the G+P columns (both).
    pub d_p_s: f64,
    /// Of `d_p_s`, the path-manifold modules alone (both branches, whole image).
    pub path_s: f64,
    /// E and the blend (guided), and the recombination of the two branches (every method).
    pub e_s: f64,
    /// Reading the results back into host memory.
    pub readback_s: f64,
    /// Everything.
    pub total_s: f64,
    pub windows: usize,
    /// Window side in pixels (input), for the record.
    pub window: usize,
}

/// [`MethodModel::forward_timed`] with each network's time booked in `t` (the runtime breakdown
/// of the paper's Table 1). Only networks that exist report, so a method's breakdown shows 0 for
/// the ones it lacks.
pub(super) fn timed_forward(model: &MethodModel, input: InputTensors, pbufs: Option<[Tensor<4>; 2]>, t: &mut Timings) -> MethodOutput {
    model.forward_timed(input, pbufs, &mut |part, secs| match part {
        Part::Path => {
            t.path_s += secs;
            t.d_p_s += secs;
        }
        Part::DG => t.d_g_s += secs,
        Part::DP => t.d_p_s += secs,
        Part::E => t.e_s += secs,
    })
}
