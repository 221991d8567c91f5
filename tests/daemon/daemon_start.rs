//! Starting beside a running daemon: a second `visobjd run` (a technician starting it by
//! hand while the service runs) on the same state folder, or on the same ports, stops with
//! a sentence before it sends a single DMX packet, and the running daemon's stream goes on.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::bin;
use crate::common::daemon::{Daemon, Osc, PATIENCE, PROTOS, UNIVERSES};

/// Every sender address seen on the wire from `since`, and whether any sACN packet since
/// then terminated its stream.
fn senders(d: &Daemon, since: Instant) -> (BTreeSet<SocketAddr>, bool) {
    let mut from = BTreeSet::new();
    let mut terminated = false;
    for proto in PROTOS {
        for u in UNIVERSES {
            for f in d.wire.frames(proto, u, since) {
                from.insert(f.from);
                terminated |= f.terminated;
            }
        }
    }
    (from, terminated)
}

/// Runs a second `visobjd run --config config` to its end (bounded) and returns its exit
/// status and stderr.
fn second_instance(config: &std::path::Path) -> (std::process::ExitStatus, String) {
    let mut child = Command::new(bin())
        .args(["run", "--config"])
        .arg(config)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("visobjd starts");
    let end = Instant::now() + PATIENCE * 2;
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            let out = child.wait_with_output().expect("stderr");
            return (status, String::from_utf8_lossy(&out.stderr).into_owned());
        }
        if Instant::now() > end {
            let _ = child.kill();
            let out = child.wait_with_output().expect("stderr");
            panic!(
                "the second instance was still running after {:?}:\n{}",
                PATIENCE * 2,
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Asserts that from `since` only the first daemon's sockets sent, and nothing
/// terminated a stream, once frames sent after the second instance ended have arrived.
fn assert_only_the_first_sent(d: &Daemon, before: &BTreeSet<SocketAddr>, since: Instant) {
    let ended = Instant::now();
    d.wire.wait_frames_after(ended, "the second instance");
    d.wire.drained_after(Instant::now());
    let (after, terminated) = senders(d, since);
    let strangers: Vec<_> = after.difference(before).collect();
    assert!(
        strangers.is_empty(),
        "the second instance sent DMX from {strangers:?} (the first sends from {before:?})"
    );
    assert!(!terminated, "a Stream_Terminated packet went out");
    d.wire
        .assert_continuous(since, ended, Duration::from_millis(250), "the second start");
}

#[test]
fn a_second_instance_on_the_same_state_folder_sends_nothing() {
    let d = Daemon::start("second-same-folder");
    let warm = Instant::now();
    d.wire.wait_frames_after(warm, "the start");
    let (before, _) = senders(&d, warm);
    assert!(!before.is_empty());

    let since = Instant::now();
    let (status, stderr) = second_instance(d.config_path());
    assert!(
        !status.success(),
        "the second instance succeeded:\n{stderr}"
    );
    assert!(
        stderr.contains(&format!("is in use by another visobjd (pid {})", d.pid())),
        "{stderr}"
    );
    assert_only_the_first_sent(&d, &before, since);
}

#[test]
fn a_second_instance_on_taken_ports_sends_nothing() {
    let d = Daemon::start("second-taken-ports");
    let warm = Instant::now();
    d.wire.wait_frames_after(warm, "the start");
    let (before, _) = senders(&d, warm);

    // Its own state folder (so its own CID and lock), the same OSC ports.
    let text = std::fs::read_to_string(d.config_path()).expect("config");
    let other = d.dir.join("second.toml");
    std::fs::write(
        &other,
        text.replace("state_dir = \"state\"", "state_dir = \"state-2\""),
    )
    .expect("write the second config");
    let since = Instant::now();
    let (status, stderr) = second_instance(&other);
    assert!(
        !status.success(),
        "the second instance succeeded:\n{stderr}"
    );
    assert!(stderr.contains("address already in use"), "{stderr}");
    assert_only_the_first_sent(&d, &before, since);
}

#[test]
fn an_empty_library_under_the_state_folder_starts_with_the_scenes_references() {
    let mut d = Daemon::start("stock-references");
    d.terminate();
    // The booth's layout: the library in the (writable) state folder, the scene shipping
    // its own refs/.
    let shipped = d.dir.join("scene/refs");
    std::fs::create_dir_all(&shipped).expect("mkdir scene/refs");
    for name in ["warm.png", "cool.png"] {
        std::fs::copy(d.refs().join(name), shipped.join(name)).expect("ship a reference");
    }
    let text = std::fs::read_to_string(d.config_path()).expect("config");
    std::fs::write(
        d.config_path(),
        text.replace("references = \"refs\"", "references = \"state/refs\""),
    )
    .expect("write the config");
    d.restart();
    let library = d.state_dir().join("refs");
    let mut names: Vec<String> = std::fs::read_dir(&library)
        .expect("the library exists")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["cool.png", "warm.png"]);
    d.add_objective("warm.png", "both");

    // Not stocked again once it holds images: a deleted one stays deleted.
    std::fs::remove_file(library.join("cool.png")).expect("delete one");
    d.terminate();
    d.restart();
    assert!(
        !library.join("cool.png").exists(),
        "the library was stocked again"
    );
}

/// The saved live look goes on the wire before the scene's images are read (docs/reliability.md,
/// "Starting"): with light 1's basis image a FIFO that no one writes, the daemon blocks
/// reading it, and meanwhile sends the look it saved; it answers OSC only once the read
/// ends (here the FIFO is closed empty, so light 1 is left out).
#[test]
fn the_saved_look_goes_out_before_the_images_are_read() {
    use crate::common::daemon::{Proto, int};
    let mut d = Daemon::start("start-before-images");
    d.ok("/vo/light/2/level", vec![int(60)], "/vo/light");
    d.ok("/vo/light/5/level", vec![int(30)], "/vo/light");
    let saved = d.live();
    assert!(d.terminate().success());

    let basis = d.dir.join("scene/basis/001.exr");
    std::fs::remove_file(&basis).expect("remove light 1's image");
    let made = Command::new("mkfifo").arg(&basis).status().expect("mkfifo");
    assert!(made.success(), "mkfifo {}", basis.display());
    let log = d.dir.join("stderr-fifo.log");
    let mut child = Command::new(bin())
        .arg("run")
        .arg("--config")
        .arg(d.config_path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).expect("log"))
        .spawn()
        .expect("visobjd starts");
    // The look, while the daemon is still held in the image read: no answer to OSC yet.
    d.wire.wait_look(Proto::Sacn, &saved);
    d.wire.wait_look(Proto::Artnet, &saved);
    let mut osc = d.client();
    osc.send("/vo/ping", vec![]);
    assert!(
        osc.next(Duration::from_millis(300)).is_none(),
        "the daemon answered before its images were read: the test did not hold it"
    );
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(!text.contains("loaded:"), "{text}");
    // Let the read end: the FIFO opened and closed with nothing in it.
    drop(
        std::fs::OpenOptions::new()
            .write(true)
            .open(&basis)
            .expect("open the FIFO"),
    );
    let end = Instant::now() + PATIENCE;
    loop {
        osc.send("/vo/ping", vec![]);
        if osc
            .next(Duration::from_millis(100))
            .is_some_and(|m| m.addr == "/vo/pong")
        {
            break;
        }
        assert!(
            Instant::now() < end,
            "no answer once the images were read:\n{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
    }
    let _ = child.kill();
    let _ = child.wait();
}
