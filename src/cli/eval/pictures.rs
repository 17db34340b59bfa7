//! The picture sheets of `pixguide eval` (images, error maps, W_G maps of one scene and spp), each
//! with a zoom on the window where the denoised images are worst.

use super::methods::{EvalMethod, PICTURE_METHODS};
use super::{picture_paths, PictureData};
use crate::cli::font;
use anyhow::{Context, Result};
use denoiser::metrics::{self, ToneMap};
use std::path::Path;

/// Side of the zoom window as a fraction of the image side; zooms are shown at this factor.
pub(super) const ZOOM: usize = 3;
const LABEL_H: u32 = 28;
const GAP: u32 = 4;

/// A grid of equally sized tiles, each under a two-line label.
struct Sheet {
    px: Vec<u8>,
    w: u32,
    tile: (u32, u32),
}

impl Sheet {
    fn new(cols: usize, rows: usize, tile: (u32, u32)) -> Sheet {
        let w = cols as u32 * (tile.0 + GAP) - GAP;
        let h = rows as u32 * (tile.1 + LABEL_H + GAP) - GAP;
        Sheet { px: vec![24u8; (w * h * 3) as usize], w, tile }
    }
    /// Puts an RGB8 image of `size` (at most the tile) at the tile's top-left corner.
    fn put(&mut self, row: usize, col: usize, rgb8: &[u8], size: (u32, u32), label: &str, sub: &str) {
        let x0 = col as u32 * (self.tile.0 + GAP);
        let y0 = row as u32 * (self.tile.1 + LABEL_H + GAP);
        for y in 0..size.1.min(self.tile.1) {
            for x in 0..size.0.min(self.tile.0) {
                let o = (((y0 + LABEL_H + y) * self.w + x0 + x) * 3) as usize;
                let i = ((y * size.0 + x) * 3) as usize;
                self.px[o..o + 3].copy_from_slice(&rgb8[i..i + 3]);
            }
        }
        let max_w = self.tile.0.saturating_sub(3);
        font::label(&mut self.px, self.w, (x0 + 2, y0 + 1), max_w, 13.0, [255, 255, 255], label);
        font::label(&mut self.px, self.w, (x0 + 2, y0 + 15), max_w, 12.0, [200, 200, 200], sub);
    }
    fn save(self, path: &Path) -> Result<()> {
        let h = self.px.len() as u32 / 3 / self.w;
        renderer::film::png::write_rgb8(path, self.w, h, self.px).with_context(|| format!("writing {}", path.display()))?;
        Ok(())
    }
}

/// A window of the image: origin and size in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    x: usize,
    y: usize,
    w: usize,
    h: usize,
}

/// The `w/ZOOM × h/ZOOM` window with the largest sum of `score` (a per-pixel map of a `w × h`
/// image), through a summed-area table; ties go to the first in reading order.
fn hardest_window(score: &[f64], w: usize, h: usize) -> Window {
    let (cw, ch) = ((w / ZOOM).max(1), (h / ZOOM).max(1));
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        for x in 0..w {
            let v = if score[y * w + x].is_finite() { score[y * w + x] } else { 0.0 };
            sat[(y + 1) * (w + 1) + x + 1] = v + sat[y * (w + 1) + x + 1] + sat[(y + 1) * (w + 1) + x] - sat[y * (w + 1) + x];
        }
    }
    let sum = |x: usize, y: usize| {
        sat[(y + ch) * (w + 1) + x + cw] - sat[y * (w + 1) + x + cw] - sat[(y + ch) * (w + 1) + x] + sat[y * (w + 1) + x]
    };
    let mut best = (f64::NEG_INFINITY, Window { x: 0, y: 0, w: cw, h: ch });
    for y in 0..=h - ch {
        for x in 0..=w - cw {
            let v = sum(x, y);
            if v > best.0 {
                best = (v, Window { x, y, w: cw, h: ch });
            }
        }
    }
    best.1
}

/// RGB8 of a whole `w`-wide per-pixel colour list.
fn rgb8(c: &[[u8; 3]]) -> Vec<u8> {
    c.iter().flatten().copied().collect()
}

/// The window of a `w`-wide colour list, enlarged ZOOM× by pixel repetition.
fn zoomed(c: &[[u8; 3]], w: usize, win: Window) -> (Vec<u8>, (u32, u32)) {
    let (zw, zh) = (win.w * ZOOM, win.h * ZOOM);
    let mut out = Vec::with_capacity(zw * zh * 3);
    for y in 0..zh {
        for x in 0..zw {
            out.extend(c[(win.y + y / ZOOM) * w + win.x + x / ZOOM]);
        }
    }
    (out, (zw as u32, zh as u32))
}

/// Outlines `win` in white (over a dark border so it shows on bright images too).
fn outline(c: &mut [[u8; 3]], w: usize, h: usize, win: Window) {
    let mut set = |x: usize, y: usize, v: [u8; 3]| {
        if x < w && y < h {
            c[y * w + x] = v;
        }
    };
    let (x1, y1) = (win.x + win.w - 1, win.y + win.h - 1);
    for (d, v) in [(1usize, [0u8; 3]), (0, [255u8; 3])] {
        for x in win.x.saturating_sub(d)..=x1 + d {
            set(x, win.y.saturating_sub(d), v);
            set(x, y1 + d, v);
        }
        for y in win.y.saturating_sub(d)..=y1 + d {
            set(win.x.saturating_sub(d), y, v);
            set(x1 + d, y, v);
        }
    }
}

/// Mean of `v` over a window of a `w`-wide map.
fn window_mean(v: &[f64], w: usize, win: Window) -> f64 {
    let mut s = 0.0;
    for y in win.y..win.y + win.h {
        s += v[y * w + win.x..y * w + win.x + win.w].iter().sum::<f64>();
    }
    s / (win.w * win.h) as f64
}

fn tonemapped(rgb: &[f32]) -> Vec<[f64; 3]> {
    metrics::tonemap(rgb, ToneMap::Paper).chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn inferno_log(e: f64) -> [u8; 3] {
    let t = ((e.max(1e-12).log10() + 4.0) / 4.0).clamp(0.0, 1.0);
    let c = colorous::INFERNO.eval_continuous(t);
    [c.r, c.g, c.b]
}

fn viridis(x: f64) -> [u8; 3] {
    let c = colorous::VIRIDIS.eval_continuous(x.clamp(0.0, 1.0));
    [c.r, c.g, c.b]
}

/// A colour bar from 0 (bottom) to 1 (top), 24 px wide, `h` high.
fn colour_bar(h: u32, colour: impl Fn(f64) -> [u8; 3]) -> (Vec<u8>, (u32, u32)) {
    let mut out = Vec::with_capacity((24 * h * 3) as usize);
    for y in 0..h {
        let c = colour(1.0 - y as f64 / (h.max(2) - 1) as f64);
        for _ in 0..24 {
            out.extend(c);
        }
    }
    (out, (24, h))
}

/// Per-pixel relMSE (mean over channels) of tone-mapped colours against the reference's.
fn error_map(t: &[[f64; 3]], reference: &[[f64; 3]]) -> Vec<f64> {
    t.iter()
        .zip(reference)
        .map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).powi(2) / (y[c] * y[c] + metrics::REL_MSE_EPS)).sum::<f64>() / 3.0)
        .collect()
}

/// Images, error maps and W_G maps of one (scene, spp): whole frames on the first row, on the
/// second the same window of each enlarged ZOOM× — the window where the denoised images' mean
/// error is largest, outlined on the frames.
pub fn write_pictures(dir: &Path, p: &PictureData) -> Result<()> {
    let [images_png, errors_png, weights_png] = picture_paths(dir, &p.scene, p.spp);
    let (w, h) = (p.width, p.height);
    let tile = (w as u32, h as u32);
    let mut ordered: Vec<&(EvalMethod, Vec<f32>, f64)> = Vec::new();
    for name in PICTURE_METHODS {
        ordered.extend(p.images.iter().filter(|i| i.0 == name));
    }
    let reference = tonemapped(&p.reference);
    let toned: Vec<Vec<[f64; 3]>> = ordered.iter().map(|i| tonemapped(&i.1)).collect();
    let errors: Vec<Vec<f64>> = toned.iter().map(|t| error_map(t, &reference)).collect();
    // The zoom goes where the denoised images differ most visibly from the reference: squared
    // error of the displayed (tone-mapped) colours, which unlike relMSE does not single out the
    // darkest corner.
    let shown: Vec<&Vec<[f64; 3]>> = ordered.iter().zip(&toned).filter(|(i, _)| i.0 != EvalMethod::Noisy).map(|(_, t)| t).collect();
    let score: Vec<f64> =
        (0..w * h).map(|i| shown.iter().map(|t| (0..3).map(|c| (t[i][c] - reference[i][c]).powi(2)).sum::<f64>()).sum()).collect();
    let win = hardest_window(&score, w, h);
    let zoom_label = format!("{ZOOM}× zoom");
    let to8 = |t: &[[f64; 3]]| -> Vec<[u8; 3]> { t.iter().map(|c| c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)).collect() };
    let mapped = |v: &[f64], colour: &dyn Fn(f64) -> [u8; 3]| -> Vec<[u8; 3]> { v.iter().map(|&x| colour(x)).collect() };
    // Frame on row 0 (window outlined), zoom on row 1.
    let both_rows = |sheet: &mut Sheet, col: usize, mut c: Vec<[u8; 3]>, label: &str, sub: &str, zoom_sub: &str| {
        let (z, zs) = zoomed(&c, w, win);
        outline(&mut c, w, h, win);
        sheet.put(0, col, &rgb8(&c), tile, label, sub);
        sheet.put(1, col, &z, zs, &zoom_label, zoom_sub);
    };

    let mut sheet = Sheet::new(ordered.len() + 1, 2, tile);
    for (k, ((method, _, rel), t)) in ordered.iter().zip(&toned).enumerate() {
        both_rows(&mut sheet, k, to8(t), method.label(), &format!("{rel:.4}"), &format!("{:.4}", window_mean(&errors[k], w, win)));
    }
    both_rows(&mut sheet, ordered.len(), to8(&reference), "reference", "8000 spp", "");
    sheet.save(&images_png)?;

    let mut sheet = Sheet::new(ordered.len() + 1, 2, tile);
    for (k, (method, _, rel)) in ordered.iter().enumerate() {
        both_rows(
            &mut sheet,
            k,
            mapped(&errors[k], &inferno_log),
            method.label(),
            &format!("relMSE {rel:.4}"),
            &format!("{:.4}", window_mean(&errors[k], w, win)),
        );
    }
    let (bar, bs) = colour_bar(tile.1, |t| inferno_log(10f64.powf(4.0 * t - 4.0)));
    sheet.put(0, ordered.len(), &bar, bs, "scale", "10⁻⁴ to 1");
    sheet.save(&errors_png)?;

    let mut sheet = Sheet::new(p.weights.len().max(1) + 1, 2, tile);
    if p.weights.is_empty() {
        let blank = vec![24u8; w * h * 3];
        sheet.put(0, 0, &blank, tile, "no guided", "model");
    }
    for (k, (name, method, map)) in p.weights.iter().enumerate() {
        let v: Vec<f64> = map.iter().map(|&x| x as f64).collect();
        both_rows(&mut sheet, k, mapped(&v, &viridis), name, method, &format!("mean {:.2}", window_mean(&v, w, win)));
    }
    let (bar, bs) = colour_bar(tile.1, viridis);
    sheet.put(0, p.weights.len().max(1), &bar, bs, "scale", "0 to 1");
    sheet.save(&weights_png)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hardest_window_finds_the_hot_spot() {
        let (w, h) = (30, 21);
        let mut score = vec![0.01; w * h];
        // A hot 4×4 block at (20, 12): the 10×7 window must contain it whole.
        for y in 12..16 {
            for x in 20..24 {
                score[y * w + x] = 5.0;
            }
        }
        score[0] = f64::NAN;
        let win = hardest_window(&score, w, h);
        assert_eq!((win.w, win.h), (10, 7));
        assert!(win.x <= 20 && win.x + win.w >= 24 && win.y <= 12 && win.y + win.h >= 16, "{win:?}");
        // Brute force agrees on the best sum.
        let sum = |x: usize, y: usize| {
            (y..y + 7).map(|yy| score[yy * w + x..yy * w + x + 10].iter().filter(|v| v.is_finite()).sum::<f64>()).sum::<f64>()
        };
        let best = (0..=h - 7).flat_map(|y| (0..=w - 10).map(move |x| (x, y))).map(|(x, y)| sum(x, y)).fold(f64::MIN, f64::max);
        assert!((sum(win.x, win.y) - best).abs() < 1e-9);
        assert!((window_mean(&score, w, win) - best / 70.0).abs() < 1e-12);
    }

    #[test]
    fn zoom_repeats_pixels_and_outline_stays_inside() {
        let (w, h) = (6, 6);
        let c: Vec<[u8; 3]> = (0..w * h).map(|i| [i as u8, 0, 0]).collect();
        let win = Window { x: 2, y: 3, w: 2, h: 2 };
        let (z, size) = zoomed(&c, w, win);
        assert_eq!(size, (6, 6));
        assert_eq!(z[0], 20); // pixel (2, 3)
        assert_eq!(z[(5 * 6 + 5) * 3], 27); // pixel (3, 4)
        assert_eq!(z[(2 * 6 + 3) * 3], 21); // pixel (3, 3): x 3 → source column 3
        let mut o = c.clone();
        outline(&mut o, w, h, Window { x: 0, y: 0, w: 6, h: 6 });
        assert_eq!(o[0], [255; 3]);
        assert_eq!(o[2 * 6 + 2], c[2 * 6 + 2]);
    }
}
