//! Builders for small synthetic scenes and reference images that tests write themselves.
#![allow(dead_code)]

pub mod daemon;
pub mod wire;

use std::path::{Path, PathBuf};

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

/// A fresh temporary folder under the target dir, unique per test name.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("visobjd-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("mkdir temp");
    dir
}

/// A reference image from a function of pixel position.
pub fn write_png(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)));
    img.save(path).expect("write PNG");
}

/// A stage of `n` lights in a row: light i lights a vertical stripe i of a 40x10 image at
/// level 0.5; each light is its own group unless `groups` assigns them; profiles alternate
/// `irgb` and `dimmer` when `mixed`, else all `irgb`.
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

/// Path of the built `visobjd` binary.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_visobjd")
}
