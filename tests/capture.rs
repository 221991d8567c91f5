//! `visobjd capture` end to end with the simulated camera: the real binary drives the rig
//! over sACN, the sim photographs the scene's own basis images lit by the DMX it receives,
//! and the captured basis must match those images. Also: the wire shows capture's
//! priority and only the light being shot at full; a stopped capture resumes; a light
//! that adds nothing is named and the exit status says so; `visobjd gallery` generates
//! from the result.

mod common;

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use common::wire::{Sacn, parse_sacn};
use common::{TestLight, bin, temp_dir, write_scene};
use visobjd_compositor::basis::read_exr;

const W: usize = 96;
const H: usize = 54;

/// A soft pool of light centred at (cx, cy), tinted.
fn pool(cx: f32, cy: f32, level: f32, tint: [f32; 3]) -> impl Fn(usize, usize) -> [f32; 3] {
    move |x, y| {
        let d2 = ((x as f32 - cx) / 18.0).powi(2) + ((y as f32 - cy) / 12.0).powi(2);
        let v = level * (-d2).exp() + 0.02 * level;
        tint.map(|t| t * v)
    }
}

/// Five lights with pools across the stage (dimmer, irgb, rgb, rgbw) and a sixth, light
/// 6, whose basis is black: it shows no light.
fn stage(dir: &Path) -> PathBuf {
    let specs: [(u32, &'static str, u16, f32, f32, f32); 5] = [
        (1, "dimmer", 1, 15.0, 20.0, 0.9),
        (2, "irgb", 11, 35.0, 30.0, 0.6),
        (3, "rgb", 21, 55.0, 25.0, 0.4),
        (4, "rgbw", 31, 75.0, 35.0, 0.8),
        (5, "dimmer", 41, 50.0, 10.0, 0.3),
    ];
    let mut lights: Vec<TestLight> = specs
        .iter()
        .map(|&(channel, profile, address, cx, cy, level)| TestLight {
            channel,
            group: Some("all"),
            profile,
            universe: 1,
            address,
            pixel: Box::new(pool(cx, cy, level, [1.0, 0.9, 0.8])),
        })
        .collect();
    lights.push(TestLight {
        channel: 6,
        group: Some("all"),
        profile: "dimmer",
        universe: 1,
        address: 51,
        pixel: Box::new(|_, _| [0.0; 3]),
    });
    let scene = write_scene(&dir.join("scene"), W, H, &["all"], &lights);
    let truth = dir.join("truth");
    std::fs::create_dir_all(&truth).expect("mkdir truth");
    for ch in 1..=6 {
        let name = format!("{ch:03}.exr");
        std::fs::copy(scene.join("basis").join(&name), truth.join(&name)).expect("copy truth");
    }
    scene
}

/// A config driving the scene to `port` on loopback (where the test listens).
fn config(dir: &Path, port: u16) -> PathBuf {
    let path = dir.join("capture.toml");
    std::fs::write(
        &path,
        format!(
            "scene = \"scene\"\nreferences = \"scene\"\nstate_dir = \"state\"\n\n[output]\nrate_hz = 44\n\n[[output.sacn]]\ndestination = \"127.0.0.1\"\nport = {port}\n"
        ),
    )
    .expect("write config");
    path
}

/// Every sACN data packet that reaches `socket`, until `done` is set.
fn listen(socket: UdpSocket, done: Arc<AtomicBool>) -> std::thread::JoinHandle<Vec<Sacn>> {
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

fn capture(config: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(bin())
        .args(["capture", "--config"])
        .arg(config)
        .args([
            "--camera", "sim", "--settle", "0.02", "--seed", "3", "--width",
        ])
        .arg(W.to_string())
        .args(extra)
        .output()
        .expect("visobjd capture runs")
}

/// Per light 1-5, the median relative error of its captured basis against the truth over
/// the pixels it lights (luminance above 5% of its brightest), after one scale factor for
/// all lights together when `up_to_scale`: a JPEG's response is known only up to a scale
/// (relighting does not care: the scene's `exposure` sets brightness), a raw capture's is
/// absolute.
fn basis_errors(dir: &Path, up_to_scale: bool) -> Vec<f64> {
    let lum = |p: &[f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let pairs: Vec<Vec<([f32; 3], [f32; 3])>> = (1..=5)
        .map(|ch| {
            let got = read_exr(&dir.join(format!("scene/basis/{ch:03}.exr"))).expect("captured");
            let want = read_exr(&dir.join(format!("truth/{ch:03}.exr"))).expect("truth");
            assert_eq!(
                (got.width, got.height),
                (want.width, want.height),
                "light {ch}: size"
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

fn end_to_end(format: &str) {
    let dir = temp_dir(&format!("capture-{format}"));
    stage(&dir);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind a receiver");
    let port = socket.local_addr().expect("addr").port();
    let done = Arc::new(AtomicBool::new(false));
    let wire = listen(socket, Arc::clone(&done));
    let cfg = config(&dir, port);
    let out = capture(&cfg, &["--format", format]);
    done.store(true, Ordering::SeqCst);
    let packets = wire.join().expect("listener");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let errors = basis_errors(&dir, format == "jpeg");
    eprintln!("{format}: median relative errors {errors:?}");
    for (ch, e) in (1..=5).zip(&errors) {
        assert!(
            *e < 0.02,
            "{format}: light {ch}: median relative error {e:.4}"
        );
    }
    // Light 6 adds nothing: named, and the exit status says so.
    assert!(!out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("light 6 (Ch 6) shows no light"),
        "{stdout}\n{stderr}"
    );
    assert!(stdout.contains("5 lights written"), "{stdout}\n{stderr}");
    // Light 6's image is not replaced: it keeps the scene's black one.
    assert!(light_6_is_untouched(&dir));
    // On the wire: capture's priority, and at most one light at full at a time, once the
    // response bracket (every light at full) is over.
    assert!(!packets.is_empty(), "no sACN reached the test");
    assert!(packets.iter().all(|p| p.priority == 200), "priority 200");
    assert!(
        packets.iter().any(|p| p.terminated),
        "the streams are terminated at the end"
    );
    let lit = |p: &Sacn| {
        [0usize, 10, 20, 30, 40, 50]
            .iter()
            .filter(|&&a| p.dmx[a] > 0 || p.dmx[a + 1] > 0)
            .count()
    };
    let singles = packets.iter().filter(|p| lit(p) == 1).count();
    assert!(singles > 0, "each light is shot alone");
    // `visobjd gallery` generates from the captured scene (light 6 keeps its black image).
    let refs = dir.join("refs");
    std::fs::create_dir_all(&refs).expect("mkdir refs");
    common::write_png(&refs.join("warm.png"), 24, 12, |x, _| {
        [255, 120 + (x * 2) as u8, 40]
    });
    let g = Command::new(bin())
        .args(["gallery", "--scene"])
        .arg(dir.join("scene"))
        .arg("--ref")
        .arg(refs.join("warm.png"))
        .args(["--seed", "7", "--out"])
        .arg(dir.join("sheet.png"))
        .output()
        .expect("visobjd gallery runs");
    assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    std::fs::remove_dir_all(&dir).ok();
}

/// Light 6's image is the scene's original black one.
fn light_6_is_untouched(dir: &Path) -> bool {
    read_exr(&dir.join("scene/basis/006.exr"))
        .map(|img| img.pixels.iter().all(|p| *p == [0.0; 3]))
        .unwrap_or(false)
}

#[test]
fn jpeg_capture_matches_the_basis_within_two_percent() {
    end_to_end("jpeg");
}

#[test]
fn raw_capture_matches_the_basis_within_two_percent() {
    end_to_end("raw");
}

#[test]
fn a_stopped_capture_resumes_where_it_left_off() {
    let dir = temp_dir("capture-resume");
    stage(&dir);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let cfg = config(&dir, socket.local_addr().expect("addr").port());
    let first = capture(&cfg, &["--lights", "1-2"]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let record = std::fs::read_to_string(dir.join("scene/capture.json")).expect("capture.json");
    assert!(record.contains("\"response\""), "the response is recorded");
    let second = capture(&cfg, &["--lights", "1-5"]);
    let stdout = String::from_utf8_lossy(&second.stdout);
    assert!(
        second.status.success() && stdout.contains("3 lights written, 2 already done"),
        "{stdout}\n{}",
        String::from_utf8_lossy(&second.stderr)
    );
    for (ch, e) in (1..=5).zip(basis_errors(&dir, true)) {
        assert!(e < 0.02, "light {ch} after resuming: {e:.4}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
