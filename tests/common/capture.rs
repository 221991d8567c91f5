//! What the `visobjd capture` end-to-end tests share (tests/capture/capture.rs with the sim
//! camera, tests/capture/capture_gphoto2.rs with the fake gphoto2): the test stage and its
//! truth images, the config, the sACN listener, which lights a DMX universe lights, and the
//! comparison of captured basis images with the truth.

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use visobjd_compositor::basis::read_exr;
use visobjd_testkit::wire::{Sacn, parse_sacn};
use visobjd_testkit::{TestLight, write_scene};

/// The stage's size in pixels.
pub const W: usize = 96;
pub const H: usize = 54;

/// A light of the test stage, on universe 1.
#[derive(Clone, Copy)]
pub struct StageLight {
    pub channel: u32,
    pub profile: &'static str,
    pub address: u16,
    /// Its DMX slots.
    pub footprint: usize,
    /// The offset of its intensity slot in the footprint, if its profile has one: such a
    /// light is dark at intensity 0 whatever its colour slots hold (visobjd keeps them at
    /// the colour, 255 for white, when it switches the light off).
    pub intensity: Option<usize>,
    /// The centre and level of its pool of light.
    pub pool: (f32, f32, f32),
}

const fn light(
    channel: u32,
    profile: &'static str,
    address: u16,
    footprint: usize,
    intensity: Option<usize>,
    pool: (f32, f32, f32),
) -> StageLight {
    StageLight {
        channel,
        profile,
        address,
        footprint,
        intensity,
        pool,
    }
}

/// Five pools across the stage (dimmer, irgb, rgb, rgbw) and light 6, whose basis is
/// black: it shows no light.
pub const LIGHTS: [StageLight; 6] = [
    light(1, "dimmer", 1, 1, Some(0), (15.0, 20.0, 0.9)),
    light(2, "irgb", 11, 4, Some(0), (35.0, 30.0, 0.6)),
    light(3, "rgb", 21, 3, None, (55.0, 25.0, 0.4)),
    light(4, "rgbw", 31, 4, None, (75.0, 35.0, 0.8)),
    light(5, "dimmer", 41, 1, Some(0), (50.0, 10.0, 0.3)),
    light(6, "dimmer", 51, 1, Some(0), (0.0, 0.0, 0.0)),
];

impl StageLight {
    /// Its level in universe 1's `dmx` (512 slots), 0-255: its intensity slot times the
    /// brightest of its other slots (full when it has none), or else its brightest slot.
    pub fn level(&self, dmx: &[u8]) -> u32 {
        let slots = &dmx[usize::from(self.address) - 1..][..self.footprint];
        let brightest = |skip: Option<usize>| {
            slots
                .iter()
                .enumerate()
                .filter(|(i, _)| Some(*i) != skip)
                .map(|(_, &v)| u32::from(v))
                .max()
        };
        match self.intensity {
            Some(i) => u32::from(slots[i]) * brightest(Some(i)).unwrap_or(255) / 255,
            None => brightest(None).unwrap_or(0),
        }
    }
}

/// A soft pool of light centred at (cx, cy), tinted.
pub fn pool(cx: f32, cy: f32, level: f32, tint: [f32; 3]) -> impl Fn(usize, usize) -> [f32; 3] {
    move |x, y| {
        let d2 = ((x as f32 - cx) / 18.0).powi(2) + ((y as f32 - cy) / 12.0).powi(2);
        let v = level * (-d2).exp() + 0.02 * level;
        tint.map(|t| t * v)
    }
}

/// The stage's lights with their true basis images.
pub fn stage_lights() -> Vec<TestLight> {
    LIGHTS
        .iter()
        .map(|l| TestLight {
            channel: l.channel,
            group: Some("all"),
            profile: l.profile,
            universe: 1,
            address: l.address,
            pixel: Box::new(pool(l.pool.0, l.pool.1, l.pool.2, [1.0, 0.9, 0.8])),
        })
        .collect()
}

/// Writes the stage to `dir/scene` and a copy of its basis images to `dir/truth`;
/// returns the scene folder.
pub fn stage(dir: &Path) -> PathBuf {
    stage_of(dir, W, H, &stage_lights())
}

/// Writes a scene of `lights` (`w` x `h`) to `dir/scene` and a copy of its basis images to
/// `dir/truth`; returns the scene folder.
pub fn stage_of(dir: &Path, w: usize, h: usize, lights: &[TestLight]) -> PathBuf {
    let scene = write_scene(&dir.join("scene"), w, h, &["all"], lights);
    let truth = dir.join("truth");
    std::fs::create_dir_all(&truth).expect("mkdir truth");
    for l in lights {
        let name = format!("{:03}.exr", l.channel);
        std::fs::copy(scene.join("basis").join(&name), truth.join(&name)).expect("copy truth");
    }
    scene
}

/// Writes a float32 `h` x `w` x 3 NumPy `.npy` file (format version 1.0: magic, version,
/// little-endian header length, a Python dict literal padded with spaces to a multiple of
/// 64 bytes and ended by a newline, then the data in C order).
pub fn write_npy(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) {
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({h}, {w}, 3), }}");
    let unpadded = 10 + dict.len() + 1;
    let header = format!(
        "{dict}{}\n",
        " ".repeat(unpadded.next_multiple_of(64) - unpadded)
    );
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    for y in 0..h {
        for x in 0..w {
            for v in f(x, y) {
                bytes.extend(v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).expect("write .npy");
}

/// A config for the scene in `dir/scene` that sends sACN to each of `ports` on loopback,
/// followed by `extra` (e.g. a `[capture]` table).
pub fn config(dir: &Path, ports: &[u16], extra: &str) -> PathBuf {
    let path = dir.join("capture.toml");
    let mut text = String::from(
        "scene = \"scene\"\nreferences = \"scene\"\nstate_dir = \"state\"\n\n[output]\nrate_hz = 44\n",
    );
    for port in ports {
        text += &format!("\n[[output.sacn]]\ndestination = \"127.0.0.1\"\nport = {port}\n");
    }
    text += "\n";
    text += extra;
    std::fs::write(&path, text).expect("write config");
    path
}

/// Every sACN data packet that reaches `socket`, until `done` is set.
pub fn listen(socket: UdpSocket, done: Arc<AtomicBool>) -> std::thread::JoinHandle<Vec<Sacn>> {
    socket
        .set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    std::thread::spawn(move || {
        let mut got = Vec::new();
        let mut buf = [0u8; 1200];
        while !done.load(Ordering::SeqCst) {
            if let Ok(n) = socket.recv(&mut buf)
                && let Some(p) = parse_sacn(&buf[..n])
            {
                got.push(p);
            }
        }
        got
    })
}

/// Every DMX state of universe 1 that reaches `socket` until `done` is set, each with the
/// Unix time it was first seen; meanwhile `path` holds the last 64 of them as the fake
/// gphoto2's `FAKE_GPHOTO2_MOTION` (`{"1": [[seconds, hex], ...]}`, written atomically at
/// each change), from which it tells a moving light still on its way.
pub fn track(
    socket: UdpSocket,
    done: Arc<AtomicBool>,
    path: PathBuf,
) -> std::thread::JoinHandle<Vec<(f64, Vec<u8>)>> {
    socket
        .set_read_timeout(Some(Duration::from_millis(20)))
        .expect("timeout");
    std::thread::spawn(move || {
        let mut states: Vec<(f64, Vec<u8>)> = Vec::new();
        let mut buf = [0u8; 1200];
        while !done.load(Ordering::SeqCst) {
            let Ok(n) = socket.recv(&mut buf) else {
                continue;
            };
            let Some(p) = parse_sacn(&buf[..n]) else {
                continue;
            };
            if p.terminated || p.universe != 1 || states.last().is_some_and(|s| s.1 == p.dmx) {
                continue;
            }
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .expect("after 1970")
                .as_secs_f64();
            states.push((now, p.dmx));
            let recent: Vec<serde_json::Value> = states[states.len().saturating_sub(64)..]
                .iter()
                .map(|(t, dmx)| {
                    let hex: String = dmx.iter().map(|b| format!("{b:02x}")).collect();
                    serde_json::json!([t, hex])
                })
                .collect();
            let tmp = path.with_extension("tmp");
            std::fs::write(&tmp, serde_json::json!({ "1": recent }).to_string())
                .expect("write the motion file");
            std::fs::rename(&tmp, &path).expect("replace the motion file");
        }
        states
    })
}

/// The channels lit in universe 1's `dmx` (512 slots), and how many are at full.
pub fn lit(dmx: &[u8]) -> (Vec<u32>, usize) {
    let lit = LIGHTS
        .iter()
        .filter(|l| l.level(dmx) > 0)
        .map(|l| l.channel)
        .collect();
    let full = LIGHTS.iter().filter(|l| l.level(dmx) == 255).count();
    (lit, full)
}

/// Whether universe 1's `dmx` lights channel `ch` alone, at full: its level 255, every
/// other light's 0, and every slot outside the lights' footprints 0.
pub fn alone_at_full(dmx: &[u8], ch: u32) -> bool {
    let outside = dmx.iter().enumerate().all(|(i, &v)| {
        v == 0
            || LIGHTS.iter().any(|l| {
                (usize::from(l.address) - 1..usize::from(l.address) - 1 + l.footprint).contains(&i)
            })
    });
    outside
        && LIGHTS
            .iter()
            .all(|l| l.level(dmx) == if l.channel == ch { 255 } else { 0 })
}

/// Per light 1-5, the median relative error of its captured basis against the truth
/// ([`errors_of`]).
pub fn basis_errors(dir: &Path, up_to_scale: bool) -> Vec<f64> {
    errors_of(dir, 1..=5, up_to_scale)
}

/// Per light of `channels`, the median relative error of its captured basis
/// (`dir/scene/basis/NNN.exr`) against the truth (`dir/truth/NNN.exr`) over the pixels it
/// lights (luminance above 5% of its brightest), after one scale factor for all lights
/// together when `up_to_scale`: a JPEG's response is known only up to a scale (relighting
/// does not care: the scene's `exposure` sets brightness), a raw capture's is absolute.
pub fn errors_of(
    dir: &Path,
    channels: impl IntoIterator<Item = u32>,
    up_to_scale: bool,
) -> Vec<f64> {
    let names: Vec<String> = channels.into_iter().map(|ch| format!("{ch:03}")).collect();
    image_errors(dir, &names, up_to_scale)
}

/// [`errors_of`] for the images `names` (`dir/scene/basis/NAME.exr` against
/// `dir/truth/NAME.exr`): a moving light's positions are `NNN-PALETTE`.
pub fn image_errors(dir: &Path, names: &[String], up_to_scale: bool) -> Vec<f64> {
    let lum = |p: &[f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let pairs: Vec<Vec<([f32; 3], [f32; 3])>> = names
        .iter()
        .map(|name| {
            let got = read_exr(&dir.join(format!("scene/basis/{name}.exr")))
                .unwrap_or_else(|e| panic!("{name} captured: {e}"));
            let want = read_exr(&dir.join(format!("truth/{name}.exr"))).expect("truth");
            assert_eq!(
                (got.width, got.height),
                (want.width, want.height),
                "{name}: size"
            );
            let peak = want.pixels.iter().map(lum).fold(0.0f32, f32::max);
            got.pixels
                .iter()
                .zip(&want.pixels)
                .filter(|(_, w)| lum(w) > 0.05 * peak)
                .map(|(g, w)| (*g, *w))
                .collect()
        })
        .collect();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let scale = if up_to_scale {
        median(
            pairs
                .iter()
                .flatten()
                .map(|(g, w)| f64::from(lum(w) / lum(g)))
                .collect(),
        )
    } else {
        1.0
    };
    pairs
        .iter()
        .map(|p| {
            median(
                p.iter()
                    .flat_map(|(g, w)| {
                        (0..3).map(move |c| {
                            ((f64::from(g[c]) * scale - f64::from(w[c])) / f64::from(w[c])).abs()
                        })
                    })
                    .collect(),
            )
        })
        .collect()
}

/// Light 6's image is the scene's original black one (a light showing no light is not
/// written).
pub fn light_6_is_untouched(dir: &Path) -> bool {
    read_exr(&dir.join("scene/basis/006.exr"))
        .map(|img| img.pixels.iter().all(|p| *p == [0.0; 3]))
        .unwrap_or(false)
}
