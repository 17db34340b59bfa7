//! Piecewise-constant 1D and 2D distributions (pbrt's `PiecewiseConstant1D/2D`), used to pick
//! lights by power and environment texels by luminance.

use glam::Vec2;

/// Largest f32 below 1: sampled coordinates stay in [0, 1) so they index a valid cell.
pub(crate) const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Maps any input (NaN included) into [0, 1).
fn sanitize_u(u: f32) -> f32 {
    if u >= 0.0 {
        u.min(ONE_MINUS_EPSILON)
    } else {
        0.0
    }
}

/// A step function over `n` equal cells of [0, 1), sampled by inverting its CDF.
#[derive(Clone, Debug)]
pub(crate) struct Distribution1D {
    func: Vec<f32>,
    /// `n + 1` entries from 0 to 1.
    cdf: Vec<f32>,
    /// Sum of `func` (in f64 so that millions of small texels do not lose precision).
    sum: f64,
    /// `guide[k]`: the first index of `cdf` above k/n, for k in 0..=n (n cells). A u in
    /// [k/n, (k+1)/n) has its answer between `guide[k − 1]` and `guide[k + 2]` (one bucket of
    /// margin either side absorbs the rounding of u·n and k/n), so `find` searches that span
    /// instead of the whole CDF: the same index, a few steps instead of log₂ n.
    guide: Vec<u32>,
}

impl Distribution1D {
    /// Negative and non-finite weights count as 0. Returns `None` if nothing is positive.
    pub fn new(weights: impl IntoIterator<Item = f64>) -> Option<Distribution1D> {
        let func: Vec<f32> = weights.into_iter().map(|w| if w.is_finite() && w > 0.0 { (w as f32).min(f32::MAX) } else { 0.0 }).collect();
        let sum: f64 = func.iter().map(|&f| f as f64).sum();
        if !(sum > 0.0) || !sum.is_finite() {
            return None;
        }
        let mut cdf = Vec::with_capacity(func.len() + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0);
        for &f in &func {
            acc += f as f64;
            cdf.push((acc / sum) as f32);
        }
        // Rounding must not leave a gap at the top that a u close to 1 could fall into.
        *cdf.last_mut().unwrap() = 1.0;
        let n = func.len();
        let guide = (0..=n).map(|k| cdf.partition_point(|&c| c <= k as f32 / n as f32) as u32).collect();
        Some(Distribution1D { func, cdf, sum, guide })
    }

    pub fn func(&self, i: usize) -> f32 {
        self.func[i]
    }

    pub fn sum(&self) -> f64 {
        self.sum
    }

    /// Probability of cell `i` under discrete sampling.
    pub fn pmf(&self, i: usize) -> f32 {
        self.func.get(i).map_or(0.0, |&f| (f as f64 / self.sum) as f32)
    }

    fn find(&self, u: f32) -> usize {
        // Largest i with cdf[i] <= u: cells of zero weight have cdf[i] == cdf[i+1] and are skipped.
        let n = self.func.len();
        let k = ((u * n as f32) as usize).min(n);
        let (lo, hi) = (self.guide[k.saturating_sub(1)] as usize, self.guide[(k + 2).min(n)] as usize);
        let first_above = lo + self.cdf[lo..hi].partition_point(|&c| c <= u);
        first_above.saturating_sub(1).min(n - 1)
    }

    /// A cell index for discrete sampling, drawn with probability `pmf`; never a zero-weight
    /// cell. Callers that sample often keep a table of `pmf`, which costs an f64 division.
    pub fn sample_index(&self, u: f32) -> usize {
        self.find(sanitize_u(u))
    }

    /// A continuous position in [0, 1) and the cell it was drawn from.
    pub fn sample_continuous(&self, u: f32) -> (f32, usize) {
        let u = sanitize_u(u);
        let i = self.find(u);
        let (c0, c1) = (self.cdf[i], self.cdf[i + 1]);
        let du = if c1 > c0 { ((u - c0) / (c1 - c0)).clamp(0.0, 1.0) } else { 0.5 };
        let x = ((i as f32 + du) / self.func.len() as f32).min(ONE_MINUS_EPSILON);
        (x, i)
    }
}

/// A step function over a `width × height` grid on [0, 1)², row `y` covering v ∈ [y/h, (y+1)/h).
#[derive(Clone, Debug)]
pub(crate) struct Distribution2D {
    width: usize,
    height: usize,
    /// One conditional distribution over u per row; `None` for rows that are entirely zero.
    rows: Vec<Option<Distribution1D>>,
    marginal: Distribution1D,
    /// Sum of all weights: the density on [0,1)² is `f · width · height / total`.
    total: f64,
}

impl Distribution2D {
    /// `weights` is row-major, `width × height` long. `None` if nothing is positive.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Option<Distribution2D> {
        if width == 0 || height == 0 || weights.len() != width * height {
            return None;
        }
        let rows: Vec<Option<Distribution1D>> =
            weights.chunks_exact(width).map(|row| Distribution1D::new(row.iter().map(|&w| w as f64))).collect();
        let marginal = Distribution1D::new(rows.iter().map(|r| r.as_ref().map_or(0.0, |r| r.sum())))?;
        let total = marginal.sum();
        Some(Distribution2D { width, height, rows, marginal, total })
    }

    /// A point of [0,1)²; its density is `self.pdf(point)` up to the cell boundary rounding.
    pub fn sample(&self, u: Vec2) -> Vec2 {
        let (v, y) = self.marginal.sample_continuous(u.y);
        // The marginal never picks a zero row, but stay total if rounding ever does.
        let x = self.rows[y].as_ref().map_or(sanitize_u(u.x), |row| row.sample_continuous(u.x).0);
        Vec2::new(x, v)
    }

    /// Density on [0,1)² (integrates to 1) of the cell containing `uv`.
    pub fn pdf(&self, uv: Vec2) -> f32 {
        let (x, y) = self.cell(uv);
        let f = self.rows[y].as_ref().map_or(0.0, |row| row.func(x));
        (f as f64 * (self.width * self.height) as f64 / self.total) as f32
    }

    fn cell(&self, uv: Vec2) -> (usize, usize) {
        let x = if uv.x >= 0.0 { ((uv.x * self.width as f32) as usize).min(self.width - 1) } else { 0 };
        let y = if uv.y >= 0.0 { ((uv.y * self.height as f32) as usize).min(self.height - 1) } else { 0 };
        (x, y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The guided search returns the index the search over the whole CDF returns, for u at
    /// random and at every bucket edge k/n and its neighbouring floats, on distributions with
    /// runs of zero-weight cells and weights spanning 12 orders of magnitude.
    #[test]
    fn guided_search_finds_what_the_full_search_finds() {
        let mut rng = crate::rng::Pcg32::new(3, 5);
        for n in [1usize, 2, 3, 7, 64, 1000, 4097] {
            for trial in 0..4 {
                let weights: Vec<f64> = (0..n)
                    .map(|i| match (trial, i % 5) {
                        (1, 0 | 1) => 0.0,
                        (2, _) => 10f64.powi((rng.next_f32() * 12.0) as i32 - 6),
                        (3, _) if i > n / 3 => 0.0,
                        _ => rng.next_f32() as f64 + 1e-3,
                    })
                    .collect();
                let Some(d) = Distribution1D::new(weights) else { continue };
                let full = |u: f32| d.cdf.partition_point(|&c| c <= u).saturating_sub(1).min(n - 1);
                let mut us: Vec<f32> = (0..2000).map(|_| rng.next_f32()).collect();
                for k in 0..=n {
                    let e = k as f32 / n as f32;
                    us.extend([e, f32::from_bits(e.to_bits().saturating_sub(1)), f32::from_bits(e.to_bits() + 1)]);
                }
                us.extend(d.cdf.iter().copied());
                for u in us {
                    let u = sanitize_u(u);
                    assert_eq!(d.find(u), full(u), "n {n} trial {trial} u {u}");
                }
            }
        }
    }
}
