//! Direct k×k convolutions (k = 1 or 3, stride 1, zero "same" padding) on [`Planes`], with the
//! bias and the ReLU fused into the store and a skip concatenation fused into the input list:
//! the layer reads its input channels from several buffers in turn, so no concatenated copy is
//! made (docs/inference-engine.md).
//!
//! Register blocking: 8 output channels (one block of the packed weights, each broadcast) × a
//! run of output pixels in vector registers (AVX-512: 2 × 16, AVX2: 1 × 8); every output value
//! sums its inputs, channels and taps in the same order whatever the run or thread it falls in,
//! so the thread count never changes the result. Work is split by output rows over rayon; each
//! row is walked in column tiles so that the input rows a tile reads stay in L2 across the
//! output-channel blocks.

use rayon::prelude::*;

use super::planes::Planes;
use super::Isa;

/// Output channels per register block (the packed weights' inner dimension).
pub const COB: usize = 8;

/// Pixels per column tile of a row (see the module comment).
const X_TILE: usize = 128;

/// One convolution's weights, packed `[cout / 8][cin][k][k][8]` (zero-padded output channels).
#[derive(Clone, Debug)]
pub struct ConvWeights {
    pub cin: usize,
    pub cout: usize,
    pub k: usize,
    packed: Vec<f32>,
    bias: Vec<f32>,
}

impl ConvWeights {
    /// From burn's `[cout, cin, k, k]` layout and `[cout]` biases.
    pub fn new(weight: &[f32], bias: &[f32], cout: usize, cin: usize, k: usize) -> Self {
        assert!(k == 1 || k == 3, "the engine runs 1×1 and 3×3 convolutions, not {k}×{k}");
        assert_eq!(weight.len(), cout * cin * k * k, "weights of a {cout}×{cin}×{k}×{k} convolution");
        assert_eq!(bias.len(), cout, "biases of a {cout}-channel convolution");
        let blocks = cout.div_ceil(COB);
        let mut packed = vec![0.0; blocks * cin * k * k * COB];
        for co in 0..cout {
            for ci in 0..cin {
                for t in 0..k * k {
                    packed[((co / COB * cin + ci) * k * k + t) * COB + co % COB] = weight[(co * cin + ci) * k * k + t];
                }
            }
        }
        let mut b = bias.to_vec();
        b.resize(blocks * COB, 0.0);
        ConvWeights { cin, cout, k, packed, bias: b }
    }

    fn blocks(&self) -> usize {
        self.cout.div_ceil(COB)
    }

    /// Multiply-accumulates of one output pixel.
    pub fn macs_per_pixel(&self) -> u64 {
        (self.cin * self.cout * self.k * self.k) as u64
    }
}

/// A raw pointer shared by the row tasks, each writing only its own rows.
#[derive(Clone, Copy)]
struct OutPtr(*mut f32);
unsafe impl Send for OutPtr {}
unsafe impl Sync for OutPtr {}

/// What one row kernel call needs: the inputs' first channel's (padded) row of the top tap, and
/// where to write.
struct Row<'a> {
    /// Per input buffer: (pointer to value (y_top, x0 − k/2) of its channel 0, plane length,
    /// channels).
    srcs: &'a [(*const f32, usize, usize)],
    stride: usize,
    /// This block's packed weights `[cin][k][k][8]`.
    wts: &'a [f32],
    bias: &'a [f32],
    /// Row pointer of each of the block's output channels at x0 (null past `cout`).
    outs: [*mut f32; COB],
    relu: bool,
}

/// `inputs` (their channels concatenated, all of one size) → `cout` planes of the same size.
pub fn conv(isa: Isa, inputs: &[&Planes], wts: &ConvWeights, relu: bool) -> Planes {
    let (h, w) = (inputs[0].h, inputs[0].w);
    assert!(inputs.iter().all(|p| p.h == h && p.w == w), "concatenated inputs of different sizes");
    assert_eq!(inputs.iter().map(|p| p.c).sum::<usize>(), wts.cin, "input channels");
    let mut out = Planes::zeros(wts.cout, h, w);
    let ptr = OutPtr(out.data.as_mut_ptr());
    let (out_plane, out_stride) = (out.plane_len(), out.stride);
    let k = wts.k;
    let run = isa.run();
    (0..h).into_par_iter().for_each(|y| {
        // The whole wrapper, not its field, goes into the closure (edition-2021 captures).
        let out_ptr = ptr;
        for xt in (0..w).step_by(X_TILE) {
            // Input rows of the top tap: padded row y + 1 − k/2, padded column x + 1 − k/2.
            let srcs: Vec<(*const f32, usize, usize)> = inputs
                .iter()
                .map(|p| (p.data[p.at(0, y, xt)..].as_ptr().wrapping_sub((k / 2) * (p.stride + 1)), p.plane_len(), p.c))
                .collect();
            for b in 0..wts.blocks() {
                let wb = &wts.packed[b * wts.cin * k * k * COB..(b + 1) * wts.cin * k * k * COB];
                let bias = &wts.bias[b * COB..(b + 1) * COB];
                let mut x = xt;
                while x < (xt + X_TILE).min(w) {
                    let n = run.min(w - x);
                    let outs: [*mut f32; COB] = std::array::from_fn(|j| {
                        let co = b * COB + j;
                        if co < wts.cout {
                            // SAFETY: inside `out.data`; rows are written by this task only.
                            unsafe { out_ptr.0.add(co * out_plane + (y + 1) * out_stride + x + 1) }
                        } else {
                            std::ptr::null_mut()
                        }
                    });
                    let shifted: Vec<(*const f32, usize, usize)> = srcs.iter().map(|&(p, l, c)| (p.wrapping_add(x - xt), l, c)).collect();
                    let row = Row { srcs: &shifted, stride: inputs[0].stride, wts: wb, bias, outs, relu };
                    // SAFETY: reads stay inside each input's padded planes (a run reads at most
                    // `run` + 2 floats from its start, within the row slack); the ISA was
                    // detected on this CPU.
                    unsafe {
                        match (isa, k) {
                            #[cfg(target_arch = "x86_64")]
                            (Isa::Avx512, 3) => x86::run_avx512::<3>(&row, n),
                            #[cfg(target_arch = "x86_64")]
                            (Isa::Avx512, _) => x86::run_avx512::<1>(&row, n),
                            #[cfg(target_arch = "x86_64")]
                            (Isa::Avx2, 3) => x86::run_avx2::<3>(&row, n),
                            #[cfg(target_arch = "x86_64")]
                            (Isa::Avx2, _) => x86::run_avx2::<1>(&row, n),
                            (_, 3) => run_scalar::<3>(&row, n),
                            _ => run_scalar::<1>(&row, n),
                        }
                    }
                    x += n;
                }
            }
        }
    });
    debug_assert!(inputs.iter().all(|p| p.stride == inputs[0].stride), "one size, one stride");
    out
}

/// The portable kernel: one pixel at a time, the same order of sums as the SIMD ones (rounded
/// twice per term where they fuse).
///
/// # Safety
/// As [`conv`] sets it up.
unsafe fn run_scalar<const K: usize>(row: &Row, n: usize) {
    for i in 0..n {
        let mut acc = [0.0f32; COB];
        let mut wi = 0;
        for &(src, plane, c) in row.srcs {
            for ci in 0..c {
                for ky in 0..K {
                    let r = src.wrapping_add(ci * plane + ky * row.stride + i);
                    for kx in 0..K {
                        let v = unsafe { *r.add(kx) };
                        let w = &row.wts[wi..wi + COB];
                        // A plain multiply and add, not `mul_add`: without FMA in the build
                        // that is a library call per term (0.2 GMAC/s measured).
                        for (a, &wj) in acc.iter_mut().zip(w) {
                            *a += v * wj;
                        }
                        wi += COB;
                    }
                }
            }
        }
        for ((&o, &a), &b) in row.outs.iter().zip(&acc).zip(row.bias) {
            if !o.is_null() {
                let v = a + b;
                unsafe { *o.add(i) = if row.relu { v.max(0.0) } else { v } };
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{Row, COB};
    use std::arch::x86_64::*;

    /// 8 output channels × 32 pixels (two vectors); `n` ≤ 32 pixels are stored.
    ///
    /// # Safety
    /// AVX-512F, AVX2 and FMA present; pointers as [`super::conv`] sets them up.
    #[target_feature(enable = "avx512f,avx2,fma")]
    pub(super) unsafe fn run_avx512<const K: usize>(row: &Row, n: usize) {
        let mut acc = [[_mm512_setzero_ps(); 2]; COB];
        let mut w = row.wts.as_ptr();
        for &(src, plane, c) in row.srcs {
            for ci in 0..c {
                for ky in 0..K {
                    let r = src.wrapping_add(ci * plane + ky * row.stride);
                    for kx in 0..K {
                        let v0 = unsafe { _mm512_loadu_ps(r.add(kx)) };
                        let v1 = unsafe { _mm512_loadu_ps(r.add(kx + 16)) };
                        for (j, a) in acc.iter_mut().enumerate() {
                            let wj = _mm512_set1_ps(unsafe { *w.add(j) });
                            a[0] = _mm512_fmadd_ps(v0, wj, a[0]);
                            a[1] = _mm512_fmadd_ps(v1, wj, a[1]);
                        }
                        w = w.wrapping_add(COB);
                    }
                }
            }
        }
        let m0: __mmask16 = if n >= 16 { 0xffff } else { (1u32 << n) as u16 - 1 };
        let m1: __mmask16 = if n >= 32 {
            0xffff
        } else if n > 16 {
            (1u32 << (n - 16)) as u16 - 1
        } else {
            0
        };
        let zero = _mm512_setzero_ps();
        for (j, a) in acc.iter().enumerate() {
            let o = row.outs[j];
            if o.is_null() {
                continue;
            }
            let b = _mm512_set1_ps(row.bias[j]);
            let (mut y0, mut y1) = (_mm512_add_ps(a[0], b), _mm512_add_ps(a[1], b));
            if row.relu {
                (y0, y1) = (_mm512_max_ps(y0, zero), _mm512_max_ps(y1, zero));
            }
            unsafe {
                _mm512_mask_storeu_ps(o, m0, y0);
                _mm512_mask_storeu_ps(o.add(16), m1, y1);
            }
        }
    }

    /// 8 output channels × 8 pixels; `n` ≤ 8 pixels are stored.
    ///
    /// # Safety
    /// AVX2 and FMA present; pointers as [`super::conv`] sets them up.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn run_avx2<const K: usize>(row: &Row, n: usize) {
        let mut acc = [_mm256_setzero_ps(); COB];
        let mut w = row.wts.as_ptr();
        for &(src, plane, c) in row.srcs {
            for ci in 0..c {
                for ky in 0..K {
                    let r = src.wrapping_add(ci * plane + ky * row.stride);
                    for kx in 0..K {
                        let v = unsafe { _mm256_loadu_ps(r.add(kx)) };
                        for (j, a) in acc.iter_mut().enumerate() {
                            *a = _mm256_fmadd_ps(v, _mm256_broadcast_ss(unsafe { &*w.add(j) }), *a);
                        }
                        w = w.wrapping_add(COB);
                    }
                }
            }
        }
        let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(n as i32), lanes);
        let zero = _mm256_setzero_ps();
        for (j, a) in acc.iter().enumerate() {
            let o = row.outs[j];
            if o.is_null() {
                continue;
            }
            let mut y = _mm256_add_ps(*a, _mm256_set1_ps(row.bias[j]));
            if row.relu {
                y = _mm256_max_ps(y, zero);
            }
            unsafe { _mm256_maskstore_ps(o, mask, y) };
        }
    }
}
