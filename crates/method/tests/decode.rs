//! Reference decoding (crates/method/src/decode.rs): every PNG and JPEG layout gives the
//! pixels the `image` crate's own decode gives, and a decode over the memory bound is
//! refused from the header, saying what it would take and the limit.

use std::path::{Path, PathBuf};

use image::{ExtendedColorType, ImageEncoder};
use visobjd_method::objective::{DECODE_LIMIT, decode_reference, decode_reference_bytes};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// What the `image` crate makes of the file: the decode the references used before.
fn by_image(bytes: &[u8]) -> image::RgbImage {
    image::load_from_memory(bytes)
        .expect("image decodes it")
        .to_rgb8()
}

fn same_as_image(name: &str, bytes: &[u8]) {
    let ours = decode_reference_bytes(bytes).unwrap_or_else(|e| panic!("{name} {e}"));
    let theirs = by_image(bytes);
    assert_eq!(ours.dimensions(), theirs.dimensions(), "{name}");
    let differ = ours.pixels().zip(theirs.pixels()).position(|(a, b)| a != b);
    assert_eq!(differ, None, "{name}: the first differing pixel");
}

#[test]
fn every_layout_decodes_as_the_image_crate_decodes_it() {
    // Interlaced PNGs (16-bit RGBA, a 4-bit palette with transparency, 2-bit grey) and
    // JPEGs (progressive, 4:2:0, grey, CMYK), from fixtures/make.py.
    for name in [
        "interlaced-rgba16.png",
        "interlaced-palette4.png",
        "interlaced-grey2.png",
        "progressive.jpg",
        "baseline-420.jpg",
        "grey.jpg",
        "cmyk.jpg",
    ] {
        let bytes = std::fs::read(fixture(name)).expect("fixture");
        same_as_image(name, &bytes);
        let from_file = decode_reference(&fixture(name)).expect("decodes from the file");
        let from_bytes = decode_reference_bytes(&bytes).expect("decodes from its bytes");
        assert!(
            from_file == from_bytes,
            "{name}: the file and its bytes decode alike"
        );
    }
    // Every PNG colour type at 8 and 16 bits, not interlaced, with odd sizes.
    let (w, h) = (41u32, 17u32);
    let value = |x: u32, y: u32, c: u32| ((x * 37 + y * 91 + c * 53) * 997 % 65536) as u16;
    for (channels, kind8, kind16) in [
        (1, ExtendedColorType::L8, ExtendedColorType::L16),
        (2, ExtendedColorType::La8, ExtendedColorType::La16),
        (3, ExtendedColorType::Rgb8, ExtendedColorType::Rgb16),
        (4, ExtendedColorType::Rgba8, ExtendedColorType::Rgba16),
    ] {
        for (kind, wide) in [(kind8, false), (kind16, true)] {
            let mut raw = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    for c in 0..channels {
                        let v = value(x, y, c);
                        if wide {
                            raw.extend(v.to_ne_bytes());
                        } else {
                            raw.push((v >> 8) as u8);
                        }
                    }
                }
            }
            let mut png = Vec::new();
            image::codecs::png::PngEncoder::new(&mut png)
                .write_image(&raw, w, h, kind)
                .expect("encode");
            same_as_image(&format!("{kind:?}"), &png);
        }
    }
}

/// `jpeg` with its frame header (SOF0 or SOF2) claiming `w` x `h`.
fn resized(jpeg: &[u8], w: u16, h: u16) -> Vec<u8> {
    let mut out = jpeg.to_vec();
    let at = out
        .windows(2)
        .position(|m| m == [0xFF, 0xC0] || m == [0xFF, 0xC2])
        .expect("a frame header");
    out[at + 5..at + 7].copy_from_slice(&h.to_be_bytes());
    out[at + 7..at + 9].copy_from_slice(&w.to_be_bytes());
    out
}

/// The refusal of `bytes` (a decode that succeeds is a failure, said without its pixels).
fn refusal(bytes: &[u8]) -> String {
    match decode_reference_bytes(bytes) {
        Ok(img) => panic!(
            "a {}x{} image was decoded, not refused",
            img.width(),
            img.height()
        ),
        Err(e) => e,
    }
}

#[test]
fn a_decode_over_the_memory_bound_is_refused_from_its_header() {
    let limit = format!("over the {} MiB", DECODE_LIMIT >> 20);
    // A progressive JPEG keeps every coefficient while it decodes: 7000 x 7000 (49
    // megapixels, under the pixel limit) would take 147 MB of image and 294 MB of
    // coefficients.
    let progressive = std::fs::read(fixture("progressive.jpg")).expect("fixture");
    let e = refusal(&resized(&progressive, 7000, 7000));
    assert!(e.starts_with("would take 427 MiB to decode"), "{e}");
    assert!(e.contains("a 7000x7000 progressive JPEG"), "{e}");
    assert!(e.contains(&limit), "{e}");
    assert!(e.contains("or as a baseline JPEG or a PNG"), "{e}");
    // The same size as a baseline JPEG is within it: decoded (its data is only the small
    // image's, so most of it is grey, but nothing is refused).
    let baseline = std::fs::read(fixture("baseline-420.jpg")).expect("fixture");
    let big = resized(&baseline, 7000, 7000);
    match decode_reference_bytes(&big) {
        Ok(img) => assert_eq!(img.dimensions(), (7000, 7000)),
        Err(e) => assert!(!e.contains(&limit), "{e}"),
    }
    // Over the pixel limit, refused as before.
    let e = refusal(&resized(&baseline, 65535, 1000));
    assert!(e.contains("over the 64 megapixel limit"), "{e}");
    // Not an image at all.
    let e = refusal(b"not a picture");
    assert_eq!(e, "is not an image (PNG or JPEG expected)");
}
