//! The block-oracle bounds of `pixguide eval`: how low the error of a per-pixel choice among
//! some experts' outputs could go. For each 8×8 block the oracle keeps whichever expert is
//! closer to the reference there, so it uses the reference: a bound on what a gate such as E
//! could gain by choosing among those outputs, not a method.
//!
//! Generic over the experts: a bound is a list of image names (a method's output is stored under
//! the method's name; a method may store more, e.g. a guided model's own expert outputs under
//! `<method>:<name>`), and [`block_oracle`] takes any number of images.

use super::methods::MethodSpec;
use anyhow::{bail, Result};
use denoiser::metrics::{self, ToneMap};

/// Side of the oracle's blocks, in pixels.
pub const BLOCK: usize = 8;

/// The image a block oracle assembled.
#[derive(Debug)]
pub struct Oracle {
    /// Interleaved RGB `[H, W, 3]`, each block copied from its chosen expert.
    pub image: Vec<f32>,
    /// Share of the image's pixels taken from each expert, in the experts' order (sums to 1).
    pub share: Vec<f64>,
}

/// Cuts the `w × h` image into `block × block` blocks (those on the right and bottom edges cut
/// short by the image) and fills each with the pixels of the expert whose summed per-pixel
/// relMSE after tone map (a) against `reference` over the block is lowest: the page's relMSE
/// restricted to the block, so the choice ranks experts the way the page does. Ties go to the
/// expert listed first. Images are interleaved RGB.
pub fn block_oracle(experts: &[&[f32]], reference: &[f32], w: usize, h: usize, block: usize) -> Result<Oracle> {
    if experts.is_empty() {
        bail!("block oracle: no expert images");
    }
    if block == 0 || w == 0 || h == 0 {
        bail!("block oracle: empty image ({w}×{h}) or block ({block})");
    }
    let n = 3 * w * h;
    if reference.len() != n {
        bail!("block oracle: the reference has {} values, expected {n} ({w}×{h} RGB)", reference.len());
    }
    if let Some((k, e)) = experts.iter().enumerate().find(|(_, e)| e.len() != n) {
        bail!("block oracle: expert {k} has {} values, expected {n} ({w}×{h} RGB)", e.len());
    }
    let maps: Vec<Vec<f64>> = experts.iter().map(|e| metrics::rel_mse_map(e, reference, w, h, ToneMap::Paper)).collect();
    let mut image = vec![0.0f32; n];
    let mut pixels = vec![0usize; experts.len()];
    for by in (0..h).step_by(block) {
        for bx in (0..w).step_by(block) {
            let (y1, x1) = ((by + block).min(h), (bx + block).min(w));
            let err = |m: &[f64]| -> f64 { (by..y1).map(|y| m[y * w + bx..y * w + x1].iter().sum::<f64>()).sum() };
            let mut best = (0, err(&maps[0]));
            for (k, m) in maps.iter().enumerate().skip(1) {
                let e = err(m);
                if e < best.1 {
                    best = (k, e);
                }
            }
            for y in by..y1 {
                let r = 3 * (y * w + bx)..3 * (y * w + x1);
                image[r.clone()].copy_from_slice(&experts[best.0][r]);
            }
            pixels[best.0] += (y1 - by) * (x1 - bx);
        }
    }
    let share = pixels.iter().map(|&p| p as f64 / (w * h) as f64).collect();
    Ok(Oracle { image, share })
}

/// One bound of the page: the block oracle over the named images.
pub struct BoundSpec {
    /// Name in the cache keys ("bound-g-p").
    pub name: String,
    /// Images it chooses among: method names, or `<method>:<image>` for an image a method's run
    /// stores besides its output.
    pub experts: Vec<String>,
    /// Identity of the inputs: the experts' producing methods' weight ids, joined; a new weight
    /// file makes the bound stale like the method's own scores.
    pub id: String,
}

impl BoundSpec {
    /// Label in tables: says it is a bound, over what, and that it uses the reference.
    pub fn label(&self) -> String {
        format!("bound: best of {} per {BLOCK}×{BLOCK} block (uses the reference)", self.experts.join(", "))
    }
    /// Label in plots.
    pub fn short_label(&self) -> String {
        format!("bound {} {BLOCK}×{BLOCK} (uses ref.)", self.experts.join("/"))
    }
}

/// The method whose run produces the image `name`.
pub fn producer(name: &str) -> &str {
    name.split(':').next().unwrap_or(name)
}

/// The bounds the page shows: every set below whose producing methods are all measured in this
/// run. New sets (e.g. a guided model's own expert outputs) are one line here.
pub fn bounds(methods: &[MethodSpec]) -> Vec<BoundSpec> {
    const SETS: [&[&str]; 2] = [&["g", "p"], &["oidn", "g", "p"]];
    let mut out = Vec::new();
    for set in SETS {
        let ids: Option<Vec<&str>> =
            set.iter().map(|e| methods.iter().find(|m| m.name() == producer(e) && m.available()).map(|m| m.id.as_str())).collect();
        if let Some(ids) = ids {
            out.push(BoundSpec {
                name: format!("bound-{}", set.join("-").replace(':', "_")),
                experts: set.iter().map(|e| e.to_string()).collect(),
                id: ids.join("+"),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(v: &[f32]) -> Vec<f32> {
        v.iter().flat_map(|&x| [x, x, x]).collect()
    }

    /// Tone map (a) of a grey pixel of value v: lum = v, so v' = (v / (1 + v/1.5))^(1/2.2).
    fn tm(v: f64) -> f64 {
        (v / (1.0 + v / 1.5)).powf(1.0 / 2.2)
    }

    fn rel(x: f64, y: f64) -> f64 {
        let (a, b) = (tm(x), tm(y));
        (a - b).powi(2) / (b * b + 1e-4)
    }

    /// Three grey pixels in a row, reference (1, 1, 1); expert A = (1, 1, 3), expert B =
    /// (2, 2, 1). Per pixel A is exact on the first two and B on the third.
    /// - Blocks of 1 pixel: each pixel from its exact expert, relMSE 0.
    /// - Blocks of 2 pixels: block {0, 1}: A errs 0, B 2·e(2) → A; block {2}: A errs e(3), B 0 →
    ///   B. relMSE 0 as well (the blocks fall on the split).
    /// - One block of 3 pixels: A's sum is e(3), B's 2·e(2), with e(v) = (tm(v) − tm(1))² /
    ///   (tm(1)² + 1e-4) and tm(v) = (v / (1 + v/1.5))^(1/2.2) (grey pixels: lum = v).
    ///   tm(1) = 0.792793, tm(2) = 0.932330, tm(3) = 1 → e(3) = 0.068300, e(2) = 0.030974, so
    ///   2·e(2) = 0.061947 < e(3): the block goes to B whole, and the image's relMSE is
    ///   2·e(2)/3 = 0.020649 (a per-pixel choice would give 0; choosing by the worst pixel
    ///   rather than the block's sum would pick A, 0.022767).
    #[test]
    fn three_pixel_hand_case() {
        let reference = grey(&[1.0, 1.0, 1.0]);
        let a = grey(&[1.0, 1.0, 3.0]);
        let b = grey(&[2.0, 2.0, 1.0]);
        // The hand figures of the comment, from the formula.
        assert!((tm(1.0) - 0.792793).abs() < 1e-6 && (tm(2.0) - 0.932330).abs() < 1e-6 && (tm(3.0) - 1.0).abs() < 1e-12);
        assert!((rel(3.0, 1.0) - 0.068300).abs() < 1e-6 && (rel(2.0, 1.0) - 0.030974).abs() < 1e-6);

        for block in [1, 2] {
            let o = block_oracle(&[&a, &b], &reference, 3, 1, block).unwrap();
            assert_eq!(o.image, grey(&[1.0, 1.0, 1.0]), "block {block}");
            assert_eq!(o.share, vec![2.0 / 3.0, 1.0 / 3.0]);
        }
        let o = block_oracle(&[&a, &b], &reference, 3, 1, 3).unwrap();
        assert_eq!(o.image, b, "the whole block goes to B");
        assert_eq!(o.share, vec![0.0, 1.0]);
        let r = metrics::rel_mse(&o.image, &reference, 3, 1, ToneMap::Paper, 0);
        assert!((r - 0.020649).abs() < 1e-6, "{r}");
        // The order of the experts does not matter when there is no tie.
        let o2 = block_oracle(&[&b, &a], &reference, 3, 1, 3).unwrap();
        assert_eq!(o2.image, b);
        assert_eq!(o2.share, vec![1.0, 0.0]);
    }

    /// On a 16×8 image two 8×8 blocks; inside each, expert A is better on most pixels but B on
    /// a few whose error is larger, so B wins one block as a whole. A per-pixel choice (or
    /// blocks of another size) gives a different image and a lower error: fails if the oracle
    /// chooses by pixel, by row, or ignores the block grid.
    #[test]
    fn chooses_per_block_not_per_pixel() {
        let (w, h) = (16, 8);
        let reference = vec![0.5f32; 3 * w * h];
        let mut a = reference.clone();
        let mut b = reference.clone();
        for y in 0..h {
            for x in 0..w {
                let i = 3 * (y * w + x);
                // A: slightly off everywhere in the left block; far off on the first row of the
                // right block. B: far off on one pixel of the left block, slightly off on the rest
                // of the right block.
                if x < 8 {
                    a[i..i + 3].fill(0.55);
                    if (x, y) == (3, 3) {
                        b[i..i + 3].fill(3.0);
                    }
                } else if y == 0 {
                    a[i..i + 3].fill(4.0);
                } else {
                    b[i..i + 3].fill(0.56);
                }
            }
        }
        let o = block_oracle(&[&a, &b], &reference, w, h, BLOCK).unwrap();
        let ma = metrics::rel_mse_map(&a, &reference, w, h, ToneMap::Paper);
        let mb = metrics::rel_mse_map(&b, &reference, w, h, ToneMap::Paper);
        let block_sum = |m: &[f64], x0: usize| -> f64 { (0..h).map(|y| m[y * w + x0..y * w + x0 + 8].iter().sum::<f64>()).sum() };
        // Left: A's 64 small errors against B's one large one; right: A's 8 large against B's 56 small.
        let left_a = block_sum(&ma, 0) < block_sum(&mb, 0);
        let right_a = block_sum(&ma, 8) < block_sum(&mb, 8);
        let mut expect = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let from_a = if x < 8 { left_a } else { right_a };
                let i = 3 * (y * w + x);
                expect.extend_from_slice(if from_a { &a[i..i + 3] } else { &b[i..i + 3] });
            }
        }
        assert_eq!(o.image, expect);
        assert!(left_a != right_a, "the case must make each expert win one block");
        let per_block = metrics::rel_mse(&o.image, &reference, w, h, ToneMap::Paper, 0);
        let per_pixel = block_oracle(&[&a, &b], &reference, w, h, 1).unwrap();
        let per_pixel = metrics::rel_mse(&per_pixel.image, &reference, w, h, ToneMap::Paper, 0);
        assert!(per_pixel < 0.5 * per_block, "per pixel {per_pixel} vs per block {per_block}");
        // Never worse than either expert: each block is the better of the two.
        for e in [&a, &b] {
            assert!(per_block <= metrics::rel_mse(e, &reference, w, h, ToneMap::Paper, 0));
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let r = vec![0.5f32; 12];
        assert!(block_oracle(&[], &r, 2, 2, 8).is_err());
        assert!(block_oracle(&[&r[..9]], &r, 2, 2, 8).is_err());
        assert!(block_oracle(&[&r], &r, 2, 2, 0).is_err());
        assert!(block_oracle(&[&r], &r[..9], 2, 2, 8).is_err());
    }
}
