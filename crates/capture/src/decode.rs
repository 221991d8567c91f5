//! A shot's file to pixels the merge takes: JPEG through the `image` crate; camera raw
//! (DNG, CR2, CR3, NEF, ARW and the other formats `rawler`, the dnglab decoder, reads) as
//! linear camera RGB with the black level subtracted, one RGB pixel per colour-filter
//! block (a 2x2 Bayer block, a 6x6 X-Trans block: no demosaicing, the basis is far
//! smaller than the sensor anyway), and the file's colour matrix taking camera RGB to
//! linear sRGB, applied after the merge (everything is linear, so it commutes).

use std::path::Path;

use rayon::prelude::*;

/// A frame's pixels, owned.
pub enum DecodedPixels {
    /// 8-bit RGB, interleaved.
    Jpeg(Vec<u8>),
    /// Linear 16-bit camera RGB, interleaved, with its black and white levels.
    Raw {
        /// The samples.
        values: Vec<u16>,
        /// Black level.
        black: u16,
        /// Saturation.
        white: u16,
        /// Camera RGB to linear sRGB (D65 white), row-major.
        to_srgb: [[f32; 3]; 3],
    },
}

/// A decoded shot.
pub struct DecodedShot {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The exposure its EXIF records.
    pub exposure: visobjd_hdr::Exposure,
    /// The pixels.
    pub pixels: DecodedPixels,
}

impl DecodedShot {
    /// The 99.9th percentile of the frame's samples as a fraction of full scale: how
    /// close its brightest pixels come to clipping.
    pub fn high(&self) -> f64 {
        // A histogram of the sample values, not a sorted copy: a 24-megapixel frame has
        // 72 million samples.
        let (counts, black, span) = match &self.pixels {
            DecodedPixels::Jpeg(p) => (histogram(p.iter().map(|&c| usize::from(c)), 256), 0, 255.0),
            DecodedPixels::Raw {
                values,
                black,
                white,
                ..
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
    pub fn frame(&self) -> visobjd_hdr::BracketFrame<'_> {
        visobjd_hdr::BracketFrame {
            width: self.width,
            height: self.height,
            exposure: self.exposure,
            pixels: match &self.pixels {
                DecodedPixels::Jpeg(p) => visobjd_hdr::Pixels::Jpeg(p),
                DecodedPixels::Raw {
                    values,
                    black,
                    white,
                    ..
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
pub fn load(path: &Path, exposure: visobjd_hdr::Exposure) -> Result<DecodedShot, String> {
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
            Ok(DecodedShot {
                width: img.width() as usize,
                height: img.height() as usize,
                exposure,
                pixels: DecodedPixels::Jpeg(img.into_raw()),
            })
        }
        _ => camera_raw(path, exposure),
    }
}

/// Linear sRGB (D65) to CIE XYZ, IEC 61966-2-1.
pub(crate) const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.4124, 0.3576, 0.1805],
    [0.2126, 0.7152, 0.0722],
    [0.0193, 0.1192, 0.9505],
];

/// The most pixels a side of a camera raw frame: past the largest sensors made (a
/// 150-megapixel back is 14204 pixels wide).
pub const MAX_RAW_SIDE: usize = 32768;

/// The most pixels of a camera raw frame in all (256 megapixels: 512 MB of 16-bit
/// samples as it is decoded).
pub const MAX_RAW_PIXELS: usize = 256 << 20;

/// The first image size (width, height) over [`MAX_RAW_SIDE`] or [`MAX_RAW_PIXELS`] that
/// the TIFF structure of a TIFF-based raw file (DNG, CR2, NEF, ARW, PEF, ...) declares in
/// any of its IFDs, read before the decoder allocates for it; `None` when none is, or the
/// file is not TIFF-based (its decoder's own checks apply).
fn oversized(source: &rawler::rawsource::RawSource) -> Option<(usize, usize)> {
    use rawler::formats::tiff::GenericTiffReader;
    use rawler::formats::tiff::reader::TiffReader;
    use rawler::tags::TiffCommonTag;
    let tiff = GenericTiffReader::new(&mut source.reader(), 0, 0, None, &[]).ok()?;
    tiff.find_ifds_with_tag(TiffCommonTag::ImageWidth)
        .into_iter()
        .map(|ifd| {
            let side = |tag| ifd.get_entry(tag).map_or(0, |e| e.force_usize(0));
            (
                side(TiffCommonTag::ImageWidth),
                side(TiffCommonTag::ImageLength),
            )
        })
        .find(|&(w, h)| {
            w > MAX_RAW_SIDE || h > MAX_RAW_SIDE || w.saturating_mul(h) > MAX_RAW_PIXELS
        })
}

/// A camera raw file through `rawler`. Its decoders panic on some malformed files, so the
/// decode runs inside `catch_unwind`: a bad file is a sentence, never the end of a capture.
fn camera_raw(path: &Path, exposure: visobjd_hdr::Exposure) -> Result<DecodedShot, String> {
    use rawler::rawimage::{RawImageData, RawPhotometricInterpretation};
    let name = path.display();
    let hint = "capture with --format jpeg, or convert the camera's raw files to DNG";
    let unreadable = |e: &dyn std::fmt::Display| {
        format!("{name}: not a raw file the decoder reads ({e}); {hint}")
    };
    let source = rawler::rawsource::RawSource::new(path).map_err(|e| unreadable(&e))?;
    if let Some((w, h)) = oversized(&source) {
        return Err(format!(
            "{name}: declares {w}x{h} pixels; a raw frame may have at most {MAX_RAW_SIDE} a side and {} megapixels; {hint}",
            MAX_RAW_PIXELS >> 20
        ));
    }
    let params = rawler::decoders::RawDecodeParams::default();
    let raw = std::panic::catch_unwind(|| rawler::decode(&source, &params))
        .map_err(|_| format!("{name}: the raw decoder failed on this file; {hint}"))?
        .map_err(|e| unreadable(&e))?;
    let RawImageData::Integer(data) = &raw.data else {
        return Err(format!(
            "{name}: floating-point raw data is not read; {hint}"
        ));
    };
    let to_srgb = to_srgb(&raw).ok_or_else(|| {
        format!("{name}: the file has no usable colour matrix for camera RGB; {hint}")
    })?;
    let area = raw.active_area.map_or((0, 0, raw.width, raw.height), |r| {
        (r.p.x, r.p.y, r.d.w, r.d.h)
    });
    let (x0, y0, w, h) = area;
    if x0 + w > raw.width || y0 + h > raw.height || data.len() < raw.width * raw.height * raw.cpp {
        return Err(format!(
            "{name}: its image area does not fit its data; {hint}"
        ));
    }
    let black = |row: usize, col: usize, c: usize| -> f32 {
        let b = &raw.blacklevel;
        let (bw, bh, bc) = (b.width.max(1), b.height.max(1), b.cpp.max(1));
        let i = ((row - y0) % bh * bw + (col - x0) % bw) * bc + c % bc;
        b.levels
            .get(i)
            .or(b.levels.first())
            .map_or(0.0, |r| r.as_f32())
    };
    let white = |c: usize| -> f32 {
        let wl = &raw.whitelevel.0;
        wl.get(c)
            .or(wl.first())
            .map_or(f32::from(u16::MAX), |&v| v as f32)
    };
    // The block (one output pixel): a colour-filter pattern's repeat, or one pixel of
    // three samples. Per sample of the block: its colour, black level and white level
    // (black levels repeat with the filter pattern, as cameras record them).
    let (bw, bh, cpp, cfa) = match &raw.photometric {
        RawPhotometricInterpretation::Cfa(cfg) if raw.cpp == 1 => {
            (cfg.cfa.width, cfg.cfa.height, 1, Some(&cfg.cfa))
        }
        RawPhotometricInterpretation::LinearRaw if raw.cpp == 3 => (1, 1, 3, None),
        _ => {
            return Err(format!(
                "{name}: neither a colour-filter mosaic nor linear RGB; {hint}"
            ));
        }
    };
    let cell: Vec<(usize, f32, f32)> = (0..bh)
        .flat_map(|dy| (0..bw).flat_map(move |dx| (0..cpp).map(move |k| (dy, dx, k))))
        .map(|(dy, dx, k)| {
            let c = cfa.map_or(k, |p| p.color_at(y0 + dy, x0 + dx));
            (c, black(y0 + dy, x0 + dx, c), white(c))
        })
        .collect();
    if bw == 0 || (0..3).any(|c| !cell.iter().any(|s| s.0 == c)) || cell.iter().any(|s| s.0 > 2) {
        let pattern = cfa.map_or(String::new(), |p| p.name.clone());
        return Err(format!(
            "{name}: its colour filter ({pattern}) is not red, green and blue; {hint}"
        ));
    }
    let (ow, oh) = (w / bw, h / bh);
    if ow == 0 || oh == 0 {
        return Err(format!("{name}: the image is empty; {hint}"));
    }
    let mut count = [0f32; 3];
    for s in &cell {
        count[s.0] += 1.0;
    }
    // Full scale after the black level: the lowest of the samples', so a saturated sample
    // of any colour reads as saturated.
    let full = cell
        .iter()
        .map(|&(_, b, w)| w - b)
        .fold(f32::INFINITY, f32::min)
        .clamp(1.0, f32::from(u16::MAX));
    let mut values = vec![0u16; ow * oh * 3];
    values
        .par_chunks_exact_mut(ow * 3)
        .enumerate()
        .for_each(|(by, row_out)| {
            for (bx, px) in row_out.chunks_exact_mut(3).enumerate() {
                let (mut sum, mut clipped) = ([0f32; 3], [false; 3]);
                let mut s = cell.iter();
                for dy in 0..bh {
                    let start = ((y0 + by * bh + dy) * raw.width + x0 + bx * bw) * cpp;
                    for &v in &data[start..start + bw * cpp] {
                        if let Some(&(c, b, w)) = s.next() {
                            let v = f32::from(v);
                            clipped[c] |= v >= w;
                            sum[c] += (v - b).max(0.0);
                        }
                    }
                }
                for c in 0..3 {
                    px[c] = if clipped[c] {
                        full as u16
                    } else {
                        // Non-negative, so adding 0.5 rounds (and stays inline: `round`
                        // is a library call without SSE4.1).
                        ((sum[c] / count[c]).min(full) + 0.5) as u16
                    };
                }
            }
        });
    Ok(DecodedShot {
        width: ow,
        height: oh,
        exposure,
        pixels: DecodedPixels::Raw {
            values,
            black: 0,
            white: full as u16,
            to_srgb,
        },
    })
}

/// Camera RGB to linear sRGB from the file's colour matrix (XYZ to camera; D65 when the
/// file has one for it, else the first by illuminant, so the choice is the same every
/// run): the inverse of `xyz_to_cam * SRGB_TO_XYZ`. None when there is no 3x3 matrix or
/// it cannot be inverted.
fn to_srgb(raw: &rawler::RawImage) -> Option<[[f32; 3]; 3]> {
    use rawler::imgop::xyz::Illuminant;
    let m = raw.color_matrix.get(&Illuminant::D65).or_else(|| {
        raw.color_matrix
            .iter()
            .min_by_key(|(k, _)| **k)
            .map(|(_, m)| m)
    })?;
    if m.len() != 9 {
        return None;
    }
    let mut rgb_to_cam = [[0f64; 3]; 3];
    for (i, row) in rgb_to_cam.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3)
                .map(|k| f64::from(m[i * 3 + k]) * SRGB_TO_XYZ[k][j])
                .sum();
        }
    }
    invert(rgb_to_cam).map(|inv| inv.map(|row| row.map(|v| v as f32)))
}

/// The inverse of a 3x3 matrix, None when it is (nearly) singular.
pub(crate) fn invert(m: [[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let det = m[0][0] * cof(1, 2, 1, 2) - m[0][1] * cof(1, 2, 0, 2) + m[0][2] * cof(1, 2, 0, 1);
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    Some([
        [
            cof(1, 2, 1, 2) / det,
            -cof(0, 2, 1, 2) / det,
            cof(0, 1, 1, 2) / det,
        ],
        [
            -cof(1, 2, 0, 2) / det,
            cof(0, 2, 0, 2) / det,
            -cof(0, 1, 0, 2) / det,
        ],
        [
            cof(1, 2, 0, 1) / det,
            -cof(0, 2, 0, 1) / det,
            cof(0, 1, 0, 1) / det,
        ],
    ])
}

impl DecodedShot {
    /// Camera RGB to linear sRGB for this shot's pixels (identity for a JPEG, which the
    /// camera already rendered in sRGB).
    pub fn to_srgb(&self) -> Option<[[f32; 3]; 3]> {
        match &self.pixels {
            DecodedPixels::Raw { to_srgb, .. } => Some(*to_srgb),
            DecodedPixels::Jpeg(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn invert_gives_the_identity_back() {
        let m = [[0.8, 0.15, 0.05], [0.1, 0.8, 0.1], [0.02, 0.18, 0.8]];
        let inv = invert(m).expect("invertible");
        for (i, row) in m.iter().enumerate() {
            for j in 0..3 {
                let v: f64 = row.iter().zip(&inv).map(|(a, b)| a * b[j]).sum();
                assert!(
                    (v - f64::from(u8::from(i == j))).abs() < 1e-12,
                    "{i},{j}: {v}"
                );
            }
        }
        assert!(invert([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]).is_none());
    }

    /// A raw file that is not one, or is cut short, is a sentence naming the file and
    /// what to do, never a panic (rawler's decoders panic on some bad input).
    #[test]
    fn bad_raw_files_are_a_sentence() {
        let dir = std::env::temp_dir().join(format!("visobjd-bad-raw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let exposure = visobjd_hdr::Exposure {
            seconds: 0.01,
            iso: 100.0,
            f_number: 8.0,
        };
        let good = dir.join("good.dng");
        let sensor = vec![[0.25f32, 0.5, 0.125]; 64 * 48];
        crate::sim::write_raw(&good, 64, 48, &sensor, 0.01).expect("write a DNG");
        let shot = load(&good, exposure).expect("the DNG reads");
        assert_eq!(
            (shot.width, shot.height),
            (32, 24),
            "one pixel per 2x2 block"
        );
        let bytes = std::fs::read(&good).expect("read it back");
        let cases: [(&str, &[u8]); 3] = [
            ("garbage.cr2", b"not a raw file at all"),
            ("empty.nef", b""),
            ("cut.dng", &bytes[..bytes.len() / 3]),
        ];
        for (name, content) in cases {
            let path = dir.join(name);
            std::fs::write(&path, content).expect("write the bad file");
            let Err(e) = load(&path, exposure) else {
                panic!("{name} was read");
            };
            assert!(
                e.contains(name) && e.contains("--format jpeg"),
                "{name}: {e}"
            );
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A few hundred bytes of DNG whose header declares 100000x100000 pixels is refused
    /// by its header, before the decoder allocates 20 GB for it, naming the limit.
    #[test]
    fn a_raw_file_declaring_too_many_pixels_is_refused_before_decoding() {
        let dir = std::env::temp_dir().join(format!("visobjd-huge-raw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("huge.dng");
        crate::sim::write_raw(&path, 4, 4, &[[0.5; 3]; 16], 0.01).expect("write a DNG");
        let mut bytes = std::fs::read(&path).expect("read it back");
        // The main IFD's ImageWidth and ImageLength become LONG 100000.
        let at =
            |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let ifd = at(4) as usize;
        let entries = usize::from(u16::from_le_bytes([bytes[ifd], bytes[ifd + 1]]));
        for e in (0..entries).map(|k| ifd + 2 + 12 * k) {
            if matches!(u16::from_le_bytes([bytes[e], bytes[e + 1]]), 256 | 257) {
                bytes[e + 2..e + 4].copy_from_slice(&4u16.to_le_bytes());
                bytes[e + 4..e + 8].copy_from_slice(&1u32.to_le_bytes());
                bytes[e + 8..e + 12].copy_from_slice(&100_000u32.to_le_bytes());
            }
        }
        std::fs::write(&path, &bytes).expect("write the DNG");
        assert!(bytes.len() < 1000, "{} bytes", bytes.len());
        let exposure = visobjd_hdr::Exposure {
            seconds: 0.01,
            iso: 100.0,
            f_number: 8.0,
        };
        let Err(e) = load(&path, exposure) else {
            panic!("a 100000x100000 frame was read");
        };
        assert!(
            e.contains("huge.dng: declares 100000x100000 pixels; a raw frame may have at most 32768 a side and 256 megapixels"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
