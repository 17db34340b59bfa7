//! Windows of a prepared image that may reach past its edges, read from the image extended by
//! mirror reflection (pixel −1 is pixel 1). Training patches and inference windows are both cut
//! here, so a network sees the same thing at an image edge in training as in use.
//!
//! The extension is the image of a mirrored scene, not a copy of the stored planes:
//! - a screen-space normal (x right, y up) flips its x component where the image is mirrored
//!   left–right and its y component where it is mirrored top–bottom;
//! - the forward-difference gradient planes are recomputed from the extended base planes, so a
//!   gradient in the pad (and on the image's own first row and column, whose left or upper
//!   neighbour is now the mirrored pixel) is the difference of what the window shows.
//!
//! Inside the image, with at least one pixel of image to the left and above, a window equals a
//! plain crop of the prepared planes.

use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::preprocess::PreparedImage;

/// Base planes of a block and their gradient planes: (base plane, x-gradient plane, y-gradient
/// plane) triples; the other planes (variances) move as they are.
pub const COLOUR_GRADIENTS: [(usize, usize, usize); 3] = [(0, 4, 7), (1, 5, 8), (2, 6, 9)];
pub const G_GRADIENTS: [(usize, usize, usize); 7] = [(0, 4, 7), (1, 5, 8), (2, 6, 9), (10, 12, 13), (14, 18, 21), (15, 19, 22), (16, 20, 23)];
/// First of the G block's two screen-space normal planes (x, y).
pub const G_NORMAL: usize = 0;

/// Mirror index into 0..n for any integer (period 2n−2), and whether the image is mirrored
/// there (an odd number of reflections; the fold pixels 0 and n−1 count as unmirrored).
pub fn reflect(i: isize, n: usize) -> (usize, bool) {
    if n == 1 {
        return (0, false);
    }
    let period = 2 * (n as isize - 1);
    let j = i.rem_euclid(period);
    if j < n as isize { (j as usize, false) } else { ((period - j) as usize, true) }
}

/// Where a window pixel reads from: image coordinates before reflection.
pub trait WindowMap {
    /// Image coordinates (possibly outside the image) of window pixel (u, v).
    fn source(&self, u: isize, v: isize) -> (isize, isize);
    /// A screen-space normal of the (extended) image as the window shows it.
    fn normal(&self, nx: f32, ny: f32) -> (f32, f32);
}

/// A plain window: pixel (u, v) reads image pixel (x0 + u, y0 + v).
#[derive(Clone, Copy, Debug)]
pub struct Offset {
    pub x0: isize,
    pub y0: isize,
}

impl WindowMap for Offset {
    fn source(&self, u: isize, v: isize) -> (isize, isize) {
        (self.x0 + u, self.y0 + v)
    }
    fn normal(&self, nx: f32, ny: f32) -> (f32, f32) {
        (nx, ny)
    }
}

/// The `w × h` window that `map` describes, without descriptors (the caller cuts those, from
/// the returned source pixel of each window pixel, row-major). Pass-through flags are cut if
/// the image has them.
pub fn cut_window(img: &PreparedImage, map: &impl WindowMap, w: usize, h: usize) -> (PreparedImage, Vec<usize>) {
    let (iw, ih) = (img.width, img.height);
    let n = iw * ih;
    // Source pixel and mirror flags of window coordinates (u, v), which may lie outside the window.
    let at = |u: isize, v: isize| -> (usize, bool, bool) {
        let (x, y) = map.source(u, v);
        let (rx, mx) = reflect(x, iw);
        let (ry, my) = reflect(y, ih);
        (ry * iw + rx, mx, my)
    };
    let index: Vec<usize> = (0..h as isize).flat_map(|v| (0..w as isize).map(move |u| (u, v))).map(|(u, v)| at(u, v).0).collect();
    let wn = w * h;
    let block = |buf: &[f32], planes: usize, grads: &[(usize, usize, usize)], normal: Option<usize>| -> Vec<f32> {
        let mut out = vec![0.0f32; planes * wn];
        let is_grad = |c: usize| grads.iter().any(|g| g.1 == c || g.2 == c);
        for c in (0..planes).filter(|&c| !is_grad(c)) {
            for (o, &i) in out[c * wn..(c + 1) * wn].iter_mut().zip(&index) {
                *o = buf[c * n + i];
            }
        }
        // Base plane c of the extended image at window coordinates (u, v).
        let value = |c: usize, u: isize, v: isize| -> f32 {
            let (i, mx, my) = at(u, v);
            match normal {
                Some(n0) if (n0..n0 + 2).contains(&c) => {
                    let sx = if mx { -1.0 } else { 1.0 };
                    let sy = if my { -1.0 } else { 1.0 };
                    let (a, b) = map.normal(sx * buf[n0 * n + i], sy * buf[(n0 + 1) * n + i]);
                    if c == n0 { a } else { b }
                }
                _ => buf[c * n + i],
            }
        };
        if let Some(n0) = normal {
            for v in 0..h {
                for u in 0..w {
                    for c in [n0, n0 + 1] {
                        out[c * wn + v * w + u] = value(c, u as isize, v as isize);
                    }
                }
            }
        }
        for &(base, gx, gy) in grads {
            for v in 0..h as isize {
                for u in 0..w as isize {
                    let here = value(base, u, v);
                    let k = v as usize * w + u as usize;
                    out[gx * wn + k] = here - value(base, u - 1, v);
                    out[gy * wn + k] = here - value(base, u, v - 1);
                }
            }
        }
        out
    };
    let window = PreparedImage {
        width: w,
        height: h,
        spp: img.spp,
        diffuse: block(&img.diffuse, COLOUR_BLOCK, &COLOUR_GRADIENTS, None),
        specular: block(&img.specular, COLOUR_BLOCK, &COLOUR_GRADIENTS, None),
        g_block: block(&img.g_block, G_BLOCK, &G_GRADIENTS, Some(G_NORMAL)),
        path_weight: index.iter().map(|&i| img.path_weight[i]).collect(),
        descriptors: None,
        records: None,
        passthrough: if img.passthrough.is_empty() { Vec::new() } else { index.iter().map(|&i| img.passthrough[i]).collect() },
    };
    (window, index)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn random_image(w: usize, h: usize, seed: u64) -> PreparedImage {
        let mut rng = SplitMix64::new(seed);
        let mut r = |k: usize| -> Vec<f32> { (0..k).map(|_| rng.next_f64() as f32 * 2.0 - 1.0).collect() };
        let n = w * h;
        PreparedImage {
            width: w,
            height: h,
            spp: 1,
            diffuse: r(COLOUR_BLOCK * n),
            specular: r(COLOUR_BLOCK * n),
            g_block: r(G_BLOCK * n),
            path_weight: r(n),
            descriptors: None,
            records: None,
            passthrough: (0..n).map(|i| i % 5 == 0).collect(),
        }
    }

    #[test]
    fn reflect_mirrors_about_the_edge_pixels() {
        let got: Vec<(usize, bool)> = (-4..9).map(|i| reflect(i, 4)).collect();
        // −4 and −3 are two reflections away (a translated copy), 4 and 5 one.
        let want = [(2, false), (3, false), (2, true), (1, true), (0, false), (1, false), (2, false), (3, false), (2, true), (1, true), (0, false), (1, false), (2, false)];
        assert_eq!(got, want);
        assert_eq!(reflect(-7, 1), (0, false));
    }

    /// A window reaching past the top-left corner equals the same window of an image that was
    /// mirror-padded by hand: planes copied from the reflected pixel, the normal's x negated in
    /// the left pad and its y in the top pad, gradients the forward differences of the padded
    /// base planes. Inside the image it is a plain crop.
    #[test]
    fn window_past_the_edge_is_the_window_of_the_padded_image() {
        let (w, h, pad) = (7usize, 5usize, 3usize);
        let img = random_image(w, h, 11);
        let (pw, ph) = (w + 2 * pad, h + 2 * pad);
        let n = w * h;
        // The padded image by hand, with its own gradient rule.
        let src = |px: usize, py: usize| -> (usize, bool, bool) {
            let fold = |p: usize, len: usize| -> (usize, bool) {
                let i = p as isize - pad as isize;
                if i < 0 {
                    ((-i) as usize, true)
                } else if i as usize >= len {
                    (2 * (len - 1) - i as usize, true)
                } else {
                    (i as usize, false)
                }
            };
            let (x, mx) = fold(px, w);
            let (y, my) = fold(py, h);
            (y * w + x, mx, my)
        };
        let padded_block = |buf: &[f32], planes: usize, grads: &[(usize, usize, usize)], normal: bool| -> Vec<f32> {
            let mut out = vec![0.0f32; planes * pw * ph];
            for c in 0..planes {
                for py in 0..ph {
                    for px in 0..pw {
                        let (i, mx, my) = src(px, py);
                        let mut v = buf[c * n + i];
                        if normal && c == 0 && mx || normal && c == 1 && my {
                            v = -v;
                        }
                        out[c * pw * ph + py * pw + px] = v;
                    }
                }
            }
            for &(b, gx, gy) in grads {
                for py in 0..ph {
                    for px in 0..pw {
                        let k = py * pw + px;
                        let here = out[b * pw * ph + k];
                        out[gx * pw * ph + k] = if px > 0 { here - out[b * pw * ph + k - 1] } else { f32::NAN };
                        out[gy * pw * ph + k] = if py > 0 { here - out[b * pw * ph + k - pw] } else { f32::NAN };
                    }
                }
            }
            out
        };
        let pd = padded_block(&img.diffuse, COLOUR_BLOCK, &COLOUR_GRADIENTS, false);
        let pg = padded_block(&img.g_block, G_BLOCK, &G_GRADIENTS, true);
        // Window of side 6×4 starting one pixel into the pad (so every gradient is defined).
        let (ww, wh) = (6usize, 4usize);
        for (x0, y0) in [(1usize, 1usize), (pw - ww, ph - wh), (4, 1), (1, 5)] {
            let (win, index) = cut_window(&img, &Offset { x0: x0 as isize - pad as isize, y0: y0 as isize - pad as isize }, ww, wh);
            let crop = |p: &[f32], planes: usize| -> Vec<f32> {
                (0..planes).flat_map(|c| (y0..y0 + wh).flat_map(move |y| (x0..x0 + ww).map(move |x| p[c * pw * ph + y * pw + x]))).collect()
            };
            assert_eq!(win.diffuse, crop(&pd, COLOUR_BLOCK), "diffuse at ({x0},{y0})");
            assert_eq!(win.g_block, crop(&pg, G_BLOCK), "G block at ({x0},{y0})");
            let idx: Vec<usize> = (y0..y0 + wh).flat_map(|y| (x0..x0 + ww).map(move |x| src(x, y).0)).collect();
            assert_eq!(index, idx);
            assert_eq!(win.passthrough, idx.iter().map(|&i| img.passthrough[i]).collect::<Vec<_>>());
        }
        // Inside the image (one pixel clear of the top-left edge) the window is a plain crop
        // once the stored gradients are true forward differences there.
        let (full, _) = cut_window(&img, &Offset { x0: 0, y0: 0 }, w, h);
        let (inner, _) = cut_window(&full, &Offset { x0: 1, y0: 2 }, 5, 3);
        assert_eq!(inner, full.crop(1, 2, 5, 3).unwrap());
    }
}
