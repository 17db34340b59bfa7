//! Patch positions: the importance map of method.md §7.2, sampling from it, and the fixed
//! validation grid.
//!
//! The reference code blurs with σ = 31 px on 1280² renders; our shots are ~128², so σ is
//! given by the caller (`sigma_for`: 31 px scaled by the image size, at least 1 px).

use crate::rng::SplitMix64;

/// Bounce-type flags of method.md §1.1.
pub const DIFFUSE: u32 = 4;
pub const GLOSSY: u32 = 8;
pub const SPECULAR: u32 = 16;

/// σ of the blur before the gradient: 31 px at 1280 px, scaled to `size`, at least 1 px.
pub fn sigma_for(width: usize, height: usize) -> f64 {
    (31.0 * width.min(height) as f64 / 1280.0).max(1.0)
}

/// Separable Gaussian blur of a single-channel image, clamp-to-edge, truncated at 3σ.
pub fn gaussian_blur(img: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as isize;
    let k: Vec<f64> = (-r..=r).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp()).collect();
    let ks: f64 = k.iter().sum();
    let pass = |src: &[f32], horizontal: bool| -> Vec<f32> {
        let mut out = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0f64;
                for (j, kv) in k.iter().enumerate() {
                    let o = j as isize - r;
                    let (sx, sy) = if horizontal {
                        ((x as isize + o).clamp(0, w as isize - 1) as usize, y)
                    } else {
                        (x, (y as isize + o).clamp(0, h as isize - 1) as usize)
                    };
                    acc += kv * src[sy * w + sx] as f64;
                }
                out[y * w + x] = (acc / ks) as f32;
            }
        }
        out
    };
    pass(&pass(img, true), false)
}

/// Sobel gradient magnitude (clamp-to-edge).
pub fn sobel_magnitude(img: &[f32], w: usize, h: usize) -> Vec<f32> {
    let at = |x: isize, y: isize| img[(y.clamp(0, h as isize - 1) as usize) * w + x.clamp(0, w as isize - 1) as usize];
    let mut out = vec![0.0; w * h];
    for y in 0..h as isize {
        for x in 0..w as isize {
            let gx =
                (at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)) - (at(x - 1, y - 1) + 2.0 * at(x - 1, y) + at(x - 1, y + 1));
            let gy =
                (at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)) - (at(x - 1, y - 1) + 2.0 * at(x, y - 1) + at(x + 1, y - 1));
            out[y as usize * w + x as usize] = (gx * gx + gy * gy).sqrt();
        }
    }
    out
}

/// Min-max normalisation to [0, 1]; a constant (or non-finite) image becomes all zeros.
pub fn min_max(v: &mut [f32]) {
    let (lo, hi) = v.iter().filter(|x| x.is_finite()).fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let span = hi - lo;
    for x in v.iter_mut() {
        *x = if span > 0.0 && x.is_finite() { (*x - lo) / span } else { 0.0 };
    }
}

/// G(·) of method.md §7.2: gradient magnitude of the blurred image, min-max normalised.
fn edge_term(img: &[f32], w: usize, h: usize, sigma: f64) -> Vec<f32> {
    let mut g = sobel_magnitude(&gaussian_blur(img, w, h, sigma), w, h);
    min_max(&mut g);
    g
}

/// The per-pixel importance map M = 0.3·G(luminance of the tone-mapped reference)
/// + 0.2·G(mean normal·½+½) + 0.5·(diffuse₀ + 4·glossy₀ + 2·specular₀)/7.
///
/// `reference` and `normal` are interleaved RGB / XYZ per pixel; `bounce0` are the per-pixel
/// fractions of samples whose first bounce has the diffuse, glossy, specular flag. The normal
/// term uses the mean of the three channels after ·½+½ (one image, as the reference code's
/// single-channel gradient does).
pub fn importance_map(reference: &[f32], normal: &[f32], bounce0: &[[f32; 3]], w: usize, h: usize, sigma: f64) -> Vec<f32> {
    let n = w * h;
    let lum = |c: &[f32]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
    let tone: Vec<f32> = (0..n)
        .map(|i| {
            let c = &reference[3 * i..3 * i + 3];
            let l = lum(c).max(0.0);
            let t: Vec<f32> = c.iter().map(|&v| (v.max(0.0) / (1.0 + l / 1.5)).powf(1.0 / 2.2).clamp(0.0, 1.0)).collect();
            let v = lum(&t);
            if v.is_finite() {
                v
            } else {
                0.0
            }
        })
        .collect();
    let nimg: Vec<f32> = (0..n)
        .map(|i| {
            let v = (normal[3 * i] + normal[3 * i + 1] + normal[3 * i + 2]) / 3.0 * 0.5 + 0.5;
            if v.is_finite() {
                v
            } else {
                0.5
            }
        })
        .collect();
    let gt = edge_term(&tone, w, h, sigma);
    let gn = edge_term(&nimg, w, h, sigma);
    (0..n)
        .map(|i| {
            let [d, g, s] = bounce0[i];
            0.3 * gt[i] + 0.2 * gn[i] + 0.5 * (d + 4.0 * g + 2.0 * s) / 7.0
        })
        .collect()
}

/// How patch corners are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    Importance,
    Uniform,
}

impl Sampling {
    pub const ALL: [Sampling; 2] = [Sampling::Importance, Sampling::Uniform];

    pub fn name(self) -> &'static str {
        match self {
            Sampling::Importance => "importance",
            Sampling::Uniform => "uniform",
        }
    }
}

crate::names::named!(Sampling, "patch sampling");

/// Draws top-left corners of `patch`² windows inside a `w × h` image.
#[derive(Clone, Debug)]
pub struct PatchSampler {
    /// Positions per row: w − patch + 1.
    nx: usize,
    /// Cumulative weights over the (w − patch + 1)·(h − patch + 1) corners; empty = uniform.
    cdf: Vec<f64>,
    ny: usize,
}

impl PatchSampler {
    pub fn uniform(w: usize, h: usize, patch: usize) -> Self {
        PatchSampler { nx: w + 1 - patch, ny: h + 1 - patch, cdf: Vec::new() }
    }

    /// A corner's weight is the map at the patch centre (the reference code crops M by half a
    /// patch per side and uses the index as the corner). Falls back to uniform when the map has
    /// no positive finite mass.
    pub fn from_map(map: &[f32], w: usize, h: usize, patch: usize) -> Self {
        let (nx, ny) = (w + 1 - patch, h + 1 - patch);
        let c = patch / 2;
        let mut cdf = Vec::with_capacity(nx * ny);
        let mut acc = 0.0f64;
        for y in 0..ny {
            for x in 0..nx {
                let v = map[(y + c) * w + x + c];
                acc += if v.is_finite() && v > 0.0 { v as f64 } else { 0.0 };
                cdf.push(acc);
            }
        }
        if !(acc > 0.0 && acc.is_finite()) {
            cdf.clear();
        }
        PatchSampler { nx, ny, cdf }
    }

    /// Probability of each corner, row-major (a pmf: non-negative, sums to 1).
    pub fn pmf(&self) -> Vec<f64> {
        let n = self.nx * self.ny;
        if self.cdf.is_empty() {
            return vec![1.0 / n as f64; n];
        }
        let total = *self.cdf.last().unwrap();
        let mut prev = 0.0;
        self.cdf
            .iter()
            .map(|&c| {
                let p = (c - prev) / total;
                prev = c;
                p
            })
            .collect()
    }

    pub fn sample(&self, rng: &mut SplitMix64) -> (usize, usize) {
        let i = if self.cdf.is_empty() {
            rng.below(self.nx * self.ny)
        } else {
            let u = rng.next_f64() * self.cdf.last().unwrap();
            self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1)
        };
        (i % self.nx, i / self.nx)
    }
}

/// Non-overlapping `patch`² windows covering the image from the top-left (method.md §7.2's
/// validation grid); a remainder narrower than a patch is left out.
pub fn grid(w: usize, h: usize, patch: usize) -> Vec<(usize, usize)> {
    let mut v = Vec::new();
    for y in (0..=h.saturating_sub(patch)).step_by(patch) {
        for x in (0..=w.saturating_sub(patch)).step_by(patch) {
            if x + patch <= w && y + patch <= h {
                v.push((x, y));
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic 96² image: left half flat grey, right half a black/white checkerboard of
    /// 8-px squares (so edges everywhere there). The map must be a valid pmf and put clearly
    /// more mass on corners whose patch lies in the edged half.
    #[test]
    fn importance_map_is_a_pmf_and_favours_edges() {
        let (w, h, p) = (96, 96, 32);
        let mut reference = vec![0.0f32; 3 * w * h];
        let normal = vec![0.0f32; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                let v = if x < w / 2 {
                    0.5
                } else if ((x / 8) + (y / 8)) % 2 == 0 {
                    2.0
                } else {
                    0.0
                };
                reference[3 * (y * w + x)..3 * (y * w + x) + 3].fill(v);
            }
        }
        let bounce = vec![[1.0, 0.0, 0.0]; w * h];
        let m = importance_map(&reference, &normal, &bounce, w, h, 1.5);
        assert!(m.iter().all(|v| v.is_finite() && *v >= 0.0));
        let s = PatchSampler::from_map(&m, w, h, p);
        let pmf = s.pmf();
        assert_eq!(pmf.len(), (w - p + 1) * (h - p + 1));
        assert!(pmf.iter().all(|&q| q >= 0.0));
        let total: f64 = pmf.iter().sum();
        assert!((total - 1.0).abs() < 1e-9, "pmf sums to {total}");
        let nx = w - p + 1;
        // Corners whose patch is entirely in the flat half (x + p ≤ 48) vs entirely in the
        // checkerboard (x ≥ 48): both sets have 17 columns, so equal mass would mean no
        // preference. The flat side still carries the constant bounce term (0.5/7), hence a
        // factor 2 rather than "zero on the flat side".
        let mass = |f: &dyn Fn(usize) -> bool| -> f64 { pmf.iter().enumerate().filter(|(i, _)| f(i % nx)).map(|(_, q)| q).sum() };
        let flat = mass(&|x| x + p <= w / 2);
        let edged = mass(&|x| x >= w / 2);
        assert!(edged > 2.0 * flat, "edged {edged} vs flat {flat}");
        // Draws follow the pmf: the empirical share of edged corners matches within 4σ of a
        // binomial at 20 000 draws (σ ≤ 0.0036).
        let mut rng = SplitMix64::new(3);
        let n = 20_000;
        let hits = (0..n).filter(|_| s.sample(&mut rng).0 >= w / 2).count() as f64 / n as f64;
        assert!((hits - edged).abs() < 4.0 * 0.0036, "drawn {hits} vs pmf {edged}");
    }

    #[test]
    fn empty_map_falls_back_to_uniform_and_grid_tiles() {
        let s = PatchSampler::from_map(&vec![0.0; 40 * 30], 40, 30, 10);
        let pmf = s.pmf();
        assert!(pmf.iter().all(|&q| (q - pmf[0]).abs() < 1e-15));
        let mut rng = SplitMix64::new(1);
        for _ in 0..100 {
            let (x, y) = s.sample(&mut rng);
            assert!(x + 10 <= 40 && y + 10 <= 30);
        }
        assert_eq!(grid(40, 30, 10).len(), 12);
        assert_eq!(grid(130, 128, 64), vec![(0, 0), (64, 0), (0, 64), (64, 64)]);
    }
}
