//! The DMX output on real sockets (127.0.0.1 only; multicast only inside a private network
//! namespace). Packets are decoded by `visobjd_testkit::wire` from the specifications' byte
//! offsets, independently of the sending code.

use std::collections::BTreeMap;
use std::net::{Ipv4Addr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use visobjd_dmx::Patch;
use visobjd_dmx::{ArtnetDest, Output, OutputConfig, SacnDest};
use visobjd_scene::Scene;
use visobjd_scene::look::{Level, Look};
use visobjd_testkit::tools;
use visobjd_testkit::wire::{
    ArtDmx, Sacn, encode_artpoll, encode_node_reply, parse_artnet, parse_discovery,
    parse_pollreply, parse_sacn, parse_sync,
};

// ---- fixtures --------------------------------------------------------------------------

/// Universe 1: an `irgb` at 1 and a `dimmer16` at 5; universe 2: a `dimmer` at 10.
fn scene() -> Scene {
    let text = r#"
[[light]]
channel = 1
basis = "a.exr"
profile = "irgb"
universe = 1
address = 1

[[light]]
channel = 2
basis = "b.exr"
profile = "dimmer16"
universe = 1
address = 5

[[light]]
channel = 3
basis = "c.exr"
profile = "dimmer"
universe = 2
address = 10
"#;
    Scene::parse(Path::new("/nonexistent"), text).expect("scene parses")
}

fn look(intensity: f32, color: [f32; 3]) -> Look {
    Look {
        levels: vec![
            Level {
                intensity,
                color,
                position: None
            };
            3
        ],
    }
}

fn receiver() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind receiver");
    s.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    s
}

fn state_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("visobjd-output-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

struct Rig {
    sacn: UdpSocket,
    artnet: UdpSocket,
    config: OutputConfig,
}

fn rig(rate_hz: u32) -> Rig {
    let sacn = receiver();
    let artnet = receiver();
    let config = OutputConfig {
        rate_hz,
        sacn: vec![SacnDest {
            port: sacn.local_addr().expect("addr").port(),
            priority: 150,
            source_name: "visobjd test".into(),
            ..SacnDest::default()
        }],
        artnet: vec![ArtnetDest {
            port: artnet.local_addr().expect("addr").port(),
            ..ArtnetDest::default()
        }],
        ..OutputConfig::default()
    };
    Rig {
        sacn,
        artnet,
        config,
    }
}

fn start(config: &OutputConfig, dir: &Path, initial: Look) -> Output {
    Output::start(config, Patch::new(&scene()), dir, initial).expect("output starts")
}

/// Receives packets until `done` says so or `limit` passes; returns them with arrival times.
fn receive_until(
    sock: &UdpSocket,
    limit: Duration,
    mut done: impl FnMut(&[u8]) -> bool,
) -> (Vec<(Instant, Vec<u8>)>, bool) {
    let end = Instant::now() + limit;
    let mut buf = [0u8; 1500];
    let mut got = Vec::new();
    while Instant::now() < end {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push((Instant::now(), buf[..n].to_vec()));
            if done(&buf[..n]) {
                return (got, true);
            }
        }
    }
    (got, false)
}

/// The first sACN data packet for `universe` that satisfies `want`.
fn wait_sacn(sock: &UdpSocket, universe: u16, want: impl Fn(&Sacn) -> bool) -> Sacn {
    let (got, ok) = receive_until(sock, Duration::from_secs(3), |p| {
        parse_sacn(p).is_some_and(|s| s.universe == universe && want(&s))
    });
    assert!(ok, "no matching sACN packet for universe {universe}");
    parse_sacn(&got.last().expect("a packet").1).expect("data packet")
}

/// The first ArtDmx packet for `port_address` that satisfies `want`.
fn wait_artnet(sock: &UdpSocket, port_address: u16, want: impl Fn(&ArtDmx) -> bool) -> ArtDmx {
    let (got, ok) = receive_until(sock, Duration::from_secs(3), |p| {
        let a = parse_artnet(p);
        a.port_address == port_address && want(&a)
    });
    assert!(
        ok,
        "no matching ArtDmx packet for port-address {port_address}"
    );
    parse_artnet(&got.last().expect("a packet").1)
}

// ---- tests -----------------------------------------------------------------------------

#[test]
fn frames_are_continuous_and_sequenced() {
    let rig = rig(10);
    let dir = state_dir("continuous");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    let window = Duration::from_millis(1000);
    let (sacn, _) = receive_until(&rig.sacn, window, |_| false);
    let (art, _) = receive_until(&rig.artnet, Duration::from_millis(100), |_| false);
    let period = Duration::from_millis(100);

    let mut by_universe: BTreeMap<u16, Vec<(Instant, Sacn)>> = BTreeMap::new();
    for (t, p) in sacn.iter().filter(|(_, p)| parse_discovery(p).is_none()) {
        let s = parse_sacn(p).expect("only data packets without sync");
        assert_eq!(s.priority, 150);
        assert_eq!(s.source_name, "visobjd test");
        assert_eq!(s.sync_universe, 0);
        assert!(!s.terminated);
        assert_eq!(s.cid, *out.cid().as_bytes());
        by_universe.entry(s.universe).or_default().push((*t, s));
    }
    assert_eq!(by_universe.keys().copied().collect::<Vec<_>>(), [1, 2]);
    for (u, packets) in &by_universe {
        // ~10 in one second; generous bounds, this is a correctness check.
        assert!(
            (6..=12).contains(&packets.len()),
            "universe {u}: {} frames in 1 s at 10 Hz",
            packets.len()
        );
        for w in packets.windows(2) {
            let gap = w[1].0 - w[0].0;
            assert!(gap < 2 * period, "universe {u}: gap of {gap:?}");
            assert_eq!(
                w[1].1.sequence,
                w[0].1.sequence.wrapping_add(1),
                "sACN sequence per universe"
            );
        }
    }

    let mut last: BTreeMap<u16, u8> = BTreeMap::new();
    for (_, p) in &art {
        let a = parse_artnet(p);
        assert_ne!(a.sequence, 0, "Art-Net sequence 0 turns sequencing off");
        if let Some(prev) = last.insert(a.port_address, a.sequence) {
            let expect = if prev == 255 { 1 } else { prev + 1 };
            assert_eq!(a.sequence, expect, "Art-Net sequence");
        }
    }
    // Scene universes 1 and 2 with the default offset -1.
    assert_eq!(last.keys().copied().collect::<Vec<_>>(), [0, 1]);

    let stats = out.stats();
    assert!(stats.frames.iter().all(|&(_, n)| n >= 6), "{stats:?}");
    assert_eq!(stats.send_errors, 0);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_look_reaches_the_wire_through_its_profiles() {
    let rig = rig(44);
    let dir = state_dir("look");
    let out = start(&rig.config, &dir, Look::off(3));
    // sRGB (1, 0.5, 0) at half: irgb = (128, 255, 55, 0); 16-bit 0.5 = 32768 = (128, 0).
    out.set_look(look(0.5, [1.0, 0.5, 0.0]), 0.0);
    let want = [128u8, 255, 55, 0, 128, 0];
    let s = wait_sacn(&rig.sacn, 1, |s| s.dmx[..6] == want);
    assert!(s.dmx[6..].iter().all(|&b| b == 0), "unused slots are 0");
    let a = wait_artnet(&rig.artnet, 0, |a| a.dmx[..6] == want);
    assert!(a.dmx[6..].iter().all(|&b| b == 0));
    let s = wait_sacn(&rig.sacn, 2, |s| s.dmx[9] == 128);
    assert!(s.dmx.iter().enumerate().all(|(i, &b)| i == 9 || b == 0));
    wait_artnet(&rig.artnet, 1, |a| a.dmx[9] == 128);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_fade_passes_through_intermediate_values() {
    let rig = rig(44);
    let dir = state_dir("fade");
    let out = start(&rig.config, &dir, Look::off(3));
    wait_sacn(&rig.sacn, 2, |s| s.dmx[9] == 0);
    let began = Instant::now();
    out.set_look(look(1.0, [1.0; 3]), 1.0);
    let (got, ok) = receive_until(&rig.sacn, Duration::from_secs(3), |p| {
        parse_sacn(p).is_some_and(|s| s.universe == 2 && s.dmx[9] == 255)
    });
    assert!(ok, "the fade ends at the target");
    let took = began.elapsed();
    assert!(
        took >= Duration::from_millis(900),
        "1 s fade done in {took:?}"
    );
    let values: Vec<u8> = got
        .iter()
        .filter_map(|(_, p)| parse_sacn(p))
        .filter(|s| s.universe == 2)
        .map(|s| s.dmx[9])
        .collect();
    assert!(values.windows(2).all(|w| w[0] <= w[1]), "{values:?}");
    let between = values.iter().filter(|&&v| v > 0 && v < 255).count();
    assert!(
        between >= 10,
        "only {between} intermediate frames: {values:?}"
    );
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn master_halves_and_blackout_zeros() {
    let rig = rig(44);
    let dir = state_dir("master");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    wait_sacn(&rig.sacn, 1, |s| {
        s.dmx[..6] == [255, 255, 255, 255, 255, 255]
    });
    out.set_master(0.5);
    // Intensity halves, colour behind the dimmer stays; 16-bit 0.5 = (128, 0).
    wait_sacn(&rig.sacn, 1, |s| s.dmx[..6] == [128, 255, 255, 255, 128, 0]);
    wait_sacn(&rig.sacn, 2, |s| s.dmx[9] == 128);
    wait_artnet(&rig.artnet, 1, |a| a.dmx[9] == 128);
    out.set_blackout(true);
    wait_sacn(&rig.sacn, 1, |s| s.dmx.iter().all(|&b| b == 0));
    wait_sacn(&rig.sacn, 2, |s| s.dmx.iter().all(|&b| b == 0));
    wait_artnet(&rig.artnet, 0, |a| a.dmx.iter().all(|&b| b == 0));
    out.set_blackout(false);
    wait_sacn(&rig.sacn, 2, |s| s.dmx[9] == 128);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cid_is_kept_and_shutdown_terminates_three_times() {
    let rig = rig(44);
    let dir = state_dir("cid");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    let first = wait_sacn(&rig.sacn, 1, |_| true).cid;
    out.shutdown();
    // All packets are already queued on the loopback receiver when shutdown returns.
    let (rest, _) = receive_until(&rig.sacn, Duration::from_millis(200), |_| false);
    let rest: Vec<Sacn> = rest.iter().filter_map(|(_, p)| parse_sacn(p)).collect();
    let start_of_end = rest
        .iter()
        .position(|s| s.terminated)
        .expect("terminated packets");
    let mut per_universe: BTreeMap<u16, usize> = BTreeMap::new();
    for s in &rest[start_of_end..] {
        assert!(s.terminated, "nothing after termination but termination");
        *per_universe.entry(s.universe).or_default() += 1;
    }
    assert_eq!(per_universe, BTreeMap::from([(1, 3), (2, 3)]));

    let again = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    let second = wait_sacn(&rig.sacn, 1, |s| !s.terminated).cid;
    assert_eq!(first, second, "the CID survives a restart");
    assert_eq!(*again.cid().as_bytes(), second);
    drop(again);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn idle_keepalive_drops_to_one_frame_a_second() {
    let mut rig = rig(44);
    rig.config.idle_keepalive = true;
    let dir = state_dir("keepalive");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    let (got, _) = receive_until(&rig.sacn, Duration::from_millis(1300), |_| false);
    let u1 = got
        .iter()
        .filter(|(_, p)| parse_sacn(p).is_some_and(|s| s.universe == 1))
        .count();
    // First frame + 3 repeats, then one a second: 5 (or 6 with scheduling slack) in 1.3 s.
    assert!(
        (5..=6).contains(&u1),
        "{u1} frames of an unchanged universe"
    );
    out.set_look(look(0.5, [1.0; 3]), 0.0);
    wait_sacn(&rig.sacn, 2, |s| s.dmx[9] == 128);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

const NETNS_CHILD: &str = "VISOBJD_TEST_IN_NETNS";

/// Multicast sACN, received on 239.255.0.1 inside a private network namespace that has
/// only loopback: nothing leaves the machine.
#[test]
fn multicast_in_private_network_namespace() {
    if std::env::var_os(NETNS_CHILD).is_some() {
        multicast_child();
        println!("NETNS-CHILD-PASSED");
        return;
    }
    let exe = std::env::current_exe().expect("test binary");
    for flags in ["-n", "-rn"] {
        let out = Command::new("unshare")
            .arg(flags)
            .arg(&exe)
            .args([
                "--exact",
                "multicast_in_private_network_namespace",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(NETNS_CHILD, "1")
            .output();
        let Ok(out) = out else {
            return tools::missing("unshare", "is not installed", "apt-get install util-linux");
        };
        let stdout = String::from_utf8_lossy(&out.stdout);
        if stdout.contains("NETNS-CHILD-PASSED") {
            assert!(out.status.success());
            return;
        }
        if stdout.contains("running 1 test") {
            panic!(
                "multicast test failed inside the namespace:\n{stdout}\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
    tools::missing(
        "unshare",
        "may not create a network namespace here",
        "run the tests as root, or allow unprivileged user namespaces",
    );
}

fn multicast_child() {
    for args in [
        &["link", "set", "lo", "up"][..],
        &["route", "add", "239.0.0.0/8", "dev", "lo"],
    ] {
        let ok = Command::new("ip")
            .args(args)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "ip {args:?} failed inside the namespace");
    }
    let rx = UdpSocket::bind("0.0.0.0:5568").expect("bind 5568 in the namespace");
    rx.join_multicast_v4(&Ipv4Addr::new(239, 255, 0, 1), &Ipv4Addr::LOCALHOST)
        .expect("join 239.255.0.1");
    rx.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    // 10.0.0.1 has no route in this namespace: every ArtDmx fails with ENETUNREACH, which
    // must be counted and must not stop the clock.
    let config = OutputConfig {
        sacn: vec![SacnDest {
            destination: "multicast".into(),
            ..SacnDest::default()
        }],
        artnet: vec![ArtnetDest {
            destination: "10.0.0.1".into(),
            bind: "0.0.0.0:0".parse().expect("addr"),
            ..ArtnetDest::default()
        }],
        ..OutputConfig::default()
    };
    let dir = state_dir("multicast");
    let out = start(&config, &dir, look(0.5, [1.0; 3]));
    let (got, _) = receive_until(&rx, Duration::from_millis(500), |_| false);
    let stats = out.stats();
    out.shutdown();
    assert!(stats.send_errors >= 5, "{stats:?}");
    std::fs::remove_dir_all(&dir).ok();
    let packets: Vec<Sacn> = got.iter().filter_map(|(_, p)| parse_sacn(p)).collect();
    assert!(packets.len() >= 5, "{} multicast packets", packets.len());
    // Only universe 1's group was joined: universe 2 goes to 239.255.0.2.
    assert!(packets.iter().all(|s| s.universe == 1));
    assert_eq!(packets[0].dmx[0], 128);
}

/// The end-of-capture marker the tshark test sends (not an sACN packet), and a display
/// filter that finds it.
const MARKER: &[u8] = b"VISEND";
const MARKER_FILTER: &str = "udp.length == 14";

/// tshark, an independent decoder, finds every packet well formed: ArtDmx, E1.31 data
/// (with a sync address and the terminated packets) and E1.31 synchronization.
#[test]
fn tshark_decodes_every_packet() {
    if Command::new("tshark").arg("-v").output().is_err() {
        return tools::missing("tshark", "is not installed", "apt-get install tshark");
    }
    let mut rig = rig(44);
    rig.config.sacn[0].sync_universe = 7;
    // A known address for the Art-Net socket, so the test can poll it.
    let art_bind = UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port");
    rig.config.artnet[0].bind = art_bind;
    let (sp, ap) = (
        rig.sacn.local_addr().expect("addr").port(),
        rig.artnet.local_addr().expect("addr").port(),
    );
    let dir = state_dir("tshark");
    std::fs::create_dir_all(&dir).expect("mkdir");
    let pcap = dir.join("capture.pcapng");
    let mut tshark = Command::new("tshark")
        .args(["-i", "lo", "-f"])
        .arg(format!("udp and (dst port {sp} or dst port {ap})"))
        .arg("-w")
        .arg(&pcap)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("tshark starts");
    // Capturing starts once tshark says so on stderr.
    let stderr = tshark.stderr.take().expect("stderr");
    let (tx, ready) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            // "Capture started." comes once dumpcap really captures (tshark 4.0).
            if line.contains("Capture started") {
                let _ = tx.send(());
            }
        }
    });
    if ready.recv_timeout(Duration::from_secs(10)).is_err() {
        let _ = tshark.kill();
        let _ = tshark.wait();
        return tools::missing(
            "tshark",
            "cannot capture on lo here",
            "run the tests as root, or let dumpcap capture (dpkg-reconfigure wireshark-common)",
        );
    }
    let out = start(&rig.config, &dir, look(0.5, [1.0, 0.5, 0.0]));
    let (mut data, mut syncs, mut discovery) = (0, 0, 0);
    receive_until(&rig.sacn, Duration::from_secs(3), |p| {
        if let Some(s) = parse_sacn(p) {
            assert_eq!(s.sync_universe, 7, "data packets carry the sync universe");
            data += 1;
        } else if parse_discovery(p).is_some() {
            discovery += 1;
        } else {
            assert_eq!(parse_sync(p), Some(7), "a sync packet for universe 7");
            syncs += 1;
        }
        data >= 20
    });
    assert!(
        syncs >= 9,
        "a sync packet follows each frame: {syncs} for {data} data"
    );
    assert!(discovery >= 1, "universe discovery at start");
    receive_until(&rig.artnet, Duration::from_secs(3), |_| true);
    // Polled, it answers with an ArtPollReply to the poller (here: the Art-Net receiver).
    rig.artnet
        .send_to(&encode_artpoll(), art_bind)
        .expect("send ArtPoll");
    let (_, replied) = receive_until(&rig.artnet, Duration::from_secs(3), |p| {
        parse_pollreply(p).is_some()
    });
    assert!(replied, "an ArtPollReply");
    out.shutdown();
    // dumpcap writes the file about half a second late: send a marker after the last
    // packet and wait until the capture file holds it before stopping tshark.
    let marker = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let flushed = Instant::now() + Duration::from_secs(10);
    while Instant::now() < flushed {
        marker
            .send_to(MARKER, ("127.0.0.1", sp))
            .expect("send marker");
        let seen = Command::new("tshark")
            .arg("-r")
            .arg(&pcap)
            .args(["-Y", MARKER_FILTER, "-T", "fields", "-e", "frame.number"])
            .output()
            .is_ok_and(|o| !o.stdout.is_empty());
        if seen {
            break;
        }
    }
    // SIGINT lets tshark finish the file; the pid is our own child's.
    let _ = Command::new("kill")
        .args(["-INT", &tshark.id().to_string()])
        .status();
    let _ = tshark.wait();

    let fields = Command::new("tshark")
        .arg("-r")
        .arg(&pcap)
        .args(["-o", "acn.dmx_enable:TRUE", "--enable-heuristic", "acn"])
        .args(["-Y", &format!("not ({MARKER_FILTER})")])
        .args(["-T", "fields", "-E", "separator=|"])
        .args(["-e", "frame.len", "-e", "frame.protocols"])
        .args(["-e", "_ws.malformed", "-e", "_ws.expert.severity"])
        .args(["-e", "acn.dmx.universe", "-e", "acn.dmx.option_s"])
        .args([
            "-e",
            "artnet.output.sequence",
            "-e",
            "artnet.poll_reply.short_name",
        ])
        .output()
        .expect("tshark reads the capture");
    let text = String::from_utf8_lossy(&fields.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines.len() > 30, "captured only {} packets", lines.len());
    let (mut art, mut acn_data, mut terminated, mut sync) = (0, 0, 0, 0);
    for line in &lines {
        let f: Vec<&str> = line.split('|').collect();
        assert_eq!(f.len(), 8, "{line}");
        assert!(f[2].is_empty(), "malformed: {line}");
        // Expert info of severity "error" (PI_ERROR = 0x00800000).
        assert!(!f[3].contains("8388608"), "expert error: {line}");
        if f[1].contains(":artnet") && !f[7].is_empty() {
            assert_eq!(f[7], "visobjd", "ArtPollReply: {line}");
        } else if f[1].contains(":artnet") {
            art += 1;
            assert!(!f[6].is_empty() && f[6] != "0", "ArtDmx sequence: {line}");
        } else if f[1].ends_with(":acn") {
            assert!(!f[4].is_empty(), "E1.31 data without a universe: {line}");
            acn_data += 1;
            if f[5] == "1" || f[5] == "True" {
                terminated += 1;
            }
        } else {
            // Wireshark 4.0 does not dissect E1.31's extended packets (root vector 0x08):
            // synchronization (49 bytes, 91 on the wire) and universe discovery (120 + 2
            // per universe: 166 with two) show as data; both are checked byte by byte above.
            assert!(
                f[1].ends_with(":udp:data") && (f[0] == "91" || f[0] == "166"),
                "not decoded as E1.31 or Art-Net: {line}"
            );
            if f[0] == "91" {
                sync += 1;
            }
        }
    }
    assert!(
        art >= 4 && acn_data >= 10,
        "{art} ArtDmx, {acn_data} E1.31 data"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.contains(":artnet") && l.ends_with("|visobjd")),
        "tshark decodes the ArtPollReply"
    );
    println!(
        "tshark: {art} ArtDmx, {acn_data} E1.31 data ({terminated} terminated), {sync} sync, none malformed"
    );
    assert_eq!(
        terminated, 6,
        "three terminated packets for each of two universes"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// Whether `p` is an ArtPoll (Art-Net ID, OpPoll 0x2000, protocol version 14).
fn is_artpoll(p: &[u8]) -> bool {
    p.len() >= 14 && &p[..8] == b"Art-Net\0" && p[8..12] == [0x00, 0x20, 0, 14]
}

/// Art-Net discovery: ArtPoll goes to the configured (broadcast) address, ArtDmx never
/// does; a node that answers gets unicast ArtDmx for exactly the universes it outputs; and
/// visobjd answers a poll with its own ports. On loopback, 127.0.0.2 stands for the
/// broadcast address and 127.0.0.3 for a node (the same port, as on a real network).
#[test]
fn artnet_discovery_sends_unicast_to_the_nodes_that_answer() {
    let broadcast = UdpSocket::bind("127.0.0.2:0").expect("bind 127.0.0.2");
    broadcast
        .set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let port = broadcast.local_addr().expect("addr").port();
    let node = UdpSocket::bind(("127.0.0.3", port)).expect("bind 127.0.0.3");
    node.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    let config = OutputConfig {
        rate_hz: 44,
        artnet: vec![ArtnetDest {
            destination: "127.0.0.2".into(),
            port,
            discover: true,
            ..ArtnetDest::default()
        }],
        ..OutputConfig::default()
    };
    let dir = state_dir("artnet-discovery");
    let out = start(&config, &dir, look(1.0, [1.0; 3]));
    // The poll arrives; until a node answers, nothing else does (no broadcast ArtDmx).
    let mut visobjd = None;
    let mut buf = [0u8; 1500];
    let end = Instant::now() + Duration::from_secs(5);
    while visobjd.is_none() && Instant::now() < end {
        if let Ok((n, from)) = broadcast.recv_from(&mut buf) {
            assert!(
                is_artpoll(&buf[..n]),
                "only ArtPoll to the broadcast address"
            );
            visobjd = Some(from);
        }
    }
    let visobjd = visobjd.expect("an ArtPoll within 5 s");
    // The node outputs port-address 0 (scene universe 1, offset -1) and 5 (not patched).
    node.send_to(&encode_node_reply([127, 0, 0, 3], 0, 0, &[0, 5]), visobjd)
        .expect("reply");
    let first = wait_artnet(&node, 0, |_| true);
    assert_eq!(first.dmx[0], 255, "the look reaches the node");
    let (rest, _) = receive_until(&node, Duration::from_millis(300), |_| false);
    assert!(
        rest.iter().all(|(_, p)| parse_artnet(p).port_address == 0),
        "only the universe the node outputs"
    );
    let (bcast, _) = receive_until(&broadcast, Duration::from_millis(300), |_| false);
    assert!(
        bcast.iter().all(|(_, p)| is_artpoll(p)),
        "no ArtDmx to the broadcast address"
    );
    // Polled, visobjd describes its two universes as input ports (onto the network).
    let poller = UdpSocket::bind("127.0.0.1:0").expect("bind poller");
    poller
        .set_read_timeout(Some(Duration::from_millis(50)))
        .expect("timeout");
    poller.send_to(&encode_artpoll(), visobjd).expect("poll");
    let (got, ok) = receive_until(&poller, Duration::from_secs(3), |p| {
        parse_pollreply(p).is_some()
    });
    assert!(ok, "an ArtPollReply");
    let reply = parse_pollreply(&got.last().expect("a reply").1).expect("a reply");
    assert_eq!(reply.short_name, "visobjd");
    assert_eq!(reply.style, 1, "StController");
    assert_eq!(reply.ip, [127, 0, 0, 1]);
    assert_eq!((reply.net, reply.sub, reply.bind_index), (0, 0, 1));
    assert_eq!(reply.ports, [(0x40, 0, 0), (0x40, 1, 0)]);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

/// E1.31 universe discovery at start (then every 10 s), to the unicast receiver: the
/// scene's universes, sorted, on one page, under the output's CID and source name.
#[test]
fn sacn_universe_discovery_lists_the_universes() {
    let rig = rig(44);
    let dir = state_dir("sacn-discovery");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    let (got, ok) = receive_until(&rig.sacn, Duration::from_secs(3), |p| {
        parse_discovery(p).is_some()
    });
    assert!(ok, "a universe discovery packet");
    let d = parse_discovery(&got.last().expect("a packet").1).expect("discovery");
    assert_eq!(d.universes, [1, 2]);
    assert_eq!((d.page, d.last_page), (0, 0));
    assert_eq!(d.source_name, "visobjd test");
    assert_eq!(d.cid, *out.cid().as_bytes());
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_rewire_moves_the_rig_without_a_gap_and_ends_only_the_streams_it_drops() {
    let rig = rig(40);
    let dir = state_dir("rewire");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    wait_sacn(&rig.sacn, 2, |s| !s.terminated);
    let second = receiver();

    // The new patch: one universe, the dimmer moved to 1/20; the old destination kept and
    // a second one added.
    let moved = Scene::parse(
        Path::new("/nonexistent"),
        "[[light]]\nchannel = 1\nbasis = \"a.exr\"\nprofile = \"irgb\"\nuniverse = 1\naddress = 1\n\n\
         [[light]]\nchannel = 3\nbasis = \"c.exr\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = 20\n",
    )
    .expect("scene parses");
    let mut config = rig.config.clone();
    config.sacn.push(SacnDest {
        port: second.local_addr().expect("addr").port(),
        ..config.sacn[0].clone()
    });
    let lit = Look {
        levels: vec![
            Level {
                intensity: 1.0,
                color: [1.0; 3],
                position: None
            };
            2
        ],
    };
    out.rewire(&config, Patch::new(&moved), lit)
        .expect("the rewire binds");
    let (got, ok) = receive_until(&rig.sacn, Duration::from_secs(3), |p| {
        parse_sacn(p).is_some_and(|s| s.universe == 1 && s.dmx[19] == 255)
    });
    assert!(ok, "the moved dimmer never showed at 1/20");
    let (after, _) = receive_until(&rig.sacn, Duration::from_millis(300), |_| false);
    let all: Vec<(Instant, Sacn)> = got
        .into_iter()
        .chain(after)
        .filter_map(|(t, p)| parse_sacn(&p).map(|s| (t, s)))
        .collect();
    // Universe 1 goes on: same CID, consecutive sequence numbers, no gap over two periods.
    let one: Vec<&(Instant, Sacn)> = all.iter().filter(|(_, s)| s.universe == 1).collect();
    for w in one.windows(2) {
        assert!(!w[1].1.terminated, "universe 1 was terminated");
        assert_eq!(w[1].1.cid, w[0].1.cid);
        assert_eq!(
            w[1].1.sequence,
            w[0].1.sequence.wrapping_add(1),
            "universe 1's sequence across the rewire"
        );
        let gap = w[1].0 - w[0].0;
        assert!(
            gap < Duration::from_millis(50),
            "a gap of {gap:?} across the rewire"
        );
    }
    // Universe 2, no longer patched, ends as at a shutdown: three terminations, then nothing.
    let two: Vec<&Sacn> = all
        .iter()
        .filter(|(_, s)| s.universe == 2)
        .map(|(_, s)| s)
        .collect();
    assert_eq!(
        two.iter().filter(|s| s.terminated).count(),
        3,
        "{}",
        two.len()
    );
    assert!(
        two.last().is_some_and(|s| s.terminated),
        "universe 2 went on"
    );
    // The new destination gets the new patch.
    let new = wait_sacn(&second, 1, |s| s.dmx[19] == 255);
    assert_eq!(new.cid, *out.cid().as_bytes());
    assert_eq!(out.stats().destinations.len(), 3);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_rewire_that_cannot_bind_changes_nothing() {
    let rig = rig(40);
    let dir = state_dir("rewire-bind");
    let out = start(&rig.config, &dir, look(1.0, [1.0; 3]));
    wait_sacn(&rig.sacn, 2, |s| !s.terminated);
    let taken = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let mut config = rig.config.clone();
    config.sacn[0].bind = taken.local_addr().expect("addr");
    let err = out
        .rewire(&config, Patch::new(&scene()), look(0.0, [1.0; 3]))
        .expect_err("the bind is taken");
    assert!(err.to_string().contains("cannot bind"), "{err}");
    // Both universes still at full from the old wiring.
    let s = wait_sacn(&rig.sacn, 2, |_| true);
    assert_eq!(s.dmx[9], 255);
    assert!(!s.terminated);
    out.shutdown();
    std::fs::remove_dir_all(&dir).ok();
}
