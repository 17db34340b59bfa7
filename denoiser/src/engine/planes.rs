//! The engine's feature maps: planar channels, each plane with a one-pixel zero border and rows
//! padded so that a SIMD run of output pixels may read (not write) past the right edge.
//!
//! Why planar with a border rather than channel-blocked pixels: every width the shipped networks
//! use (24–144 input channels, heads of 30–31) then needs no channel padding, a 3×3 tap is an
//! unaligned load of a row shifted by −1, 0 or +1, and the border is the convolution's zero
//! padding, so the kernels have no edge cases. The register blocking runs over output channels
//! (weights broadcast) × runs of 16 or 32 pixels (one or two vectors).

/// Extra floats after each row: the widest kernel reads two 16-lane vectors from a run's start,
/// shifted by up to 2, and a run may start at any x < w.
const ROW_SLACK: usize = 40;

/// `c` planes of `h × w` values, stored `[c][h + 2][stride]` with value (y, x) at row y + 1,
/// column x + 1; the border and the slack are zero.
#[derive(Clone, Debug)]
pub struct Planes {
    pub c: usize,
    pub h: usize,
    pub w: usize,
    pub stride: usize,
    pub data: Vec<f32>,
}

impl Planes {
    pub fn zeros(c: usize, h: usize, w: usize) -> Self {
        let stride = (w + 2).div_ceil(16) * 16 + ROW_SLACK;
        Planes { c, h, w, stride, data: vec![0.0; c * (h + 2) * stride] }
    }

    /// Floats per plane.
    pub fn plane_len(&self) -> usize {
        (self.h + 2) * self.stride
    }

    /// Index of value (y, x) of plane `p`.
    #[inline]
    pub fn at(&self, p: usize, y: usize, x: usize) -> usize {
        p * self.plane_len() + (y + 1) * self.stride + x + 1
    }

    /// From planar `[c, h, w]` values.
    pub fn from_planar(v: &[f32], c: usize, h: usize, w: usize) -> Self {
        assert_eq!(v.len(), c * h * w, "planar buffer of {} values for {c}×{h}×{w}", v.len());
        let mut p = Planes::zeros(c, h, w);
        for ch in 0..c {
            for y in 0..h {
                let o = p.at(ch, y, 0);
                p.data[o..o + w].copy_from_slice(&v[(ch * h + y) * w..(ch * h + y + 1) * w]);
            }
        }
        p
    }

    /// Planes `from..from + n` as planar `[n, h, w]` values.
    pub fn to_planar(&self, from: usize, n: usize) -> Vec<f32> {
        let mut out = Vec::with_capacity(n * self.h * self.w);
        for ch in from..from + n {
            for y in 0..self.h {
                let o = self.at(ch, y, 0);
                out.extend_from_slice(&self.data[o..o + self.w]);
            }
        }
        out
    }

    /// 2×2 max-pooling with stride 2, flooring odd sizes (burn's `max_pool2d` without padding).
    pub fn max_pool(&self) -> Planes {
        let (h, w) = (self.h / 2, self.w / 2);
        let mut out = Planes::zeros(self.c, h, w);
        for ch in 0..self.c {
            for y in 0..h {
                let (r0, r1) = (self.at(ch, 2 * y, 0), self.at(ch, 2 * y + 1, 0));
                let o = out.at(ch, y, 0);
                for x in 0..w {
                    let a = self.data[r0 + 2 * x].max(self.data[r0 + 2 * x + 1]);
                    let b = self.data[r1 + 2 * x].max(self.data[r1 + 2 * x + 1]);
                    out.data[o + x] = a.max(b);
                }
            }
        }
        out
    }

    /// Bilinear resampling to `h × w` with half-pixel centres (align_corners = false), with the
    /// coordinate arithmetic and the four-term sum of burn flex's `interpolate`, so the result is
    /// the same to the bit.
    pub fn upsample_to(&self, h: usize, w: usize) -> Planes {
        let taps = |n_in: usize, n_out: usize| -> Vec<(usize, usize, f32)> {
            let ratio = n_in as f64 / n_out as f64;
            (0..n_out)
                .map(|o| {
                    let c = (o as f64 + 0.5) * ratio - 0.5;
                    let lo = c.floor().max(0.0) as usize;
                    (lo, (lo + 1).min(n_in - 1), (c - lo as f64).max(0.0) as f32)
                })
                .collect()
        };
        let (ty, tx) = (taps(self.h, h), taps(self.w, w));
        let mut out = Planes::zeros(self.c, h, w);
        for ch in 0..self.c {
            for (y, &(y0, y1, wy)) in ty.iter().enumerate() {
                let (r0, r1) = (self.at(ch, y0, 0), self.at(ch, y1, 0));
                let o = out.at(ch, y, 0);
                for (x, &(x0, x1, wx)) in tx.iter().enumerate() {
                    let (a, b) = (self.data[r0 + x0], self.data[r0 + x1]);
                    let (c, d) = (self.data[r1 + x0], self.data[r1 + x1]);
                    out.data[o + x] = a * (1.0 - wx) * (1.0 - wy) + b * wx * (1.0 - wy) + c * (1.0 - wx) * wy + d * wx * wy;
                }
            }
        }
        out
    }
}
