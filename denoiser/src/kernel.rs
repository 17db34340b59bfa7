//! Kernel-predicting reconstruction (method.md §3): per output pixel a k×k filter, normalised
//! by a softmax over its k² taps, applied to the noisy colour with the same weights for every
//! channel. Taps outside the input buffer read zero and the weights are not renormalised.
//!
//! The input may be larger than the kernel map: the map is centred on it and the filter reads
//! the margin, so a network trained with valid convolutions filters from the uncropped buffer
//! and its border pixels are not darkened (the ⚠ note of method.md §3).
//!
//! Implementation: `unfold4d` gathers the k² neighbours of every pixel (im2col, a strided view
//! when called without padding), then a broadcast multiply and a sum over the taps. This was the
//! fastest of the variants measured on flex; autodiff differentiates through the view ops.

use burn::tensor::activation::softmax;
use burn::tensor::module::unfold4d;
use burn::tensor::ops::{PadMode, UnfoldOptions};
use burn::tensor::Tensor;

/// Softmax over the k² tap channels: `[B, k², H, W]` logits → weights in [0,1] summing to 1.
pub fn kernel_weights(logits: Tensor<4>) -> Tensor<4> {
    softmax(logits, 1)
}

/// Filter size k from the number of tap channels k², which must be an odd square.
pub fn filter_size(taps: usize) -> usize {
    let k = (taps as f64).sqrt().round() as usize;
    assert!(k * k == taps && k % 2 == 1, "kernel map needs an odd square number of channels, got {taps}");
    k
}

/// Applies softmax kernels.
///
/// Shapes: `input` `[B, C, Hi, Wi]`, `logits` `[B, k², Ho, Wo]` with Hi − Ho and Wi − Wo even
/// and ≥ 0 → `[B, C, Ho, Wo]`, where
/// out_c(y,x) = Σ_{i,j∈[−r,r]} w_{(i+r)k+(j+r)}(y,x) · in_c(y+oy+i, x+ox+j), r = k/2,
/// oy = (Hi−Ho)/2, ox = (Wi−Wo)/2, and in = 0 outside the buffer.
pub fn apply_kernel(input: Tensor<4>, logits: Tensor<4>) -> Tensor<4> {
    apply_weights(input, kernel_weights(logits))
}

/// As [`apply_kernel`] with already-normalised weights.
pub fn apply_weights(input: Tensor<4>, weights: Tensor<4>) -> Tensor<4> {
    let [b, c, hi, wi] = input.dims();
    let [bw, taps, ho, wo] = weights.dims();
    assert_eq!(b, bw, "kernel map batch {bw} ≠ input batch {b}");
    let k = filter_size(taps);
    let r = k / 2;
    assert!(
        hi >= ho && wi >= wo && (hi - ho) % 2 == 0 && (wi - wo) % 2 == 0,
        "input {hi}×{wi} must exceed kernel map {ho}×{wo} by an even margin"
    );
    let (oy, ox) = ((hi - ho) / 2, (wi - wo) / 2);
    // Keep at most r pixels of real context per side; pad the rest with zeros, symmetrically.
    let (cy, cx) = (oy.min(r), ox.min(r));
    let mut x = input.narrow(2, oy - cy, ho + 2 * cy).narrow(3, ox - cx, wo + 2 * cx);
    if cy < r || cx < r {
        // Pad explicitly: burn's unfold4d is a zero-copy strided view only without padding;
        // with padding it falls back to a one-hot convolution costing (C·k²)² MACs per pixel.
        let (py, px) = (r - cy, r - cx);
        x = x.pad([(py, py), (px, px)], PadMode::Constant(0.0));
    }
    let cols = unfold4d(x, [k, k], UnfoldOptions::new([1, 1], [0, 0], [1, 1]));
    // unfold4d orders its rows channel-major then tap (row-major in the window), so tap index
    // (i+r)·k + (j+r) matches the kernel-map channel order.
    let cols = cols.reshape([b, c, taps, ho * wo]);
    let w = weights.reshape([b, 1, taps, ho * wo]);
    (cols * w).sum_dim(2).reshape([b, c, ho, wo])
}

/// Slow f64 reference of [`apply_kernel`] on flat NCHW buffers (used by the tests and handy for
/// checking other implementations). Returns the `[B, C, Ho, Wo]` output.
pub fn reference_apply_kernel(input: &[f64], [b, c, hi, wi]: [usize; 4], logits: &[f64], [_, taps, ho, wo]: [usize; 4]) -> Vec<f64> {
    let k = filter_size(taps);
    let r = (k / 2) as isize;
    let (oy, ox) = (((hi - ho) / 2) as isize, ((wi - wo) / 2) as isize);
    let mut out = vec![0.0; b * c * ho * wo];
    let mut w = vec![0.0; taps];
    for n in 0..b {
        for y in 0..ho {
            for x in 0..wo {
                let at = |t: usize| logits[((n * taps + t) * ho + y) * wo + x];
                let m = (0..taps).map(at).fold(f64::NEG_INFINITY, f64::max);
                let z: f64 = (0..taps).map(|t| (at(t) - m).exp()).sum();
                for (t, wt) in w.iter_mut().enumerate() {
                    *wt = (at(t) - m).exp() / z;
                }
                for ch in 0..c {
                    let mut acc = 0.0;
                    for i in -r..=r {
                        for j in -r..=r {
                            let (sy, sx) = (y as isize + oy + i, x as isize + ox + j);
                            if sy < 0 || sx < 0 || sy >= hi as isize || sx >= wi as isize {
                                continue;
                            }
                            let t = ((i + r) * k as isize + (j + r)) as usize;
                            acc += w[t] * input[((n * c + ch) * hi + sy as usize) * wi + sx as usize];
                        }
                    }
                    out[((n * c + ch) * ho + y) * wo + x] = acc;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::test_util::{grad_of, tensor, to_vec};
    use crate::{cpu_device, cpu_training_device};

    fn random(n: usize, scale: f64, rng: &mut SplitMix64) -> Vec<f64> {
        (0..n).map(|_| rng.symmetric(scale) as f64).collect()
    }

    /// Forward agrees with the reference, and the autodiff gradient agrees with central finite
    /// differences of the f64 reference, for full, partial and no margin around the kernel map.
    #[test]
    fn gradient_matches_finite_differences() {
        for (hi, ho, k) in [(9, 5, 5), (7, 5, 5), (5, 5, 3), (6, 4, 3)] {
            let mut rng = SplitMix64::new(hi as u64 * 31 + k as u64);
            let (b, c, taps) = (2, 3, k * k);
            let in_dims = [b, c, hi, hi + 2];
            let lg_dims = [b, taps, ho, ho + 2];
            let input = random(in_dims.iter().product(), 1.0, &mut rng);
            let logits = random(lg_dims.iter().product(), 2.0, &mut rng);
            let out_n = b * c * ho * (ho + 2);
            let probe = random(out_n, 1.0, &mut rng);
            let objective = |inp: &[f64], lg: &[f64]| -> f64 {
                let o = reference_apply_kernel(inp, in_dims, lg, lg_dims);
                o.iter().zip(&probe).map(|(a, b)| a * b).sum()
            };

            let dev = cpu_training_device();
            let x = tensor(&input, in_dims, &dev).require_grad();
            let l = tensor(&logits, lg_dims, &dev).require_grad();
            let g = tensor(&probe, [b, c, ho, ho + 2], &dev);
            let out = apply_kernel(x.clone(), l.clone());
            let fwd = to_vec(out.clone());
            let reference = reference_apply_kernel(&input, in_dims, &logits, lg_dims);
            for (a, r) in fwd.iter().zip(&reference) {
                // f32 sums of ≤ 25 terms of size ≤ 1: errors stay near 1e-6.
                assert!((a - r).abs() < 1e-5, "forward {a} vs reference {r}");
            }
            let grads = (out * g).sum().backward();
            let gx = grad_of(&x, &grads);
            let gl = grad_of(&l, &grads);

            let h = 1e-5;
            let fd = |v: &[f64], i: usize, is_input: bool| -> f64 {
                let (mut p, mut m) = (v.to_vec(), v.to_vec());
                p[i] += h;
                m[i] -= h;
                if is_input {
                    (objective(&p, &logits) - objective(&m, &logits)) / (2.0 * h)
                } else {
                    (objective(&input, &p) - objective(&input, &m)) / (2.0 * h)
                }
            };
            let fd_x: Vec<f64> = (0..input.len()).map(|i| fd(&input, i, true)).collect();
            let fd_l: Vec<f64> = (0..logits.len()).map(|i| fd(&logits, i, false)).collect();
            // Bound: max |analytic − FD| ≤ 1e-4 · max |FD|. The FD error in f64 with h = 1e-5 is
            // ~1e-10 (truncation h²) and the f32 analytic gradient is off by ~1e-6 relative, so
            // 1e-4 leaves 100× headroom while any indexing or softmax-Jacobian bug is O(1).
            for (name, an, num) in [("input", &gx, &fd_x), ("logits", &gl, &fd_l)] {
                let scale = num.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let err = an.iter().zip(num.iter()).fold(0.0f64, |m, (a, n)| m.max((a - n).abs()));
                assert!(scale > 1e-3, "degenerate probe for {name}");
                assert!(err <= 1e-4 * scale, "{name} grad: max err {err} vs scale {scale} (hi {hi}, k {k})");
            }
        }
    }

    /// Softmax weights lie in [0,1] and sum to 1 per pixel, even for extreme logits.
    #[test]
    fn weights_are_a_partition_of_unity() {
        let d = cpu_device();
        let mut rng = SplitMix64::new(3);
        let taps = 9;
        let mut lg = random(2 * taps * 4 * 4, 20.0, &mut rng);
        lg[0] = 1e6;
        lg[17] = -1e6;
        lg[40] = 3e4;
        let w = to_vec(kernel_weights(tensor(&lg, [2, taps, 4, 4], &d)));
        for n in 0..2 {
            for p in 0..16 {
                let s: f64 = (0..taps).map(|t| w[(n * taps + t) * 16 + p]).sum();
                // f32 softmax normalisation: sum exact to a few ulps of 1.
                assert!((s - 1.0).abs() < 1e-5, "sum {s}");
            }
        }
        assert!(w.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
    }

    /// A one-hot kernel on the centre tap is the identity; on a corner tap it is a shift that
    /// reads zeros past the buffer edge.
    #[test]
    fn one_hot_kernels_copy_and_shift() {
        let d = cpu_device();
        let (h, w, k) = (4, 5, 3);
        let img: Vec<f64> = (0..h * w).map(|i| i as f64 + 1.0).collect();
        for (tap, dy, dx) in [(4usize, 0isize, 0isize), (0, -1, -1), (8, 1, 1)] {
            let mut lg = vec![-1e4; k * k * h * w];
            for p in 0..h * w {
                lg[tap * h * w + p] = 1e4;
            }
            let out = to_vec(apply_kernel(tensor(&img, [1, 1, h, w], &d), tensor(&lg, [1, k * k, h, w], &d)));
            for y in 0..h as isize {
                for x in 0..w as isize {
                    let (sy, sx) = (y + dy, x + dx);
                    let expect =
                        if sy < 0 || sx < 0 || sy >= h as isize || sx >= w as isize { 0.0 } else { img[(sy * w as isize + sx) as usize] };
                    assert_eq!(out[(y * w as isize + x) as usize], expect, "tap {tap} at ({y},{x})");
                }
            }
        }
    }
}
