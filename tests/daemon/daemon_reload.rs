//! A booth that is changed while it runs: `SIGHUP` (what the unit's `ExecReload=` sends) and
//! `/vo/reload` re-read the config and the scene without a gap in the DMX; a broken config
//! changes nothing; a scene with a bad basis image runs without that light; a scene whose
//! description is broken keeps the saved look on the wire, answers, refuses changes, and
//! loads once the file is fixed.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use rosc::OscMessage;

use crate::common::daemon::{
    Daemon, DmxPacket, GAP, LightLevel, Osc, PATIENCE, PERIOD, PROTOS, Proto, Setup, UNIVERSES,
    float, int, status_part, text,
};
use visobjd_testkit::{TestLight, temp_dir, write_scene};

/// Waits (bounded) until the latest sACN frame of universe 1 satisfies `want`.
fn wait_sacn(d: &Daemon, what: &str, want: impl Fn(&DmxPacket) -> bool) {
    let end = Instant::now() + PATIENCE;
    loop {
        if d.wire.latest(Proto::Sacn, 1).is_some_and(|f| want(&f)) {
            return;
        }
        assert!(Instant::now() < end, "sACN never {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// When every universe on both protocols has had its first frame after `t`.
fn first_frames_after(d: &Daemon, t: Instant) -> Instant {
    d.wire.wait_frames_after(t, "the start");
    PROTOS
        .iter()
        .flat_map(|&p| UNIVERSES.iter().map(move |&u| (p, u)))
        .map(|(p, u)| d.wire.frames(p, u, t)[0].at)
        .max()
        .expect("frames")
}

fn hangup(pid: u32) {
    let ok = Command::new("kill")
        .args(["-HUP", &pid.to_string()])
        .status()
        .is_ok_and(|s| s.success());
    assert!(ok, "kill -HUP failed");
}

fn scene_file(d: &Daemon) -> PathBuf {
    d.dir.join("scene/scene.toml")
}

/// The longest interval between two frames of any universe and protocol in `from..now`,
/// once later frames have arrived.
fn longest_interval(d: &Daemon, from: Instant) -> Duration {
    let to = Instant::now();
    d.wire.wait_frames_after(to, "the reload");
    PROTOS
        .iter()
        .flat_map(|&p| UNIVERSES.iter().map(move |&u| (p, u)))
        .map(|(p, u)| d.wire.max_gap(p, u, from, to))
        .max()
        .unwrap_or_default()
}

/// Stops the daemon (SIGTERM: the last fader move is written), lets `change` break a file,
/// starts it again and waits until `live` is back on both protocols; returns when the
/// restart began.
fn restart_with(d: &mut Daemon, live: &[LightLevel], change: impl FnOnce()) -> Instant {
    d.terminate();
    change();
    d.wire.drained_after(Instant::now());
    let restarted = Instant::now();
    d.restart();
    for proto in PROTOS {
        d.wire.wait_look(proto, live);
    }
    restarted
}

fn status_message(d: &mut Daemon) -> OscMessage {
    d.ok("/vo/status", vec![], "/vo/status")
}

#[test]
fn sighup_mid_show_moves_a_light_and_a_priority_without_a_dark_frame() {
    let mut d = Daemon::start("reload-sighup");
    d.ok("/vo/group/front/intensity", vec![float(0.7)], "/vo/group");
    let live = d.live();
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    let level = d.wire.latest(Proto::Sacn, 1).expect("a frame").dmx[1];
    assert!(level > 100, "light 2 at 1/2 shows {level}");

    // Light 2 moves from 1/2 to 1/30, and sACN goes out at priority 120.
    let scene = std::fs::read_to_string(scene_file(&d)).expect("scene.toml");
    let moved = scene.replacen(
        "universe = 1\naddress = 2\n",
        "universe = 1\naddress = 30\n",
        1,
    );
    assert_ne!(moved, scene, "light 2's patch line");
    std::fs::write(scene_file(&d), moved).expect("write scene.toml");
    let config = std::fs::read_to_string(d.config_path()).expect("config");
    std::fs::write(
        d.config_path(),
        config.replace("priority = 100", "priority = 120"),
    )
    .expect("write config");

    let before = Instant::now();
    hangup(d.pid());
    wait_sacn(&d, "moved light 2 to 1/30 at priority 120", |f| {
        f.priority == 120 && f.dmx[29] == level && f.dmx[1] == 0
    });
    let longest = longest_interval(&d, before);
    eprintln!("the longest frame interval across the reload: {longest:?} (period {PERIOD:?})");
    assert!(
        longest < GAP,
        "a frame interval of {longest:?} across the reload (period {PERIOD:?})"
    );
    // Nothing else moved, and the session is the one before the reload.
    let after = d.wire.latest(Proto::Sacn, 1).expect("a frame");
    assert!(!after.terminated);
    assert_eq!(d.live(), live);
    assert!(status_part(&status_message(&mut d), "problem").is_none());
    assert!(d.alive());
}

#[test]
fn a_sighup_while_the_daemon_starts_reloads_once_it_answers() {
    // Large basis images, so that reading them takes a while after the first frame.
    let lights: Vec<TestLight> = (1..=8u16)
        .map(|ch| TestLight {
            channel: u32::from(ch),
            group: None,
            profile: "dimmer",
            universe: if ch <= 4 { 1 } else { 2 },
            address: ch,
            pixel: Box::new(move |x, _| {
                if x / 240 == usize::from(ch - 1) {
                    [0.5; 3]
                } else {
                    [0.0; 3]
                }
            }),
        })
        .collect();
    let scene = write_scene(
        &temp_dir("reload-early-hangup-scene").join("scene"),
        1920,
        1080,
        &[],
        &lights,
    );
    let mut d = Daemon::start_setup(
        "reload-early-hangup",
        Setup {
            scene_from: Some(scene),
            ..Setup::default()
        },
    );
    d.ok("/vo/light/3/intensity", vec![float(0.7)], "/vo/light");
    let live = d.live();
    d.terminate();
    // SIGHUP again and again from the moment the saved look is on the wire (the basis
    // images still loading) until the daemon answers: its default action would end the
    // process.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let mut sender = None;
    d.restart_with_first_frames(|pid| {
        let stop = std::sync::Arc::clone(&stop);
        sender = Some(std::thread::spawn(move || {
            while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                hangup(pid);
            }
        }));
    });
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    sender
        .expect("the SIGHUP sender")
        .join()
        .expect("the SIGHUP sender ends");
    let end = Instant::now() + PATIENCE;
    while !d.log_text().contains("reloaded ") {
        assert!(
            d.alive(),
            "the daemon ended on an early SIGHUP:\n{}",
            d.log()
        );
        assert!(
            Instant::now() < end,
            "no reload after an early SIGHUP:\n{}",
            d.log()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(d.alive());
    assert_eq!(d.live(), live);
}

#[test]
fn a_broken_config_changes_nothing_and_vo_reload_applies_a_good_one() {
    let mut d = Daemon::start("reload-osc");
    let config = std::fs::read_to_string(d.config_path()).expect("config");
    std::fs::write(d.config_path(), format!("{config}\n[output\n")).expect("write config");
    let why = d.err("/vo/reload", vec![]);
    assert!(why.starts_with("config not reloaded: "), "{why}");
    assert!(why.contains("everything stays as it was"), "{why}");
    hangup(d.pid());
    // The same refusal by SIGHUP: the daemon logs it and runs on.
    d.fence();
    assert!(d.alive());
    assert_eq!(
        d.wire.latest(Proto::Sacn, 1).expect("a frame").priority,
        100
    );

    std::fs::write(
        d.config_path(),
        config.replace("priority = 100", "priority = 90"),
    )
    .expect("write config");
    let done = d.ok("/vo/reload", vec![], "/vo/reloaded");
    let done = text(&done.args[0]);
    assert!(done.starts_with("reloaded "), "{done}");
    assert!(done.contains("6 lights"), "{done}");
    wait_sacn(&d, "at priority 90", |f| f.priority == 90);
}

#[test]
fn a_bad_basis_image_leaves_its_light_out_and_the_rest_works() {
    let mut d = Daemon::start("reload-bad-image");
    d.ok("/vo/light/3/intensity", vec![float(0.5)], "/vo/light");
    let live = d.live();
    let image = d.dir.join("scene/basis/003.exr");
    let good = std::fs::read(&image).expect("basis 003");
    let restarted = restart_with(&mut d, &live, || {
        std::fs::write(&image, b"not an EXR at all").expect("corrupt it");
    });
    let status = status_message(&mut d);
    let unseen = status_part(&status, "unseen").expect("an unseen part");
    assert_eq!(unseen[0], int(1), "{unseen:?}");
    assert_eq!(unseen[1], int(3), "{unseen:?}");
    assert!(text(&unseen[2]).contains("003.exr"), "{unseen:?}");

    // The rest generates; light 3 keeps its level in every entry.
    d.add_objective("warm.png", "both");
    d.generate();
    for k in 1..=d.gallery().len() as i32 {
        let c = d.candidate(k, 1);
        assert_eq!(c[2], live[2], "entry {k} moved light 3");
    }
    let first = first_frames_after(&d, restarted);
    d.wire
        .assert_continuous_since(first, "the run without light 3");

    // Fixed on disk, it loads without a restart.
    std::fs::write(&image, good).expect("fix it");
    let end = Instant::now() + PATIENCE * 2;
    while status_part(&status_message(&mut d), "unseen").is_some() {
        assert!(Instant::now() < end, "the fixed image never loaded");
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_broken_scene_keeps_the_saved_look_on_the_wire_and_loads_once_fixed() {
    let mut d = Daemon::start("reload-bad-scene");
    d.ok("/vo/group/side/intensity", vec![float(0.6)], "/vo/group");
    let live = d.live();
    let good = std::fs::read_to_string(scene_file(&d)).expect("scene.toml");
    let broken = scene_file(&d);
    let restarted = restart_with(&mut d, &live, || {
        std::fs::write(&broken, "[[light]]\nchannel = \"one\"\n").expect("break it");
    });
    let status = status_message(&mut d);
    let problem = status_part(&status, "problem").expect("a problem part");
    let sentence = text(&problem[0]);
    assert!(sentence.starts_with("scene not loaded: "), "{sentence}");
    assert!(sentence.contains("scene.toml"), "{sentence}");
    let why = d.refused("/vo/fade", vec![float(2.0)]);
    assert_eq!(why, sentence);
    let why = d.refused("/vo/generate", vec![]);
    assert_eq!(why, sentence);
    let first = first_frames_after(&d, restarted);
    d.wire.assert_continuous_since(first, "a broken scene");

    std::fs::write(scene_file(&d), good).expect("fix it");
    let end = Instant::now() + PATIENCE * 2;
    while status_part(&status_message(&mut d), "problem").is_some() {
        assert!(Instant::now() < end, "the fixed scene never loaded");
        std::thread::sleep(Duration::from_millis(100));
    }
    d.ok("/vo/fade", vec![float(2.0)], "/vo/fade");
    assert_eq!(d.live(), live);
}
