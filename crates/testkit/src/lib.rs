//! What the workspace's tests share, whichever crate they test: builders for the small
//! synthetic scenes and images they write themselves, the rule for a missing tool
//! ([`tools`]) and Art-Net and sACN decoded independently of the sending code ([`wire`]).
//! A dev-dependency only; it depends on no visobjd crate.

pub mod tools;
pub mod wire;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, PoisonError};

/// A light of a synthetic scene: its basis image as a function of pixel position.
pub struct TestLight {
    pub channel: u32,
    pub group: Option<&'static str>,
    pub profile: &'static str,
    pub universe: u16,
    pub address: u16,
    /// Linear RGB at (x, y).
    pub pixel: Box<dyn Fn(usize, usize) -> [f32; 3] + Sync>,
}

impl TestLight {
    /// A light patched at `address` on universe 1 that lights `rect` (pixel bounds, end
    /// exclusive) with `level` of white.
    pub fn rect(
        channel: u32,
        group: Option<&'static str>,
        profile: &'static str,
        address: u16,
        rect: (usize, usize, usize, usize),
        level: f32,
    ) -> TestLight {
        TestLight {
            channel,
            group,
            profile,
            universe: 1,
            address,
            pixel: Box::new(move |x, y| {
                if x >= rect.0 && x < rect.2 && y >= rect.1 && y < rect.3 {
                    [level; 3]
                } else {
                    [0.0; 3]
                }
            }),
        }
    }
}

/// Writes a float RGB EXR.
pub fn write_exr(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3] + Sync) {
    exr::prelude::write_rgb_file(path, w, h, |x, y| {
        let p = f(x, y);
        (p[0], p[1], p[2])
    })
    .expect("write test EXR");
}

/// Writes `dir/scene.toml` and `dir/basis/NNN.exr`; returns `dir`.
pub fn write_scene(
    dir: &Path,
    w: usize,
    h: usize,
    groups: &[&str],
    lights: &[TestLight],
) -> PathBuf {
    std::fs::create_dir_all(dir.join("basis")).expect("mkdir");
    let mut toml = String::from("name = \"test scene\"\n");
    for g in groups {
        toml += &format!("[[group]]\nname = \"{g}\"\n");
    }
    for l in lights {
        let basis = format!("basis/{:03}.exr", l.channel);
        write_exr(&dir.join(&basis), w, h, |x, y| (l.pixel)(x, y));
        toml += &format!(
            "[[light]]\nchannel = {}\nbasis = \"{basis}\"\nprofile = \"{}\"\nuniverse = {}\naddress = {}\n",
            l.channel, l.profile, l.universe, l.address
        );
        if let Some(g) = l.group {
            toml += &format!("group = \"{g}\"\n");
        }
    }
    std::fs::write(dir.join("scene.toml"), toml).expect("write scene.toml");
    dir.to_path_buf()
}

/// A fresh temporary folder, unique per test name and process. A name is handed out once
/// per process: two tests of one binary asking for the same one would wipe each other's.
pub fn temp_dir(name: &str) -> PathBuf {
    static TAKEN: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());
    let fresh = TAKEN
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .insert(name.to_owned());
    assert!(
        fresh,
        "temp_dir({name:?}) was already handed out in this process"
    );
    let dir = std::env::temp_dir().join(format!("visobjd-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("mkdir temp");
    dir
}

/// A PNG whose header claims `w` x `h` (RGB, 8 bits) with no pixel data behind it: refused
/// by its header alone when it is over the size limit.
pub fn png_header_only(path: &Path, w: u32, h: u32) {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut c = 0xffff_ffffu32;
        for &b in bytes {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
        }
        !c
    }
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        png.extend((data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        png.extend_from_slice(&body);
        png.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    std::fs::write(path, png).expect("write a header-only PNG");
}

/// A real, decodable PNG of `w` x `h` black pixels: a few hundred KiB on disk that decode
/// to `3 w h` bytes (a decompression bomb when large).
pub fn png_bomb(path: &Path, w: u32, h: u32) {
    use image::ImageEncoder;
    let pixels = vec![0u8; w as usize * h as usize * 3];
    let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create bomb"));
    image::codecs::png::PngEncoder::new_with_quality(
        file,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::NoFilter,
    )
    .write_image(&pixels, w, h, image::ExtendedColorType::Rgb8)
    .expect("write bomb");
}

/// A `w` x `h` 16-bit RGBA PNG, a smooth gradient (red along x, green along y: 8 x the
/// coordinate, so pixel (1000, 2000) reads 8-bit (31, 62, 78) with blue 20000 and alpha
/// opaque), written row by row: a few MB on disk that decode to 8 bytes a pixel at their own
/// depth, and never held whole by the test.
pub fn png16(path: &Path, w: u32, h: u32) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).expect("create PNG"));
    let mut encoder = png::Encoder::new(file, w, h);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Sixteen);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header().expect("PNG header");
    let mut stream = writer.stream_writer().expect("PNG stream");
    let mut row = Vec::with_capacity(w as usize * 8);
    for y in 0..h {
        row.clear();
        for x in 0..w {
            for v in [x * 8, y * 8, 20_000, 65_535] {
                row.extend((v as u16).to_be_bytes());
            }
        }
        std::io::Write::write_all(&mut stream, &row).expect("PNG row");
    }
    stream.finish().expect("PNG end");
}

/// A small progressive JPEG (crates/method/tests/fixtures/progressive.jpg) whose frame
/// header claims `w` x `h`: read from its header as that size, so refused before decoding
/// when too large.
pub fn progressive_jpeg_claiming(path: &Path, w: u16, h: u16) {
    let mut jpeg = include_bytes!("../../method/tests/fixtures/progressive.jpg").to_vec();
    let at = jpeg
        .windows(2)
        .position(|m| m == [0xFF, 0xC2])
        .expect("a progressive frame header");
    jpeg[at + 5..at + 7].copy_from_slice(&h.to_be_bytes());
    jpeg[at + 7..at + 9].copy_from_slice(&w.to_be_bytes());
    std::fs::write(path, jpeg).expect("write JPEG");
}

/// A reference image from a function of pixel position.
pub fn write_png(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    img.save(path).expect("write PNG");
}

/// A stage of `n` ungrouped lights in a row: light i lights the 4-pixel stripe i of a
/// `4n` x 10 image at level 0.5; profiles alternate `irgb` and `dimmer` when `mixed`, else
/// all `irgb`.
pub fn stripes(dir: &Path, n: usize, mixed: bool) -> PathBuf {
    let w = 4 * n;
    let lights: Vec<TestLight> = (0..n)
        .map(|i| {
            let profile = if mixed && i % 2 == 1 {
                "dimmer"
            } else {
                "irgb"
            };
            TestLight::rect(
                i as u32 + 1,
                None,
                profile,
                (i * 4 + 1) as u16,
                (i * 4, 0, i * 4 + 4, 10),
                0.5,
            )
        })
        .collect();
    write_scene(dir, w, 10, &[], &lights)
}
