//! Image error metrics of method.md §7.3: test relMSE after tone mapping, 1 − SSIM, and the
//! validation relMSE on linear radiance.
//!
//! Images are interleaved RGB `[H, W, 3]` (the layout of `Frame::radiance.mean`). Every function
//! returns a finite number whatever the input: NaN counts as 0 and ±Inf as ±1e30 before anything
//! else (the paper's code drops NaN terms instead; a finite renderer and denoiser never produce
//! them, so the choice only matters for broken inputs, which must not poison an average).

/// ε of the test relMSE denominator.
pub const REL_MSE_EPS: f64 = 1e-4;
/// ε of the validation relMSE denominator.
pub const REL_MSE_VAL_EPS: f64 = 0.01;
/// SSIM window side (scikit-image default).
pub const SSIM_WINDOW: usize = 7;
pub const SSIM_K1: f64 = 0.01;
pub const SSIM_K2: f64 = 0.03;
/// SSIM data range. Tone-mapped images lie in [0, 1], so 1 is the correct range. (scikit-image's
/// old default for float input was 2, which makes C1, C2 four times larger and 1 − SSIM smaller;
/// method.md §7.3 leaves the choice to us as long as it is stated.)
pub const SSIM_DATA_RANGE: f64 = 1.0;
/// Pixels skipped at every image border by the evaluation (the paper's 28 = 18 + 10 came from
/// its valid-convolution tiling; our tiles cover the whole image, so no crop is needed and 0 is
/// the default — the option exists to reproduce the paper's protocol).
pub const DEFAULT_BORDER: usize = 0;

/// Tone maps of method.md §7.3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToneMap {
    /// (a): c / (1 + lum(c)/1.5), clamp ≥ 0, ^(1/2.2), clip to [0, 1]; lum = Rec. 709 weights.
    Paper,
    /// clip(max(c, 0)^(1/2.2), 0, 1) (Xu et al.'s convention).
    Gamma,
    /// No tone map (linear radiance).
    Linear,
}

fn clean(x: f32) -> f64 {
    if x.is_nan() {
        0.0
    } else {
        (x as f64).clamp(-1e30, 1e30)
    }
}

/// Tone-maps an interleaved RGB image into f64.
pub fn tonemap(rgb: &[f32], map: ToneMap) -> Vec<f64> {
    let mut out = Vec::with_capacity(rgb.len());
    for p in rgb.chunks(3) {
        let c = [clean(p[0]), clean(p.get(1).copied().unwrap_or(0.0)), clean(p.get(2).copied().unwrap_or(0.0))];
        match map {
            ToneMap::Paper => {
                let c = c.map(|v| v.max(0.0));
                let lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                out.extend(c.iter().map(|v| (v / (1.0 + lum / 1.5)).powf(1.0 / 2.2).clamp(0.0, 1.0)));
            }
            ToneMap::Gamma => out.extend(c.iter().map(|v| v.max(0.0).powf(1.0 / 2.2).clamp(0.0, 1.0))),
            ToneMap::Linear => out.extend(c),
        }
    }
    out.truncate(rgb.len());
    out
}

/// Interleaved RGB values of the image with `border` pixels removed on every side.
fn crop(v: &[f64], w: usize, h: usize, border: usize) -> (Vec<f64>, usize, usize) {
    if 2 * border >= w || 2 * border >= h {
        return (Vec::new(), 0, 0);
    }
    let (cw, ch) = (w - 2 * border, h - 2 * border);
    let mut out = Vec::with_capacity(3 * cw * ch);
    for y in border..h - border {
        out.extend_from_slice(&v[3 * (y * w + border)..3 * (y * w + w - border)]);
    }
    (out, cw, ch)
}

fn check(x: &[f32], y: &[f32], w: usize, h: usize) {
    assert!(x.len() == 3 * w * h && y.len() == 3 * w * h, "images must be {w}×{h} RGB");
}

/// Test relMSE: mean over pixels and channels of (x − y)² / (y² + 1e-4) after `map`, with
/// `border` pixels skipped per side; `y` is the reference. 0 for an empty crop.
pub fn rel_mse(x: &[f32], y: &[f32], w: usize, h: usize, map: ToneMap, border: usize) -> f64 {
    check(x, y, w, h);
    let (a, _, _) = crop(&tonemap(x, map), w, h, border);
    let (b, _, _) = crop(&tonemap(y, map), w, h, border);
    if a.is_empty() {
        return 0.0;
    }
    let s: f64 = a.iter().zip(&b).map(|(x, y)| (x - y).powi(2) / (y * y + REL_MSE_EPS)).sum();
    (s / a.len() as f64).min(1e300)
}

/// Per-pixel test relMSE: for each pixel the mean over its three channels of (x − y)² / (y² + 1e-4)
/// after `map`, `[H, W]` in reading order; `y` is the reference. Its mean is [`rel_mse`] without
/// border, so sums of it over any set of pixels rank images the way the page's relMSE does (the
/// block oracle of `pixguide eval` and the error maps of its pictures).
pub fn rel_mse_map(x: &[f32], y: &[f32], w: usize, h: usize, map: ToneMap) -> Vec<f64> {
    check(x, y, w, h);
    let (a, b) = (tonemap(x, map), tonemap(y, map));
    a.chunks(3)
        .zip(b.chunks(3))
        .map(|(p, q)| p.iter().zip(q).map(|(x, y)| (x - y).powi(2) / (y * y + REL_MSE_EPS)).sum::<f64>() / 3.0)
        .collect()
}

/// Validation relMSE: ½ · mean (x − y)² / (y² + 0.01) on linear radiance (any layout; `y` is
/// the reference).
pub fn rel_mse_val(x: &[f32], y: &[f32]) -> f64 {
    assert_eq!(x.len(), y.len(), "images must have the same size");
    if x.is_empty() {
        return 0.0;
    }
    let s: f64 = x
        .iter()
        .zip(y)
        .map(|(&x, &y)| {
            let (x, y) = (clean(x), clean(y));
            (x - y).powi(2) / (y * y + REL_MSE_VAL_EPS)
        })
        .sum();
    (0.5 * s / x.len() as f64).min(1e300)
}

/// Sums of every `k × k` window of a `w × h` plane: `(w−k+1) × (h−k+1)` values.
fn box_sums(p: &[f64], w: usize, h: usize, k: usize) -> Vec<f64> {
    let ow = w - k + 1;
    let mut rows = vec![0.0; ow * h];
    for y in 0..h {
        let r = &p[y * w..(y + 1) * w];
        let mut s: f64 = r[..k].iter().sum();
        rows[y * ow] = s;
        for x in 1..ow {
            s += r[x + k - 1] - r[x - 1];
            rows[y * ow + x] = s;
        }
    }
    let oh = h - k + 1;
    let mut out = vec![0.0; ow * oh];
    for x in 0..ow {
        let mut s: f64 = (0..k).map(|y| rows[y * ow + x]).sum();
        out[x] = s;
        for y in 1..oh {
            s += rows[(y + k - 1) * ow + x] - rows[(y - 1) * ow + x];
            out[y * ow + x] = s;
        }
    }
    out
}

/// Mean SSIM of one plane pair, windows fully inside the image only (what scikit-image keeps
/// after discarding its padded border). Window `k` ≤ min(w, h), odd.
fn ssim_plane(a: &[f64], b: &[f64], w: usize, h: usize, k: usize, range: f64) -> f64 {
    let n = (k * k) as f64;
    let cov_norm = if k > 1 { n / (n - 1.0) } else { 1.0 };
    let prod = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { (0..w * h).map(f).collect() };
    let sa = box_sums(a, w, h, k);
    let sb = box_sums(b, w, h, k);
    let saa = box_sums(&prod(&|i| a[i] * a[i]), w, h, k);
    let sbb = box_sums(&prod(&|i| b[i] * b[i]), w, h, k);
    let sab = box_sums(&prod(&|i| a[i] * b[i]), w, h, k);
    let c1 = (SSIM_K1 * range).powi(2);
    let c2 = (SSIM_K2 * range).powi(2);
    let mut total = 0.0;
    for i in 0..sa.len() {
        let (ux, uy) = (sa[i] / n, sb[i] / n);
        let vx = cov_norm * (saa[i] / n - ux * ux);
        let vy = cov_norm * (sbb[i] / n - uy * uy);
        let vxy = cov_norm * (sab[i] / n - ux * uy);
        let s = (2.0 * ux * uy + c1) * (2.0 * vxy + c2) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
        total += s;
    }
    total / sa.len() as f64
}

/// SSIM of two interleaved RGB images already in [0, `range`]: 7×7 uniform window, sample
/// covariance, K1 0.01, K2 0.03, mean over valid windows and then over channels (scikit-image
/// `structural_similarity(..., channel_axis=-1, data_range=range)`). An image smaller than
/// 7 pixels uses the largest odd window that fits. 1 for an empty image.
pub fn ssim_rgb(x: &[f64], y: &[f64], w: usize, h: usize, range: f64) -> f64 {
    if w == 0 || h == 0 {
        return 1.0;
    }
    let k = SSIM_WINDOW.min(w).min(h);
    let k = if k.is_multiple_of(2) { k - 1 } else { k };
    let plane = |v: &[f64], c: usize| -> Vec<f64> { (0..w * h).map(|i| v[3 * i + c]).collect() };
    let s: f64 = (0..3).map(|c| ssim_plane(&plane(x, c), &plane(y, c), w, h, k, range)).sum::<f64>() / 3.0;
    if s.is_finite() {
        s
    } else {
        0.0
    }
}

/// 1 − SSIM after `map` (normally [`ToneMap::Paper`]) with `border` pixels skipped, data range
/// [`SSIM_DATA_RANGE`].
pub fn one_minus_ssim(x: &[f32], y: &[f32], w: usize, h: usize, map: ToneMap, border: usize) -> f64 {
    check(x, y, w, h);
    let (a, cw, ch) = crop(&tonemap(x, map), w, h, border);
    let (b, _, _) = crop(&tonemap(y, map), w, h, border);
    1.0 - ssim_rgb(&a, &b, cw, ch, SSIM_DATA_RANGE)
}

/// The errors reported for one image against its reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Errors {
    /// relMSE after tone map (a).
    pub rel_mse: f64,
    /// relMSE after plain gamma.
    pub rel_mse_gamma: f64,
    /// 1 − SSIM after tone map (a).
    pub one_minus_ssim: f64,
}

pub fn evaluate(x: &[f32], reference: &[f32], w: usize, h: usize, border: usize) -> Errors {
    Errors {
        rel_mse: rel_mse(x, reference, w, h, ToneMap::Paper, border),
        rel_mse_gamma: rel_mse(x, reference, w, h, ToneMap::Gamma, border),
        one_minus_ssim: one_minus_ssim(x, reference, w, h, ToneMap::Paper, border),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize, f: impl Fn(usize, usize, usize) -> f32) -> Vec<f32> {
        (0..w * h * 3).map(|i| f((i / 3) % w, (i / 3) / w, i % 3)).collect()
    }

    #[test]
    fn identical_images_score_perfectly() {
        let (w, h) = (13, 9);
        let x = ramp(w, h, |x, y, c| (x * 7 + y * 3 + c) as f32 * 0.05);
        let e = evaluate(&x, &x, w, h, 2);
        assert_eq!(e.rel_mse, 0.0);
        assert_eq!(e.rel_mse_gamma, 0.0);
        assert!(e.one_minus_ssim.abs() < 1e-12, "{}", e.one_minus_ssim);
        assert_eq!(rel_mse_val(&x, &x), 0.0);
    }

    /// Hand case for the tone map and relMSE: one pixel, x = (1, 0, 0), y = (0.5, 0.5, 0.5).
    /// Map (a): lum(x) = 0.2126 → x' = (1/1.14173…)^(1/2.2) = 0.941530…, 0, 0;
    /// lum(y) = 0.5 → y' = (0.5/1.33333…)^(1/2.2) = 0.640292… for every channel.
    /// relMSE = mean[(0.941530−0.640292)²/(0.640292² + 1e-4), 0.640292²/(…), 0.640292²/(…)]
    /// = 0.740267… (pure-Python evaluation of the same formula).
    /// Gamma: x' = (1, 0, 0), y' = 0.5^(1/2.2) = 0.729740…; relMSE = 0.712253….
    /// relMSE_val: ½·mean[0.25, 0.25, 0.25]/(0.25 + 0.01) = 0.480769….
    #[test]
    fn rel_mse_hand_case() {
        let x = [1.0, 0.0, 0.0];
        let y = [0.5, 0.5, 0.5];
        let t = tonemap(&x, ToneMap::Paper);
        assert!((t[0] - 0.941530).abs() < 1e-5, "{t:?}");
        let r = rel_mse(&x, &y, 1, 1, ToneMap::Paper, 0);
        assert!((r - 0.740267).abs() < 1e-5, "{r}");
        let g = rel_mse(&x, &y, 1, 1, ToneMap::Gamma, 0);
        assert!((g - 0.712253).abs() < 1e-5, "{g}");
        let v = rel_mse_val(&x, &y);
        assert!((v - 0.480769).abs() < 1e-5, "{v}");
        // Border: a 5×5 image with a wrong border ring and a correct 3×3 centre scores 0.
        let (w, h) = (5, 5);
        let good = ramp(w, h, |_, _, _| 0.3);
        let bad = ramp(w, h, |x, y, _| if x == 0 || y == 0 || x == 4 || y == 4 { 9.0 } else { 0.3 });
        assert_eq!(rel_mse(&bad, &good, w, h, ToneMap::Paper, 1), 0.0);
        assert!(rel_mse(&bad, &good, w, h, ToneMap::Paper, 0) > 0.1);
    }

    /// Hand case for SSIM: one 7×7 window (a 7×7 image) per channel, x[i] = i/48 and
    /// y[i] = (i/48)² for i = 0..49 in row-major order, the same in all three channels, data range 1.
    /// Closed form with sample covariance (divide by 48): μx = 0.5, μy = 0.336806, σx² = 0.088614,
    /// σy² = 0.094760, σxy = 0.088614 → SSIM = 0.895832 (pure-Python evaluation).
    #[test]
    fn ssim_hand_case() {
        let (w, h) = (7, 7);
        let x: Vec<f64> = (0..49 * 3).map(|i| (i / 3) as f64 / 48.0).collect();
        let y: Vec<f64> = x.iter().map(|v| v * v).collect();
        let s = ssim_rgb(&x, &y, w, h, 1.0);
        assert!((s - 0.895832).abs() < 1e-5, "{s}");
        // A larger image averages windows: a constant offset of 0.1 on a constant image gives
        // (2·0.2·0.3 + C1)/(0.04 + 0.09 + C1) in every window (variances are 0).
        let (w, h) = (12, 10);
        let a = vec![0.2; 3 * w * h];
        let b = vec![0.3; 3 * w * h];
        let c1 = 1e-4;
        let expect = (0.12 + c1) / (0.13 + c1);
        assert!((ssim_rgb(&a, &b, w, h, 1.0) - expect).abs() < 1e-12);
    }

    /// The map is the relMSE pixel by pixel: its mean is the image's relMSE (the oracle of
    /// `pixguide eval` relies on it to rank blocks as the page ranks images).
    #[test]
    fn rel_mse_map_averages_to_rel_mse() {
        let (w, h) = (11, 6);
        let x = ramp(w, h, |x, y, c| (x * 3 + y * 5 + c) as f32 * 0.07);
        let y = ramp(w, h, |x, y, c| ((x + y + 2 * c) % 5) as f32 * 0.3);
        let m = rel_mse_map(&x, &y, w, h, ToneMap::Paper);
        assert_eq!(m.len(), w * h);
        let mean = m.iter().sum::<f64>() / m.len() as f64;
        let r = rel_mse(&x, &y, w, h, ToneMap::Paper, 0);
        assert!((mean - r).abs() <= 1e-12 * r, "{mean} vs {r}");
        // One pixel of the hand case above: 0.740267….
        let one = rel_mse_map(&[1.0, 0.0, 0.0], &[0.5, 0.5, 0.5], 1, 1, ToneMap::Paper);
        assert!((one[0] - 0.740267).abs() < 1e-5, "{one:?}");
    }

    #[test]
    fn finite_on_hostile_input() {
        let (w, h) = (8, 8);
        let specials = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, 0.0, -5.0];
        let x: Vec<f32> = (0..3 * w * h).map(|i| specials[i % 6]).collect();
        let y: Vec<f32> = (0..3 * w * h).map(|i| specials[(i + 1) % 6]).collect();
        for map in [ToneMap::Paper, ToneMap::Gamma, ToneMap::Linear] {
            assert!(rel_mse(&x, &y, w, h, map, 0).is_finite());
            assert!(one_minus_ssim(&x, &y, w, h, map, 0).is_finite());
        }
        assert!(rel_mse_val(&x, &y).is_finite());
        // Degenerate sizes: tiny images and a crop that removes everything.
        assert!(one_minus_ssim(&x[..12], &y[..12], 2, 2, ToneMap::Paper, 0).is_finite());
        assert_eq!(rel_mse(&x, &y, w, h, ToneMap::Paper, 4), 0.0);
    }
}
