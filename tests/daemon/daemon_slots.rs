//! Connection slots a hostile host cannot starve (issue 30): the web page's connections and
//! event streams, the OSC TCP connections and subscriptions are shared out by host, the
//! configured backup and consoles always get in, and the real sockets of one host (every
//! loopback address is one, for the page) never lock the others out.

use std::io::{ErrorKind, Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream, UdpSocket};
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{
    Daemon, LOCALHOST, Osc, PATIENCE, Setup, TcpFraming, connect_from, float, int, string, text,
};

fn ip(s: &str) -> IpAddr {
    s.parse().expect("an address")
}

/// Whether the daemon has closed `s` (EOF or reset), waiting at most `wait` for it.
fn closed_within(s: &mut TcpStream, wait: Duration) -> bool {
    let end = Instant::now() + wait;
    let mut buf = [0u8; 4096];
    loop {
        let left = end.saturating_duration_since(Instant::now());
        s.set_read_timeout(Some(left.max(Duration::from_millis(1))))
            .expect("timeout");
        match s.read(&mut buf) {
            Ok(0) => return true,
            Ok(_) => {}
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => return true,
        }
        if Instant::now() >= end {
            return false;
        }
    }
}

/// Waits (bounded) until at most `most` of `streams` are still open; returns which are.
fn settle_open(streams: &mut [TcpStream], most: usize) -> Vec<usize> {
    let end = Instant::now() + PATIENCE;
    loop {
        let open: Vec<usize> = (0..streams.len())
            .filter(|&i| !closed_within(&mut streams[i], Duration::from_millis(1)))
            .collect();
        if open.len() <= most || Instant::now() > end {
            return open;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Opens the page's event stream on a new connection: the answer's status (0: closed).
fn event_stream(addr: SocketAddr) -> (TcpStream, u16) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let request = format!("GET /events HTTP/1.1\r\nHost: {addr}\r\n\r\n");
    let _ = s.write_all(request.as_bytes());
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        match s.read(&mut byte) {
            Ok(1) => head.push(byte[0]),
            _ => return (s, 0),
        }
    }
    let status = String::from_utf8_lossy(&head)
        .split(' ')
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    (s, status)
}

#[test]
fn forty_event_streams_from_one_host_leave_the_page_to_a_browser() {
    let (d, addr) = common::http::start("slots-streams");
    // Forty event streams from one host (every loopback address is one): each is answered,
    // and the host keeps its newest four; the older ones are closed for them.
    let mut streams = Vec::new();
    for i in 0..40 {
        let (s, status) = event_stream(addr);
        assert_eq!(status, 200, "event stream {i} was not answered");
        streams.push(s);
    }
    let open = settle_open(&mut streams, 4);
    assert_eq!(open, [36, 37, 38, 39], "the newest four stay open");
    // A browser on that host still gets the page, its state and the references.
    let page = common::http::get(addr, "/");
    assert_eq!(page.status, 200);
    assert!(String::from_utf8_lossy(&page.body).contains("<html"));
    assert_eq!(common::http::get(addr, "/state.json").status, 200);
    // And its own event stream: the oldest of the four gives way.
    let (_mine, status) = event_stream(addr);
    assert_eq!(status, 200);
    let open = settle_open(&mut streams, 3);
    assert_eq!(open, [37, 38, 39]);
    drop(d);
}

/// A ping over a new TCP connection from `from`: the connection, kept open, if the ping
/// was answered; `None` if the daemon closed it.
fn ping_from(d: &Daemon, from: IpAddr) -> Option<TcpStream> {
    let mut s = connect_from(from, d.tcp_addr()).ok()?;
    let ping = rosc::encoder::encode(&common::daemon::msg("/vo/ping", vec![string("hi")]))
        .expect("encode");
    let mut frame = (ping.len() as u32).to_be_bytes().to_vec();
    frame.extend(ping);
    s.write_all(&frame).ok()?;
    s.set_read_timeout(Some(PATIENCE)).expect("timeout");
    let mut len = [0u8; 4];
    s.read_exact(&mut len).ok()?;
    let mut pong = vec![0u8; u32::from_be_bytes(len) as usize];
    s.read_exact(&mut pong).ok()?;
    Some(s)
}

#[test]
fn idle_tcp_connections_from_one_host_leave_room_for_another() {
    let d = Daemon::start("slots-tcp-idle");
    // 64 idle connections from 127.0.0.1 (the old limit of every host together): it keeps
    // its newest eight; the older ones are closed, each for a newer one of its own.
    let mut idle: Vec<TcpStream> = (0..64)
        .map(|_| connect_from(LOCALHOST, d.tcp_addr()).expect("connect"))
        .collect();
    let open = settle_open(&mut idle, 8);
    assert_eq!(
        open,
        (56..64).collect::<Vec<_>>(),
        "the newest eight stay open"
    );
    // Another host (as a backup would connect) is answered at once, and so is a ninth
    // connection of the first host (its oldest idle one gives way).
    assert!(
        ping_from(&d, ip("127.0.0.2")).is_some(),
        "127.0.0.2 was shut out"
    );
    assert!(ping_from(&d, LOCALHOST).is_some(), "127.0.0.1 was shut out");
}

#[test]
fn the_backup_and_a_console_always_get_a_slot() {
    let setup = Setup {
        extra: "\n[[osc.peer]]\nname = \"eos\"\naddress = \"127.0.0.4\"\nreply_port = 9000\nframing = \"udp\"\n"
            .into(),
        ..Setup::default()
    };
    let mut d = Daemon::start_setup("slots-reserved", setup);
    // The main knows its backup's address (osc.backups).
    let config = d.config_path().to_path_buf();
    let text = std::fs::read_to_string(&config).expect("config");
    std::fs::write(
        &config,
        text.replacen("[osc]\n", "[osc]\nbackups = [\"127.0.0.3\"]\n", 1),
    )
    .expect("write");
    d.terminate();
    d.restart();
    // The backup connects first and idles: the oldest idle connection of all.
    let mut backup = d.tcp_from(ip("127.0.0.3"), TcpFraming::LengthPrefix);
    backup.ok("/vo/ping", vec![string("backup")], "/vo/pong");
    let _console = d.tcp_from(ip("127.0.0.4"), TcpFraming::LengthPrefix);
    // 62 hosts with one connection each fill the other slots (64 in all).
    let mut others: Vec<TcpStream> = (1..=62)
        .map(|i| connect_from(ip(&format!("127.0.1.{i}")), d.tcp_addr()).expect("connect"))
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    assert!(
        settle_open(&mut others, 62).len() == 62,
        "all 64 slots are taken"
    );
    // Every host has one: a second connection from one of them is refused...
    assert!(
        ping_from(&d, ip("127.0.1.1")).is_none(),
        "a second connection was let in"
    );
    // ...but the console's second is let in, closing the oldest idle one of another host
    // (127.0.1.1's: the backup's is older, but a backup's is never closed for another);
    let _console_again = ping_from(&d, ip("127.0.0.4")).expect("the console was shut out");
    let open = settle_open(&mut others, 61);
    assert_eq!(open, (1..62).collect::<Vec<_>>(), "127.0.1.1 made room");
    // and a new host is let in the same way, never closing the backup's connection.
    let _new = ping_from(&d, ip("127.0.2.1")).expect("a new host was shut out");
    let open = settle_open(&mut others, 60);
    assert_eq!(open, (2..62).collect::<Vec<_>>(), "127.0.1.2 made room");
    let r = backup.ok("/vo/ping", vec![string("still")], "/vo/pong");
    assert_eq!(r.args, [string("still")]);
    assert!(
        d.log_text().contains("127.0.1.1:") && d.log_text().contains("closed"),
        "the refusal is logged:\n{}",
        d.log_text()
    );
}

/// Ports pushes may go to without reaching another test's socket: outside the range the
/// harness picks daemons' ports from (20000..32000), the kernel's ephemeral range
/// (32768..60999) and the DMX ports.
fn quiet_ports() -> impl Iterator<Item = u16> {
    (1024..5000).chain(7000..20000).chain(61000..=65535)
}

#[test]
fn twenty_thousand_subscriptions_from_one_host_leave_eight() {
    let d = Daemon::start("slots-subscribe");
    // From an address no other test uses, so pushes to its ports reach nobody else.
    let host = ip("127.0.0.77");
    let mut t = d.tcp_from(host, TcpFraming::LengthPrefix);
    let listeners: Vec<UdpSocket> = (0..16)
        .map(|_| UdpSocket::bind((host, 0)).expect("bind a subscriber"))
        .collect();
    let ports: Vec<u16> = quiet_ports()
        .take(20_000 - listeners.len())
        .chain(
            listeners
                .iter()
                .map(|l| l.local_addr().expect("addr").port()),
        )
        .collect();
    let started = Instant::now();
    let mut notes = Vec::new();
    for batch in ports.chunks(500) {
        for &port in batch {
            t.send("/vo/subscribe", vec![int(i32::from(port))]);
        }
        t.send("/vo/ping", vec![string("batch")]);
        let got = t.collect("/vo/pong", Duration::from_secs(60), "a batch of subscribes");
        let subscribed = got.iter().filter(|m| m.addr == "/vo/subscribed").count();
        assert_eq!(subscribed, batch.len(), "{:?}", got.last());
        notes.extend(got.into_iter().filter(|m| m.addr == "/vo/note"));
    }
    println!("20,000 subscribes in {:?}", started.elapsed());
    // The ninth and every later one is answered with a sentence naming the one it ended.
    assert_eq!(notes.len(), 20_000 - 8);
    let first = text(&notes[0].args[0]);
    assert!(
        first.contains("at most 8 subscriptions")
            && first.contains(&format!("{host}:{}", ports[0])),
        "{first}"
    );
    // A change is pushed to the newest eight alone.
    for l in &listeners {
        l.set_read_timeout(Some(Duration::from_millis(50)))
            .expect("timeout");
        let mut buf = [0u8; 65536];
        while l.recv(&mut buf).is_ok() {}
    }
    let sent = Instant::now();
    t.ok("/vo/master", vec![float(0.5)], "/vo/master");
    println!("a fader's answer in {:?}", sent.elapsed());
    let pushed: Vec<bool> = listeners
        .iter()
        .map(|l| {
            l.set_read_timeout(Some(Duration::from_millis(300)))
                .expect("timeout");
            l.recv(&mut [0u8; 65536]).is_ok()
        })
        .collect();
    let want: Vec<bool> = (0..16).map(|i| i >= 8).collect();
    assert_eq!(pushed, want, "pushed to the newest eight only");
}
