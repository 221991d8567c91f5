//! Export to Eos against a fake console: a TCP (length-prefixed or SLIP) or UDP OSC
//! listener that records the command lines the daemon sends, checked against the DMX the
//! daemon puts on the wire (decoded by the tests' own decoder), parameter by parameter.

use std::collections::BTreeMap;
use std::io::Read;
use std::net::{TcpListener, UdpSocket};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{Daemon, Osc, Proto, Setup, float, int, num};
use rosc::{OscPacket, OscType};
use visobjd_testkit::{TestLight, temp_dir, write_scene};

/// Command lines (the string arguments) in `packets`, each of which must be addressed to
/// Eos user `user`'s command line.
fn command_lines(packets: &[Vec<u8>], user: u32) -> Vec<String> {
    let addr = format!("/eos/user/{user}/newcmd");
    packets
        .iter()
        .map(|p| match rosc::decoder::decode_udp(p) {
            Ok((_, OscPacket::Message(m))) => {
                assert_eq!(m.addr, addr);
                match m.args.as_slice() {
                    [OscType::String(s)] => s.clone(),
                    other => panic!("one string argument expected, got {other:?}"),
                }
            }
            other => panic!("not an OSC message: {other:?}"),
        })
        .collect()
}

/// Splits a length-prefixed (OSC 1.0) stream into packets.
fn unprefix(mut bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    while bytes.len() >= 4 {
        let n = u32::from_be_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as usize;
        out.push(bytes[4..4 + n].to_vec());
        bytes = &bytes[4 + n..];
    }
    assert!(bytes.is_empty(), "trailing bytes");
    out
}

/// Splits a SLIP (OSC 1.1) stream into packets.
fn unslip(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    let mut esc = false;
    for &b in bytes {
        match (esc, b) {
            (false, 0xC0) => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
            (false, 0xDB) => esc = true,
            (true, 0xDC) => (cur.push(0xC0), esc = false).1,
            (true, 0xDD) => (cur.push(0xDB), esc = false).1,
            (_, b) => cur.push(b),
        }
    }
    out
}

/// Each test profile's slots in DMX order as the Eos parameter they should be exported as:
/// `At16` is a 16-bit pair, `-` a slot left out (uv, fixed).
const PROFILES: &[(&str, &[&str])] = &[
    ("dimmer", &["At"]),
    ("irgb", &["At", "Red", "Green", "Blue"]),
    ("rgb", &["Red", "Green", "Blue"]),
    ("rgbw", &["Red", "Green", "Blue", "White"]),
    (
        "full16",
        &[
            "At16", "Red", "Green", "Blue", "White", "Amber", "Lime", "-", "-",
        ],
    ),
    ("cmy", &["At", "Cyan", "Magenta", "Yellow", "-"]),
    ("irgbl", &["At", "Red", "Green", "Blue", "Lime"]),
];

/// The custom profiles as scene.toml writes them.
const CUSTOM: &str = r#"
[[profile]]
name = "full16"
channels = ["intensity16", "red", "green", "blue", "white", "amber", "lime", "uv", "fixed:255"]

[[profile]]
name = "cmy"
channels = ["intensity", "cyan", "magenta", "yellow", "fixed:7"]

[[profile]]
name = "irgbl"
channels = ["intensity", "red", "green", "blue", "lime"]
"#;

/// A light of the export stage: channel, profile, universe, address.
type Patched = (u32, &'static str, u16, usize);

/// Six lights covering every exported parameter: 16-bit intensity with white, amber and
/// lime (and a uv and fixed slot left out), CMY flags, an rgbw without a dimmer, a dimmer,
/// lime alone, an rgb.
const STAGE: [Patched; 6] = [
    (1, "full16", 1, 1),
    (2, "cmy", 1, 20),
    (3, "rgbw", 1, 30),
    (4, "dimmer", 2, 1),
    (5, "irgbl", 2, 10),
    (6, "rgb", 2, 20),
];

/// The export stage's scene folder, written under `dir`.
fn export_scene(dir: &std::path::Path) -> PathBuf {
    let lights: Vec<TestLight> = STAGE
        .iter()
        .enumerate()
        .map(|(i, &(channel, profile, universe, address))| TestLight {
            channel,
            group: None,
            profile,
            universe,
            address: address as u16,
            pixel: Box::new(move |x, _| if x / 8 == i { [0.5; 3] } else { [0.0; 3] }),
        })
        .collect();
    let scene = write_scene(&dir.join("eos-scene"), 48, 20, &[], &lights);
    let toml = scene.join("scene.toml");
    let text = std::fs::read_to_string(&toml).unwrap() + CUSTOM;
    std::fs::write(&toml, text).unwrap();
    scene
}

/// A look that drives every parameter away from 0 and 100 somewhere (lime on light 5).
fn set_export_look(d: &mut Daemon) {
    let looks: [(u32, f32, [f32; 3]); 6] = [
        (1, 0.6237, [1.0, 0.8, 0.3]),
        (2, 0.5, [0.2, 0.6, 1.0]),
        (3, 0.7, [1.0, 0.9, 0.6]),
        (4, 0.33, [1.0; 3]),
        (5, 0.8, [0.9, 1.0, 0.2]),
        (6, 0.4, [0.5, 0.5, 1.0]),
    ];
    for (ch, intensity, color) in looks {
        d.ok(
            &format!("/vo/light/{ch}/intensity"),
            vec![float(intensity)],
            "/vo/light",
        );
        if ch != 4 {
            d.ok(
                &format!("/vo/light/{ch}/color"),
                color.map(float).to_vec(),
                "/vo/light",
            );
        }
    }
}

/// The command lines as (channel, parameter) -> percent; the record line is left out.
fn parameters(lines: &[String]) -> BTreeMap<(u32, String), f64> {
    let mut out = BTreeMap::new();
    for line in lines.iter().filter(|l| !l.contains("Record")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(
            (words[0], words.last().copied()),
            ("Chan", Some("Enter")),
            "{line}"
        );
        let ch: u32 = words[1].parse().expect("a channel number");
        for pair in words[2..words.len() - 1].chunks(2) {
            let value: f64 = pair[1].parse().expect("a level");
            let old = out.insert((ch, pair[0].to_string()), value);
            assert!(old.is_none(), "{} set twice for channel {ch}", pair[0]);
        }
    }
    out
}

/// What the wire's slots `dmx` of universe `universe` say each exported parameter must
/// be, with the tolerance of one DMX step; a light without a dimmer is `At 100`.
fn wire_parameters(universe: u16, dmx: &[u8]) -> Vec<((u32, String), f64, f64)> {
    let mut out = Vec::new();
    for &(ch, profile, u, address) in STAGE.iter().filter(|s| s.2 == universe) {
        assert_eq!(u, universe);
        let slots = PROFILES.iter().find(|p| p.0 == profile).unwrap().1;
        let mut at = address - 1;
        if !slots.iter().any(|s| s.starts_with("At")) {
            out.push(((ch, "At".to_string()), 100.0, 0.0));
        }
        for &s in slots {
            match s {
                "At16" => {
                    let v = f64::from(dmx[at]) * 256.0 + f64::from(dmx[at + 1]);
                    out.push(((ch, "At".into()), v / 655.35, 100.0 / 65535.0));
                    at += 2;
                }
                "-" => at += 1,
                p => {
                    out.push(((ch, p.into()), f64::from(dmx[at]) / 2.55, 100.0 / 255.0));
                    at += 1;
                }
            }
        }
    }
    out
}

/// Waits until the wire shows what the command lines say, parameter for parameter within
/// one DMX step, and checks the lines hold no other parameter.
fn assert_lines_match_the_wire(d: &Daemon, lines: &[String]) {
    let sent = parameters(lines);
    let mut expected = 0;
    for universe in [1, 2] {
        let mismatch = |dmx: &[u8]| -> Option<String> {
            wire_parameters(universe, dmx)
                .into_iter()
                .find_map(|(key, want, tol)| match sent.get(&key) {
                    Some(got) if (got - want).abs() <= tol + 1e-9 => None,
                    got => Some(format!("{key:?}: exported {got:?}, wire {want}")),
                })
        };
        let dmx = d
            .wire
            .wait(Proto::Sacn, universe, "the exported levels", |dmx| {
                mismatch(dmx).is_none()
            });
        assert_eq!(mismatch(&dmx), None);
        expected += wire_parameters(universe, &dmx).len();
    }
    assert_eq!(sent.len(), expected, "extra parameters exported: {lines:?}");
}

/// The export stage with `[eos]` pointing at `console`.
fn export_daemon(
    name: &str,
    console: std::net::SocketAddr,
    protocol: &str,
    user: Option<u32>,
) -> Daemon {
    let dir = temp_dir(&format!("{name}-scene"));
    let mut extra = format!("\n[eos]\naddress = \"{console}\"\nprotocol = \"{protocol}\"\n");
    if let Some(u) = user {
        extra += &format!("user = {u}\n");
    }
    let mut d = Daemon::start_setup(
        name,
        Setup {
            extra,
            scene_from: Some(export_scene(&dir)),
            ..Setup::default()
        },
    );
    set_export_look(&mut d);
    d
}

/// Checks what every export must hold beyond the levels: every parameter kind, a 16-bit
/// intensity with decimals, the record line last.
fn assert_every_parameter(lines: &[String], n: u32) {
    let sent = parameters(lines);
    for p in [
        "Red", "Green", "Blue", "White", "Amber", "Lime", "Cyan", "Magenta", "Yellow",
    ] {
        assert!(
            sent.keys().any(|(_, q)| q == p),
            "no {p} exported: {lines:?}"
        );
    }
    assert!(sent[&(5, "Lime".to_string())] > 0.0, "{lines:?}");
    assert!(sent[&(1, "Amber".to_string())] > 0.0, "{lines:?}");
    let at = lines
        .iter()
        .find(|l| l.starts_with("Chan 1 At "))
        .expect("light 1's intensity");
    assert!(at.contains('.'), "16-bit intensity without decimals: {at}");
    assert!(!lines.iter().any(|l| l.contains("Uv")), "{lines:?}");
    assert_eq!(
        lines.last().unwrap(),
        &format!("Chan 1 Thru 6 Record Preset {n} Enter")
    );
}

#[test]
fn a_preset_reaches_a_tcp_console_as_its_own_user_with_the_wire_levels() {
    for (protocol, slip, user) in [("tcp", false, Some(7)), ("tcp-slip", true, None)] {
        let console = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = console.local_addr().unwrap();
        let mut d = export_daemon(&format!("eos-{protocol}"), addr, protocol, user);
        let r = d.ok("/vo/eos/preset", vec![int(5)], "/vo/eos/preset");
        assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (5, 6));
        let (mut stream, _) = console.accept().unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let mut bytes = Vec::new();
        stream.read_to_end(&mut bytes).unwrap();
        let packets = if slip {
            unslip(&bytes)
        } else {
            unprefix(&bytes)
        };
        // The default user is 90.
        let lines = command_lines(&packets, user.unwrap_or(90));
        assert_every_parameter(&lines, 5);
        assert_lines_match_the_wire(&d, &lines);
    }
}

#[test]
fn a_preset_reaches_a_udp_console_and_an_absent_console_is_an_error() {
    let console = UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = console.local_addr().unwrap();
    let mut d = export_daemon("eos-udp", addr, "udp", Some(12));
    d.ok("/vo/eos/preset", vec![int(12)], "/vo/eos/preset");
    console
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut packets = Vec::new();
    let end = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 2048];
    while Instant::now() < end {
        let n = console.recv(&mut buf).unwrap();
        packets.push(buf[..n].to_vec());
        if command_lines(&packets, 12)
            .last()
            .is_some_and(|l| l.contains("Record"))
        {
            break;
        }
    }
    let lines = command_lines(&packets, 12);
    assert_every_parameter(&lines, 12);
    assert_lines_match_the_wire(&d, &lines);

    // A console that is not listening: a clear error, nothing changes.
    let closed = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let extra = format!("\n[eos]\naddress = \"{closed}\"\nprotocol = \"tcp\"\n");
    let mut d = Daemon::start_with("eos-closed", &extra);
    d.refused("/vo/eos/preset", vec![int(1)]);
}

#[test]
fn a_bad_eos_user_is_refused_at_start() {
    let dir = temp_dir("eos-bad-user");
    let config = dir.join("c.toml");
    std::fs::write(&config, "[eos]\nuser = 0\n").unwrap();
    let out = std::process::Command::new(common::bin())
        .arg("check")
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("eos.user must be 1..=99"), "{err}");
}
