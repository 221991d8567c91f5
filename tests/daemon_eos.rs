//! Export to Eos against a fake console: a TCP (length-prefixed or SLIP) or UDP OSC
//! listener that records the command lines the daemon sends, checked line by line.

mod common;

use std::io::Read;
use std::net::{TcpListener, UdpSocket};
use std::time::{Duration, Instant};

use common::daemon::{Daemon, Light, Osc, float, int, num};
use rosc::{OscPacket, OscType};

/// Command lines (`/eos/newcmd` string arguments) in the packets of `bytes`.
fn command_lines(packets: &[Vec<u8>]) -> Vec<String> {
    packets
        .iter()
        .map(|p| match rosc::decoder::decode_udp(p) {
            Ok((_, OscPacket::Message(m))) => {
                assert_eq!(m.addr, "/eos/newcmd");
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

/// What a 6-light look must become: intensity lines, colour lines for colour lights, then
/// the record line (the harness's stage: channels 1-6, 1 and 2 dimmers).
fn expected(live: &[Light], colour: &[bool], n: u32) -> Vec<String> {
    let pct = |v: f32| {
        let p = (v * 1000.0).round() / 10.0;
        if p.fract() == 0.0 {
            format!("{}", p as u32)
        } else {
            format!("{p:.1}")
        }
    };
    let lin = |c: f32| visobjd_scene::srgb::srgb_to_linear(c);
    let mut want = Vec::new();
    for (i, l) in live.iter().enumerate() {
        let (ch, [r, g, b]) = (l.ch, l.color);
        want.push(format!("Chan {ch} At {} Enter", pct(l.intensity)));
        if colour[i] {
            want.push(format!(
                "Chan {ch} Red {} Green {} Blue {} Enter",
                pct(lin(r)),
                pct(lin(g)),
                pct(lin(b))
            ));
        }
    }
    want.push(format!(
        "Chan 1 Thru {} Record Preset {n} Enter",
        live.len()
    ));
    want
}

fn set_a_look(d: &mut Daemon) {
    d.ok("/vo/light/1/level", vec![int(62)], "/vo/light");
    d.ok("/vo/light/3/intensity", vec![float(0.8)], "/vo/light");
    d.ok(
        "/vo/light/3/color",
        vec![float(1.0), float(0.5), float(0.0)],
        "/vo/light",
    );
}

#[test]
fn a_preset_reaches_a_tcp_console_as_command_lines() {
    for (protocol, slip) in [("tcp", false), ("tcp-slip", true)] {
        let console = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = console.local_addr().unwrap();
        let extra = format!("\n[eos]\naddress = \"{addr}\"\nprotocol = \"{protocol}\"\n");
        let mut d = Daemon::start_with(&format!("eos-{protocol}"), &extra);
        set_a_look(&mut d);
        let live = d.live();
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
        let lines = command_lines(&packets);
        let colour = [false, false, true, true, true, true];
        assert_eq!(lines, expected(&live, &colour, 5), "{protocol}");
        assert!(
            lines.contains(&"Chan 1 At 62 Enter".to_string()),
            "{lines:?}"
        );
        assert!(
            lines.contains(&"Chan 3 Red 100 Green 21.4 Blue 0 Enter".to_string()),
            "{lines:?}"
        );
    }
}

#[test]
fn a_preset_reaches_a_udp_console_and_an_absent_console_is_an_error() {
    let console = UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = console.local_addr().unwrap();
    let extra = format!("\n[eos]\naddress = \"{addr}\"\nprotocol = \"udp\"\n");
    let mut d = Daemon::start_with("eos-udp", &extra);
    set_a_look(&mut d);
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
        if command_lines(&packets)
            .last()
            .is_some_and(|l| l.contains("Record"))
        {
            break;
        }
    }
    let lines = command_lines(&packets);
    assert_eq!(
        lines.last().unwrap(),
        "Chan 1 Thru 6 Record Preset 12 Enter"
    );
    assert_eq!(lines.len(), 6 + 4 + 1, "{lines:?}");

    // A console that is not listening: a clear error, nothing changes.
    let closed = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let extra = format!("\n[eos]\naddress = \"{closed}\"\nprotocol = \"tcp\"\n");
    let mut d = Daemon::start_with("eos-closed", &extra);
    d.refused("/vo/eos/preset", vec![int(1)]);
}
