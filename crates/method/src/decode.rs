//! Reference images (PNG, JPEG) decoded to 8-bit sRGB within a memory bound: what a decode
//! will take is worked out from the header, before a pixel is decoded, and a decode that
//! would take more than [`DECODE_LIMIT`] is refused. A PNG is decoded row by row straight
//! into the 8-bit image (a 16-bit or RGBA one never exists whole at its own depth); a JPEG
//! into the image's own buffer. So a decode holds the image at 3 bytes per pixel (192 MB at
//! the 64-megapixel limit) plus the rows in flight, and for a JPEG its file and, for a
//! progressive one, the decoder's coefficients (2 bytes per sample of each component).

use std::io::{BufRead, Read, Seek};
use std::path::Path;

use image::RgbImage;

use crate::objective::MAX_REFERENCE_PIXELS;

/// The most memory one reference decode may take, in bytes (docs/osc.md, "Objectives").
pub const DECODE_LIMIT: u64 = 256 << 20;

/// What a decode takes beyond what [`need`] counts: the decoders' tables, the zlib window,
/// the scratch rows of the upsampler.
const DECODER_STATE: u64 = 4 << 20;

/// Decodes a reference image (PNG, JPEG) to 8-bit sRGB, refusing non-images, images over
/// [`MAX_REFERENCE_PIXELS`] and images whose decode would take over [`DECODE_LIMIT`], all
/// before the pixels are allocated. Err is a phrase to follow the file's name ("is not a
/// readable image: ...").
pub fn decode_reference(path: &Path) -> Result<RgbImage, String> {
    let mut file = std::fs::File::open(path).map_err(|e| format!("cannot open it: {e}"))?;
    let mut head = [0u8; 16];
    let n = read_head(&mut file, &mut head).map_err(|e| format!("cannot read it: {e}"))?;
    file.rewind().map_err(|e| format!("cannot read it: {e}"))?;
    match image::guess_format(&head[..n]) {
        Ok(image::ImageFormat::Png) => decode_png(std::io::BufReader::new(file)),
        Ok(image::ImageFormat::Jpeg) => {
            // The JPEG decoder works on the whole file in memory: its size counts.
            let len = file.metadata().map_or(0, |m| m.len());
            if len > DECODE_LIMIT {
                return Err(over(len, "a JPEG file of that size"));
            }
            let mut bytes = Vec::with_capacity(len as usize);
            file.read_to_end(&mut bytes)
                .map_err(|e| format!("cannot read it: {e}"))?;
            decode_jpeg(&bytes)
        }
        _ => Err("is not an image (PNG or JPEG expected)".into()),
    }
}

/// [`decode_reference`] of a file's bytes already in memory: the same checks and limits,
/// without the file system (the fuzz target drives this).
pub fn decode_reference_bytes(bytes: &[u8]) -> Result<RgbImage, String> {
    match image::guess_format(bytes) {
        Ok(image::ImageFormat::Png) => decode_png(std::io::Cursor::new(bytes)),
        Ok(image::ImageFormat::Jpeg) => decode_jpeg(bytes),
        _ => Err("is not an image (PNG or JPEG expected)".into()),
    }
}

fn read_head(r: &mut impl Read, head: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < head.len() {
        match r.read(&mut head[n..])? {
            0 => break,
            got => n += got,
        }
    }
    Ok(n)
}

/// The refusal of a decode that would take `need` bytes.
fn over(need: u64, what: &str) -> String {
    format!(
        "would take {} MiB to decode ({what}), over the {} MiB a reference's decode may take; save it smaller{}",
        need.div_ceil(1 << 20),
        DECODE_LIMIT >> 20,
        if what.contains("progressive") {
            ", or as a baseline JPEG or a PNG"
        } else {
            ""
        }
    )
}

/// Refuses `w` x `h` over the pixel limit, or empty.
fn check_size(w: u64, h: u64) -> Result<(), String> {
    if w * h > MAX_REFERENCE_PIXELS {
        return Err(format!(
            "is {w}x{h}, over the {} megapixel limit",
            MAX_REFERENCE_PIXELS / 1_000_000
        ));
    }
    if w == 0 || h == 0 {
        return Err("has no pixels".into());
    }
    Ok(())
}

/// The 8-bit RGB image's buffer, or a refusal when the allocation fails.
fn image_buffer(w: u64, h: u64) -> Result<Vec<u8>, String> {
    let len = (w * h * 3) as usize;
    let mut buf = Vec::new();
    buf.try_reserve_exact(len)
        .map_err(|_| format!("cannot be decoded: {} MiB are not free", len >> 20))?;
    buf.resize(len, 0);
    Ok(buf)
}

/// Runs a decoder, a panic inside it read as a corrupt file.
fn guarded<T>(f: impl FnOnce() -> Result<T, String>) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| Err("is corrupt (the decoder gave up)".to_string()))
}

/// A PNG, row by row, each row converted to 8-bit RGB as it arrives (alpha dropped, grey
/// repeated, 16-bit samples rounded as the `image` crate rounds them).
fn decode_png<R: BufRead + Seek>(r: R) -> Result<RgbImage, String> {
    guarded(|| {
        let unreadable = |e: png::DecodingError| format!("is not a readable image: {e}");
        let mut decoder = png::Decoder::new_with_limits(
            r,
            png::Limits {
                bytes: DECODE_LIMIT as usize,
            },
        );
        // Palettes and low bit depths to 8 bits, transparency to an alpha channel.
        decoder.set_transformations(png::Transformations::EXPAND);
        let header = decoder.read_header_info().map_err(unreadable)?;
        let (w, h) = (u64::from(header.width), u64::from(header.height));
        check_size(w, h)?;
        let mut reader = decoder.read_info().map_err(unreadable)?;
        let (color, depth) = reader.output_color_type();
        let channels = color.samples();
        let wide = depth == png::BitDepth::Sixteen;
        let line = reader
            .output_line_size(reader.info().width)
            .ok_or("is not a readable image: its rows are too long")? as u64;
        // The image, the decoder's current and previous raw rows and its output row, and one
        // converted row for an interlaced pass.
        let need = 3 * w * h + 3 * line + 3 * w + DECODER_STATE;
        if need > DECODE_LIMIT {
            return Err(over(need, &format!("a {w}x{h} PNG")));
        }
        let stride = 3 * w as usize;
        let mut out = image_buffer(w, h)?;
        let mut pass_row = Vec::new();
        let mut y = 0usize;
        while let Some(row) = reader.next_interlaced_row().map_err(unreadable)? {
            let data = row.data();
            match row.interlace() {
                png::InterlaceInfo::Null(_) => {
                    let Some(dst) = out.get_mut(y * stride..(y + 1) * stride) else {
                        return Err("is not a readable image: too many rows".into());
                    };
                    to_rgb8(data, channels, wide, dst);
                    y += 1;
                }
                png::InterlaceInfo::Adam7(info) => {
                    let samples = data.len() / (channels * if wide { 2 } else { 1 });
                    pass_row.resize(3 * samples, 0);
                    to_rgb8(data, channels, wide, &mut pass_row);
                    png::expand_interlaced_row(&mut out, stride, &pass_row, info, 24);
                }
            }
        }
        RgbImage::from_raw(w as u32, h as u32, out)
            .ok_or_else(|| "is not a readable image".to_string())
    })
}

/// One row of `channels`-sample pixels (8-bit, or 16-bit big-endian when `wide`) as 8-bit
/// RGB into `dst`: grey repeated, alpha dropped.
fn to_rgb8(src: &[u8], channels: usize, wide: bool, dst: &mut [u8]) {
    let sample = |px: &[u8], i: usize| -> u8 {
        if wide {
            let v = u32::from(u16::from_be_bytes([px[2 * i], px[2 * i + 1]]));
            ((v + 128) / 257) as u8
        } else {
            px[i]
        }
    };
    let bytes = channels * if wide { 2 } else { 1 };
    for (px, rgb) in src.chunks_exact(bytes).zip(dst.chunks_exact_mut(3)) {
        if channels >= 3 {
            rgb.copy_from_slice(&[sample(px, 0), sample(px, 1), sample(px, 2)]);
        } else {
            rgb.fill(sample(px, 0));
        }
    }
}

/// A JPEG, decoded by zune-jpeg straight into the 8-bit RGB image (grey and CMYK converted
/// as they are decoded).
fn decode_jpeg(bytes: &[u8]) -> Result<RgbImage, String> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;
    guarded(|| {
        let unreadable =
            |e: zune_jpeg::errors::DecodeErrors| format!("is not a readable image: {e}");
        let max = MAX_REFERENCE_PIXELS as usize;
        let options = DecoderOptions::default()
            .set_strict_mode(false)
            .set_max_width(max)
            .set_max_height(max)
            .jpeg_set_out_colorspace(ColorSpace::RGB);
        let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
        decoder.decode_headers().map_err(unreadable)?;
        let info = decoder.info().ok_or("is not a readable image")?;
        let (w, h) = (u64::from(info.width), u64::from(info.height));
        check_size(w, h)?;
        let components = u64::from(info.components.max(1));
        let progressive = info.sof.is_progressive();
        // The file, the image, and a progressive decode's coefficients: one i16 per sample
        // of every component, over the image padded to whole 16-pixel blocks (a
        // subsampled component takes less: this is the most).
        let coefficients = if progressive {
            2 * components * w.next_multiple_of(16) * h.next_multiple_of(16)
        } else {
            0
        };
        let rows = 16 * components * w.next_multiple_of(16) * 4;
        let need = bytes.len() as u64 + 3 * w * h + coefficients + rows + DECODER_STATE;
        if need > DECODE_LIMIT {
            let kind = if progressive { "progressive " } else { "" };
            return Err(over(need, &format!("a {w}x{h} {kind}JPEG")));
        }
        let mut out = image_buffer(w, h)?;
        match decoder.output_buffer_size() {
            Some(n) if n == out.len() => {}
            _ => return Err("is not a readable image: an unexpected colour layout".into()),
        }
        decoder.decode_into(&mut out).map_err(unreadable)?;
        RgbImage::from_raw(w as u32, h as u32, out)
            .ok_or_else(|| "is not a readable image".to_string())
    })
}
