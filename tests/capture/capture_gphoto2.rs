//! `visobjd capture` end to end with its default camera, gphoto2: the real binary runs the
//! fake `gphoto2` (`tests/peers/fake_gphoto2.py`, found first on the child's `PATH`), which
//! renders every frame from the truth basis images by the DMX it receives on the wire, so
//! the whole chain (sACN out, gphoto2 calls, EXIF, JPEG response, merge) is measured
//! against the truth. Also: what the wire and the fake saw (capture's priority, streams
//! terminated, one light at a time after the response bracket), a light that shows no
//! light, and a camera that stops answering mid-capture (a clear timeout error, the
//! streams terminated, and a run without the fault resuming).

use std::ffi::OsString;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::common::bin;
use crate::common::capture::{
    H, LIGHTS, W, alone_at_full, basis_errors, config, light_6_is_untouched, listen, lit, stage,
    stage_lights, write_npy,
};
use visobjd_testkit::wire::Sacn;
use visobjd_testkit::{TestLight, temp_dir, tools};

/// The fake camera rendering the stage `ZOOM` times larger than the basis (capture's box
/// downsampling to `W` then averages JPEG's blocks and the noise as a real sensor's).
const ZOOM: usize = 4;

/// A light of the fake's rig: where it is patched (universe, address), its DMX footprint
/// and intensity slot, and its true image (a moving light's: one per position, `mover`).
pub struct RigLight<'a> {
    pub light: &'a TestLight,
    pub footprint: usize,
    pub intensity: Option<usize>,
    pub mover: Option<&'a RigMover>,
}

/// A moving light of the fake's rig: the footprint offsets of its 16-bit pan and tilt,
/// their full travel in degrees, and its positions.
pub struct RigMover {
    pub pan: usize,
    pub tilt: usize,
    pub pan_range: f64,
    pub tilt_range: f64,
    pub positions: Vec<RigPosition>,
}

/// One position of a [`RigMover`]: its focus palette, pan and tilt in degrees from the
/// centre of the travel, and the stage it lights there alone at full.
pub struct RigPosition {
    pub palette: u32,
    pub pan: f64,
    pub tilt: f64,
    pub pixel: Box<dyn Fn(usize, usize) -> [f32; 3] + Sync>,
}

/// The fake gphoto2 set up for the test in `dir`: a `bin/gphoto2` link to it, its rig
/// (the truth basis as `.npy`), the sACN port it listens on while shooting, its logs.
pub struct Fake {
    dir: PathBuf,
    pub port: u16,
    /// The basis width asked of capture (the rig's).
    width: usize,
    env: Vec<(OsString, OsString)>,
}

impl Fake {
    /// The fake on the test stage ([`stage_lights`]).
    fn new(dir: &Path) -> Option<Fake> {
        let lights = stage_lights();
        let rig: Vec<RigLight<'_>> = lights
            .iter()
            .zip(LIGHTS)
            .map(|(light, l)| RigLight {
                light,
                footprint: l.footprint,
                intensity: l.intensity,
                mover: None,
            })
            .collect();
        Fake::on_rig(dir, (W, H), &rig, &[])
    }

    /// The fake looking at `rig` (`size`: its images' width and height), with `body` added
    /// to its environment (`FAKE_GPHOTO2_BODY`, say). `None` (after a note, or a failure
    /// under CI) without python3, Pillow, piexif, numpy and PiDNG.
    pub fn on_rig(
        dir: &Path,
        size: (usize, usize),
        rig: &[RigLight<'_>],
        body: &[(&str, &str)],
    ) -> Option<Fake> {
        if !tools::fake_gphoto2() {
            return None;
        }
        let bin_dir = dir.join("bin");
        std::fs::create_dir_all(&bin_dir).expect("mkdir bin");
        let fake = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/peers/fake_gphoto2.py")
            .canonicalize()
            .expect("tests/peers/fake_gphoto2.py exists");
        std::os::unix::fs::symlink(&fake, bin_dir.join("gphoto2")).expect("link the fake");
        // The rig: the same pixels as the scene's truth EXRs, as the fake's .npy images.
        let rig_dir = dir.join("rig");
        std::fs::create_dir_all(&rig_dir).expect("mkdir rig");
        let mut entries = Vec::new();
        for l in rig {
            let ch = l.light.channel;
            let mut entry = serde_json::json!({
                "universe": l.light.universe, "address": l.light.address,
                "footprint": l.footprint,
            });
            if let Some(m) = l.mover {
                let positions: Vec<serde_json::Value> = m
                    .positions
                    .iter()
                    .map(|p| {
                        let name = format!("{ch:03}-{}.npy", p.palette);
                        write_npy(&rig_dir.join(&name), size.0, size.1, |x, y| (p.pixel)(x, y));
                        serde_json::json!({"pan": p.pan, "tilt": p.tilt, "basis": name})
                    })
                    .collect();
                entry["pan"] = m.pan.into();
                entry["tilt"] = m.tilt.into();
                entry["pan_range"] = m.pan_range.into();
                entry["tilt_range"] = m.tilt_range.into();
                entry["positions"] = positions.into();
            } else {
                let name = format!("{ch:03}.npy");
                write_npy(&rig_dir.join(&name), size.0, size.1, |x, y| {
                    (l.light.pixel)(x, y)
                });
                entry["basis"] = name.into();
            }
            if let Some(i) = l.intensity {
                entry["intensity"] = i.into();
            }
            entries.push(entry);
        }
        let rig_json = rig_dir.join("rig.json");
        std::fs::write(&rig_json, serde_json::Value::from(entries).to_string()).expect("rig.json");
        // A free loopback port for the fake (it binds it during each capture).
        let port = UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .expect("a free port")
            .port();
        let mut path = OsString::from(&bin_dir);
        path.push(":");
        path.push(std::env::var_os("PATH").unwrap_or_default());
        let env = [
            ("PATH", path),
            ("FAKE_GPHOTO2_STATE", dir.join("camera.json").into()),
            ("FAKE_GPHOTO2_LOG", dir.join("calls.log").into()),
            ("FAKE_GPHOTO2_DMX_LOG", dir.join("dmx.log").into()),
            ("FAKE_GPHOTO2_SACN_PORT", port.to_string().into()),
            ("FAKE_GPHOTO2_RIG", rig_json.into()),
            ("FAKE_GPHOTO2_ZOOM", ZOOM.to_string().into()),
            ("FAKE_GPHOTO2_SEED", "5".into()),
        ]
        .into_iter()
        .chain(body.iter().map(|&(k, v)| (k, v.into())))
        .map(|(k, v)| (OsString::from(k), v))
        .collect();
        Some(Fake {
            dir: dir.to_path_buf(),
            port,
            width: size.0,
            env,
        })
    }

    /// `visobjd capture --config config args` with the fake as its camera and `fault`
    /// added to the fake's environment.
    pub fn capture(&self, config: &Path, args: &[&str], fault: &[(&str, &str)]) -> Output {
        Command::new(bin())
            .args(["capture", "--config"])
            .arg(config)
            .args(["--settle", "0.02", "--seed", "3", "--width"])
            .arg(self.width.to_string())
            .args(args)
            .envs(self.env.iter().map(|(k, v)| (k, v)))
            .envs(fault.iter().copied())
            .output()
            .expect("visobjd capture runs")
    }

    /// Universe 1's DMX of every frame the fake rendered, in order.
    pub fn frames(&self) -> Vec<Vec<u8>> {
        self.log()
            .iter()
            .map(|entry| {
                let hex = entry["universes"]["1"]
                    .as_str()
                    .unwrap_or_else(|| panic!("a frame rendered without universe 1: {entry}"));
                (0..512)
                    .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).expect("hex"))
                    .collect()
            })
            .collect()
    }

    /// Every frame the fake rendered, in order, as its DMX log has it (capture number,
    /// universes, levels, the position each moving light was rendered at).
    pub fn log(&self) -> Vec<serde_json::Value> {
        std::fs::read_to_string(self.dir.join("dmx.log"))
            .unwrap_or_default()
            .lines()
            .map(|line| serde_json::from_str(line).expect("a JSON line"))
            .collect()
    }
}

/// A stage, the fake, a listener of the test's own, and a config sending to both.
struct Setup {
    dir: PathBuf,
    fake: Fake,
    config: PathBuf,
    socket: UdpSocket,
}

fn setup(name: &str, extra_config: &str) -> Option<Setup> {
    let dir = temp_dir(name);
    stage(&dir);
    let fake = Fake::new(&dir)?;
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind a receiver");
    let port = socket.local_addr().expect("addr").port();
    let config = config(&dir, &[fake.port, port], extra_config);
    Some(Setup {
        dir,
        fake,
        config,
        socket,
    })
}

impl Setup {
    /// A capture with `args` and `fault`, and the sACN packets the test received meanwhile.
    fn run(&self, args: &[&str], fault: &[(&str, &str)]) -> (Output, Vec<Sacn>) {
        let done = Arc::new(AtomicBool::new(false));
        let socket = self.socket.try_clone().expect("clone the receiver");
        let wire = listen(socket, Arc::clone(&done));
        let out = self.fake.capture(&self.config, args, fault);
        done.store(true, Ordering::SeqCst);
        (out, wire.join().expect("listener"))
    }
}

pub fn text(out: &Output) -> String {
    format!(
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Lights 1-5 each within 2% (median relative error) of the truth after one common scale.
fn assert_accurate(dir: &Path, when: &str) {
    let errors = basis_errors(dir, true);
    eprintln!("{when}: median relative errors {errors:?}");
    for (ch, e) in (1..=5).zip(&errors) {
        assert!(
            *e < 0.02,
            "{when}: light {ch}: median relative error {e:.4}"
        );
    }
}

#[test]
fn gphoto2_capture_matches_the_basis_within_two_percent() {
    let Some(s) = setup("capture-gphoto2", "") else {
        return;
    };
    let (out, packets) = s.run(&[], &[]);
    assert!(
        std::fs::read_to_string(s.dir.join("calls.log"))
            .is_ok_and(|log| log.contains("--capture-image-and-download")),
        "the fake gphoto2 was used: {}",
        text(&out)
    );
    assert_accurate(&s.dir, "gphoto2");
    // Light 6 adds nothing: named, not written, and the exit status says so.
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("light 6 (Ch 6) shows no light"),
        "{}",
        text(&out)
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("5 lights written"),
        "{}",
        text(&out)
    );
    assert!(light_6_is_untouched(&s.dir));

    // The wire: capture's priority on every data packet, the streams terminated at the
    // end, each light alone at some point, and after the response bracket (the last
    // packet with every light at full) never two lights at full.
    assert!(!packets.is_empty(), "no sACN reached the test");
    assert!(packets.iter().all(|p| p.priority == 200), "priority 200");
    assert!(packets.iter().any(|p| p.terminated), "streams terminated");
    let live: Vec<&Sacn> = packets.iter().filter(|p| !p.terminated).collect();
    let last_all = live
        .iter()
        .rposition(|p| lit(&p.dmx).1 == LIGHTS.len())
        .expect("the response bracket puts every light at full");
    assert!(
        live[last_all + 1..].iter().all(|p| lit(&p.dmx).1 <= 1),
        "two lights at full after the response bracket"
    );
    for ch in LIGHTS.map(|l| l.channel) {
        assert!(
            live.iter().any(|p| alone_at_full(&p.dmx, ch)),
            "light {ch} alone at full on the wire"
        );
    }

    // What the fake rendered: every frame saw DMX; the response bracket's frames (every
    // light at full) come first; after them no frame has two lights at full; every light
    // has its metering and bracket frames (at least two) with it alone at full.
    let frames = s.fake.frames();
    let all_full = frames
        .iter()
        .take_while(|d| lit(d).1 == LIGHTS.len())
        .count();
    assert!(all_full >= 7, "the response bracket: {all_full} frames");
    assert!(
        frames[all_full..].iter().all(|d| lit(d).1 <= 1),
        "a frame after the response bracket had two lights at full"
    );
    for ch in LIGHTS.map(|l| l.channel) {
        let alone = frames.iter().filter(|d| alone_at_full(d, ch)).count();
        assert!(
            alone >= 2,
            "light {ch}: {alone} frames with it alone at full"
        );
    }
    assert!(
        frames.iter().any(|d| lit(d).0.is_empty()),
        "the ambient frames (everything off)"
    );
    std::fs::remove_dir_all(&s.dir).ok();
}

/// `--format raw`: the fake writes DNGs with its own writer (PiDNG), a Bayer mosaic of a
/// camera RGB that is not sRGB, and capture reads them through rawler and the file's
/// colour matrix.
#[test]
fn gphoto2_raw_capture_matches_the_basis_within_two_percent() {
    let Some(s) = setup("capture-gphoto2-raw", "") else {
        return;
    };
    let (out, _) = s.run(&["--format", "raw", "--lights", "1-5"], &[]);
    assert!(out.status.success(), "{}", text(&out));
    let shots: Vec<String> = std::fs::read_to_string(s.dir.join("calls.log"))
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains("--capture-image-and-download"))
        .map(String::from)
        .collect();
    assert!(
        !shots.is_empty(),
        "the fake gphoto2 was used: {}",
        text(&out)
    );
    assert!(
        std::fs::read_to_string(s.dir.join("camera.json")).is_ok_and(|c| c.contains("\"RAW\"")),
        "the body was set to RAW"
    );
    assert_accurate(&s.dir, "gphoto2 raw");
    std::fs::remove_dir_all(&s.dir).ok();
}

#[test]
fn a_camera_that_stops_answering_fails_clearly_and_the_capture_resumes() {
    let Some(s) = setup("capture-gphoto2-hang", "[capture]\ncamera_timeout_s = 3\n") else {
        return;
    };
    // Every capture while light 3 is lit alone hangs: its first frame, and the retry.
    let (out, packets) = s.run(&[], &[("FAKE_GPHOTO2_HANG_CAPTURE", "lit:3")]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        stderr.contains("timed out after 3 s")
            && stderr.contains("--capture-image-and-download")
            && stderr.contains("camera_timeout_s"),
        "{}",
        text(&out)
    );
    let hung = s
        .fake
        .frames()
        .iter()
        .filter(|d| alone_at_full(d, 3))
        .count();
    assert_eq!(hung, 2, "one try and one retry with light 3 up");
    assert!(
        packets.iter().any(|p| p.terminated),
        "the streams are terminated after the error"
    );
    assert!(packets.iter().all(|p| p.priority == 200), "priority 200");

    // The same command without the fault resumes after lights 1 and 2.
    let (again, _) = s.run(&[], &[]);
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(
        stdout.contains("3 lights written, 2 already done, 1 showing no light"),
        "{}",
        text(&again)
    );
    assert!(
        String::from_utf8_lossy(&again.stderr).contains("light 6 (Ch 6) shows no light"),
        "{}",
        text(&again)
    );
    assert_accurate(&s.dir, "resumed");
    std::fs::remove_dir_all(&s.dir).ok();
}

/// A raw frame whose header declares 100000x100000 pixels is refused by its header,
/// before a decoder allocates 20 GB for it: the capture stops at once with the sentence
/// and terminates its streams, so the console takes the rig back.
#[test]
fn a_raw_frame_declaring_too_many_pixels_stops_the_capture_and_terminates_its_streams() {
    let Some(s) = setup("capture-gphoto2-huge-raw", "") else {
        return;
    };
    let started = std::time::Instant::now();
    let (out, packets) = s.run(
        &["--format", "raw"],
        &[("FAKE_GPHOTO2_RAW_DECLARES", "100000x100000")],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        stderr.contains("shot-1.DNG: declares 100000x100000 pixels; a raw frame may have at most 32768 a side and 256 megapixels")
            && !stderr.contains("panicked")
            && !stderr.contains("memory allocation"),
        "{}",
        text(&out)
    );
    assert!(
        started.elapsed() < std::time::Duration::from_secs(60),
        "stopped at the first frame: {:?}",
        started.elapsed()
    );
    assert!(
        packets.iter().any(|p| p.terminated),
        "the streams are terminated after the error"
    );
    assert!(packets.iter().all(|p| p.priority == 200), "priority 200");
    std::fs::remove_dir_all(&s.dir).ok();
}
