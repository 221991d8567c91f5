//! A shot's file to pixels the merge takes: JPEG through the `image` crate; raw as a
//! 16-bit linear RGB TIFF with its black and white levels (`BlackLevel`, `WhiteLevel`, as
//! DNG names them). Camera raw formats (CR2, NEF, ARW, packed DNG) are not read yet: such a
//! file is refused with a sentence that says to capture JPEG.

use std::path::Path;

/// DNG's `BlackLevel` tag.
pub const BLACK_LEVEL: u16 = 50714;
/// DNG's `WhiteLevel` tag.
pub const WHITE_LEVEL: u16 = 50717;

/// A frame's pixels, owned.
pub enum Pixels {
    /// 8-bit RGB, interleaved.
    Jpeg(Vec<u8>),
    /// Linear 16-bit RGB, interleaved, with its black and white levels.
    Raw {
        /// The samples.
        values: Vec<u16>,
        /// Black level.
        black: u16,
        /// Saturation.
        white: u16,
    },
}

/// A decoded shot.
pub struct Shot {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The exposure its EXIF records.
    pub exposure: visobjd_hdr::Exposure,
    /// The pixels.
    pub pixels: Pixels,
}

impl Shot {
    /// The 99.9th percentile of the frame's samples as a fraction of full scale: how
    /// close its brightest pixels come to clipping.
    pub fn high(&self) -> f64 {
        // A histogram of the sample values, not a sorted copy: a 24-megapixel frame has
        // 72 million samples.
        let (counts, black, span) = match &self.pixels {
            Pixels::Jpeg(p) => (histogram(p.iter().map(|&c| usize::from(c)), 256), 0, 255.0),
            Pixels::Raw {
                values,
                black,
                white,
            } => (
                histogram(values.iter().map(|&x| usize::from(x)), 65536),
                usize::from(*black),
                f64::from(white - black),
            ),
        };
        let total: usize = counts.iter().sum();
        if total == 0 {
            return 0.0;
        }
        let rank = (total - 1) * 999 / 1000;
        let mut seen = 0;
        let value = counts
            .iter()
            .position(|&n| {
                seen += n;
                seen > rank
            })
            .unwrap_or(0);
        value.saturating_sub(black) as f64 / span
    }

    /// The shot as the merge takes it (borrowed, not copied).
    pub fn frame(&self) -> visobjd_hdr::Frame<'_> {
        visobjd_hdr::Frame {
            width: self.width,
            height: self.height,
            exposure: self.exposure,
            pixels: match &self.pixels {
                Pixels::Jpeg(p) => visobjd_hdr::Pixels::Jpeg(p),
                Pixels::Raw {
                    values,
                    black,
                    white,
                } => visobjd_hdr::Pixels::Raw {
                    values,
                    black: *black,
                    white: *white,
                },
            },
        }
    }
}

/// How many of `values` (each below `bins`) fall on each value.
fn histogram(values: impl Iterator<Item = usize>, bins: usize) -> Vec<usize> {
    let mut counts = vec![0usize; bins];
    for v in values {
        counts[v.min(bins - 1)] += 1;
    }
    counts
}

/// Reads the shot at `path` taken with `exposure` (ISO and aperture default to the
/// session's when the file does not record them).
pub fn load(path: &Path, exposure: visobjd_hdr::Exposure) -> Result<Shot, String> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "jpg" | "jpeg" => {
            let img = image::ImageReader::open(path)
                .and_then(|r| r.with_guessed_format())
                .map_err(|e| format!("{}: cannot open it: {e}", path.display()))?
                .decode()
                .map_err(|e| format!("{}: not a readable JPEG: {e}", path.display()))?
                .into_rgb8();
            Ok(Shot {
                width: img.width() as usize,
                height: img.height() as usize,
                exposure,
                pixels: Pixels::Jpeg(img.into_raw()),
            })
        }
        "tif" | "tiff" => raw_tiff(path, exposure),
        other => Err(format!(
            "{}: `.{other}` raw files are not read yet; capture with --format jpeg",
            path.display()
        )),
    }
}

fn raw_tiff(path: &Path, exposure: visobjd_hdr::Exposure) -> Result<Shot, String> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::tags::Tag;
    let bad =
        |e: &dyn std::fmt::Display| format!("{}: not a readable raw TIFF: {e}", path.display());
    let file = std::fs::File::open(path)
        .map_err(|e| format!("{}: cannot open it: {e}", path.display()))?;
    let mut d = Decoder::new(std::io::BufReader::new(file)).map_err(|e| bad(&e))?;
    let (w, h) = d.dimensions().map_err(|e| bad(&e))?;
    let level = |d: &mut Decoder<_>, tag: u16, default: u16| {
        d.find_tag_unsigned::<u16>(Tag::Unknown(tag))
            .ok()
            .flatten()
            .unwrap_or(default)
    };
    let black = level(&mut d, BLACK_LEVEL, 0);
    let white = level(&mut d, WHITE_LEVEL, u16::MAX);
    let values = match d.read_image().map_err(|e| bad(&e))? {
        DecodingResult::U16(v) => v,
        _ => return Err(bad(&"expected 16-bit RGB samples")),
    };
    if values.len() != w as usize * h as usize * 3 || black >= white {
        return Err(bad(&"expected 16-bit RGB samples with black below white"));
    }
    Ok(Shot {
        width: w as usize,
        height: h as usize,
        exposure,
        pixels: Pixels::Raw {
            values,
            black,
            white,
        },
    })
}
