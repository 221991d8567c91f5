//! `[[osc.peer]]`: a tablet (UDP, listening on its own port, not the one it sends from) and
//! an Eos console (TCP, in either framing) each get their replies and pushes where they
//! listen. The console either has visobjd connect to its port, or opened its own
//! connection, which then carries them.

use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{Daemon, Osc, PATIENCE, Setup, TcpFraming, float, int, msg, string};
use rosc::{OscMessage, OscPacket, OscType};

const TABLET: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));
const CONSOLE: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 3));

/// A tablet: sends from one socket, listens on another (TouchOSC's send and receive ports).
struct Tablet {
    send: UdpSocket,
    listen: UdpSocket,
    daemon: SocketAddr,
}

impl Tablet {
    fn new(daemon: SocketAddr) -> Tablet {
        let listen = UdpSocket::bind((TABLET, 0)).unwrap();
        listen.set_read_timeout(Some(PATIENCE)).unwrap();
        Tablet {
            send: UdpSocket::bind((TABLET, 0)).unwrap(),
            listen,
            daemon,
        }
    }

    fn port(&self) -> u16 {
        self.listen.local_addr().unwrap().port()
    }

    fn send(&self, addr: &str, args: Vec<OscType>) {
        let bytes = rosc::encoder::encode(&msg(addr, args)).unwrap();
        self.send.send_to(&bytes, self.daemon).unwrap();
    }

    /// Messages on the listening port up to and including the first `until` `args`.
    fn until(&self, until: &str, args: &[OscType]) -> Vec<OscMessage> {
        let mut got = Vec::new();
        let mut buf = [0u8; 65536];
        loop {
            let n = self
                .listen
                .recv(&mut buf)
                .unwrap_or_else(|e| panic!("no {until} on the tablet's port: {e}; got {got:?}"));
            let (_, p) = rosc::decoder::decode_udp(&buf[..n]).unwrap();
            let OscPacket::Message(m) = p else {
                panic!("{p:?}")
            };
            let done = m.addr == until && m.args == args;
            got.push(m);
            if done {
                return got;
            }
        }
    }
}

/// Collects `tcp`'s messages up to and including `until` with `args`.
fn tcp_until(tcp: &mut impl Osc, until: &str, args: &[OscType]) -> Vec<OscMessage> {
    let end = Instant::now() + PATIENCE;
    let mut got = Vec::new();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Some(m) = tcp.next(left) {
            let done = m.addr == until && m.args == args;
            got.push(m);
            if done {
                return got;
            }
        }
    }
    panic!("no {until} {args:?} on the console's connection; got {got:?}");
}

/// Accepts the connection the daemon opens to the console, waiting at most [`PATIENCE`].
fn accept(listener: &TcpListener) -> TcpStream {
    listener.set_nonblocking(true).unwrap();
    let end = Instant::now() + PATIENCE;
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                stream.set_nonblocking(false).unwrap();
                return stream;
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                assert!(Instant::now() < end, "the daemon never connected");
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => panic!("accept: {e}"),
        }
    }
}

fn peers(tablet_port: u16, console_port: u16, framing: &str) -> String {
    format!(
        "\n[[osc.peer]]\nname = \"tablet\"\naddress = \"{TABLET}\"\nreply_port = {tablet_port}\nframing = \"udp\"\n\
         \n[[osc.peer]]\nname = \"eos\"\naddress = \"{CONSOLE}\"\nreply_port = {console_port}\nframing = \"{framing}\"\n"
    )
}

#[test]
fn a_tablet_and_a_tcp_console_each_get_replies_and_pushes_where_they_listen() {
    for (framing, theirs) in [
        ("tcp", TcpFraming::LengthPrefix),
        ("slip", TcpFraming::Slip),
    ] {
        let console_listen = TcpListener::bind((CONSOLE, 0)).unwrap();
        let console_port = console_listen.local_addr().unwrap().port();
        // The tablet's listening port must be known before the daemon starts.
        let probe = Tablet::new("127.0.0.1:9".parse().unwrap());
        let d = Daemon::start_setup(
            &format!("peers-{framing}"),
            Setup {
                extra: peers(probe.port(), console_port, framing),
                ..Setup::default()
            },
        );
        let tablet = Tablet {
            daemon: SocketAddr::new(d.setup.udp, d.port),
            ..probe
        };

        // The tablet's reply comes to its listening port, not the one it sent from.
        tablet.send("/vo/ping", vec![string("tablet")]);
        tablet.until("/vo/pong", &[string("tablet")]);

        // Eos sends over UDP and wants its answers on TCP: the daemon connects to it.
        let console = UdpSocket::bind((CONSOLE, 0)).unwrap();
        let to_daemon = |addr: &str, args: Vec<OscType>| {
            let bytes = rosc::encoder::encode(&msg(addr, args)).unwrap();
            console.send_to(&bytes, (d.setup.udp, d.port)).unwrap();
        };
        to_daemon("/vo/ping", vec![string("console")]);
        let mut link = d.tcp_accepted(accept(&console_listen), theirs);
        tcp_until(&mut link, "/vo/pong", &[string("console")]);

        // Both subscribe; the state and the reply come where each listens.
        to_daemon("/vo/subscribe", vec![]);
        let got = tcp_until(&mut link, "/vo/subscribed", &[int(i32::from(console_port))]);
        assert!(got.iter().any(|m| m.addr == "/vo/status"), "{got:?}");
        tablet.send("/vo/subscribe", vec![]);
        let got = tablet.until("/vo/subscribed", &[int(i32::from(tablet.port()))]);
        assert!(got.iter().any(|m| m.addr == "/vo/status"), "{got:?}");

        // A change from the tablet: its reply and the push on its port, the push to the
        // console.
        tablet.send("/vo/fade", vec![float(3.0)]);
        tablet.until("/vo/fade", &[float(3.0)]);
        tcp_until(&mut link, "/vo/fade", &[float(3.0)]);

        // A change from the console: pushed to the tablet.
        to_daemon("/vo/master", vec![float(0.5)]);
        tcp_until(&mut link, "/vo/master", &[float(0.5)]);
        tablet.until("/vo/master", &[float(0.5)]);
        // A sender without an entry keeps the old rule: replies to its source port.
        let mut other = d.client();
        other.ok("/vo/fade", vec![float(1.0)], "/vo/fade");
    }
}

#[test]
fn a_console_that_opened_its_own_connection_gets_everything_on_it() {
    // reply_port 9 (discard): nothing listens there, so anything arriving must have come
    // on the console's own connection.
    let probe = Tablet::new("127.0.0.1:9".parse().unwrap());
    let d = Daemon::start_setup(
        "peers-own",
        Setup {
            extra: peers(probe.port(), 9, "slip"),
            ..Setup::default()
        },
    );
    let tablet = Tablet {
        daemon: SocketAddr::new(d.setup.udp, d.port),
        ..probe
    };
    let mut console = d.tcp_from(CONSOLE, TcpFraming::Slip);
    console.send("/vo/subscribe", vec![]);
    let got = tcp_until(&mut console, "/vo/subscribed", &[int(9)]);
    assert!(got.iter().any(|m| m.addr == "/vo/status"), "{got:?}");
    // A message from the console over UDP: its answer also comes on the connection.
    let udp = UdpSocket::bind((CONSOLE, 0)).unwrap();
    let bytes = rosc::encoder::encode(&msg("/vo/ping", vec![string("udp")])).unwrap();
    udp.send_to(&bytes, (d.setup.udp, d.port)).unwrap();
    tcp_until(&mut console, "/vo/pong", &[string("udp")]);
    // The tablet's change is pushed on the console's connection.
    tablet.send("/vo/blackout", vec![int(1)]);
    tablet.until("/vo/blackout", &[int(1)]);
    tcp_until(&mut console, "/vo/blackout", &[int(1)]);
}

#[test]
fn bad_peers_are_refused_at_start() {
    let dir = visobjd_testkit::temp_dir("peers-bad");
    let config = dir.join("c.toml");
    for (entries, says) in [
        (
            "[[osc.peer]]\nname = \"a\"\naddress = \"127.0.0.2\"\nreply_port = 9000\nframing = \"udp\"\n\
             [[osc.peer]]\nname = \"a\"\naddress = \"127.0.0.3\"\nreply_port = 9000\nframing = \"udp\"\n",
            "used twice",
        ),
        (
            "[[osc.peer]]\nname = \"a\"\naddress = \"127.0.0.2\"\nreply_port = 9000\nframing = \"udp\"\n\
             [[osc.peer]]\nname = \"b\"\naddress = \"127.0.0.2\"\nreply_port = 9001\nframing = \"tcp\"\n",
            "also peer `a`",
        ),
        (
            "[[osc.peer]]\nname = \"a\"\naddress = \"127.0.0.2\"\nreply_port = 9000\nframing = \"osc\"\n",
            "unknown variant `osc`",
        ),
        (
            "[[osc.peer]]\nname = \"a\"\naddress = \"127.0.0.2:9000\"\nreply_port = 9000\nframing = \"udp\"\n",
            "not an IP address",
        ),
    ] {
        std::fs::write(&config, entries).unwrap();
        let out = std::process::Command::new(common::bin())
            .arg("check")
            .arg("--config")
            .arg(&config)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{entries}");
        assert!(err.contains(says), "{says}: {err}");
    }
}

#[test]
fn an_unreachable_tcp_peer_costs_nobody_else_anything() {
    // A port nothing listens on: every connection to it is refused.
    let closed = TcpListener::bind((CONSOLE, 0))
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let probe = Tablet::new("127.0.0.1:9".parse().unwrap());
    let mut d = Daemon::start_setup(
        "peers-unreachable",
        Setup {
            extra: peers(probe.port(), closed, "tcp"),
            ..Setup::default()
        },
    );
    let tablet = Tablet {
        daemon: SocketAddr::new(d.setup.udp, d.port),
        ..probe
    };
    let console = UdpSocket::bind((CONSOLE, 0)).unwrap();
    for i in 0..200 {
        let bytes =
            rosc::encoder::encode(&msg("/vo/master", vec![float(i as f32 / 200.0)])).unwrap();
        console.send_to(&bytes, (d.setup.udp, d.port)).unwrap();
    }
    // Everyone else is still served, and the console's commands ran.
    tablet.send("/vo/ping", vec![string("still here")]);
    tablet.until("/vo/pong", &[string("still here")]);
    let end = Instant::now() + PATIENCE;
    loop {
        let r = d.ok("/vo/status", vec![], "/vo/status");
        let master = match r.args[8] {
            OscType::Float(m) => m,
            ref other => panic!("master: {other:?}"),
        };
        if (master - 199.0 / 200.0).abs() < 1e-6 {
            break;
        }
        assert!(
            Instant::now() < end,
            "the console's last master never ran: {master}"
        );
    }
    // And the daemon says why the console hears nothing.
    while !d.log().contains("cannot reach peer `eos`") {
        assert!(Instant::now() < end, "no warning: {}", d.log());
        std::thread::sleep(Duration::from_millis(10));
    }
}
