//! Text of the plots and picture sheets in DejaVu Sans (assets/fonts/, licence beside it),
//! embedded in the binary: the PNGs come out the same on a fresh machine with no system fonts,
//! and no font-kit, fontconfig or freetype is involved.

use ab_glyph::{point, Font, FontRef, GlyphId, PxScale, ScaleFont};
use std::sync::LazyLock;

static FONT: LazyLock<FontRef<'static>> = LazyLock::new(|| {
    FontRef::try_from_slice(include_bytes!("../../assets/fonts/DejaVuSans.ttf")).expect("the embedded DejaVu Sans is a valid TrueType font")
});

/// Coverage (0 to 1) of one line of text over its box, `w × h` pixels row by row. The box is the
/// font's ascent to descent at the size, so lines of one size have one height whatever letters
/// they hold, and anchoring by the box centre centres every label alike.
pub struct Mask {
    pub w: u32,
    pub h: u32,
    pub coverage: Vec<f32>,
}

impl Mask {
    fn at(&self, x: u32, y: u32) -> f32 {
        self.coverage[(y * self.w + x) as usize]
    }
}

/// Glyphs of `text` at `size` pixels (ascent − descent) laid out on one line with kerning, the
/// baseline on a whole pixel (sharper horizontals); and the box size.
fn layout(text: &str, size: f32) -> (Vec<ab_glyph::Glyph>, u32, u32) {
    let font = FONT.as_scaled(PxScale::from(size));
    let baseline = font.ascent().round();
    let (mut x, mut prev) = (0.0f32, None::<GlyphId>);
    let mut glyphs = Vec::with_capacity(text.len());
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            x += font.kern(p, id);
        }
        glyphs.push(id.with_scale_and_position(size, point(x, baseline)));
        x += font.h_advance(id);
        prev = Some(id);
    }
    (glyphs, x.ceil().max(0.0) as u32, (baseline - font.descent()).ceil() as u32)
}

/// Width and height of the box of `text` at `size` pixels.
pub fn text_size(text: &str, size: f32) -> (u32, u32) {
    let (_, w, h) = layout(text, size);
    (w, h)
}

/// `text` rasterised at `size` pixels; ink outside the box (a glyph reaching left of its origin
/// or right of its advance) is cut off, so that what is drawn is what was measured.
pub fn mask(text: &str, size: f32) -> Mask {
    let (glyphs, w, h) = layout(text, size);
    let mut coverage = vec![0.0f32; (w * h) as usize];
    for g in glyphs {
        let Some(outline) = FONT.outline_glyph(g) else { continue };
        let b = outline.px_bounds();
        outline.draw(|gx, gy, c| {
            let (x, y) = (b.min.x as i32 + gx as i32, b.min.y as i32 + gy as i32);
            if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h {
                // Neighbouring glyphs can share an edge pixel: their coverages add up.
                let v = &mut coverage[(y as u32 * w + x as u32) as usize];
                *v = (*v + c).min(1.0);
            }
        });
    }
    Mask { w, h, coverage }
}

/// Largest size up to `size` at which `text` is at most `max_w` pixels wide, but not below
/// 8 pixels, where DejaVu stops being legible: a longer label gets clipped instead.
pub fn fitting_size(text: &str, size: f32, max_w: u32) -> f32 {
    let w = text_size(text, size).0;
    if w <= max_w {
        return size;
    }
    // Widths scale with the size, up to rounding: step down from the proportional guess.
    let mut s = (size * max_w as f32 / w as f32).floor().max(8.0);
    while s > 8.0 && text_size(text, s).0 > max_w {
        s -= 0.5;
    }
    s
}

/// Blends `rgb` at coverage `a` into pixel `o` (byte offset) of an RGB8 buffer.
fn blend(px: &mut [u8], o: usize, rgb: [u8; 3], a: f32) {
    for k in 0..3 {
        px[o + k] = (px[o + k] as f32 * (1.0 - a) + rgb[k] as f32 * a).round() as u8;
    }
}

/// Draws `text` in `rgb` at `size` pixels with the top-left of its box at (x, y) into an RGB8
/// buffer `width` pixels wide, clipped to the buffer and to `max_w` pixels from x.
pub fn draw(px: &mut [u8], width: u32, (x, y): (u32, u32), max_w: u32, size: f32, rgb: [u8; 3], text: &str) {
    let m = mask(text, size);
    let height = px.len() as u32 / 3 / width.max(1);
    for my in 0..m.h.min(height.saturating_sub(y)) {
        for mx in 0..m.w.min(max_w).min(width.saturating_sub(x)) {
            let a = m.at(mx, my);
            if a > 0.0 {
                blend(px, (((y + my) * width + x + mx) * 3) as usize, rgb, a);
            }
        }
    }
}

/// A label in a bar above a tile `max_w` pixels wide: `size` pixels, smaller if it would not fit.
pub fn label(px: &mut [u8], width: u32, at: (u32, u32), max_w: u32, size: f32, rgb: [u8; 3], text: &str) {
    draw(px, width, at, max_w, fitting_size(text, size, max_w), rgb, text);
}

/// Height of the one-line label bar above each tile of a contact sheet.
pub const BAR_H: u32 = 16;

/// A white label in the bar above a tile `tile_w` pixels wide whose bar starts at (x, y).
pub fn bar_label(px: &mut [u8], width: u32, (x, y): (u32, u32), tile_w: u32, text: &str) {
    label(px, width, (x + 2, y + 2), tile_w.saturating_sub(3), 13.0, [255, 255, 255], text);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_grow_with_text_and_size_and_ink_stays_inside() {
        let (w1, h1) = text_size("relMSE", 14.0);
        let (w2, h2) = text_size("relMSE / 2-spp noisy", 14.0);
        assert!(w2 > 2 * w1 && h1 == h2 && (14..=15).contains(&h1), "{w1}×{h1}, {w2}×{h2}");
        let (w3, h3) = text_size("relMSE", 28.0);
        assert!(w3.abs_diff(2 * w1) <= 2 && h3.abs_diff(2 * h1) <= 2, "{w3}×{h3}");
        assert_eq!(text_size("", 14.0).0, 0);
        // "g" has a descender and "É" an accent above the cap height: both stay in the box.
        let m = mask("gÉ", 20.0);
        let ink = |rows: std::ops::Range<u32>| rows.flat_map(|y| (0..m.w).map(move |x| (x, y))).map(|(x, y)| m.at(x, y)).sum::<f32>();
        assert!(ink(0..m.h) > 20.0 && ink(m.h - 4..m.h) > 0.5 && ink(0..4) > 0.5);
        assert!(m.coverage.iter().all(|c| (0.0..=1.0).contains(c)));
    }

    #[test]
    fn labels_shrink_to_fit_down_to_the_legible_minimum() {
        let t = "guided (half)";
        let wide = text_size(t, 13.0).0;
        assert_eq!(fitting_size(t, 13.0, wide), 13.0);
        let s = fitting_size(t, 13.0, wide * 2 / 3);
        assert!((8.0..13.0).contains(&s) && text_size(t, s).0 <= wide * 2 / 3, "{s}");
        assert_eq!(fitting_size(t, 13.0, 5), 8.0);
        // Drawing clips to the buffer and to max_w.
        let (w, h) = (40u32, 10u32);
        let mut px = vec![0u8; (w * h * 3) as usize];
        draw(&mut px, w, (30, 2), 6, 14.0, [255, 255, 255], t);
        let lit: Vec<u32> = (0..w * h).filter(|i| px[*i as usize * 3] > 0).map(|i| i % w).collect();
        assert!(!lit.is_empty() && lit.iter().all(|&x| (30..36).contains(&x)));
    }
}
