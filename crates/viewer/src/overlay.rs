//! Text drawn into the window's pixels: the public-domain 8x8 bitmap font (`font8x8`, basic
//! Latin), on a dimmed band so it reads over any picture.

use font8x8::legacy::BASIC_LEGACY;

/// Height of one text line in pixels (8 rows of glyph, 2 of spacing).
pub const LINE_HEIGHT_PX: usize = 10;

/// Width of one character in pixels.
pub const CHAR_WIDTH_PX: usize = 8;

/// An `0RGB` pixel buffer of `width * height` pixels, rows from the top.
pub struct Canvas<'a> {
    /// Pixels, `0x00RRGGBB`.
    pub pixels: &'a mut [u32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl Canvas<'_> {
    /// Draws `lines` from pixel `(x, y)` down, each on a band darkened to a third of the
    /// picture; text beyond the canvas is clipped.
    pub fn text_block(&mut self, x: usize, y: usize, lines: &[String], color: u32) {
        let cols = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
        let (w, h) = (cols * CHAR_WIDTH_PX + 4, lines.len() * LINE_HEIGHT_PX + 2);
        for py in y..(y + h).min(self.height) {
            for px in x..(x + w).min(self.width) {
                let p = &mut self.pixels[py * self.width + px];
                *p = (*p >> 2) & 0x003f_3f3f;
            }
        }
        for (i, line) in lines.iter().enumerate() {
            self.text(x + 2, y + 2 + i * LINE_HEIGHT_PX, line, color);
        }
    }

    /// Draws one line of text with its top-left corner at `(x, y)`; characters outside basic
    /// Latin are drawn as `?`.
    pub fn text(&mut self, x: usize, y: usize, line: &str, color: u32) {
        for (i, ch) in line.chars().enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                '?' as usize
            };
            let glyph = BASIC_LEGACY[code];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        self.put(x + i * CHAR_WIDTH_PX + col, y + row, color);
                    }
                }
            }
        }
    }

    /// A vertical line at column `x`.
    pub fn vline(&mut self, x: usize, color: u32) {
        for y in 0..self.height {
            self.put(x, y, color);
        }
    }

    fn put(&mut self, x: usize, y: usize, color: u32) {
        if x < self.width && y < self.height {
            self.pixels[y * self.width + x] = color;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_sets_pixels_and_clips_at_the_border() {
        let mut pixels = vec![0x00ff_ffff; 20 * 12];
        let mut c = Canvas {
            pixels: &mut pixels,
            width: 20,
            height: 12,
        };
        c.text_block(0, 0, &["1 ms".to_string()], 0x00ff_0000);
        assert!(pixels.contains(&0x00ff_0000), "glyph pixels drawn");
        assert!(pixels.contains(&0x003f_3f3f), "band dimmed");
        let mut c = Canvas {
            pixels: &mut pixels,
            width: 20,
            height: 12,
        };
        c.text(15, 10, "\u{e9}WWW", 0x0000_ff00);
        c.vline(19, 1);
    }
}
