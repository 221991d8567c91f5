//! The allow-list (docs/osc.md, docs/security.md) against the real daemon. Loopback has all
//! of 127.0.0.0/8 and ::1, so a config that admits 127.0.0.2 (or ::1) and not 127.0.0.1
//! gives an allowed and a refused sender on one machine. Refused senders get nothing back
//! (no amplification), change nothing, and are counted in the log at most once per 10 s.

use std::io::{ErrorKind, Read, Write};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

use crate::common::daemon::{
    Daemon, LOCALHOST, Osc, PATIENCE, Setup, TcpFraming, connect_from, int, msg, string,
};

const SECOND: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));
const V6: IpAddr = IpAddr::V6(Ipv6Addr::LOCALHOST);

/// Log lines that report refused senders.
fn refusal_lines(d: &Daemon) -> Vec<String> {
    d.log_text()
        .lines()
        .filter(|l| l.contains("not in osc.allow"))
        .map(str::to_string)
        .collect()
}

/// Whether a TCP connection from `ip` is closed without a byte of reply to a ping.
fn tcp_refused(d: &Daemon, ip: IpAddr) -> bool {
    let Ok(mut s) = connect_from(ip, d.tcp_addr()) else {
        return true;
    };
    s.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let ping = rosc::encoder::encode(&msg("/vo/ping", vec![int(1)])).expect("encode");
    let mut framed = (ping.len() as u32).to_be_bytes().to_vec();
    framed.extend(ping);
    // The daemon may already have closed it: a failed write is a refusal too.
    let _ = s.write_all(&framed);
    let mut buf = [0u8; 64];
    match s.read(&mut buf) {
        Ok(0) => true,
        Ok(n) => panic!("a refused connection got {n} bytes"),
        Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
            panic!("a refused connection was left open")
        }
        Err(_) => true,
    }
}

#[test]
fn senders_outside_the_allow_list_get_nothing_and_change_nothing() {
    let mut d = Daemon::start_setup(
        "access-v4",
        Setup {
            allow: vec!["127.0.0.2/32".into(), "::1".into()],
            client: SECOND,
            ..Setup::default()
        },
    );
    // Allowed: UDP and TCP from 127.0.0.2.
    let r = d.ok("/vo/ping", vec![string("in")], "/vo/pong");
    assert_eq!(r.args, [string("in")]);
    let mut t = d.tcp_from(SECOND, TcpFraming::Slip);
    t.ok("/vo/ping", vec![int(2)], "/vo/pong");

    // Refused: 127.0.0.1, with everything that would be answered, large answers included,
    // and what would change the stage.
    let before = d.snapshot();
    let mut outsider = d.client_from(LOCALHOST);
    let packets: Vec<Vec<u8>> = [
        msg("/vo/light/1/level", vec![int(90)]),
        msg("/vo/live", vec![]),
        msg("/vo/subscribe", vec![]),
        msg("/vo/look/save", vec![int(5)]),
        msg("/vo/nonsense", vec![]),
    ]
    .iter()
    .map(|p| rosc::encoder::encode(p).expect("encode"))
    .chain([b"not OSC at all".to_vec()])
    .collect();
    for i in 0..240 {
        outsider.send_raw(&packets[i % packets.len()]);
    }
    assert!(tcp_refused(&d, LOCALHOST), "TCP from 127.0.0.1");
    // One UDP socket, handled in arrival order: after the allowed client's fence every
    // refused datagram has been seen.
    assert!(d.fence().is_empty());
    assert_eq!(
        outsider.next(std::time::Duration::from_millis(1)),
        None,
        "a refused sender was answered"
    );
    assert_eq!(d.snapshot(), before, "a refused sender changed something");
    // Counted, rate-limited: a single line for the whole burst.
    let lines = refusal_lines(&d);
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(lines[0].contains("127.0.0.1"), "{lines:?}");
}

#[test]
fn ipv6_addresses_and_blocks_are_checked_too() {
    // TCP on ::1, UDP (the harness's own client) on 127.0.0.1 from 127.0.0.2.
    let setup = |allow: &[&str]| Setup {
        tcp: V6,
        allow: allow.iter().map(|a| a.to_string()).collect(),
        client: SECOND,
        ..Setup::default()
    };
    let d = Daemon::start_setup("access-v6-in", setup(&["127.0.0.2", "::1/128"]));
    let mut t = d.tcp_from(V6, TcpFraming::LengthPrefix);
    let r = t.ok("/vo/ping", vec![string("v6")], "/vo/pong");
    assert_eq!(r.args, [string("v6")]);
    drop(d);

    let mut d = Daemon::start_setup("access-v6-out", setup(&["127.0.0.2", "fd00::/8"]));
    assert!(tcp_refused(&d, V6), "TCP from ::1 outside fd00::/8");
    assert!(d.fence().is_empty());
    let lines = refusal_lines(&d);
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(lines[0].contains("::1"), "{lines:?}");
}
