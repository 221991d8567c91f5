//! The OSC transport over real loopback sockets: a test handler behind the server, clients
//! speaking UDP, TCP with a length prefix and TCP with SLIP, the `visobjd send` binary, and
//! python-osc as an independent peer.

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};
use visobjd::config::OscConfig;
use visobjd::osc::args::Request;
use visobjd::osc::framing::{self, Decoder, Framing, StreamFrame};
use visobjd::osc::{Handler, Limits, Peer, Server, Transport};
use visobjd_testkit::tools;

const PATIENCE: Duration = Duration::from_secs(5);
/// How long "nothing arrives" is watched for, after a later probe has already come back.
const QUIET: Duration = Duration::from_millis(150);

/// Echoes `/echo`, answers `/late` from another thread, floods with `/flood n`, panics on
/// `/panic`, answers `/vo/generate`; anything else is an unknown address.
#[derive(Default)]
struct TestHandler {
    seen: Mutex<Vec<Request>>,
}

impl TestHandler {
    fn seen(&self) -> Vec<String> {
        let seen = self.seen.lock().unwrap();
        seen.iter().map(|m| m.addr.clone()).collect()
    }
}

fn msg(addr: &str, args: Vec<OscType>) -> OscMessage {
    OscMessage {
        addr: addr.into(),
        args,
    }
}

impl Handler for TestHandler {
    fn handle(&self, m: Request, peer: &Peer) -> Vec<OscMessage> {
        self.seen.lock().unwrap().push(m.clone());
        match m.addr.to_lowercase().as_str() {
            "/echo" => vec![msg("/echo", m.args().to_vec())],
            "/vo/generate" => vec![msg("/vo/generated", vec![])],
            "/transport" => vec![msg(
                "/transport",
                vec![OscType::String(format!("{:?}", peer.transport()))],
            )],
            "/late" => {
                let peer = peer.clone();
                std::thread::spawn(move || peer.reply(&[msg("/late", vec![])]));
                vec![]
            }
            "/flood" => {
                let n = m.args().first().and_then(|a| a.clone().int()).unwrap_or(0);
                let ok = (0..n).all(|i| peer.reply(&[msg("/flood", vec![OscType::Int(i)])]));
                vec![msg("/flooded", vec![OscType::Bool(ok)])]
            }
            "/panic" => panic!("the test handler was asked to panic"),
            // Stands in for a handler waiting on a slow disk.
            "/slow" => {
                std::thread::sleep(Duration::from_millis(300));
                vec![msg("/slow", vec![])]
            }
            _ => vec![msg(
                "/vo/error",
                vec![
                    OscType::String(m.addr),
                    OscType::String("unknown address".into()),
                ],
            )],
        }
    }
}

/// A server on loopback port 0 with its runtime; the server drops first.
struct Harness {
    server: Server,
    handler: Arc<TestHandler>,
    _rt: tokio::runtime::Runtime,
}

fn loopback() -> OscConfig {
    OscConfig {
        udp: "127.0.0.1:0".into(),
        tcp: "127.0.0.1:0".into(),
        reply_port: 0,
        allow: vec![],
        peer: vec![],
        backups: vec![],
    }
}

fn serve_with(config: OscConfig, limits: Limits) -> Harness {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let handler = Arc::new(TestHandler::default());
    let server = {
        let _ctx = rt.enter();
        Server::start_with_limits(&config, handler.clone(), limits).unwrap()
    };
    Harness {
        server,
        handler,
        _rt: rt,
    }
}

fn serve() -> Harness {
    serve_with(loopback(), Limits::default())
}

impl Harness {
    fn udp(&self) -> SocketAddr {
        self.server.udp_addr().unwrap()
    }
    fn tcp(&self) -> SocketAddr {
        self.server.tcp_addr().unwrap()
    }
}

fn encode(p: &OscPacket) -> Vec<u8> {
    rosc::encoder::encode(p).unwrap()
}

fn echo(i: i32) -> OscPacket {
    OscPacket::Message(msg("/echo", vec![OscType::Int(i)]))
}

fn bundle(content: Vec<OscPacket>) -> OscPacket {
    OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content,
    })
}

fn udp_client() -> UdpSocket {
    udp_client_from("127.0.0.1")
}

/// A UDP client on `ip` (any loopback address: another host to the server).
fn udp_client_from(ip: &str) -> UdpSocket {
    let s = UdpSocket::bind((ip, 0)).unwrap();
    s.set_read_timeout(Some(PATIENCE)).unwrap();
    s
}

/// The next datagram's message (panics after PATIENCE).
fn recv(s: &UdpSocket) -> OscMessage {
    let mut buf = [0u8; 65536];
    let (n, _) = s.recv_from(&mut buf).expect("a reply");
    match rosc::decoder::decode_udp(&buf[..n]).unwrap().1 {
        OscPacket::Message(m) => m,
        OscPacket::Bundle(b) => panic!("replies are messages, got {b:?}"),
    }
}

fn nothing_arrives(s: &UdpSocket) {
    s.set_read_timeout(Some(QUIET)).unwrap();
    let mut buf = [0u8; 65536];
    let got = s.recv_from(&mut buf);
    assert!(got.is_err(), "expected nothing, got {got:?}");
    s.set_read_timeout(Some(PATIENCE)).unwrap();
}

fn ints(m: &OscMessage) -> Vec<i32> {
    m.args.iter().filter_map(|a| a.clone().int()).collect()
}

#[test]
fn udp_message_and_bundles_in_order() {
    let h = serve();
    let c = udp_client();
    let m = msg(
        "/ECHO",
        vec![OscType::Int(1), OscType::String("a b".into())],
    );
    c.send_to(&encode(&OscPacket::Message(m)), h.udp()).unwrap();
    let r = recv(&c);
    assert_eq!(r.addr, "/echo");
    assert_eq!(r.args, [OscType::Int(1), OscType::String("a b".into())]);

    let p = bundle(vec![
        echo(1),
        echo(2),
        bundle(vec![echo(3), bundle(vec![echo(4)])]),
        echo(5),
    ]);
    c.send_to(&encode(&p), h.udp()).unwrap();
    let got: Vec<i32> = (0..5).flat_map(|_| ints(&recv(&c))).collect();
    assert_eq!(got, [1, 2, 3, 4, 5]);

    c.send_to(&encode(&OscPacket::Message(msg("/nope", vec![]))), h.udp())
        .unwrap();
    let r = recv(&c);
    assert_eq!((r.addr.as_str(), r.args.len()), ("/vo/error", 2));
}

#[test]
fn too_deep_bundles_get_an_error_and_garbage_nothing() {
    let h = serve();
    let c = udp_client();
    let nest = |levels: usize, i: i32| (0..levels).fold(echo(i), |p, _| bundle(vec![p]));
    c.send_to(&encode(&nest(8, 8)), h.udp()).unwrap();
    assert_eq!(ints(&recv(&c)), [8]);
    c.send_to(&encode(&nest(100, 9)), h.udp()).unwrap();
    let e = recv(&c);
    assert_eq!(e.addr, "/vo/error", "{e:?}");
    assert_eq!(e.args[0], OscType::String("/echo".into()));
    c.send_to(b"GET / HTTP/1.1\r\n\r\n", h.udp()).unwrap();
    c.send_to(&encode(&echo(10)), h.udp()).unwrap();
    // Datagrams are handled in order: the probe's reply comes first if nothing else did.
    assert_eq!(ints(&recv(&c)), [10]);
    nothing_arrives(&c);
    assert_eq!(h.server.not_osc(), 1);
    assert_eq!(h.handler.seen(), ["/echo", "/echo"]);
}

#[test]
fn a_slow_sender_delays_only_its_host_and_its_backlog_is_bounded() {
    let h = serve_with(
        loopback(),
        Limits {
            udp_backlog: 200,
            ..Limits::default()
        },
    );
    let slow = udp_client();
    let quick = udp_client_from("127.0.0.2");
    slow.send_to(&encode(&OscPacket::Message(msg("/slow", vec![]))), h.udp())
        .unwrap();
    // Its backlog (200 bytes) holds a few messages; the rest are dropped.
    for i in 0..40 {
        slow.send_to(&encode(&echo(i)), h.udp()).unwrap();
    }
    quick.send_to(&encode(&echo(99)), h.udp()).unwrap();
    assert_eq!(ints(&recv(&quick)), [99]);
    // The quick sender was answered while the slow one still waited on its handler.
    slow.set_read_timeout(Some(Duration::from_millis(1)))
        .unwrap();
    let mut buf = [0u8; 1024];
    assert!(slow.recv(&mut buf).is_err(), "the slow reply came first");
    slow.set_read_timeout(Some(PATIENCE)).unwrap();
    assert_eq!(recv(&slow).addr, "/slow");
    // The quick reply came after the server had taken in all 40 (they were queued before
    // it): those over the backlog were dropped and counted, the rest answer in order.
    let kept = 40 - h.server.dropped() as usize;
    assert!(kept > 0 && kept < 40, "{kept} of 40 kept");
    let got: Vec<i32> = (0..kept).map(|_| ints(&recv(&slow))[0]).collect();
    assert!(got.windows(2).all(|w| w[0] < w[1]), "in order: {got:?}");
    // Nothing more: the next reply is that of a fence sent now (the backlog is empty).
    slow.send_to(&encode(&echo(1000)), h.udp()).unwrap();
    assert_eq!(ints(&recv(&slow)), [1000]);
}

#[test]
fn one_hosts_ports_take_one_senders_place_and_share_its_budget() {
    // Places for three sending hosts, four ports of one host served at once, 4 KiB
    // waiting per host.
    let h = serve_with(
        loopback(),
        Limits {
            udp_senders: 3,
            per_host: 4,
            udp_backlog: 4096,
            ..Limits::default()
        },
    );
    let slow = || encode(&OscPacket::Message(msg("/slow", vec![])));
    // One host sends from four ports, each message waiting on its handler: counted by
    // port, they would take every place and lose one.
    let ports: Vec<UdpSocket> = (0..4).map(|_| udp_client()).collect();
    for p in &ports {
        p.send_to(&slow(), h.udp()).unwrap();
    }
    std::thread::sleep(Duration::from_millis(50));
    // A fifth port of that host waits for one of the four: its datagram is dropped.
    let fifth = udp_client();
    fifth.send_to(&encode(&echo(5)), h.udp()).unwrap();
    // The other hosts are answered while the four wait: before any of their replies.
    for other in ["127.0.0.2", "127.0.0.3"] {
        let c = udp_client_from(other);
        c.send_to(&encode(&echo(7)), h.udp()).unwrap();
        assert_eq!(ints(&recv(&c)), [7], "{other} was answered");
    }
    let mut buf = [0u8; 1024];
    for p in &ports {
        p.set_read_timeout(Some(Duration::from_millis(1))).unwrap();
        assert!(p.recv(&mut buf).is_err(), "a slow reply came first");
        p.set_read_timeout(Some(PATIENCE)).unwrap();
    }
    for p in &ports {
        assert_eq!(recv(p).addr, "/slow");
    }
    nothing_arrives(&fifth);
    assert_eq!(h.server.dropped(), 1);
    // Its ports share one backlog: of 8 KiB of echoes sent from the four while they wait,
    // at most 4 KiB are kept, whichever ports they came from.
    for p in &ports {
        p.send_to(&slow(), h.udp()).unwrap();
    }
    std::thread::sleep(Duration::from_millis(50));
    let size = encode(&echo(0)).len();
    let sent = 2 * 4096 / size;
    for i in 0..sent {
        ports[i % 4]
            .send_to(&encode(&echo(i as i32)), h.udp())
            .unwrap();
    }
    let mut kept = 0;
    for p in &ports {
        assert_eq!(recv(p).addr, "/slow");
        p.set_read_timeout(Some(QUIET)).unwrap();
        let mut buf = [0u8; 1024];
        while p.recv(&mut buf).is_ok() {
            kept += 1;
        }
    }
    assert_eq!(kept, sent - (h.server.dropped() as usize - 1));
    assert!(kept > 0 && kept * size <= 4096, "{kept} of {sent} kept");
}

#[test]
fn button_releases_are_ignored() {
    let h = serve();
    let c = udp_client();
    c.send_to(
        &encode(&OscPacket::Message(msg(
            "/vo/generate",
            vec![OscType::Float(0.0)],
        ))),
        h.udp(),
    )
    .unwrap();
    c.send_to(
        &encode(&OscPacket::Message(msg("/vo/Generate/0", vec![]))),
        h.udp(),
    )
    .unwrap();
    c.send_to(
        &encode(&OscPacket::Message(msg(
            "/vo/generate",
            vec![OscType::Float(1.0)],
        ))),
        h.udp(),
    )
    .unwrap();
    assert_eq!(recv(&c).addr, "/vo/generated");
    nothing_arrives(&c);
    assert_eq!(h.handler.seen(), ["/vo/generate"]);
}

#[test]
fn a_handler_panic_is_answered_with_an_error() {
    let h = serve();
    let c = udp_client();
    c.send_to(&encode(&OscPacket::Message(msg("/panic", vec![]))), h.udp())
        .unwrap();
    let r = recv(&c);
    assert_eq!(r.addr, "/vo/error");
    assert_eq!(r.args[0], OscType::String("/panic".into()));
    // The listener survived.
    c.send_to(&encode(&echo(1)), h.udp()).unwrap();
    assert_eq!(ints(&recv(&c)), [1]);
}

#[test]
fn reply_port_routes_udp_replies() {
    let listener = udp_client();
    let port = listener.local_addr().unwrap().port();
    let h = serve_with(
        OscConfig {
            reply_port: port,
            ..loopback()
        },
        Limits::default(),
    );
    let c = udp_client();
    c.send_to(&encode(&echo(7)), h.udp()).unwrap();
    c.send_to(&encode(&OscPacket::Message(msg("/late", vec![]))), h.udp())
        .unwrap();
    let mut buf = [0u8; 1024];
    let (n, from) = listener.recv_from(&mut buf).unwrap();
    assert_eq!(from, h.udp(), "replies leave from the port clients talk to");
    assert_eq!(rosc::decoder::decode_udp(&buf[..n]).unwrap().1, echo(7));
    assert_eq!(recv(&listener).addr, "/late");
    nothing_arrives(&c);
}

#[test]
fn late_replies_and_pushes_over_udp() {
    let h = serve();
    let c = udp_client();
    c.send_to(&encode(&OscPacket::Message(msg("/late", vec![]))), h.udp())
        .unwrap();
    assert_eq!(recv(&c).addr, "/late");
    let sender = h.server.sender().unwrap();
    sender
        .send(c.local_addr().unwrap(), &msg("/vo/status", vec![]))
        .unwrap();
    let mut buf = [0u8; 1024];
    let (_, from) = c.recv_from(&mut buf).unwrap();
    assert_eq!(from, h.udp());
}

#[test]
fn senders_outside_the_allow_list_get_nothing() {
    let h = serve_with(
        OscConfig {
            allow: vec!["10.9.9.9".into()],
            ..loopback()
        },
        Limits::default(),
    );
    let c = udp_client();
    c.send_to(&encode(&echo(1)), h.udp()).unwrap();
    let mut t = TcpStream::connect(h.tcp()).unwrap();
    t.set_read_timeout(Some(PATIENCE)).unwrap();
    // The refused connection is closed at once (EOF or reset), without a byte sent.
    let _ = t.write_all(&framing::encode(Framing::LengthPrefix, &encode(&echo(2))));
    let mut buf = [0u8; 64];
    assert!(matches!(t.read(&mut buf), Ok(0) | Err(_)));
    let deadline = Instant::now() + PATIENCE;
    while h.server.refused() < 2 {
        assert!(Instant::now() < deadline, "refusals not counted");
        std::thread::yield_now();
    }
    nothing_arrives(&c);
    assert!(h.handler.seen().is_empty());
}

#[test]
fn udp_on_ipv6_loopback() {
    if UdpSocket::bind("[::1]:0").is_err() {
        return tools::missing(
            "IPv6 loopback (::1)",
            "is not available",
            "sysctl -w net.ipv6.conf.lo.disable_ipv6=0",
        );
    }
    let h = serve_with(
        OscConfig {
            udp: "[::1]:0".into(),
            tcp: String::new(),
            ..loopback()
        },
        Limits::default(),
    );
    assert!(h.server.tcp_addr().is_none());
    let c = UdpSocket::bind("[::1]:0").unwrap();
    c.set_read_timeout(Some(PATIENCE)).unwrap();
    c.send_to(&encode(&echo(6)), h.udp()).unwrap();
    assert_eq!(ints(&recv(&c)), [6]);
}

/// A TCP client reading whole frames.
struct Tcp {
    stream: TcpStream,
    decoder: Decoder,
    frames: Vec<StreamFrame>,
}

impl Tcp {
    fn connect(addr: SocketAddr) -> Tcp {
        let stream = TcpStream::connect(addr).unwrap();
        stream.set_read_timeout(Some(PATIENCE)).unwrap();
        stream.set_nodelay(true).unwrap();
        Tcp {
            stream,
            decoder: Decoder::default(),
            frames: Vec::new(),
        }
    }

    fn next(&mut self) -> OscMessage {
        let mut buf = [0u8; 4096];
        while self.frames.is_empty() {
            let n = self.stream.read(&mut buf).expect("a reply");
            assert!(n > 0, "closed while waiting for a reply");
            self.decoder.feed(&buf[..n], &mut self.frames);
        }
        let StreamFrame::Packet(frame) = self.frames.remove(0) else {
            panic!("replies are never over the frame limit");
        };
        match rosc::decoder::decode_udp(&frame).unwrap().1 {
            OscPacket::Message(m) => m,
            OscPacket::Bundle(b) => panic!("replies are messages, got {b:?}"),
        }
    }

    /// Waits for the server to close the connection (EOF or reset).
    fn closed(&mut self) -> bool {
        let mut buf = [0u8; 4096];
        loop {
            match self.stream.read(&mut buf) {
                Ok(0) => return true,
                Ok(_) => {}
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    return false;
                }
                Err(_) => return true,
            }
        }
    }
}

fn tcp_exchange(framing: Framing) {
    let h = serve();
    let mut t = Tcp::connect(h.tcp());
    let frame = |p: &OscPacket| framing::encode(framing, &encode(p));
    t.stream.write_all(&frame(&echo(1))).unwrap();
    assert_eq!(ints(&t.next()), [1]);
    assert_eq!(
        t.decoder.framing(),
        Some(framing),
        "replies come in the client's framing"
    );

    // Two frames in one write, then a bundle frame split over many writes.
    let mut two = frame(&echo(2));
    two.extend(frame(&echo(3)));
    t.stream.write_all(&two).unwrap();
    assert_eq!(ints(&t.next()), [2]);
    assert_eq!(ints(&t.next()), [3]);
    let split = frame(&bundle(vec![echo(4), echo(5)]));
    for piece in split.chunks(3) {
        t.stream.write_all(piece).unwrap();
        t.stream.flush().unwrap();
    }
    assert_eq!(ints(&t.next()), [4]);
    assert_eq!(ints(&t.next()), [5]);

    t.stream
        .write_all(&frame(&OscPacket::Message(msg("/transport", vec![]))))
        .unwrap();
    let want = format!("{:?}", Transport::Tcp(framing));
    assert_eq!(t.next().args, [OscType::String(want)]);
    t.stream
        .write_all(&frame(&OscPacket::Message(msg("/late", vec![]))))
        .unwrap();
    assert_eq!(t.next().addr, "/late");

    // A frame that is not OSC gets nothing; the connection stays usable.
    t.stream
        .write_all(&framing::encode(framing, b"\xc0\xdbnot osc"))
        .unwrap();
    t.stream.write_all(&frame(&echo(6))).unwrap();
    assert_eq!(ints(&t.next()), [6]);
    assert_eq!(h.server.not_osc(), 1);
}

#[test]
fn tcp_with_a_length_prefix() {
    tcp_exchange(Framing::LengthPrefix);
}

#[test]
fn tcp_with_slip() {
    tcp_exchange(Framing::Slip);
}

#[test]
fn oversize_frames_are_answered_and_skipped() {
    let limits = Limits {
        max_frame: 1024,
        ..Limits::default()
    };
    let h = serve_with(loopback(), limits);
    for framing in [Framing::LengthPrefix, Framing::Slip] {
        let mut t = Tcp::connect(h.tcp());
        let big = OscPacket::Message(msg("/big", vec![OscType::String("x".repeat(5000))]));
        t.stream
            .write_all(&framing::encode(framing, &encode(&big)))
            .unwrap();
        let e = t.next();
        assert_eq!(e.addr, "/vo/error", "{e:?}");
        assert_eq!(e.args[0], OscType::String("/big".into()));
        // The connection goes on after it.
        t.stream
            .write_all(&framing::encode(framing, &encode(&echo(7))))
            .unwrap();
        assert_eq!(ints(&t.next()), [7]);
    }
    assert!(!h.handler.seen().contains(&"/big".to_string()));
    // An oversize frame that is not OSC gets nothing.
    let mut t = Tcp::connect(h.tcp());
    let mut endless = vec![0xC0];
    endless.extend([b'x'; 2000]);
    endless.push(0xC0);
    t.stream.write_all(&endless).unwrap();
    t.stream
        .write_all(&framing::encode(Framing::Slip, &encode(&echo(8))))
        .unwrap();
    assert_eq!(ints(&t.next()), [8]);
}

#[test]
fn the_connection_cap_closes_extra_connections() {
    let h = serve_with(
        loopback(),
        Limits {
            max_connections: 2,
            ..Limits::default()
        },
    );
    let hello = framing::encode(Framing::LengthPrefix, &encode(&echo(1)));
    let mut a = Tcp::connect(h.tcp());
    let mut b = Tcp::connect(h.tcp());
    for t in [&mut a, &mut b] {
        t.stream.write_all(&hello).unwrap();
        assert_eq!(ints(&t.next()), [1]);
    }
    let mut c = Tcp::connect(h.tcp());
    let _ = c.stream.write_all(&hello);
    assert!(c.closed(), "a third connection is closed at once");
    assert_eq!(h.handler.seen().len(), 2);
    drop(a);
    // Once the server has seen the first one go, a new connection is served.
    let deadline = Instant::now() + PATIENCE;
    loop {
        let mut d = Tcp::connect(h.tcp());
        let _ = d.stream.write_all(&hello);
        if !d.closed_before_reply() {
            break;
        }
        assert!(Instant::now() < deadline, "the freed slot was never reused");
    }
}

impl Tcp {
    /// True if the server closed the connection instead of answering.
    fn closed_before_reply(&mut self) -> bool {
        let mut buf = [0u8; 4096];
        loop {
            match self.stream.read(&mut buf) {
                Ok(0) | Err(_) => return true,
                Ok(n) => {
                    self.decoder.feed(&buf[..n], &mut self.frames);
                    if !self.frames.is_empty() {
                        return false;
                    }
                }
            }
        }
    }
}

#[test]
fn idle_connections_are_closed() {
    let idle = Duration::from_millis(300);
    let h = serve_with(
        loopback(),
        Limits {
            idle_timeout: idle,
            ..Limits::default()
        },
    );
    let start = Instant::now();
    let mut t = Tcp::connect(h.tcp());
    // Half a length prefix is not a frame: it does not keep the connection alive.
    t.stream.write_all(&[0, 0]).unwrap();
    assert!(t.closed());
    assert!(
        start.elapsed() >= idle,
        "closed after {:?}",
        start.elapsed()
    );
}

#[test]
fn a_client_that_does_not_keep_up_is_dropped_alone() {
    let h = serve_with(
        loopback(),
        Limits {
            reply_queue: 4,
            ..Limits::default()
        },
    );
    let frame = |p: &OscPacket| framing::encode(Framing::LengthPrefix, &encode(p));
    let mut slow = Tcp::connect(h.tcp());
    let flood = OscPacket::Message(msg("/flood", vec![OscType::Int(100)]));
    slow.stream.write_all(&frame(&flood)).unwrap();
    assert!(slow.closed(), "the overflowing connection is dropped");
    let mut other = Tcp::connect(h.tcp());
    other.stream.write_all(&frame(&echo(1))).unwrap();
    assert_eq!(ints(&other.next()), [1]);
}

#[test]
fn bind_errors_name_the_address_and_stop_frees_the_port() {
    let taken = UdpSocket::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let _ctx = rt.enter();
    let config = OscConfig {
        udp: addr.to_string(),
        tcp: String::new(),
        ..loopback()
    };
    let err = Server::start(&config, Arc::new(TestHandler::default()))
        .err()
        .expect("the port is taken");
    assert_eq!(err, format!("osc.udp {addr}: address already in use"));

    let config = OscConfig {
        udp: String::new(),
        tcp: "127.0.0.1:0".into(),
        ..loopback()
    };
    let server = Server::start(&config, Arc::new(TestHandler::default())).unwrap();
    let tcp = server.tcp_addr().unwrap();
    rt.block_on(server.stop());
    TcpListener::bind(tcp).expect("the port is free after stop");

    let bad = OscConfig {
        udp: "nowhere".into(),
        ..loopback()
    };
    let err = Server::start(&bad, Arc::new(TestHandler::default()))
        .err()
        .unwrap();
    assert!(err.starts_with("osc.udp `nowhere`"), "{err}");
}

fn send(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_visobjd"))
        .arg("send")
        .args(args)
        .output()
        .expect("run visobjd send")
}

#[test]
fn send_over_udp() {
    let h = serve();
    let to = h.udp().to_string();
    let out = send(&["--to", &to, "/echo", "1", "-2.5", "two words", "x"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "/echo 1 -2.5 \"two words\" x\n"
    );
    let out = send(&["--to", &to, "-s", "/echo", "1"]);
    assert_eq!(String::from_utf8_lossy(&out.stdout), "/echo 1\n");
    let seen = h.handler.seen.lock().unwrap();
    assert_eq!(seen[1].args(), [OscType::String("1".into())]);
}

#[test]
fn send_over_tcp_in_both_framings() {
    let h = serve();
    let to = h.tcp().to_string();
    for extra in [&["--tcp"][..], &["--slip"][..], &["--tcp", "--slip"][..]] {
        let mut args = vec!["--to", to.as_str()];
        args.extend(extra);
        args.extend(["/echo", "3"]);
        let out = send(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            String::from_utf8_lossy(&out.stdout),
            "/echo 3\n",
            "{extra:?}"
        );
    }
}

#[test]
fn send_reports_errors_in_one_line() {
    let closed = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .to_string();
    for (args, needle) in [
        (
            vec!["--to", closed.as_str(), "--tcp", "/vo/ping"],
            "cannot connect",
        ),
        (
            vec!["--to", closed.as_str(), "vo/ping"],
            "must start with /",
        ),
        (vec!["--to", "nowhere", "/vo/ping"], "HOST:PORT"),
    ] {
        let out = send(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} should fail");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(needle), "`{needle}` not in {err}");
    }
    // UDP with nobody listening, not waiting for a reply: sent, success, no output.
    let out = send(&["--to", closed.as_str(), "--wait", "0", "/vo/ping"]);
    assert!(out.status.success());
    assert!(out.stdout.is_empty());
    // Waiting for a reply that never comes: said on stderr, with the hint, and a failure.
    let silent = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = silent.local_addr().unwrap().to_string();
    let out = send(&["--to", &to, "--wait", "0.2", "/vo/ping"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "no reply, yet success");
    assert!(
        err.contains(&format!("no reply from {to} within 0.2 s")),
        "{err}"
    );
    assert!(err.contains("--tcp"), "{err}");
    let mut buf = [0u8; 512];
    assert!(
        silent.recv(&mut buf).is_ok(),
        "the message was sent all the same"
    );
}

#[test]
fn send_sends_whole_numbers_beyond_int32_as_int64() {
    let h = serve();
    let to = h.udp().to_string();
    let out = send(&["--to", &to, "/echo", "4294967296", "7"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout), "/echo 4294967296 7\n");
    let seen = h.handler.seen.lock().unwrap();
    assert_eq!(
        seen[0].args(),
        [OscType::Long(4_294_967_296), OscType::Int(7)]
    );
}

const PYTHON_CLIENT: &str = r#"
import sys
from pythonosc.udp_client import SimpleUDPClient
from pythonosc.tcp_client import SimpleTCPClient
host, udp, tcp = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
c = SimpleUDPClient(host, udp)
c.send_message("/echo", [1, 2.5, "hi there"])
for m in c.get_messages(5):
    print("udp", m.address, m.params)
    break
for mode in ("1.0", "1.1"):
    t = SimpleTCPClient(host, tcp, mode=mode, timeout=5)
    t.send_message("/echo", [mode])
    for m in t.get_messages(5):
        print("tcp", m.address, m.params)
        break
    t.close()
"#;

#[test]
fn python_osc_talks_to_the_server() {
    if !tools::python_osc() {
        return;
    }
    let h = serve();
    let out = Command::new("python3")
        .args(["-c", PYTHON_CLIENT, "127.0.0.1"])
        .arg(h.udp().port().to_string())
        .arg(h.tcp().port().to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "udp /echo [1, 2.5, 'hi there']\ntcp /echo ['1.0']\ntcp /echo ['1.1']\n"
    );
}
