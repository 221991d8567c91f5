//! `visobjd capture` of moving lights (issue 31) through the real binary and the fake
//! gphoto2: each mover is shot alone at full at each of its focus palettes, its pan and
//! tilt sent from the palette. The fake decodes the 16-bit pan and tilt off the wire itself
//! and renders the truth image of the position they match within one 16-bit step (black
//! when none does), and a mover takes `MOVE_S` to get there: until then the fake renders it
//! where it was (`FAKE_GPHOTO2_MOTION`, kept from the wire by [`track`]). So a capture that
//! sends the wrong position, forgets to move the light or does not wait writes the wrong
//! image. Also: moves happen dark, the validation look holds movers at other positions
//! than their first, and a second run resumes (nothing, then the one image deleted).

use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::capture_gphoto2::{Fake, RigLight, RigMover, RigPosition, text};
use crate::common::capture::{config, image_errors, pool, stage_of, track};
use visobjd_testkit::{TestLight, temp_dir, write_exr};

const W: usize = 96;
const H: usize = 54;
/// Seconds the fake's movers take to reach a new position.
const MOVE_S: f64 = 1.5;
/// What capture is given for a move (`[capture] move_settle_s`): more than `MOVE_S`.
const MOVE_SETTLE_S: f64 = 2.0;

/// A position of a stage mover: palette, pan and tilt in degrees, and the centre and
/// level of the pool it lights there.
type Aim = (u32, f64, f64, (f32, f32, f32));

/// A moving light of the stage: channel, address, and its positions. Profile `spot`:
/// intensity, pan16, tilt16.
struct Mover {
    channel: u32,
    address: u16,
    positions: &'static [Aim],
}

const MOVERS: [Mover; 2] = [
    Mover {
        channel: 3,
        address: 11,
        positions: &[
            (1, -30.0, 10.0, (25.0, 30.0, 0.7)),
            (2, 45.5, -20.0, (60.0, 18.0, 0.6)),
            (3, 90.123, 33.3, (72.0, 40.0, 0.8)),
        ],
    },
    Mover {
        channel: 4,
        address: 21,
        positions: &[
            (1, 0.0, 0.0, (40.0, 42.0, 0.5)),
            // Differs from palette 1 by about one 8-bit pan step (2.1 degrees), many
            // 16-bit ones: an 8-bit pan would not tell them apart.
            (2, 2.0, 0.0, (80.0, 25.0, 0.9)),
        ],
    },
];

const NAMES: [&str; 3] = ["DS left", "centre", "US right"];

/// The two fixed lights (dimmers at 1 and 2).
fn fixed() -> Vec<TestLight> {
    [(1, 1, (15.0, 15.0, 0.9)), (2, 2, (85.0, 45.0, 0.5))]
        .into_iter()
        .map(|(channel, address, (x, y, v))| TestLight {
            channel,
            group: Some("all"),
            profile: "dimmer",
            universe: 1,
            address,
            pixel: Box::new(pool(x, y, v, [1.0, 0.9, 0.8])),
        })
        .collect()
}

/// Every image capture writes, as `image_errors` names them.
fn images() -> Vec<String> {
    let mut names = vec!["001".to_string(), "002".to_string()];
    for m in &MOVERS {
        for p in m.positions {
            names.push(format!("{:03}-{}", m.channel, p.0));
        }
    }
    names
}

struct Setup {
    dir: PathBuf,
    fake: Fake,
    config: PathBuf,
    tracker: UdpSocket,
}

/// The stage (the fixed lights through `stage_of`, the movers appended to scene.toml with
/// their truth images in `truth/` only: capture must write the scene's), the fake with the
/// movers, and a config sending to the fake and to the tracker.
fn setup(name: &str, move_settle_s: f64) -> Option<Setup> {
    let dir = temp_dir(name);
    let fixed = fixed();
    let scene = stage_of(&dir, W, H, &fixed);
    let mut toml = std::fs::read_to_string(scene.join("scene.toml")).expect("scene.toml");
    toml += "[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\npan_range = 540\ntilt_range = 270\n";
    for m in &MOVERS {
        toml += &format!(
            "[[light]]\nchannel = {}\nprofile = \"spot\"\nuniverse = 1\naddress = {}\ngroup = \"all\"\n",
            m.channel, m.address
        );
        for &(palette, pan, tilt, (x, y, v)) in m.positions {
            let name = format!("{:03}-{palette}.exr", m.channel);
            toml += &format!(
                "[[light.position]]\npalette = {palette}\nname = \"{}\"\npan = {pan}\ntilt = {tilt}\nbasis = \"basis/{name}\"\n",
                NAMES[palette as usize - 1]
            );
            write_exr(
                &dir.join("truth").join(&name),
                W,
                H,
                pool(x, y, v, [0.8, 0.9, 1.0]),
            );
        }
    }
    std::fs::write(scene.join("scene.toml"), toml).expect("write scene.toml");

    let movers: Vec<(TestLight, RigMover)> = MOVERS
        .iter()
        .map(|m| {
            let light = TestLight {
                channel: m.channel,
                group: Some("all"),
                profile: "spot",
                universe: 1,
                address: m.address,
                pixel: Box::new(|_, _| [0.0; 3]),
            };
            let positions = m
                .positions
                .iter()
                .map(|&(palette, pan, tilt, (x, y, v))| RigPosition {
                    palette,
                    pan,
                    tilt,
                    pixel: Box::new(pool(x, y, v, [0.8, 0.9, 1.0])),
                })
                .collect();
            let rig = RigMover {
                pan: 1,
                tilt: 3,
                pan_range: 540.0,
                tilt_range: 270.0,
                positions,
            };
            (light, rig)
        })
        .collect();
    let mut rig: Vec<RigLight<'_>> = fixed
        .iter()
        .map(|light| RigLight {
            light,
            footprint: 1,
            intensity: None,
            mover: None,
        })
        .collect();
    rig.extend(movers.iter().map(|(light, m)| RigLight {
        light,
        footprint: 5,
        intensity: Some(0),
        mover: Some(m),
    }));
    let motion = dir.join("motion.json");
    let motion = motion.to_str().expect("a UTF-8 temporary path");
    let move_s = MOVE_S.to_string();
    let fake = Fake::on_rig(
        &dir,
        (W, H),
        &rig,
        &[
            ("FAKE_GPHOTO2_MOTION", motion),
            ("FAKE_GPHOTO2_MOVE_S", &move_s),
        ],
    )?;
    let tracker = UdpSocket::bind("127.0.0.1:0").expect("bind the tracker");
    let port = tracker.local_addr().expect("addr").port();
    let config = config(
        &dir,
        &[fake.port, port],
        &format!("[capture]\nmove_settle_s = {move_settle_s}\n"),
    );
    Some(Setup {
        dir,
        fake,
        config,
        tracker,
    })
}

/// What one run did: its output, the universe 1 states the tracker saw, the fake's log
/// entries of its frames.
struct Run {
    out: std::process::Output,
    wire: Vec<(f64, Vec<u8>)>,
    frames: Vec<serde_json::Value>,
}

impl Setup {
    fn run(&self, args: &[&str]) -> Run {
        let before = self.fake.log().len();
        let done = Arc::new(AtomicBool::new(false));
        let socket = self.tracker.try_clone().expect("clone the tracker");
        let tracker = track(socket, Arc::clone(&done), self.dir.join("motion.json"));
        let out = self.fake.capture(&self.config, args, &[]);
        done.store(true, Ordering::SeqCst);
        let wire = tracker.join().expect("tracker");
        let frames = self.fake.log().split_off(before);
        Run { out, wire, frames }
    }
}

/// The rig's levels (fixed lights, then the movers) and the position index each mover was
/// rendered at (None: black) in a frame of the fake's log.
fn levels_and_aims(frame: &serde_json::Value) -> (Vec<f64>, Vec<Option<u64>>) {
    let levels = frame["levels"]
        .as_array()
        .expect("levels")
        .iter()
        .map(|v| v.as_f64().expect("a level"))
        .collect();
    let aims = frame["aims"]
        .as_array()
        .expect("aims")
        .iter()
        .map(serde_json::Value::as_u64)
        .collect();
    (levels, aims)
}

/// The frames of `run` with rig light `k` (0: channel 1, 2: channel 3, ...) alone at full,
/// with the position index it was rendered at when it is a mover.
fn alone_at_full(run: &Run, k: usize) -> Vec<Option<u64>> {
    run.frames
        .iter()
        .map(levels_and_aims)
        .filter(|(levels, _)| {
            levels
                .iter()
                .enumerate()
                .all(|(i, &v)| if i == k { v == 1.0 } else { v == 0.0 })
        })
        .map(|(_, aims)| aims[k])
        .collect()
}

/// Every image within 3% of the truth (median relative error after one common factor);
/// returns the errors.
fn assert_accurate(dir: &Path, when: &str) -> Vec<f64> {
    let names = images();
    let errors = image_errors(dir, &names, true);
    let mut sorted = errors.clone();
    sorted.sort_by(f64::total_cmp);
    eprintln!(
        "{when}: median relative errors {:?}; median {:.4}, worst {:.4}",
        names.iter().zip(&errors).collect::<Vec<_>>(),
        sorted[sorted.len() / 2],
        sorted[sorted.len() - 1]
    );
    for (name, e) in names.iter().zip(&errors) {
        assert!(*e < 0.03, "{when}: {name}: median relative error {e:.4}");
    }
    errors
}

/// Whether every change of mover `m`'s pan or tilt on the wire (`states`, universe 1)
/// came with its intensity at 0 and stayed dark for `settle` seconds (less 0.1 s of
/// the tracker's own timing) before it was lit.
fn moves_dark(states: &[(f64, Vec<u8>)], m: &Mover, settle: f64) -> Result<usize, String> {
    let at = usize::from(m.address) - 1;
    let aim = |d: &[u8]| d[at + 1..at + 5].to_vec();
    let mut moves = 0;
    for (i, pair) in states.windows(2).enumerate() {
        if aim(&pair[0].1) == aim(&pair[1].1) {
            continue;
        }
        moves += 1;
        let moved = pair[1].0;
        if pair[1].1[at] != 0 {
            return Err(format!("light {} moved lit at {moved:.3}", m.channel));
        }
        if let Some(lit) = states[i + 1..].iter().find(|s| s.1[at] != 0)
            && lit.0 - moved < settle - 0.1
        {
            return Err(format!(
                "light {} lit {:.3} s after it was sent to a new position",
                m.channel,
                lit.0 - moved
            ));
        }
    }
    Ok(moves)
}

#[test]
fn movers_are_captured_at_every_palette_moved_dark_validated_and_resumed() {
    let Some(s) = setup("capture-movers", MOVE_SETTLE_S) else {
        return;
    };
    let first = s.run(&[]);
    assert!(first.out.status.success(), "{}", text(&first.out));
    let stdout = String::from_utf8_lossy(&first.out.stdout);
    assert!(
        stdout.contains("4 lights written, 0 already done, 0 showing no light")
            && stdout.contains("moving lights: 5 positions written, 0 already done"),
        "{}",
        text(&first.out)
    );
    eprintln!("first run:\n{stdout}");
    assert_accurate(&s.dir, "movers");

    // Each mover alone at full was rendered at each of its positions (at least a metering
    // frame and a bracket frame), never black nor elsewhere than a palette it has.
    for (k, m) in MOVERS.iter().enumerate() {
        let aims = alone_at_full(&first, 2 + k);
        for p in 0..m.positions.len() as u64 {
            let n = aims.iter().filter(|a| **a == Some(p)).count();
            assert!(
                n >= 2,
                "light {}: {n} frames alone at full at its position {p}: {aims:?}",
                m.channel
            );
        }
        assert!(
            aims.iter().all(Option::is_some),
            "light {}: a frame alone at full aimed at none of its positions",
            m.channel
        );
        let moves = moves_dark(&first.wire, m, MOVE_SETTLE_S).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            moves >= m.positions.len() - 1,
            "light {}: {moves} moves",
            m.channel
        );
    }

    // The validation look (several lights lit, below full) holds a mover at another
    // position than its first, and composite and shot agree.
    let validation = first
        .frames
        .iter()
        .map(levels_and_aims)
        .rfind(|(levels, _)| levels.iter().filter(|&&v| v > 0.0 && v < 1.0).count() >= 2)
        .expect("the validation look's frames");
    assert!(
        (2..4).any(|k| validation.0[k] > 0.0 && validation.1[k].is_some_and(|p| p >= 1)),
        "no mover in the validation look at a position other than its first: {validation:?}"
    );
    let record: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(s.dir.join("scene/capture.json")).expect("capture.json"),
    )
    .expect("capture.json is JSON");
    let v = record["validation"].as_f64().expect("a validation figure");
    eprintln!("validation: {:.2}%", v * 100.0);
    assert!(v < 0.05, "validation {v}");

    // A second run shoots no light alone: everything is resumed.
    let second = s.run(&[]);
    assert!(second.out.status.success(), "{}", text(&second.out));
    let stdout = String::from_utf8_lossy(&second.out.stdout);
    assert!(
        stdout.contains("0 lights written, 4 already done")
            && stdout.contains("moving lights: 0 positions written, 5 already done"),
        "{}",
        text(&second.out)
    );
    for k in 0..4 {
        assert!(
            alone_at_full(&second, k).is_empty(),
            "second run: rig light {k} shot alone at full"
        );
    }

    // Without one palette's image, a third run shoots that one alone.
    std::fs::remove_file(s.dir.join("scene/basis/003-2.exr")).expect("remove 003-2.exr");
    let third = s.run(&[]);
    assert!(third.out.status.success(), "{}", text(&third.out));
    let stdout = String::from_utf8_lossy(&third.out.stdout);
    assert!(
        stdout.contains("1 lights written, 3 already done")
            && stdout.contains("moving lights: 1 positions written, 4 already done"),
        "{}",
        text(&third.out)
    );
    for k in [0, 1, 3] {
        assert!(
            alone_at_full(&third, k).is_empty(),
            "third run: rig light {k} shot alone at full"
        );
    }
    let aims = alone_at_full(&third, 2);
    assert!(
        aims.len() >= 2 && aims.iter().all(|a| *a == Some(1)),
        "third run: light 3 alone at full only at palette 2: {aims:?}"
    );
    moves_dark(&third.wire, &MOVERS[0], MOVE_SETTLE_S).unwrap_or_else(|e| panic!("{e}"));
    assert_accurate(&s.dir, "resumed");
    std::fs::remove_dir_all(&s.dir).ok();
}

/// The fake's movers take `MOVE_S`: a capture given no time for the move
/// (`move_settle_s = 0`) photographs light 3 where it was, and its palettes 2 and 3 come
/// out far from the truth. This is what makes the settle tested at all.
#[test]
fn a_capture_that_does_not_wait_for_the_move_gets_the_wrong_image() {
    let Some(s) = setup("capture-movers-no-settle", 0.0) else {
        return;
    };
    let run = s.run(&["--lights", "3"]);
    assert!(run.out.status.success(), "{}", text(&run.out));
    let names: Vec<String> = (1..=3).map(|p| format!("003-{p}")).collect();
    let errors = image_errors(&s.dir, &names, true);
    eprintln!("no settle: {names:?} {errors:?}");
    assert!(
        errors[1] > 0.2 && errors[2] > 0.2,
        "palettes 2 and 3 shot without waiting for the move: {errors:?}"
    );
    std::fs::remove_dir_all(&s.dir).ok();
}

/// `--camera sim` photographs a mover at the position its pan and tilt on the wire are
/// for (the scene's image of that position, copied before the capture replaces it): a
/// sim capture of the stage writes every position's image back within 3%.
#[test]
fn the_sim_camera_shows_each_mover_at_the_position_sent() {
    let Some(s) = setup("capture-movers-sim", 0.0) else {
        return;
    };
    for name in images().iter().filter(|n| n.contains('-')) {
        std::fs::copy(
            s.dir.join(format!("truth/{name}.exr")),
            s.dir.join(format!("scene/basis/{name}.exr")),
        )
        .expect("the sim's stage");
    }
    let out = std::process::Command::new(crate::common::bin())
        .args(["capture", "--config"])
        .arg(&s.config)
        .args([
            "--camera", "sim", "--settle", "0.02", "--seed", "3", "--width",
        ])
        .arg(W.to_string())
        .output()
        .expect("visobjd capture runs");
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout)
            .contains("moving lights: 5 positions written, 0 already done"),
        "{}",
        text(&out)
    );
    assert_accurate(&s.dir, "sim");
    std::fs::remove_dir_all(&s.dir).ok();
}
