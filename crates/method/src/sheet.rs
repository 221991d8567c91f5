//! The contact sheet: gallery entries in a grid, each labelled with the number `/vo/pick`
//! uses, so a designer can say "pick 7" from a printout or a screen.

use image::{Rgb, RgbImage};

/// 3x5 bitmaps of the digits 0-9, one row per entry, most significant bit left.
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b010, 0b010, 0b010],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// Gap between thumbnails and around the sheet, in pixels.
const GAP: u32 = 8;

/// Lays thumbnails out in a grid (at most four across), labelling thumbnail i with i + 1.
pub fn contact_sheet(thumbs: &[RgbImage]) -> RgbImage {
    let Some(first) = thumbs.first() else {
        return RgbImage::from_pixel(GAP * 2, GAP * 2, Rgb([24, 24, 24]));
    };
    let (tw, th) = first.dimensions();
    let cols = (thumbs.len() as u32).clamp(1, 4);
    let rows = (thumbs.len() as u32).div_ceil(cols);
    let mut sheet = RgbImage::from_pixel(
        GAP + cols * (tw + GAP),
        GAP + rows * (th + GAP),
        Rgb([24, 24, 24]),
    );
    let scale = (th / 40).clamp(2, 6);
    for (i, thumb) in thumbs.iter().enumerate() {
        let (col, row) = (i as u32 % cols, i as u32 / cols);
        let (x, y) = (GAP + col * (tw + GAP), GAP + row * (th + GAP));
        image::imageops::replace(&mut sheet, thumb, i64::from(x), i64::from(y));
        label(&mut sheet, x + 4, y + 4, i + 1, scale);
    }
    sheet
}

/// Draws `n` as white digits on a black box at (x, y).
fn label(img: &mut RgbImage, x: u32, y: u32, n: usize, scale: u32) {
    let digits: Vec<usize> = n
        .to_string()
        .bytes()
        .map(|b| usize::from(b - b'0'))
        .collect();
    let (w, h) = (digits.len() as u32 * 4 * scale + scale, 7 * scale);
    for dy in 0..h {
        for dx in 0..w {
            put(img, x + dx, y + dy, Rgb([0, 0, 0]));
        }
    }
    for (k, &d) in digits.iter().enumerate() {
        for (row, bits) in DIGITS[d].iter().enumerate() {
            for col in 0..3 {
                if bits & (0b100 >> col) == 0 {
                    continue;
                }
                for sy in 0..scale {
                    for sx in 0..scale {
                        let px = x + scale + (k as u32 * 4 + col) * scale + sx;
                        let py = y + scale + row as u32 * scale + sy;
                        put(img, px, py, Rgb([255, 255, 255]));
                    }
                }
            }
        }
    }
}

fn put(img: &mut RgbImage, x: u32, y: u32, c: Rgb<u8>) {
    if x < img.width() && y < img.height() {
        img.put_pixel(x, y, c);
    }
}
