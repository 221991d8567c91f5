//! A backup never drifts silently (docs/reliability.md, "Backup", issue 30): what a main
//! accepts is bounded where it is accepted (a 65 KB label is refused on the main), and a
//! backup that cannot take what its main sends (a frame over the largest state a main of
//! its scene can send, a state that does not fit, a malformed packet, a command that fails
//! there or comes before the state) says so in its `/vo/status`, applies nothing after it,
//! and subscribes again for a whole state, backing off while the reason repeats and
//! logging it once.

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use crate::common::daemon::{
    Daemon, LightLevel, Osc, PATIENCE, STAGE, Setup, TcpFraming, int, same_look, status_part,
    string, text,
};
use rosc::{OscMessage, OscPacket, OscType};

/// A backup of the daemon at `main`, its sACN to its own receiver.
fn backup_of(name: &str, main: SocketAddr) -> Daemon {
    Daemon::start_setup(
        name,
        Setup {
            artnet: false,
            extra: format!("\n[backup]\nmain = \"{main}\"\n"),
            ..Setup::default()
        },
    )
}

/// How many times the daemon logged `what`.
fn logged(d: &Daemon, what: &str) -> usize {
    d.log_text().matches(what).count()
}

/// Waits until the backup has taken its main's state `times` times since it started.
fn wait_following(backup: &Daemon, times: usize) {
    let end = Instant::now() + PATIENCE;
    while logged(backup, "backup: following the main") < times {
        assert!(
            Instant::now() < end,
            "the backup never followed the main:\n{}",
            backup.log_text()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The problem sentence of the daemon's `/vo/status`, if it has one.
fn problem(d: &mut Daemon) -> Option<String> {
    let status = d.ok("/vo/status", vec![], "/vo/status");
    status_part(&status, "problem").map(|p| text(&p[0]))
}

/// Waits until the daemon's `/vo/status` has a problem saying `what`; returns it.
fn wait_problem(d: &mut Daemon, within: Duration, what: &str) -> String {
    let end = Instant::now() + within;
    loop {
        let now = problem(d);
        if let Some(p) = now.as_ref().filter(|p| p.contains(what)) {
            return p.clone();
        }
        assert!(
            Instant::now() < end,
            "/vo/status never said `{what}`: its problem is {now:?}\n--- log ---\n{}",
            d.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Light `ch`'s intensity in `look`.
fn level(look: &[LightLevel], ch: i32) -> f32 {
    look.iter()
        .find(|l| l.ch == ch)
        .expect("the light")
        .intensity
}

/// A 65 KB label is refused on the main with a sentence and nothing changes, on the main or
/// its backup; a label at the limit is saved and mirrored.
#[test]
fn a_label_of_65_kb_is_refused_on_the_main_and_one_of_100_characters_is_mirrored() {
    let mut main = Daemon::start("resync-label-main");
    let mut backup = backup_of("resync-label-backup", main.tcp_addr());
    wait_following(&backup, 1);
    let why = main.refused("/vo/look/save", vec![int(1), string(&"x".repeat(65_000))]);
    assert!(why.contains("at most 100 characters, got 65000"), "{why}");
    let name = format!("{}.png", "r".repeat(97));
    let why = main.refused("/vo/objective/add", vec![string(&name)]);
    assert!(why.contains("at most 100 characters, got 101"), "{why}");
    let label: String = "\u{e9}".repeat(100);
    main.ok(
        "/vo/look/save",
        vec![int(1), string(&label)],
        "/vo/look/saved",
    );
    let want = vec![(1, label)];
    assert_eq!(main.looks(), want);
    let end = Instant::now() + PATIENCE;
    while backup.looks() != want {
        assert!(Instant::now() < end, "the backup never took the look");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(problem(&mut backup), None);
}

/// A main whose saved looks were made on a larger rig (a saved look outlives a patch)
/// sends a state over what a main of the backup's scene can send: the backup says so in
/// its `/vo/status`, logs it once however often it subscribes again, and applies none of
/// the main's later commands to its old session; once the main's state fits again, it
/// follows.
#[test]
fn a_state_over_the_backups_limit_is_said_and_later_commands_are_not_applied() {
    let mut main = Daemon::start("resync-big-main");
    assert!(main.terminate().success());
    // 1000 saved looks of 300 lights each: about 18 MB of state, over the 2 MB or so the
    // six lights of the test stage allow.
    let look: Vec<serde_json::Value> = (1..=300)
        .map(|ch| serde_json::json!({"channel": ch, "intensity": 0.123_456_79}))
        .collect();
    let looks: serde_json::Map<String, serde_json::Value> = (1..=1000)
        .map(|n| {
            let file = serde_json::json!({"label": format!("Look {n}"), "lights": look});
            (n.to_string(), file)
        })
        .collect();
    let path = main.state_dir().join("looks.json");
    std::fs::write(&path, serde_json::json!({ "looks": looks }).to_string()).expect("looks.json");
    main.restart();
    // (Over TCP: a thousand replies over UDP on loopback may lose some.)
    let mut tcp = main.tcp(TcpFraming::LengthPrefix);
    let listed = tcp.call("/vo/looks", vec![], "/vo/looks/end");
    assert_eq!(listed.last().map(|m| m.args.clone()), Some(vec![int(1000)]));
    drop(tcp);

    let mut backup = backup_of("resync-big-backup", main.tcp_addr());
    let before = backup.live();
    let why = wait_problem(&mut backup, PATIENCE, "from the main is over the");
    assert!(
        why.starts_with(&format!(
            "backup: not following the main {}: a ",
            main.tcp_addr()
        )) && why.contains("-byte /vo/backup/state from the main is over the")
            && why.contains("bytes of the largest state a main of this backup's scene can send"),
        "{why}"
    );
    assert!(
        main.log_text()
            .contains("a backup of this scene takes: it will not follow"),
        "the main says so too:\n{}",
        main.log_text()
    );
    // Later commands on the main reach the backup neither on this connection (it ended)
    // nor on the next ones (each gets the same state first, and ends there).
    let ch = STAGE[1].channel;
    main.ok(&format!("/vo/light/{ch}/level"), vec![int(37)], "/vo/light");
    let subscribed = |main: &Daemon| logged(main, " subscribed: ");
    let (first, end) = (subscribed(&main), Instant::now() + PATIENCE);
    while subscribed(&main) < first + 2 {
        assert!(Instant::now() < end, "the backup did not subscribe again");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        same_look(&backup.live(), &before, 1e-6),
        "the backup applied a command to a session that is not the main's"
    );
    assert_eq!(
        logged(&backup, "from the main is over the"),
        1,
        "logged once, not at each subscription:\n{}",
        backup.log_text()
    );

    // A state that fits again: the backup follows, its problem gone.
    assert!(main.terminate().success());
    std::fs::write(&path, r#"{"looks": {}}"#).expect("looks.json");
    main.restart();
    // The backup may be waiting out its backoff (10 s at most).
    let end = Instant::now() + Duration::from_secs(15);
    while problem(&mut backup).is_some() || level(&backup.live(), ch) < 0.3 {
        assert!(
            Instant::now() < end,
            "the backup never followed the main again:\n{}",
            backup.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(backup.looks(), Vec::new());
}

/// A main played by the test: accepts the backup's connections one at a time.
struct FakeMain {
    listener: TcpListener,
}

impl FakeMain {
    fn start() -> FakeMain {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        listener.set_nonblocking(true).expect("nonblocking");
        FakeMain { listener }
    }

    fn addr(&self) -> SocketAddr {
        self.listener.local_addr().expect("addr")
    }

    /// The backup's next connection, once its `/vo/backup/subscribe` arrived, and when it
    /// was accepted.
    fn subscription(&self, backup: &Daemon) -> (TcpStream, Instant) {
        let end = Instant::now() + PATIENCE * 3;
        let (mut c, at) = loop {
            match self.listener.accept() {
                Ok((c, _)) => break (c, Instant::now()),
                Err(e) if e.kind() == ErrorKind::WouldBlock => {
                    assert!(
                        Instant::now() < end,
                        "the backup did not subscribe again:\n{}",
                        backup.log_text()
                    );
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(e) => panic!("accept: {e}"),
            }
        };
        c.set_nonblocking(false).expect("blocking");
        c.set_read_timeout(Some(PATIENCE)).expect("timeout");
        let mut len = [0u8; 4];
        c.read_exact(&mut len).expect("a frame from the backup");
        let mut body = vec![0u8; u32::from_be_bytes(len) as usize];
        c.read_exact(&mut body).expect("its body");
        let (_, p) = rosc::decoder::decode_udp(&body).expect("OSC");
        match p {
            OscPacket::Message(m) => assert_eq!(m.addr, "/vo/backup/subscribe"),
            other => panic!("not a subscription: {other:?}"),
        }
        (c, at)
    }
}

/// `m`, length-prefixed as the main sends it.
fn frame(m: &OscMessage) -> Vec<u8> {
    let bytes = rosc::encoder::encode(&OscPacket::Message(m.clone())).expect("encode");
    let mut out = (bytes.len() as u32).to_be_bytes().to_vec();
    out.extend(bytes);
    out
}

fn osc(addr: &str, args: Vec<OscType>) -> OscMessage {
    OscMessage {
        addr: addr.into(),
        args,
    }
}

/// Sends `bytes` and waits until the backup hangs up (it may already have, mid-write).
fn send_and_see_it_hang_up(c: &mut TcpStream, bytes: &[u8], backup: &Daemon) {
    let _ = c.write_all(bytes);
    let mut buf = [0u8; 4096];
    loop {
        match c.read(&mut buf) {
            Ok(0) => return,
            Ok(_) => {} // its keepalive ping
            Err(e) if matches!(e.kind(), ErrorKind::ConnectionReset | ErrorKind::BrokenPipe) => {
                return;
            }
            Err(e) => panic!(
                "the backup kept the connection ({e}):\n{}",
                backup.log_text()
            ),
        }
    }
}

/// Each thing a backup cannot take ends the connection before anything after it is
/// applied, is said in `/vo/status` and logged once while it repeats, and the backup
/// subscribes again (backing off while the reason repeats) until a whole state it can take
/// arrives; then it follows again.
#[test]
fn what_a_backup_cannot_take_ends_the_connection_and_it_subscribes_again() {
    // A real main's state for the test stage, to play back: light 1 at 50%.
    let mut real = Daemon::start("resync-fake-real");
    real.ok("/vo/light/1/level", vec![int(50)], "/vo/light");
    let want = real.live();
    let mut tcp = real.tcp(TcpFraming::LengthPrefix);
    tcp.send("/vo/backup/subscribe", vec![]);
    let state = loop {
        let m = tcp.next(PATIENCE).expect("the main's state");
        if m.addr == "/vo/backup/state" {
            break m;
        }
    };
    drop(tcp);
    drop(real);

    let fake = FakeMain::start();
    let mut backup = backup_of("resync-fake-backup", fake.addr());
    let later = osc("/vo/light/2/level", vec![int(37)]);

    // The state, then a command that fails here, then one that would apply: the backup
    // takes the state, hangs up at the failure and never applies the third.
    let (mut c, _) = fake.subscription(&backup);
    let bytes = [
        frame(&state),
        frame(&osc("/vo/look/recall", vec![int(77)])),
        frame(&later),
    ]
    .concat();
    send_and_see_it_hang_up(&mut c, &bytes, &backup);
    assert!(
        same_look(&backup.live(), &want, 1e-6),
        "the state was taken"
    );
    let why = wait_problem(
        &mut backup,
        PATIENCE,
        "/vo/look/recall from the main failed here: there is no saved look 77",
    );
    assert!(why.ends_with("; subscribing again"), "{why}");

    // A frame over the largest state a main of this scene can send: refused by its first
    // bytes, never buffered.
    let (mut c, _) = fake.subscription(&backup);
    let packet = &frame(&state)[4..];
    let mut bytes = (1u32 << 30).to_be_bytes().to_vec();
    bytes.extend_from_slice(&packet[..300]);
    send_and_see_it_hang_up(&mut c, &bytes, &backup);
    wait_problem(
        &mut backup,
        PATIENCE,
        "a 1073741824-byte /vo/backup/state from the main is over the",
    );

    // A malformed message, four times: said and logged once, and the backup waits longer
    // each time (0.2, 0.4, 0.8 s).
    let mut malformed = b"/vo/light/2/level\0\0\0,i\0\0".to_vec();
    malformed.extend_from_slice(&[0, 0]);
    let mut bad = (malformed.len() as u32).to_be_bytes().to_vec();
    bad.extend(malformed);
    let mut times = Vec::new();
    for _ in 0..4 {
        let (mut c, at) = fake.subscription(&backup);
        times.push(at);
        send_and_see_it_hang_up(&mut c, &bad, &backup);
    }
    wait_problem(
        &mut backup,
        PATIENCE,
        "a malformed /vo/light/2/level from the main",
    );
    assert_eq!(
        logged(&backup, "a malformed /vo/light/2/level from the main"),
        1,
        "{}",
        backup.log_text()
    );
    let last_gap = times[3] - times[2];
    assert!(
        last_gap >= Duration::from_millis(800),
        "the third repeat came {last_gap:?} after the second: no backoff"
    );

    // A command before the state: not applied.
    let (mut c, _) = fake.subscription(&backup);
    send_and_see_it_hang_up(&mut c, &frame(&later), &backup);
    wait_problem(
        &mut backup,
        PATIENCE,
        "the main sent /vo/light/2/level before its state",
    );

    // A state whose live look has a light this scene lacks: not taken.
    let mut misfit = state.clone();
    let OscType::String(live) = &mut misfit.args[1] else {
        panic!("the live part is a string: {misfit:?}");
    };
    *live = live.replacen("\"channel\":6,", "\"channel\":99,", 1);
    assert!(live.contains("\"channel\":99,"), "{live}");
    let (mut c, _) = fake.subscription(&backup);
    send_and_see_it_hang_up(&mut c, &frame(&misfit), &backup);
    wait_problem(&mut backup, PATIENCE, "its state could not be taken here");
    assert!(same_look(&backup.live(), &want, 1e-6));

    // The whole state again: the backup follows, and takes the commands after it.
    let (mut c, _) = fake.subscription(&backup);
    c.write_all(&[frame(&state), frame(&later)].concat())
        .expect("write");
    let end = Instant::now() + PATIENCE;
    while problem(&mut backup).is_some() || (level(&backup.live(), 2) - 0.37).abs() > 1e-3 {
        assert!(
            Instant::now() < end,
            "the backup never followed again:\n{}",
            backup.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(c);
}
