//! A 3×5 pixel font for labelling contact sheets and plots without shipping a font file.

/// Each glyph is 5 rows of 3 bits (MSB = left column), top row first. Letters have one case.
pub fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [6, 1, 2, 4, 7],
        '3' => [6, 1, 2, 1, 6],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 6, 1, 6],
        '6' => [3, 4, 7, 5, 7],
        '7' => [7, 1, 2, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 6],
        '-' => [0, 0, 7, 0, 0],
        '.' => [0, 0, 0, 0, 2],
        '_' => [0, 0, 0, 0, 7],
        '/' => [1, 1, 2, 4, 4],
        ':' => [0, 2, 0, 2, 0],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '=' => [0, 7, 0, 7, 0],
        '+' => [0, 2, 7, 2, 0],
        ',' => [0, 0, 0, 2, 4],
        '%' => [5, 1, 2, 4, 5],
        '<' => [1, 2, 4, 2, 1],
        '>' => [4, 2, 1, 2, 4],
        '*' => [0, 5, 2, 5, 0],
        '^' => [2, 5, 0, 0, 0],
        '²' => [6, 2, 4, 6, 0],
        '−' => [0, 0, 7, 0, 0],
        '×' => [0, 5, 2, 5, 0],
        _ => [0; 5],
    }
}

/// The pixels `text` covers at glyph scale `s` (each font pixel an s × s block, glyphs 4·s
/// apart), as offsets from its top-left corner, glyph by glyph, row by row.
pub fn pixels(text: &str, s: u32) -> impl Iterator<Item = (u32, u32)> + '_ {
    text.chars().enumerate().flat_map(move |(k, c)| {
        glyph(c).into_iter().enumerate().flat_map(move |(row, bits)| {
            (0..3u32).filter(move |col| bits & (4 >> col) != 0).flat_map(move |col| {
                (0..s).flat_map(move |sy| (0..s).map(move |sx| (k as u32 * 4 * s + col * s + sx, row as u32 * s + sy)))
            })
        })
    })
}

/// Draws `text` in white at (x, y) into an RGB8 buffer `width` pixels wide, scaled ×2.
pub fn draw_text(px: &mut [u8], width: u32, x: u32, y: u32, text: &str) {
    let height = px.len() as u32 / 3 / width.max(1);
    for (gx, gy) in pixels(text, 2) {
        let (xx, yy) = (x + gx, y + gy);
        if xx < width && yy < height {
            let o = ((yy * width + xx) * 3) as usize;
            px[o..o + 3].copy_from_slice(&[255, 255, 255]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_are_the_set_bits_scaled_and_spaced() {
        let t: Vec<_> = pixels("T", 1).collect();
        assert_eq!(t, [(0, 0), (1, 0), (2, 0), (1, 1), (1, 2), (1, 3), (1, 4)]);
        let tt: Vec<_> = pixels("TT", 2).collect();
        assert_eq!(tt.len(), 2 * 7 * 4);
        assert_eq!(&tt[..4], [(0, 0), (1, 0), (0, 1), (1, 1)]);
        assert_eq!(tt[7 * 4], (8, 0));
    }
}
