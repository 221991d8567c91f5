//! The argument rules and transports of docs/osc.md against the real daemon: number forms, path
//! arguments, case, button releases, bundles, unknown addresses, non-OSC input, TCP with
//! both framings, reply types, and `visobjd send`.

use std::process::Command;

use crate::common;
use crate::common::bin;
use crate::common::daemon::{Daemon, Osc, TcpFraming, double, float, int, long, msg, num, string};
use rosc::{OscBundle, OscPacket, OscTime, OscType};
use visobjd_testkit::tools;

#[test]
fn numbers_arrive_in_every_form() {
    let mut d = Daemon::start("args-numbers");
    for (arg, want) in [
        (int(1), 1.0),
        (long(0), 0.0),
        (float(0.25), 0.25),
        (double(0.75), 0.75),
        (string("0.5"), 0.5),
        (string(" 0.125 "), 0.125),
    ] {
        let r = d.ok("/vo/master", vec![arg.clone()], "/vo/master");
        assert!((num(&r.args[0]) - want).abs() < 1e-6, "{arg:?}: {r:?}");
        assert!((d.status().master - want).abs() < 1e-6, "{arg:?}");
    }
    // Not numbers: refused, nothing changed.
    for bad in [
        string("half"),
        string(""),
        OscType::Bool(true),
        OscType::Blob(vec![1]),
        float(f32::NAN),
        double(f64::INFINITY),
    ] {
        d.refused("/vo/master", vec![bad]);
    }
}

#[test]
fn trailing_path_numbers_are_arguments_and_case_does_not_matter() {
    let mut d = Daemon::start("args-path");
    let r = d.ok("/vo/light/2/level", vec![int(50)], "/vo/light");
    assert_eq!(num(&r.args[0]) as i32, 2, "{r:?}");
    assert!((num(&r.args[1]) - 0.5).abs() < 1e-6, "{r:?}");
    // The value itself in the path, and any case.
    d.ok("/VO/Light/3/Level/25", vec![], "/vo/light");
    d.ok("/vo/MASTER/0.5", vec![], "/vo/master");
    let live = d.live();
    assert!((live[1].intensity - 0.5).abs() < 1e-6, "{live:?}");
    assert!((live[2].intensity - 0.25).abs() < 1e-6, "{live:?}");
    assert!((d.status().master - 0.5).abs() < 1e-6);
    let r = d.ok("/Vo/Ping", vec![int(7)], "/vo/pong");
    assert_eq!(r.args, [int(7)]);

    // /vo/pick/3 is /vo/pick 3.
    d.add_objective("warm.png", "both");
    d.generate();
    let c = d.gallery().len() as i32;
    let k = c.min(3);
    let r = d.ok(&format!("/vo/pick/{k}"), vec![], "/vo/picked");
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (k, 1));
    assert_eq!(d.status().entry, k);
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    assert_eq!(d.status().entry, 1);
    d.ok(&format!("/VO/PICK/{k}/1"), vec![], "/vo/picked");
    assert_eq!(d.status().entry, k);
}

#[test]
fn button_releases_get_no_reply_and_change_nothing() {
    let mut d = Daemon::start("args-buttons");
    d.add_objective("warm.png", "both");
    d.generate();
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let before = d.snapshot();
    for (addr, args) in [
        ("/vo/next", vec![int(0)]),
        ("/vo/prev", vec![float(0.0)]),
        ("/vo/next/0", vec![]),
        ("/vo/undo", vec![double(0.0)]),
        ("/vo/redo", vec![string("0")]),
        ("/vo/generate", vec![int(0)]),
        ("/vo/objective/clear", vec![float(0.0)]),
        ("/vo/status", vec![int(0)]),
        ("/vo/live", vec![long(0)]),
        ("/vo/gallery", vec![int(0)]),
        ("/vo/looks", vec![int(0)]),
        ("/vo/objectives", vec![int(0)]),
    ] {
        d.silent(addr, args);
    }
    assert_eq!(d.snapshot(), before);
    // A press (1, or nothing) triggers.
    let r = d.ok("/vo/next", vec![int(1)], "/vo/picked");
    assert_eq!(num(&r.args[0]) as i32, 2.min(d.gallery().len() as i32));
    d.ok("/vo/status", vec![float(1.0)], "/vo/status");
}

#[test]
fn bundles_run_in_order() {
    let mut d = Daemon::start("args-bundles");
    let bundle = OscPacket::Bundle(OscBundle {
        // A time tag in the future: not scheduled, run at once.
        timetag: OscTime::from((u32::MAX, 0)),
        content: vec![
            msg("/vo/light/1/level", vec![int(10)]),
            msg("/vo/light/1/level", vec![int(90)]),
            msg("/vo/nonsense", vec![]),
            msg("/vo/live", vec![]),
        ],
    });
    d.send_packet(&bundle);
    let got = d.collect("/vo/live", common::daemon::PATIENCE, "a bundle");
    let addrs: Vec<&str> = got.iter().map(|m| m.addr.as_str()).collect();
    // collect stops at the first error: read on to the live reply.
    assert_eq!(addrs, ["/vo/light", "/vo/light", "/vo/error"], "{got:?}");
    assert!((num(&got[0].args[1]) - 0.1).abs() < 1e-6);
    assert!((num(&got[1].args[1]) - 0.9).abs() < 1e-6);
    let rest = d.collect(
        "/vo/live",
        common::daemon::PATIENCE,
        "the bundle's /vo/live",
    );
    assert_eq!(rest.len(), 1, "{rest:?}");
    assert!((num(&rest[0].args[1]) - 0.9).abs() < 1e-6, "{rest:?}");
}

#[test]
fn unknown_addresses_are_errors_and_garbage_gets_nothing() {
    let mut d = Daemon::start("args-unknown");
    for addr in [
        "/vo/nonsense",
        "/vo",
        "/vo/pingg",
        "/vo/light/1",
        "/vo/light/1/flash",
        "/vo/group/front",
        "/vo/objective",
        "/vo/look",
        "/other/ping",
    ] {
        d.refused(addr, vec![int(1)]);
    }
    // A near miss names the address meant, and where the list is.
    for (sent, meant) in [
        ("/vo/pikc", "/vo/pick"),
        ("/vo/pingg", "/vo/ping"),
        ("/vo/light/4/levle", "/vo/light/4/level"),
        ("/vo/objectives/add", "/vo/objective/add"),
    ] {
        let why = d.refused(sent, vec![int(1)]);
        assert!(
            why.contains(&format!("did you mean {meant}?")),
            "{sent}: {why}"
        );
        assert!(why.contains("docs/osc.md"), "{why}");
    }
    let far = d.refused("/other/ping", vec![]);
    assert!(!far.contains("did you mean"), "{far}");
    // Arguments a command does not take are refused, not ignored; a trigger takes a
    // button's one value; a ping takes anything.
    let why = d.refused("/vo/fade", vec![float(2.0), float(3.0)]);
    assert!(why.contains("/vo/fade takes 1 argument, got 2"), "{why}");
    let why = d.refused("/vo/light/1/level", vec![int(50), int(60)]);
    assert!(why.contains("takes 1 argument, got 2"), "{why}");
    d.ok("/vo/status", vec![float(1.0)], "/vo/status");
    let why = d.refused("/vo/status", vec![float(1.0), float(1.0)]);
    assert!(why.contains("/vo/status takes 1 argument, got 2"), "{why}");
    d.ok("/vo/ping", vec![int(1), int(2), int(3)], "/vo/pong");
    let mut raw = d.client();
    raw.send_raw(b"GET / HTTP/1.1\r\n\r\n");
    raw.send_raw(&[0xff; 40]);
    let got = raw.fence();
    assert!(got.is_empty(), "non-OSC input was answered: {got:?}");
}

fn over_tcp(framing: TcpFraming) {
    let mut d = Daemon::start(&format!("args-tcp-{framing:?}"));
    let mut c = d.tcp(framing);
    let r = c.ok("/vo/ping", vec![int(1), string("a\u{c0}b")], "/vo/pong");
    assert_eq!(r.args, [int(1), string("a\u{c0}b")]);
    let r = c.ok("/vo/light/1/level", vec![int(40)], "/vo/light");
    assert!((num(&r.args[1]) - 0.4).abs() < 1e-6);
    c.err("/vo/light/99/level", vec![int(40)]);
    c.silent("/vo/next", vec![int(0)]);
    // A frame that is not OSC gets nothing.
    let garbage = match framing {
        TcpFraming::LengthPrefix => [&[0, 0, 0, 8][..], b"not osc!"].concat(),
        TcpFraming::Slip => [&[0xC0][..], b"not osc!", &[0xC0]].concat(),
    };
    c.send_raw(&garbage);
    let got = c.fence();
    assert!(got.is_empty(), "a non-OSC frame was answered: {got:?}");
    c.send_packet(&OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content: vec![
            msg("/vo/fade", vec![int(3)]),
            msg("/vo/master", vec![float(0.5)]),
        ],
    }));
    assert_eq!(
        c.collect("/vo/fade", common::daemon::PATIENCE, "bundle")
            .len(),
        1
    );
    assert_eq!(
        c.collect("/vo/master", common::daemon::PATIENCE, "bundle")
            .len(),
        1
    );
    // The UDP side sees the same daemon.
    let s = d.status();
    assert_eq!((s.fade, s.master), (3.0, 0.5));
    assert!((d.live()[0].intensity - 0.4).abs() < 1e-6);
}

#[test]
fn tcp_length_prefixed() {
    over_tcp(TcpFraming::LengthPrefix);
}

#[test]
fn tcp_slip() {
    over_tcp(TcpFraming::Slip);
}

/// The type tags docs/osc.md gives (`:i` int32, `:f` float32, `:s` string).
#[test]
fn replies_carry_the_contract_types() {
    let mut d = Daemon::start("args-types");
    let tags = |m: &rosc::OscMessage| -> String {
        m.args
            .iter()
            .map(|a| match a {
                OscType::Int(_) => 'i',
                OscType::Float(_) => 'f',
                OscType::String(_) => 's',
                _ => '?',
            })
            .collect()
    };
    let r = d.ok("/vo/status", vec![], "/vo/status");
    // The session, the output's health, and a label and count per destination (one sACN,
    // one Art-Net).
    assert_eq!(
        tags(&r),
        format!("siiiiifif{}{}", "fii", "si".repeat(2)),
        "{r:?}"
    );
    let r = d.ok(
        "/vo/objective/add",
        vec![string("grey.png")],
        "/vo/objective/added",
    );
    assert_eq!(tags(&r), "isfff", "{r:?}");
    let r = d.ok("/vo/light/3/intensity", vec![float(0.5)], "/vo/light");
    assert_eq!(tags(&r), "iffff", "{r:?}");
    let r = d.ok("/vo/live", vec![], "/vo/live");
    assert_eq!(tags(&r), "iffff".repeat(6), "{r:?}");
    let r = d.generate();
    assert_eq!(tags(&r), "iifi", "{r:?}");
    let r = d.ok("/vo/candidate", vec![int(1)], "/vo/candidate");
    assert_eq!(tags(&r), format!("ii{}", "iffff".repeat(6)), "{r:?}");
    let r = d.ok("/vo/group/back/level", vec![int(20)], "/vo/group");
    assert_eq!(tags(&r), "si", "{r:?}");
    let r = d.call("/vo/error-please", vec![], "/vo/error");
    assert_eq!(tags(&r[0]), "ss", "{r:?}");
}

#[test]
fn visobjd_send_prints_the_pong() {
    let d = Daemon::start("args-send");
    let out = Command::new(bin())
        .args([
            "send",
            "--to",
            &format!("127.0.0.1:{}", d.port),
            "/vo/ping",
            "1",
        ])
        .output()
        .expect("visobjd send runs");
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.lines().any(|l| l.trim() == "/vo/pong 1"),
        "stdout: {stdout:?}"
    );
}

const PYTHON_DAEMON_CLIENT: &str = r#"
import sys
from pythonosc.udp_client import SimpleUDPClient
from pythonosc.tcp_client import SimpleTCPClient
port = int(sys.argv[1])
c = SimpleUDPClient("127.0.0.1", port)
for address, args in [("/vo/ping", [7]), ("/vo/status", []), ("/vo/light/99/level", [50])]:
    c.send_message(address, args)
    for m in c.get_messages(5):
        print("udp", m.address, m.params)
        break
for mode in ("1.0", "1.1"):
    t = SimpleTCPClient("127.0.0.1", port, mode=mode, timeout=5)
    t.send_message("/vo/generate/count", [30])
    for m in t.get_messages(5):
        print("tcp", m.address, m.params)
        break
    t.close()
"#;

/// An independent OSC implementation (python-osc) gets the documented replies from the
/// real daemon over UDP and both TCP framings.
#[test]
fn python_osc_gets_the_documented_replies() {
    if !tools::python_osc() {
        return;
    }
    let d = Daemon::start("python-osc");
    let out = Command::new("python3")
        .args(["-c", PYTHON_DAEMON_CLIENT])
        .arg(d.port.to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "udp /vo/pong [7]", "{text}");
    assert!(
        lines[1].starts_with("udp /vo/status ['test scene', 6, 0, 0, 0, 0,"),
        "{text}"
    );
    assert_eq!(
        lines[2],
        "udp /vo/error ['/vo/light/99/level', 'light 99 is not in the scene (channels 1-6)']",
        "{text}"
    );
    assert_eq!(&lines[3..], ["tcp /vo/generate/count [30]"; 2], "{text}");
}
