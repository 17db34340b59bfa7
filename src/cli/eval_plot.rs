//! Plots of `pixguide eval`: plotters drawing into an RGB buffer through a backend whose text is
//! the embedded DejaVu Sans (src/cli/font.rs), so no system font is looked for.

use super::font;
use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{BackendColor, BackendCoord, BackendTextStyle, DrawingErrorKind, FontTransform};
use std::path::Path;

/// An RGB8 canvas for plotters; every primitive but text uses plotters' pixel fallbacks.
pub struct Canvas<'a> {
    px: &'a mut [u8],
    w: u32,
    h: u32,
}

impl<'a> Canvas<'a> {
    /// `px` holds `w × h` RGB8 pixels.
    pub fn new(px: &'a mut [u8], w: u32, h: u32) -> Self {
        Canvas { px, w, h }
    }
}

impl DrawingBackend for Canvas<'_> {
    type ErrorType = std::io::Error;

    fn get_size(&self) -> (u32, u32) {
        (self.w, self.h)
    }

    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        Ok(())
    }

    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        Ok(())
    }

    fn draw_pixel(&mut self, (x, y): BackendCoord, c: BackendColor) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        if x < 0 || y < 0 || x >= self.w as i32 || y >= self.h as i32 || c.alpha <= 0.0 {
            return Ok(());
        }
        let o = ((y as u32 * self.w + x as u32) * 3) as usize;
        let a = c.alpha.min(1.0);
        for (k, v) in [c.rgb.0, c.rgb.1, c.rgb.2].into_iter().enumerate() {
            self.px[o + k] = (self.px[o + k] as f64 * (1.0 - a) + v as f64 * a).round() as u8;
        }
        Ok(())
    }

    fn draw_text<S: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &S,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        let m = font::mask(text, style.size() as f32);
        let (tw, th) = (m.w as i32, m.h as i32);
        let anchor = style.anchor();
        let dx = match anchor.h_pos {
            HPos::Left => 0,
            HPos::Center => -tw / 2,
            HPos::Right => -tw,
        };
        let dy = match anchor.v_pos {
            VPos::Top => 0,
            VPos::Center => -th / 2,
            VPos::Bottom => -th,
        };
        // The anchor applies before the rotation, as in plotters' own backends: a rotated axis
        // label is centred on its axis.
        let trans: FontTransform = style.transform();
        let color = style.color();
        for my in 0..th {
            for mx in 0..tw {
                let c = m.coverage[(my * tw + mx) as usize] as f64;
                if c > 0.0 {
                    let (x, y) = trans.transform(mx + dx, my + dy);
                    self.draw_pixel((pos.0 + x, pos.1 + y), BackendColor { alpha: color.alpha * c, rgb: color.rgb })?;
                }
            }
        }
        Ok(())
    }

    fn estimate_text_size<S: BackendTextStyle>(&self, text: &str, style: &S) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        Ok(font::text_size(text, style.size() as f32))
    }
}

/// One curve: label, colour index and (x, y) points (non-positive values are left out: the axes
/// are logarithmic).
pub struct Curve {
    pub label: String,
    pub colour: usize,
    pub points: Vec<(f64, f64)>,
}

/// Distinct colours for up to 10 curves (Tableau 10).
pub fn colour(i: usize) -> RGBColor {
    const C: [(u8, u8, u8); 10] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ];
    let (r, g, b) = C[i % C.len()];
    RGBColor(r, g, b)
}

/// Log range covering `v` with a margin of 20 % on each side (a decade if all equal or empty).
fn log_range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for x in v.filter(|x| x.is_finite() && *x > 0.0) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() {
        return (0.1, 1.0);
    }
    if hi / lo < 1.5 {
        return (lo / 2.0, hi * 2.0);
    }
    (lo / 1.2, hi * 1.2)
}

/// Tick values inside [lo, hi]: the 1-2-5 sequence of each decade, or a finer one if that
/// leaves fewer than three (plotters' own log ticks skip narrow ranges entirely).
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    ticks_at_least(lo, hi, 3)
}

/// As `ticks`, taking a finer sequence while the coarser one leaves fewer than `n`.
pub(super) fn ticks_at_least(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    for steps in
        [&[1.0, 2.0, 5.0][..], &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0][..], &[1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0][..]]
    {
        let mut out = Vec::new();
        let mut e = lo.log10().floor() as i32;
        while 10f64.powi(e) <= hi && out.len() < 40 {
            for &k in steps {
                let v = k * 10f64.powi(e);
                if v >= lo && v <= hi {
                    out.push(v);
                }
            }
            e += 1;
        }
        if out.len() >= n || steps.len() > 6 {
            return out;
        }
    }
    Vec::new()
}

fn tick(v: f64) -> String {
    if v >= 100.0 || (v >= 1.0 && v.fract() == 0.0) {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else if v >= 0.01 {
        format!("{v:.2}")
    } else {
        format!("{v:.0e}")
    }
}

fn panel(
    area: &DrawingArea<Canvas<'_>, Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
    x_keys: Option<Vec<f64>>,
) -> Result<()> {
    let (x0, x1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
    let (y0, y1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)));
    let x_keys = x_keys.unwrap_or_else(|| ticks(x0, x1));
    let err = |e: DrawingAreaErrorKind<std::io::Error>| anyhow!("plot: {e}");
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", CAPTION_SIZE))
        .margin(10)
        .x_label_area_size(42)
        .y_label_area_size(56)
        .build_cartesian_2d((x0..x1).log_scale().with_key_points(x_keys), (y0..y1).log_scale().with_key_points(ticks(y0, y1)))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style(("sans-serif", TICK_SIZE))
        .axis_desc_style(("sans-serif", AXIS_SIZE))
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(err)?;
    for c in curves {
        let pts: Vec<(f64, f64)> =
            c.points.iter().copied().filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite()).collect();
        if pts.is_empty() {
            continue;
        }
        let col = colour(c.colour);
        chart.draw_series(LineSeries::new(pts.clone(), col.stroke_width(2))).map_err(err)?;
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, col.filled()))).map_err(err)?;
    }
    Ok(())
}

/// Legend entries (colour, label) of the curves with at least one drawable point, in order,
/// without repeats.
fn legend_entries<'a>(sets: &[&'a [Curve]]) -> Vec<(usize, &'a str)> {
    let mut out: Vec<(usize, &str)> = Vec::new();
    for c in sets.iter().flat_map(|s| s.iter()) {
        let drawable = c.points.iter().any(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite());
        if drawable && !out.iter().any(|e| e.1 == c.label) {
            out.push((c.colour, &c.label));
        }
    }
    out
}

/// Text sizes in pixels (ascent to descent) of the panel captions, tick labels, axis names and
/// legend, shared with the training plots.
pub(super) const CAPTION_SIZE: f32 = 18.0;
pub(super) const TICK_SIZE: f32 = 14.0;
pub(super) const AXIS_SIZE: f32 = 15.0;
const LEGEND_SIZE: f32 = 15.0;
const LEGEND_ROW: u32 = 22;
/// Swatch and gap before a legend label, and space after it.
const SWATCH_W: u32 = 22;
const ENTRY_GAP: u32 = 18;

/// Rows of legend entries laid out left to right in `width` pixels: (x, row) of each entry.
fn legend_layout(entries: &[(usize, &str)], width: u32) -> Vec<(u32, u32)> {
    let (mut x, mut row) = (12u32, 0u32);
    let mut out = Vec::with_capacity(entries.len());
    for (_, label) in entries {
        let w = SWATCH_W + font::text_size(label, LEGEND_SIZE).0 + ENTRY_GAP;
        if x + w > width && x > 12 {
            x = 12;
            row += 1;
        }
        out.push((x, row));
        x += w;
    }
    out
}

/// Height in pixels of the legend of `entries` in `width` pixels (0 without entries).
pub(super) fn legend_height(entries: &[(usize, &str)], width: u32) -> u32 {
    let rows = legend_layout(entries, width).iter().map(|p| p.1 + 1).max().unwrap_or(0);
    rows * LEGEND_ROW + if rows > 0 { 8 } else { 0 }
}

/// Draws the legend of `entries` (a colour swatch and a label each) from row `top` of an RGB8
/// buffer `width` pixels wide; it takes `legend_height` rows.
pub(super) fn draw_legend(px: &mut [u8], width: u32, top: u32, entries: &[(usize, &str)]) {
    let h = px.len() as u32 / 3 / width.max(1);
    for (&(c, label), (x, row)) in entries.iter().zip(legend_layout(entries, width)) {
        let y = top + row * LEGEND_ROW + 4;
        let RGBColor(r, g, b) = colour(c);
        // Level with the middle of the lower-case letters.
        for yy in (y + 7..y + 10).filter(|&yy| yy < h) {
            for xx in (x..x + 16).filter(|&xx| xx < width) {
                let o = ((yy * width + xx) * 3) as usize;
                px[o..o + 3].copy_from_slice(&[r, g, b]);
            }
        }
        font::draw(px, width, (x + SWATCH_W, y), width, LEGEND_SIZE, [40, 40, 40], label);
    }
}

/// Two log-log panels side by side (left: relMSE, right: 1 − SSIM) written as a PNG.
/// `x_keys`: the x ticks (e.g. the spp values), or None for a 1-2-5 sequence.
pub fn write_pair(path: &Path, x_label: &str, x_keys: Option<Vec<f64>>, left: (&str, &[Curve]), right: (&str, &[Curve])) -> Result<()> {
    let (w, plot_h) = (1100u32, 440u32);
    // One legend for both panels, below them, so it never covers a curve.
    let entries = legend_entries(&[left.1, right.1]);
    let h = plot_h + legend_height(&entries, w);
    let mut px = vec![255u8; (w * h * 3) as usize];
    {
        let root = DrawingArea::from(Canvas { px: &mut px, w, h });
        let (plots, _) = root.split_vertically(plot_h);
        let halves = plots.split_evenly((1, 2));
        panel(&halves[0], left.0, x_label, left.0, left.1, x_keys.clone())?;
        panel(&halves[1], right.0, x_label, right.0, right.1, x_keys)?;
    }
    draw_legend(&mut px, w, plot_h, &entries);
    super::shared::ensure_parent(path)?;
    renderer::film::png::write_rgb8(path, w, h, px)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve(label: &str, colour: usize, points: Vec<(f64, f64)>) -> Curve {
        Curve { label: label.to_string(), colour, points }
    }

    #[test]
    fn legend_lists_drawable_curves_once_and_fits() {
        let a = [
            curve("noisy (MC)", 0, vec![(1.0, 1.0)]),
            curve("E radiances only", 7, vec![(2.0, 0.5)]),
            curve("empty", 3, vec![(0.0, 1.0), (f64::NAN, 2.0)]),
        ];
        let b = [curve("noisy (MC)", 0, vec![(1.0, 0.9)])];
        let e = legend_entries(&[&a, &b]);
        assert_eq!(e, vec![(0, "noisy (MC)"), (7, "E radiances only")]);
        // Many long labels wrap onto several rows; no entry runs past the width or into the next.
        let labels: Vec<String> = (0..9).map(|i| format!("method number {i} long")).collect();
        let entries: Vec<(usize, &str)> = labels.iter().enumerate().map(|(i, l)| (i, l.as_str())).collect();
        let layout = legend_layout(&entries, 600);
        assert!(layout.iter().map(|p| p.1).max().unwrap() >= 2);
        for (k, ((_, l), (x, row))) in entries.iter().zip(&layout).enumerate() {
            let end = x + SWATCH_W + font::text_size(l, LEGEND_SIZE).0;
            assert!(end <= 600, "{l} ends at {end}");
            if let Some(&(nx, nrow)) = layout.get(k + 1) {
                assert!(nrow > *row || nx > end);
            }
        }
    }
}
