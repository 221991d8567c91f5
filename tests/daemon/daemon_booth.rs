//! What the booth relies on, against the real daemon: systemd's readiness and watchdog
//! (fed only while the DMX clock ticks), a panicking DMX clock that ends the process so
//! the service restarts with the saved look, a panicking generate that leaves the daemon
//! able to generate, SIGTERM that writes the last fader move, a restore that says what it
//! could not bring back, and log lines that carry journald priorities. Faults are injected
//! through the daemon's test hooks (`VISOBJD_TEST_HOOKS`).

use std::os::unix::net::UnixDatagram;
use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{Daemon, Osc, PATIENCE, Proto, Setup, int, same_look, string};

/// The environment that turns the test hooks on, plus `more`.
fn env(more: &[(&str, &str)]) -> Vec<(String, String)> {
    [("VISOBJD_TEST_HOOKS", "1")]
        .iter()
        .chain(more)
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}

fn start(name: &str, more: &[(&str, &str)]) -> Daemon {
    Daemon::start_setup(
        name,
        Setup {
            env: env(more),
            ..Setup::default()
        },
    )
}

/// A datagram socket standing in for systemd's notification socket.
struct Notify {
    sock: UnixDatagram,
    path: PathBuf,
}

impl Notify {
    fn bind(name: &str) -> Notify {
        let path = std::env::temp_dir().join(format!("visobjd-{name}-{}.sock", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let sock = UnixDatagram::bind(&path).expect("bind the notify socket");
        Notify { sock, path }
    }

    /// The next notification within `wait`, as its text.
    fn next(&self, wait: Duration) -> Option<String> {
        self.sock.set_read_timeout(Some(wait)).expect("timeout");
        let mut buf = [0u8; 4096];
        let n = self.sock.recv(&mut buf).ok()?;
        Some(String::from_utf8_lossy(&buf[..n]).into_owned())
    }

    /// Notifications that arrive within `wait`, at their arrival times.
    fn during(&self, wait: Duration) -> Vec<(Instant, String)> {
        let end = Instant::now() + wait;
        let mut got = Vec::new();
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            if let Some(m) = self.next(left.max(Duration::from_millis(1))) {
                got.push((Instant::now(), m));
            }
        }
        got
    }

    /// Waits for a notification holding `line`.
    fn wait_for(&self, line: &str) -> Instant {
        let end = Instant::now() + PATIENCE;
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            if let Some(m) = self.next(left.max(Duration::from_millis(1)))
                && m.lines().any(|l| l == line)
            {
                return Instant::now();
            }
        }
        panic!("no {line} on the notify socket within {PATIENCE:?}");
    }
}

impl Drop for Notify {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

const WATCHDOG: Duration = Duration::from_secs(1);

#[test]
fn the_watchdog_is_fed_only_while_the_dmx_clock_ticks() {
    let notify = Notify::bind("watchdog");
    let usec = WATCHDOG.as_micros().to_string();
    let path = notify.path.to_string_lossy().into_owned();
    let mut d = start(
        "booth-watchdog",
        &[("NOTIFY_SOCKET", &path), ("WATCHDOG_USEC", &usec)],
    );
    notify.wait_for("READY=1");
    // Fed: systemd restarts a service that stays silent for a whole period.
    let mut last = notify.wait_for("WATCHDOG=1");
    for _ in 0..4 {
        let at = notify.wait_for("WATCHDOG=1");
        assert!(
            at - last < WATCHDOG,
            "{:?} between pings, the watchdog period is {WATCHDOG:?}",
            at - last
        );
        last = at;
    }
    // The clock stalls: one ping may already be decided, then none for three periods
    // (six at the daemon's pace of one per half period).
    d.ok("/vo/test/stall", vec![int(1)], "/vo/test");
    let stalled = notify.during(3 * WATCHDOG);
    let pings = stalled.iter().filter(|(_, m)| m == "WATCHDOG=1").count();
    assert!(pings <= 1, "{pings} pings while the DMX clock stood still");
    assert!(d.log_text().contains("no watchdog ping"), "{}", d.log());
    // OSC still answers; the clock goes again, and so do the pings and the wire.
    d.ok("/vo/test/stall", vec![int(0)], "/vo/test");
    let again = notify.wait_for("WATCHDOG=1");
    d.wire.wait_frames_after(again, "after the stall");
    let health = d.health();
    assert!(
        health.late >= 1,
        "the stall shows as a late frame: {health:?}"
    );
}

#[test]
fn a_panic_on_the_dmx_clock_ends_the_process_and_the_restart_shows_the_look() {
    let mut d = start("booth-dmx-panic", &[]);
    d.ok("/vo/light/1/level", vec![int(70)], "/vo/light");
    d.ok("/vo/group/back/level", vec![int(30)], "/vo/group");
    // A discrete change waits for the disk, so the live look is saved.
    d.ok("/vo/fade", vec![common::daemon::float(0.0)], "/vo/fade");
    let look = d.live();
    d.wire.wait_look(Proto::Sacn, &look);
    d.ok("/vo/test/panic", vec![string("dmx")], "/vo/test");
    let status = d.wait_exit("the DMX clock's panic");
    assert_eq!(
        status.signal(),
        Some(libc_sigabrt()),
        "the process aborts so the service manager restarts it: {status:?}\n{}",
        d.log()
    );
    let restarted = Instant::now();
    d.restart();
    d.wire.wait_frames_after(restarted, "after the restart");
    d.wire.wait_look(Proto::Sacn, &look);
    d.wire.wait_look(Proto::Artnet, &look);
    assert!(same_look(&d.live(), &look, 1e-6));
}

/// SIGABRT's number on Linux.
fn libc_sigabrt() -> i32 {
    6
}

#[test]
fn a_generate_that_panics_is_answered_and_the_next_one_works() {
    let mut d = start("booth-generate-panic", &[]);
    d.add_objective("warm.png", "both");
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence(); // the state pushed at subscription
    d.ok("/vo/test/panic", vec![string("generate")], "/vo/test");
    let got = d.call("/vo/generate", vec![], "/vo/generated");
    let last = got.last().expect("a reply");
    assert_eq!(last.addr, "/vo/error", "{got:?}");
    assert_eq!(common::daemon::text(&last.args[0]), "/vo/generate");
    // Subscribers' progress bars end, and their status line stops saying it generates
    // (pushed before the requester is answered).
    let pushed = listen.fence();
    let progress: Vec<f64> = pushed
        .iter()
        .filter(|m| m.addr == "/vo/progress")
        .map(|m| common::daemon::num(&m.args[0]))
        .collect();
    assert_eq!(progress.first(), Some(&0.0), "{pushed:?}");
    assert_eq!(progress.last(), Some(&1.0), "{pushed:?}");
    let line = pushed.iter().rev().find(|m| m.addr == "/vo/status/text");
    let line = common::daemon::text(&line.expect("a status line").args[0]);
    assert!(!line.contains("generating"), "{line}");
    let g = d.generate();
    assert!(common::daemon::num(&g.args[1]) >= 1.0, "{g:?}");
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
}

#[test]
fn test_hooks_are_refused_unless_enabled() {
    let mut d = Daemon::start("booth-no-hooks");
    let sentence = d.refused("/vo/test/panic", vec![string("dmx")]);
    assert!(sentence.contains("VISOBJD_TEST_HOOKS"), "{sentence}");
    assert!(d.alive());
}

#[test]
fn sigterm_right_after_a_fader_move_keeps_it() {
    let mut d = start("booth-sigterm", &[]);
    // A burst of fader moves that do not wait for the disk; only the last one counts.
    for level in 1..=50 {
        d.send("/vo/light/2/level", vec![int(level)]);
    }
    d.fence();
    let mut look = d.live();
    look[2].intensity = 0.42;
    // A slow disk keeps the last move's write queued when SIGTERM comes.
    d.ok("/vo/test/slow_disk", vec![int(500)], "/vo/test");
    d.ok("/vo/light/3/level", vec![int(42)], "/vo/light");
    let status = d.terminate();
    assert!(status.success(), "{status:?}");
    d.restart();
    let back = d.live();
    assert!(
        same_look(&back, &look, 1e-6),
        "the look before SIGTERM {look:?}\nafter the restart {back:?}"
    );
}

#[test]
fn a_restore_names_what_it_lost_and_keeps_the_file() {
    let mut d = start("booth-restore", &[("JOURNAL_STREAM", "8:12345")]);
    d.ok("/vo/group/back/lock", vec![int(1)], "/vo/group/lock");
    d.ok("/vo/light/2/lock", vec![int(1)], "/vo/light/lock");
    assert!(d.terminate().success());
    let state = d.state_dir();
    let path = state.join("session.json");
    let text = std::fs::read_to_string(&path).expect("session.json");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    v["locked_groups"] = serde_json::json!(["back", "gone"]);
    v["locked_lights"] = serde_json::json!([2, 99]);
    let edited = serde_json::to_string_pretty(&v).expect("JSON");
    std::fs::write(&path, &edited).expect("write session.json");
    d.restart();
    // What it lost is named in the log, with journald's error priority (and only that).
    let log = d.log_text();
    assert!(
        !log.lines().any(|l| l.contains("not restored")
            && (l.contains("`back`") || l.contains("light 2:"))),
        "{log}"
    );
    for lost in ["group `gone`", "light 99"] {
        assert!(
            log.lines()
                .any(|l| l.starts_with("<3>") && l.contains("not restored") && l.contains(lost)),
            "no <3> line naming {lost}:\n{log}"
        );
    }
    assert!(
        log.lines()
            .any(|l| l.starts_with("<6>") && l.contains("DMX output running")),
        "info lines carry <6>:\n{log}"
    );
    // ...and the file as it was is kept before the daemon rewrites it.
    d.ok("/vo/fade", vec![common::daemon::float(1.0)], "/vo/fade");
    let kept: Vec<_> = std::fs::read_dir(&state)
        .expect("state")
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("session.json.partial-")
        })
        .collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(
        std::fs::read_to_string(kept[0].path()).expect("kept"),
        edited
    );
}
