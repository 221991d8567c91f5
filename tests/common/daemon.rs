//! The real `visobjd run` on loopback: a small scene, its config and state folder, OSC
//! clients over UDP and both TCP framings, and Art-Net/sACN receivers that decode every
//! packet independently of the sending code (`visobjd_testkit::wire`).
//!
//! Only `rosc` encodes and decodes OSC here; stream framing is written out below.

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{ErrorKind, Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU16, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use rosc::{OscMessage, OscPacket, OscType};

use visobjd_testkit::wire::{parse_artnet, parse_sacn};
use visobjd_testkit::{TestLight, temp_dir, write_png, write_scene};

use super::bin;

/// `output.rate_hz` of the test config.
pub const RATE_HZ: u32 = 20;
/// One frame period at [`RATE_HZ`].
pub const PERIOD: Duration = Duration::from_millis(1000 / RATE_HZ as u64);
/// The contract's continuity bound: no gap over two frame periods.
pub const GAP: Duration = Duration::from_millis(2 * PERIOD.as_millis() as u64);
/// How long a reply or a wire condition is waited for.
pub const PATIENCE: Duration = Duration::from_secs(5);
/// How long a generate may take (a debug build on two busy cores).
pub const GENERATE_PATIENCE: Duration = Duration::from_secs(60);
/// Basis image size.
pub const W: usize = 48;
pub const H: usize = 20;
/// `generate.count` and `generate.clusters` of the test config.
pub const COUNT: i32 = 30;
pub const CLUSTERS: i32 = 6;

// ---- the stage ---------------------------------------------------------------------------

/// A light of the test stage as the tests see it.
#[derive(Debug, Clone, Copy)]
pub struct PatchedLight {
    pub channel: i32,
    pub profile: &'static str,
    pub group: &'static str,
    pub universe: u16,
    /// DMX start address (1-based).
    pub address: usize,
}

/// Six lights, each lighting its own vertical 8-pixel stripe of the 48x20 stage (light 1
/// the left-most): two dimmers (front), two irgb (side), an rgb and an rgbw (back).
pub const STAGE: [PatchedLight; 6] = [
    fx(1, "dimmer", "front", 1, 1),
    fx(2, "dimmer", "front", 1, 2),
    fx(3, "irgb", "side", 1, 10),
    fx(4, "irgb", "side", 2, 1),
    fx(5, "rgb", "back", 2, 10),
    fx(6, "rgbw", "back", 2, 20),
];

const fn fx(
    channel: i32,
    profile: &'static str,
    group: &'static str,
    universe: u16,
    address: usize,
) -> PatchedLight {
    PatchedLight {
        channel,
        profile,
        group,
        universe,
        address,
    }
}

pub const GROUPS: [&str; 3] = ["front", "side", "back"];
pub const UNIVERSES: [u16; 2] = [1, 2];

impl PatchedLight {
    /// DMX slots the profile takes.
    pub fn footprint(&self) -> usize {
        match self.profile {
            "dimmer" => 1,
            "rgb" => 3,
            "irgb" | "rgbw" => 4,
            other => panic!("no footprint for {other}"),
        }
    }

    /// This light's slots in its universe's 512.
    pub fn slots<'a>(&self, dmx: &'a [u8]) -> &'a [u8] {
        &dmx[self.address - 1..self.address - 1 + self.footprint()]
    }

    pub fn has_colour(&self) -> bool {
        self.profile != "dimmer"
    }
}

pub fn fixture(channel: i32) -> PatchedLight {
    *STAGE
        .iter()
        .find(|f| f.channel == channel)
        .expect("a stage channel")
}

/// Copies the folder `from` to `to`, recursively.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read the folder") {
        let entry = entry.expect("a folder entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("its type").is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy a file");
        }
    }
}

/// Writes the scene, the references and an outside image into `dir`.
fn build_stage(dir: &Path) {
    let lights: Vec<TestLight> = STAGE
        .iter()
        .enumerate()
        .map(|(i, f)| {
            // Distinct levels so the lights are not interchangeable.
            let level = 0.4 + 0.1 * i as f32;
            TestLight {
                channel: f.channel as u32,
                group: Some(f.group),
                profile: f.profile,
                universe: f.universe,
                address: f.address as u16,
                pixel: Box::new(move |x, _| {
                    if x / 8 == i {
                        [level, level * 0.95, level * 0.9]
                    } else {
                        [0.0; 3]
                    }
                }),
            }
        })
        .collect();
    write_scene(&dir.join("scene"), W, H, &GROUPS, &lights);
    let refs = dir.join("refs");
    std::fs::create_dir_all(&refs).expect("mkdir refs");
    write_png(&refs.join("warm.png"), 24, 12, |x, _| {
        [255, 120 + (x * 2) as u8, 40]
    });
    write_png(&refs.join("cool.png"), 24, 12, |_, y| {
        [40, 80 + (y * 3) as u8, 255]
    });
    write_png(&refs.join("grey.png"), 24, 12, |_, _| [128, 128, 128]);
    // Left half white, right half black: mean L* 50, key L* 100, half the pixels bright.
    write_png(&refs.join("split.png"), 24, 12, |x, _| {
        if x < 12 { [255; 3] } else { [0; 3] }
    });
    write_png(&dir.join("outside.png"), 24, 12, |_, _| [200, 30, 30]);
}

/// sRGB-encoded 0..1 to linear light (IEC 61966-2-1), written out here on purpose.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

// ---- replies -------------------------------------------------------------------------------

pub fn int(v: i32) -> OscType {
    OscType::Int(v)
}
pub fn long(v: i64) -> OscType {
    OscType::Long(v)
}
pub fn float(v: f32) -> OscType {
    OscType::Float(v)
}
pub fn double(v: f64) -> OscType {
    OscType::Double(v)
}
pub fn string(v: &str) -> OscType {
    OscType::String(v.into())
}

pub fn msg(addr: &str, args: Vec<OscType>) -> OscPacket {
    OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    })
}

/// A number in a reply, whatever its OSC type.
pub fn num(a: &OscType) -> f64 {
    match a {
        OscType::Int(i) => f64::from(*i),
        OscType::Long(i) => *i as f64,
        OscType::Float(f) => f64::from(*f),
        OscType::Double(d) => *d,
        other => panic!("expected a number, got {other:?}"),
    }
}

/// A string in a reply.
pub fn text(a: &OscType) -> String {
    match a {
        OscType::String(s) => s.clone(),
        other => panic!("expected a string, got {other:?}"),
    }
}

/// One light of a `/vo/live` or `/vo/candidate` reply.
#[derive(Debug, Clone, PartialEq)]
pub struct LightLevel {
    pub ch: i32,
    pub intensity: f32,
    /// sRGB 0..1.
    pub color: [f32; 3],
}

/// `ch intensity r g b` groups, in order.
pub fn lights(args: &[OscType]) -> Vec<LightLevel> {
    assert_eq!(args.len() % 5, 0, "ch intensity r g b per light: {args:?}");
    args.chunks(5)
        .map(|c| LightLevel {
            ch: num(&c[0]) as i32,
            intensity: num(&c[1]) as f32,
            color: [num(&c[2]) as f32, num(&c[3]) as f32, num(&c[4]) as f32],
        })
        .collect()
}

/// Whether two looks agree within `tol` on every value.
pub fn same_look(a: &[LightLevel], b: &[LightLevel], tol: f32) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            x.ch == y.ch
                && (x.intensity - y.intensity).abs() <= tol
                && x.color
                    .iter()
                    .zip(y.color)
                    .all(|(p, q)| (p - q).abs() <= tol)
        })
}

/// The `/vo/status` reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    pub scene: String,
    pub lights: i32,
    pub objectives: i32,
    pub candidates: i32,
    pub clusters: i32,
    pub entry: i32,
    pub fade: f64,
    pub blackout: i32,
    pub master: f64,
}

/// The output's health as `/vo/status` ends with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Health {
    pub fps: f64,
    pub late: i32,
    pub send_errors: i32,
    /// (label, failed sends) per destination.
    pub destinations: Vec<(String, i32)>,
}

/// The words that start `/vo/status`'s tagged parts after the destinations (no
/// destination label is one word).
const STATUS_PARTS: [&str; 3] = ["console", "problem", "unseen"];

/// The arguments of `/vo/status`'s part `tag` (`console`, `problem`, `unseen`) up to the
/// next part, if it has one.
pub fn status_part<'a>(m: &'a OscMessage, tag: &str) -> Option<&'a [OscType]> {
    let is_part = |a: &OscType| {
        STATUS_PARTS
            .iter()
            .any(|p| *a == OscType::String((*p).into()))
    };
    let start = m
        .args
        .iter()
        .position(|a| *a == OscType::String(tag.into()))?
        + 1;
    let len = m.args[start..]
        .iter()
        .position(is_part)
        .unwrap_or(m.args.len() - start);
    Some(&m.args[start..start + len])
}

impl Health {
    pub fn parse(m: &OscMessage) -> Health {
        // The tagged parts (the console with `[input.sacn]`, a scene's problems) start at
        // their words.
        let end = m
            .args
            .iter()
            .position(|a| {
                STATUS_PARTS
                    .iter()
                    .any(|p| *a == OscType::String((*p).into()))
            })
            .unwrap_or(m.args.len());
        let a = &m.args[..end];
        assert!(
            a.len() >= 12 && (a.len() - 12).is_multiple_of(2),
            "/vo/status: 9 session arguments, fps, late, errors, then (destination, errors) pairs: {a:?}"
        );
        Health {
            fps: num(&a[9]),
            late: num(&a[10]) as i32,
            send_errors: num(&a[11]) as i32,
            destinations: a[12..]
                .chunks(2)
                .map(|p| (text(&p[0]), num(&p[1]) as i32))
                .collect(),
        }
    }
}

impl Status {
    pub fn parse(m: &OscMessage) -> Status {
        let a = &m.args;
        Health::parse(m);
        Status {
            scene: text(&a[0]),
            lights: num(&a[1]) as i32,
            objectives: num(&a[2]) as i32,
            candidates: num(&a[3]) as i32,
            clusters: num(&a[4]) as i32,
            entry: num(&a[5]) as i32,
            fade: num(&a[6]),
            blackout: num(&a[7]) as i32,
            master: num(&a[8]),
        }
    }
}

/// What a command that fails must leave as it was.
#[derive(Debug, Clone, PartialEq)]
pub struct Untouched {
    pub status: Status,
    pub live: Vec<LightLevel>,
    /// `(ch, palette)` per moving light.
    pub positions: Vec<(i32, i32)>,
    pub objectives: Vec<OscMessage>,
    pub looks: Vec<(i32, String)>,
}

static TOKEN: AtomicI32 = AtomicI32::new(1);

/// The `/vo/error` address names the address sent: as sent, or without its trailing
/// numeric segments (they are arguments), in any case.
fn names_address(error_addr: &str, sent: &str) -> bool {
    let sent = sent.to_lowercase();
    let mut stripped: Vec<&str> = sent.split('/').collect();
    while stripped.len() > 2 && stripped.last().is_some_and(|s| s.parse::<f64>().is_ok()) {
        stripped.pop();
    }
    let e = error_addr.to_lowercase();
    e == sent || e == stripped.join("/")
}

/// An OSC connection to the daemon: UDP or TCP. The provided methods are the test
/// vocabulary.
pub trait Osc {
    fn send_packet(&mut self, p: &OscPacket);
    /// The next message that arrives within `wait` (bundles are flattened).
    fn next(&mut self, wait: Duration) -> Option<OscMessage>;
    /// The daemon's stderr, for failure messages.
    fn log(&self) -> String;

    fn send(&mut self, addr: &str, args: Vec<OscType>) {
        self.send_packet(&msg(addr, args));
    }

    /// Sends one message and collects what arrives up to and including the `until` reply or
    /// a `/vo/error`.
    fn call(&mut self, addr: &str, args: Vec<OscType>, until: &str) -> Vec<OscMessage> {
        self.send(addr, args.clone());
        self.collect(until, PATIENCE, &format!("{addr} {args:?}"))
    }

    /// Collects messages up to and including `until` or a `/vo/error`.
    fn collect(&mut self, until: &str, wait: Duration, what: &str) -> Vec<OscMessage> {
        let end = Instant::now() + wait;
        let mut got = Vec::new();
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            if let Some(m) = self.next(left) {
                // A start-up ping's pong can come late, once several were sent.
                if m.addr == "/vo/pong" && m.args.first() == Some(&string("ready")) {
                    continue;
                }
                let done = m.addr == until || m.addr == "/vo/error";
                got.push(m);
                if done {
                    return got;
                }
            }
        }
        panic!(
            "no {until} (nor /vo/error) for {what} within {wait:?}; got {got:?}\n--- daemon log ---\n{}",
            self.log()
        );
    }

    /// Sends one message that must succeed with the single reply `reply`; returns it.
    fn ok(&mut self, addr: &str, args: Vec<OscType>, reply: &str) -> OscMessage {
        let what = format!("{addr} {args:?}");
        let mut got = self.call(addr, args, reply);
        let last = got.pop().expect("a reply");
        assert_eq!(
            last.addr,
            reply,
            "{what} was refused: {:?}\n--- daemon log ---\n{}",
            last.args,
            self.log()
        );
        assert!(got.is_empty(), "{what}: more than one reply: {got:?}");
        let extra = self.fence();
        assert!(extra.is_empty(), "{what}: more after {reply}: {extra:?}");
        last
    }

    /// Sends one message that must be refused: exactly one `/vo/error` naming the address
    /// with a non-empty sentence. Returns the sentence.
    fn err(&mut self, addr: &str, args: Vec<OscType>) -> String {
        let what = format!("{addr} {args:?}");
        let got = self.call(addr, args, "/vo/error");
        let last = got.last().expect("a reply");
        assert_eq!(
            (got.len(), last.addr.as_str()),
            (1, "/vo/error"),
            "{what} should be refused, got {got:?}"
        );
        assert_eq!(last.args.len(), 2, "/vo/error address message: {last:?}");
        let (a, sentence) = (text(&last.args[0]), text(&last.args[1]));
        assert!(names_address(&a, addr), "the error names {a}, not {addr}");
        assert!(
            sentence.trim().len() > 5,
            "an actionable sentence: {last:?}"
        );
        let extra = self.fence();
        assert!(extra.is_empty(), "{what}: more after the error: {extra:?}");
        sentence
    }

    /// Like [`Osc::err`], and checks the daemon's state did not change.
    fn refused(&mut self, addr: &str, args: Vec<OscType>) -> String {
        let before = self.snapshot();
        let sentence = self.err(addr, args.clone());
        assert_eq!(
            self.snapshot(),
            before,
            "{addr} {args:?} failed ({sentence}) but changed something"
        );
        sentence
    }

    /// Sends one message that gets no reply at all: the pong of a following ping is the
    /// next thing to arrive.
    fn silent(&mut self, addr: &str, args: Vec<OscType>) {
        let what = format!("{addr} {args:?}");
        self.send(addr, args);
        let got = self.fence();
        assert!(got.is_empty(), "{what} should get no reply, got {got:?}");
    }

    /// Pings with a fresh token; returns whatever arrived before its pong.
    fn fence(&mut self) -> Vec<OscMessage> {
        let token = TOKEN.fetch_add(1, Ordering::Relaxed);
        self.send("/vo/ping", vec![string("fence"), int(token)]);
        let end = Instant::now() + PATIENCE;
        let mut before = Vec::new();
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            if let Some(m) = self.next(left) {
                if m.addr == "/vo/pong" && m.args == [string("fence"), int(token)] {
                    return before;
                }
                // A start-up ping's pong can come late, once several were sent.
                if m.addr == "/vo/pong" && m.args.first() == Some(&string("ready")) {
                    continue;
                }
                before.push(m);
            }
        }
        panic!(
            "no /vo/pong for the fence ping {token}; got {before:?}\n--- daemon log ---\n{}",
            self.log()
        );
    }

    fn health(&mut self) -> Health {
        Health::parse(&self.ok("/vo/status", vec![], "/vo/status"))
    }

    fn status(&mut self) -> Status {
        Status::parse(&self.ok("/vo/status", vec![], "/vo/status"))
    }

    fn live(&mut self) -> Vec<LightLevel> {
        self.live_aimed().0
    }

    /// `/vo/live`: the levels, and `(ch, palette)` per moving light from the
    /// `/vo/live/positions` that follows it on a rig with movers (none on a rig without).
    fn live_aimed(&mut self) -> (Vec<LightLevel>, Vec<(i32, i32)>) {
        let mut got = self.call("/vo/live", vec![], "/vo/live");
        let m = got.pop().expect("a reply");
        assert_eq!(
            (m.addr.as_str(), got.len()),
            ("/vo/live", 0),
            "{m:?} after {got:?}"
        );
        let rest = self.fence();
        let positions = match rest.as_slice() {
            [] => Vec::new(),
            [p] if p.addr == "/vo/live/positions" && p.args.len() % 2 == 0 => p
                .args
                .chunks(2)
                .map(|c| (num(&c[0]) as i32, num(&c[1]) as i32))
                .collect(),
            other => panic!("after /vo/live: {other:?}"),
        };
        (lights(&m.args), positions)
    }

    /// Gallery entry `k`, member `m`.
    fn candidate(&mut self, k: i32, m: i32) -> Vec<LightLevel> {
        let r = self.ok("/vo/candidate", vec![int(k), int(m)], "/vo/candidate");
        assert!(r.args.len() >= 2, "{r:?}");
        assert_eq!(
            (num(&r.args[0]) as i32, num(&r.args[1]) as i32),
            (k, m),
            "{r:?}"
        );
        lights(&r.args[2..])
    }

    /// The `/vo/gallery` sizes, one per entry.
    fn gallery(&mut self) -> Vec<i32> {
        let r = self.ok("/vo/gallery", vec![], "/vo/gallery");
        let c = num(&r.args[0]) as usize;
        assert_eq!(r.args.len(), 1 + c, "clusters then one size each: {r:?}");
        r.args[1..].iter().map(|a| num(a) as i32).collect()
    }

    /// The `/vo/objective` messages of `/vo/objectives` (the count checked).
    fn objectives(&mut self) -> Vec<OscMessage> {
        let mut got = self.call("/vo/objectives", vec![], "/vo/objectives/end");
        let end = got.pop().expect("a reply");
        assert_eq!(end.addr, "/vo/objectives/end", "{end:?}");
        assert_eq!(num(&end.args[0]) as usize, got.len(), "count: {end:?}");
        assert!(got.iter().all(|m| m.addr == "/vo/objective"), "{got:?}");
        got
    }

    /// `(n, label)` of `/vo/looks` (the count checked).
    fn looks(&mut self) -> Vec<(i32, String)> {
        let mut got = self.call("/vo/looks", vec![], "/vo/looks/end");
        let end = got.pop().expect("a reply");
        assert_eq!(end.addr, "/vo/looks/end", "{end:?}");
        assert_eq!(num(&end.args[0]) as usize, got.len(), "count: {end:?}");
        got.iter()
            .map(|m| {
                assert_eq!(m.addr, "/vo/look", "{m:?}");
                (num(&m.args[0]) as i32, text(&m.args[1]))
            })
            .collect()
    }

    fn snapshot(&mut self) -> Untouched {
        let (live, positions) = self.live_aimed();
        Untouched {
            status: self.status(),
            live,
            positions,
            objectives: self.objectives(),
            looks: self.looks(),
        }
    }

    /// Adds an objective; returns its id.
    fn add_objective(&mut self, image: &str, aspects: &str) -> i32 {
        let r = self.ok(
            "/vo/objective/add",
            vec![string(image), string(aspects)],
            "/vo/objective/added",
        );
        num(&r.args[0]) as i32
    }

    /// Runs `/vo/generate`; returns the `/vo/generated` reply.
    fn generate(&mut self) -> OscMessage {
        self.send("/vo/generate", vec![]);
        let mut got = self.collect("/vo/generated", GENERATE_PATIENCE, "/vo/generate");
        let last = got.pop().expect("a reply");
        assert_eq!(last.addr, "/vo/generated", "generate refused: {last:?}");
        last
    }
}

fn flatten(p: OscPacket, out: &mut VecDeque<OscMessage>) {
    match p {
        OscPacket::Message(m) => out.push_back(m),
        OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| flatten(p, out)),
    }
}

/// An OSC client over UDP from its own loopback port.
pub struct Udp {
    sock: UdpSocket,
    to: SocketAddr,
    queue: VecDeque<OscMessage>,
    log: PathBuf,
}

impl Udp {
    pub fn port(&self) -> u16 {
        self.sock.local_addr().expect("addr").port()
    }

    /// Sends raw bytes (not OSC, or OSC built by hand).
    pub fn send_raw(&self, bytes: &[u8]) {
        self.sock.send_to(bytes, self.to).expect("send");
    }
}

impl Osc for Udp {
    fn send_packet(&mut self, p: &OscPacket) {
        self.send_raw(&rosc::encoder::encode(p).expect("encode"));
    }

    fn next(&mut self, wait: Duration) -> Option<OscMessage> {
        let end = Instant::now() + wait;
        let mut buf = vec![0u8; 65536];
        while self.queue.is_empty() {
            let left = end.checked_duration_since(Instant::now())?;
            self.sock
                .set_read_timeout(Some(left.max(Duration::from_millis(1))))
                .expect("timeout");
            if let Ok(n) = self.sock.recv(&mut buf) {
                let (_, p) = rosc::decoder::decode_udp(&buf[..n]).expect("a reply is OSC");
                flatten(p, &mut self.queue);
            }
        }
        self.queue.pop_front()
    }

    fn log(&self) -> String {
        log_tail(&self.log)
    }
}

/// TCP framing, written out here.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TcpFraming {
    /// OSC 1.0: a big-endian u32 length before each packet.
    LengthPrefix,
    /// OSC 1.1: RFC 1055 SLIP (END 0xC0, ESC 0xDB, ESC_END 0xDC, ESC_ESC 0xDD).
    Slip,
}

/// An OSC client over one TCP connection.
pub struct Tcp {
    stream: TcpStream,
    framing: TcpFraming,
    buf: Vec<u8>,
    queue: VecDeque<OscMessage>,
    log: PathBuf,
}

impl Tcp {
    fn frame(&self, packet: &[u8]) -> Vec<u8> {
        match self.framing {
            TcpFraming::LengthPrefix => {
                let mut v = (packet.len() as u32).to_be_bytes().to_vec();
                v.extend_from_slice(packet);
                v
            }
            TcpFraming::Slip => {
                let mut v = vec![0xC0];
                for &b in packet {
                    match b {
                        0xC0 => v.extend([0xDB, 0xDC]),
                        0xDB => v.extend([0xDB, 0xDD]),
                        b => v.push(b),
                    }
                }
                v.push(0xC0);
                v
            }
        }
    }

    /// Takes every whole frame out of `buf`.
    fn unframe(&mut self) -> Vec<Vec<u8>> {
        let mut frames = Vec::new();
        match self.framing {
            TcpFraming::LengthPrefix => {
                while self.buf.len() >= 4 {
                    let len = u32::from_be_bytes(self.buf[..4].try_into().expect("4")) as usize;
                    if self.buf.len() < 4 + len {
                        break;
                    }
                    frames.push(self.buf[4..4 + len].to_vec());
                    self.buf.drain(..4 + len);
                }
            }
            TcpFraming::Slip => {
                while let Some(end) = self.buf.iter().position(|&b| b == 0xC0) {
                    let raw: Vec<u8> = self.buf.drain(..=end).collect();
                    let mut frame = Vec::new();
                    let mut esc = false;
                    for &b in &raw[..raw.len() - 1] {
                        match (esc, b) {
                            (false, 0xDB) => esc = true,
                            (true, 0xDC) => (frame.push(0xC0), esc = false).1,
                            (true, 0xDD) => (frame.push(0xDB), esc = false).1,
                            (_, b) => (frame.push(b), esc = false).1,
                        }
                    }
                    if !frame.is_empty() {
                        frames.push(frame);
                    }
                }
            }
        }
        frames
    }

    /// Writes raw bytes on the stream.
    pub fn send_raw(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).expect("TCP write");
    }
}

impl Osc for Tcp {
    fn send_packet(&mut self, p: &OscPacket) {
        let framed = self.frame(&rosc::encoder::encode(p).expect("encode"));
        self.send_raw(&framed);
    }

    fn next(&mut self, wait: Duration) -> Option<OscMessage> {
        let end = Instant::now() + wait;
        let mut chunk = [0u8; 8192];
        while self.queue.is_empty() {
            for f in self.unframe() {
                let (_, p) = rosc::decoder::decode_udp(&f).expect("a TCP reply is OSC");
                flatten(p, &mut self.queue);
            }
            if !self.queue.is_empty() {
                break;
            }
            let left = end.checked_duration_since(Instant::now())?;
            self.stream
                .set_read_timeout(Some(left.max(Duration::from_millis(1))))
                .expect("timeout");
            match self.stream.read(&mut chunk) {
                Ok(0) => panic!("the daemon closed the TCP connection"),
                Ok(n) => self.buf.extend_from_slice(&chunk[..n]),
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(e) => panic!("TCP read: {e}"),
            }
        }
        self.queue.pop_front()
    }

    fn log(&self) -> String {
        log_tail(&self.log)
    }
}

fn log_tail(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(40)..].join("\n")
}

// ---- the wire --------------------------------------------------------------------------

/// Which output a frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Proto {
    Sacn,
    Artnet,
}

pub const PROTOS: [Proto; 2] = [Proto::Sacn, Proto::Artnet];

/// One received DMX packet of a scene universe.
#[derive(Debug, Clone)]
pub struct DmxPacket {
    pub at: Instant,
    /// The sender's address (its socket: a second process sends from another port).
    pub from: SocketAddr,
    pub sequence: u8,
    /// sACN Stream_Terminated (always false for Art-Net).
    pub terminated: bool,
    /// sACN CID (zero for Art-Net).
    pub cid: [u8; 16],
    pub source_name: String,
    pub priority: u8,
    pub dmx: Vec<u8>,
}

#[derive(Default)]
struct Log {
    /// By (protocol, scene universe), in arrival order.
    frames: BTreeMap<(Proto, u16), Vec<DmxPacket>>,
    /// Packets that failed to decode.
    malformed: Vec<String>,
    /// The last time each receiver found its socket empty.
    idle: BTreeMap<Proto, Instant>,
}

/// Art-Net and sACN receivers on loopback, each decoding in a background thread.
pub struct Wire {
    log: Arc<Mutex<Log>>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    pub sacn_port: u16,
    pub artnet_port: u16,
}

/// Art-Net port-address = scene universe + this (config `universe_offset`).
pub const ARTNET_OFFSET: i32 = -1;

fn decode(proto: Proto, p: &[u8], at: Instant, from: SocketAddr) -> Option<(u16, DmxPacket)> {
    match proto {
        Proto::Sacn => parse_sacn(p).map(|s| {
            (
                s.universe,
                DmxPacket {
                    at,
                    from,
                    sequence: s.sequence,
                    terminated: s.terminated,
                    cid: s.cid,
                    source_name: s.source_name,
                    priority: s.priority,
                    dmx: s.dmx,
                },
            )
        }),
        Proto::Artnet => {
            let a = parse_artnet(p);
            let universe = (i32::from(a.port_address) - ARTNET_OFFSET) as u16;
            Some((
                universe,
                DmxPacket {
                    at,
                    from,
                    sequence: a.sequence,
                    terminated: false,
                    cid: [0; 16],
                    source_name: String::new(),
                    priority: 0,
                    dmx: a.dmx,
                },
            ))
        }
    }
}

impl Wire {
    fn start() -> Wire {
        let log = Arc::new(Mutex::new(Log::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let mut ports = Vec::new();
        let threads = PROTOS
            .iter()
            .map(|&proto| {
                let sock = UdpSocket::bind("127.0.0.1:0").expect("bind a receiver");
                sock.set_read_timeout(Some(Duration::from_millis(20)))
                    .expect("timeout");
                ports.push(sock.local_addr().expect("addr").port());
                let (log, stop) = (log.clone(), stop.clone());
                std::thread::spawn(move || {
                    let mut buf = [0u8; 2048];
                    while !stop.load(Ordering::Relaxed) {
                        let Ok((n, from)) = sock.recv_from(&mut buf) else {
                            log.lock().expect("log").idle.insert(proto, Instant::now());
                            continue;
                        };
                        let at = visobjd_dmx::kernel_arrival(&sock, Instant::now());
                        let p = buf[..n].to_vec();
                        let got = std::panic::catch_unwind(|| decode(proto, &p, at, from));
                        let mut log = log.lock().expect("log");
                        match got {
                            Ok(Some((u, f))) => log.frames.entry((proto, u)).or_default().push(f),
                            Ok(None) => {}
                            Err(_) => log.malformed.push(format!(
                                "{proto:?} packet of {n} bytes: {:02x?}",
                                &p[..n.min(40)]
                            )),
                        }
                    }
                })
            })
            .collect();
        Wire {
            log,
            stop,
            threads,
            sacn_port: ports[0],
            artnet_port: ports[1],
        }
    }

    fn check(&self) {
        let log = self.log.lock().expect("log");
        assert!(log.malformed.is_empty(), "malformed: {:?}", log.malformed);
    }

    /// Every frame of `universe` from `proto` that arrived at or after `since`.
    pub fn frames(&self, proto: Proto, universe: u16, since: Instant) -> Vec<DmxPacket> {
        self.check();
        let log = self.log.lock().expect("log");
        log.frames
            .get(&(proto, universe))
            .map(|v| v.iter().filter(|f| f.at >= since).cloned().collect())
            .unwrap_or_default()
    }

    /// The latest frame of `universe` from `proto`.
    pub fn latest(&self, proto: Proto, universe: u16) -> Option<DmxPacket> {
        self.check();
        let log = self.log.lock().expect("log");
        log.frames
            .get(&(proto, universe))
            .and_then(|v| v.last().cloned())
    }

    /// Waits (bounded) until the latest frame of `universe` from `proto` satisfies `want`;
    /// returns its slots.
    pub fn wait(
        &self,
        proto: Proto,
        universe: u16,
        what: &str,
        want: impl Fn(&[u8]) -> bool,
    ) -> Vec<u8> {
        let end = Instant::now() + PATIENCE;
        loop {
            let latest = self.latest(proto, universe);
            if let Some(f) = &latest
                && want(&f.dmx)
            {
                return f.dmx.clone();
            }
            assert!(
                Instant::now() < end,
                "{proto:?} universe {universe}: never {what}; last slots {:?}",
                latest.map(|f| f.dmx[..32].to_vec())
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// [`Wire::wait`] on both protocols.
    pub fn wait_both(&self, universe: u16, what: &str, want: impl Fn(&[u8]) -> bool) {
        for proto in PROTOS {
            self.wait(proto, universe, what, &want);
        }
    }

    /// Waits until the latest frames of both universes from `proto` show `look` (within a
    /// DMX step); returns nothing or panics with the last mismatch.
    pub fn wait_look(&self, proto: Proto, look: &[LightLevel]) {
        let end = Instant::now() + PATIENCE;
        loop {
            let mismatch = match self.latest_universes(proto) {
                Some(dmx) => look_mismatch(look, &dmx),
                None => Some("no frames yet".into()),
            };
            let Some(why) = mismatch else { return };
            assert!(
                Instant::now() < end,
                "{proto:?} never showed the look {look:?}: {why}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The latest slots of every stage universe from `proto`, if each has had a frame.
    pub fn latest_universes(&self, proto: Proto) -> Option<BTreeMap<u16, Vec<u8>>> {
        UNIVERSES
            .iter()
            .map(|&u| self.latest(proto, u).map(|f| (u, f.dmx)))
            .collect()
    }

    /// The longest time in `from..to` without a frame of `universe` from `proto` (the
    /// stretches before the first and after the last frame count).
    pub fn max_gap(&self, proto: Proto, universe: u16, from: Instant, to: Instant) -> Duration {
        let times: Vec<Instant> = self
            .frames(proto, universe, from)
            .iter()
            .map(|f| f.at)
            .filter(|&t| t <= to)
            .collect();
        std::iter::once(from)
            .chain(times)
            .chain(std::iter::once(to))
            .collect::<Vec<_>>()
            .windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or_default()
    }

    /// Asserts that every universe on both protocols had no gap over `bound` in `from..to`.
    pub fn assert_continuous(&self, from: Instant, to: Instant, bound: Duration, during: &str) {
        for proto in PROTOS {
            for u in UNIVERSES {
                let gap = self.max_gap(proto, u, from, to);
                assert!(
                    gap <= bound,
                    "{proto:?} universe {u}: a gap of {gap:?} (> {bound:?}) {during}"
                );
            }
        }
    }

    /// Waits (bounded) until every universe on both protocols had a frame after `t`: only
    /// then does a gap that ends at `t` show.
    pub fn wait_frames_after(&self, t: Instant, during: &str) {
        let end = Instant::now() + PATIENCE;
        while !PROTOS
            .iter()
            .all(|&p| UNIVERSES.iter().all(|&u| !self.frames(p, u, t).is_empty()))
        {
            assert!(Instant::now() < end, "no frames after {during}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Asserts no gap over [`GAP`] from `from` until now, once later frames have arrived.
    pub fn assert_continuous_since(&self, from: Instant, during: &str) {
        let to = Instant::now();
        self.wait_frames_after(to, during);
        self.assert_continuous(from, to, GAP, during);
    }

    /// Waits until both receivers have found their sockets empty after `t`: every packet
    /// sent before `t` has been decoded.
    pub fn drained_after(&self, t: Instant) {
        let end = Instant::now() + PATIENCE;
        loop {
            let done = {
                let log = self.log.lock().expect("log");
                PROTOS
                    .iter()
                    .all(|p| log.idle.get(p).is_some_and(|&i| i > t))
            };
            if done {
                return;
            }
            assert!(Instant::now() < end, "the receivers never drained");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Wire {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// One light's slots decoded back through its profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decoded {
    /// The dimmer slot (profiles with one).
    pub intensity: Option<f32>,
    /// The linear light the emitters make (`rgbw`: the white emitter, R + G + B, added
    /// back to each);
    /// for profiles with a dimmer, the colour at full.
    pub emitters: [f32; 3],
}

pub fn decode_light(f: &PatchedLight, dmx_of_universe: &[u8]) -> Decoded {
    let s: Vec<f32> = f
        .slots(dmx_of_universe)
        .iter()
        .map(|&b| f32::from(b) / 255.0)
        .collect();
    match f.profile {
        "dimmer" => Decoded {
            intensity: Some(s[0]),
            emitters: [1.0; 3],
        },
        "irgb" => Decoded {
            intensity: Some(s[0]),
            emitters: [s[1], s[2], s[3]],
        },
        "rgb" => Decoded {
            intensity: None,
            emitters: [s[0], s[1], s[2]],
        },
        "rgbw" => Decoded {
            intensity: None,
            emitters: [s[0] + s[3], s[1] + s[3], s[2] + s[3]],
        },
        other => panic!("no decoder for {other}"),
    }
}

/// One DMX step, and a little for float rounding.
pub const STEP: f32 = 1.0 / 255.0 + 1e-4;

/// Where the slots disagree with `look` (decoded through each light's profile, within one
/// DMX step per slot involved), or `None`.
pub fn look_mismatch(look: &[LightLevel], dmx: &BTreeMap<u16, Vec<u8>>) -> Option<String> {
    assert_eq!(look.len(), STAGE.len(), "a look of every light: {look:?}");
    for l in look {
        let f = fixture(l.ch);
        let d = decode_light(&f, &dmx[&f.universe]);
        let lin = l.color.map(srgb_to_linear);
        let (want_i, want_e, tol) = match f.profile {
            "dimmer" => (Some(l.intensity), [1.0; 3], STEP),
            "irgb" => (Some(l.intensity), lin, STEP),
            "rgb" => (None, lin.map(|c| c * l.intensity), STEP),
            // rgbw: the default white emitter is R + G + B at full (D65 at Y = 1), so the
            // colour at its most light is k times it, k the largest with every emitter
            // within 0..1: W takes what R, G and B share, and at most doubles the light.
            // Each emitter plus the white slot: two roundings.
            _ => {
                let peak = lin.iter().copied().fold(0.0f32, f32::max);
                let share = if peak > 0.0 {
                    lin.iter().copied().fold(f32::MAX, f32::min) / peak
                } else {
                    0.0
                };
                let k = if share >= 0.5 {
                    2.0
                } else {
                    1.0 / (1.0 - share)
                };
                (None, lin.map(|c| c * k * l.intensity), 2.0 * STEP)
            }
        };
        let i_ok = match (d.intensity, want_i) {
            (Some(a), Some(b)) => (a - b).abs() <= STEP,
            _ => true,
        };
        let e_ok = d
            .emitters
            .iter()
            .zip(want_e)
            .all(|(a, b)| (a - b).abs() <= tol);
        if !(i_ok && e_ok) {
            return Some(format!(
                "channel {} ({}): wire says {d:?}, the look wants intensity {want_i:?} emitters {want_e:?} ({l:?})",
                l.ch, f.profile
            ));
        }
    }
    None
}

// ---- the daemon --------------------------------------------------------------------------

/// A port that is free for UDP on `udp` and TCP on `tcp` right now, and that no other call
/// in this process hands out. The ports come from below Linux's ephemeral range (which
/// starts at 32768), where the kernel never picks a port for a socket bound to port 0: a
/// daemon restarting after `kill -9` once found its port taken by another test's client
/// socket, which the kernel had given it in the moment the port was free.
pub fn free_port(udp: IpAddr, tcp: IpAddr) -> u16 {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    // Test binaries run one at a time, but give each process its own stretch anyway.
    let base = 20_000 + (std::process::id() % 24) as u16 * 500;
    loop {
        let port = base + NEXT.fetch_add(1, Ordering::Relaxed) % 500;
        if UdpSocket::bind((udp, port)).is_ok() && TcpListener::bind((tcp, port)).is_ok() {
            return port;
        }
    }
}

/// How a test daemon listens and whom it lets in; [`Setup::default`] is what
/// [`Daemon::start`] runs: everything on 127.0.0.1, the default (loopback) allow-list.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Address of `osc.udp` (the port is picked free, the same for both).
    pub udp: IpAddr,
    /// Address of `osc.tcp`.
    pub tcp: IpAddr,
    /// `osc.allow`.
    pub allow: Vec<String>,
    /// Where the harness's own clients send from: it must be allowed.
    pub client: IpAddr,
    /// TOML appended to the config (new sections).
    pub extra: String,
    /// Environment variables the daemon is started with.
    pub env: Vec<(String, String)>,
    /// A scene folder to run instead of the built test stage (copied in; the
    /// references are the test stage's).
    pub scene_from: Option<PathBuf>,
    /// Where sACN goes instead of the daemon's own [`Wire`] (a test's own receiver that
    /// several daemons send to), on 127.0.0.1.
    pub sacn_port: Option<u16>,
    /// Whether the config has an `[[output.artnet]]` (a backup may not).
    pub artnet: bool,
}

pub const LOCALHOST: IpAddr = IpAddr::V4(Ipv4Addr::LOCALHOST);

impl Default for Setup {
    fn default() -> Self {
        Setup {
            udp: LOCALHOST,
            tcp: LOCALHOST,
            allow: Vec::new(),
            client: LOCALHOST,
            extra: String::new(),
            env: Vec::new(),
            scene_from: None,
            sacn_port: None,
            artnet: true,
        }
    }
}

/// Changes the daemon's `Command` just before each start, given the daemon's folder: the
/// program, arguments and stdio are set; a test adds what a service manager would (a system
/// call filter, another user, its environment).
pub type Launch = Box<dyn FnMut(&Path, &mut Command) + Send>;

/// A running `visobjd run` with its own folder, ports and receivers. Dropping it kills the
/// daemon; the folder is removed unless the test failed.
pub struct Daemon {
    pub dir: PathBuf,
    config: PathBuf,
    pub port: u16,
    pub setup: Setup,
    child: Option<Child>,
    starts: u32,
    log: PathBuf,
    pub wire: Wire,
    osc: Udp,
    launch: Launch,
}

impl Daemon {
    /// Builds the stage in a fresh folder named after the test and starts the daemon.
    pub fn start(name: &str) -> Daemon {
        Daemon::start_setup(name, Setup::default())
    }

    /// As [`Daemon::start`], with `extra` TOML appended to the config (new sections).
    pub fn start_with(name: &str, extra: &str) -> Daemon {
        Daemon::start_setup(
            name,
            Setup {
                extra: extra.to_string(),
                ..Setup::default()
            },
        )
    }

    /// [`Daemon::start`] with other listen addresses, allow-list or extra config.
    pub fn start_setup(name: &str, setup: Setup) -> Daemon {
        Daemon::start_setup_with(name, setup, Box::new(|_, _| {}))
    }

    /// [`Daemon::start_setup`], each start (restarts too) launched through `launch`.
    pub fn start_setup_with(name: &str, setup: Setup, launch: Launch) -> Daemon {
        let dir = temp_dir(&format!("daemon-{name}"));
        build_stage(&dir);
        if let Some(from) = &setup.scene_from {
            let scene = dir.join("scene");
            std::fs::remove_dir_all(&scene).expect("remove the test stage's scene");
            copy_dir(from, &scene);
        }
        let wire = Wire::start();
        let log = dir.join("stderr-0.log");
        let mut d = Daemon {
            config: dir.join("visobjd.toml"),
            dir,
            port: 0,
            child: None,
            starts: 0,
            osc: udp_client(setup.client, SocketAddr::new(setup.udp, 0), &log),
            setup,
            log,
            wire,
            launch,
        };
        let mut last = String::new();
        for _ in 0..3 {
            // Another test may take the port between the probe and the daemon's bind.
            d.port = free_port(d.setup.udp, d.setup.tcp);
            let text = config_text(d.port, &d.setup, &d.wire) + &d.setup.extra;
            std::fs::write(&d.config, text).expect("write config");
            d.osc = d.client_from(d.setup.client);
            match d.spawn() {
                Ok(()) => return d,
                Err(e) => last = e,
            }
        }
        panic!("the daemon did not start:\n{last}");
    }

    /// Starts the process and waits until it answers `/vo/ping`.
    fn spawn(&mut self) -> Result<(), String> {
        self.launch_child();
        self.await_ready()
    }

    /// Starts the process.
    fn launch_child(&mut self) {
        self.starts += 1;
        self.log = self.dir.join(format!("stderr-{}.log", self.starts));
        self.osc.log = self.log.clone();
        let mut command = Command::new(bin());
        command
            .arg("run")
            .arg("--config")
            .arg(&self.config)
            .envs(self.setup.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(File::create(&self.log).expect("stderr file"));
        (self.launch)(&self.dir, &mut command);
        let child = command.spawn().expect("visobjd starts");
        self.child = Some(child);
    }

    /// Waits until the started process answers `/vo/ping`.
    fn await_ready(&mut self) -> Result<(), String> {
        let end = Instant::now() + Duration::from_secs(10);
        let token = TOKEN.fetch_add(1, Ordering::Relaxed);
        while Instant::now() < end {
            if let Some(status) = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten())
            {
                self.child = None;
                return Err(format!("exited with {status}:\n{}", log_tail(&self.log)));
            }
            self.osc.send("/vo/ping", vec![string("ready"), int(token)]);
            while let Some(m) = self.osc.next(Duration::from_millis(100)) {
                if m.addr == "/vo/pong" && m.args == [string("ready"), int(token)] {
                    // Later pongs of the same token may still come: take them out.
                    while self.osc.next(Duration::ZERO).is_some() {}
                    return Ok(());
                }
            }
        }
        self.kill();
        Err(format!("no /vo/pong within 10 s:\n{}", log_tail(&self.log)))
    }

    /// The references folder.
    pub fn refs(&self) -> PathBuf {
        self.dir.join("refs")
    }

    pub fn state_dir(&self) -> PathBuf {
        self.dir.join("state")
    }

    /// The config file the daemon runs.
    pub fn config_path(&self) -> &Path {
        &self.config
    }

    /// A new UDP client from its own port.
    pub fn client(&self) -> Udp {
        self.client_from(self.setup.client)
    }

    /// A new UDP client from its own port on `ip` (any loopback address).
    pub fn client_from(&self, ip: IpAddr) -> Udp {
        udp_client(ip, SocketAddr::new(self.setup.udp, self.port), &self.log)
    }

    /// A new TCP connection in `framing`.
    pub fn tcp(&self, framing: TcpFraming) -> Tcp {
        self.tcp_from(self.setup.client, framing)
    }

    /// The daemon's TCP address.
    pub fn tcp_addr(&self) -> SocketAddr {
        SocketAddr::new(self.setup.tcp, self.port)
    }

    /// A TCP connection the daemon opened (to a `[[osc.peer]]`), accepted by the test, read
    /// and written in `framing`.
    pub fn tcp_accepted(&self, stream: TcpStream, framing: TcpFraming) -> Tcp {
        Tcp {
            stream,
            framing,
            buf: Vec::new(),
            queue: VecDeque::new(),
            log: self.log.clone(),
        }
    }

    /// A new TCP connection from `ip` (any loopback address) in `framing`.
    pub fn tcp_from(&self, ip: IpAddr, framing: TcpFraming) -> Tcp {
        let stream = connect_from(ip, self.tcp_addr()).expect("TCP connect");
        stream.set_nodelay(true).expect("nodelay");
        self.tcp_accepted(stream, framing)
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("running").id()
    }

    /// The daemon's resident memory (VmRSS), in KiB.
    pub fn rss_kib(&self) -> u64 {
        let status = std::fs::read_to_string(format!("/proc/{}/status", self.pid()))
            .expect("/proc/PID/status");
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .expect("a VmRSS line")
    }

    /// How many file descriptors the daemon has open.
    pub fn open_fds(&self) -> usize {
        std::fs::read_dir(format!("/proc/{}/fd", self.pid()))
            .expect("/proc/PID/fd")
            .count()
    }

    /// Whether the process is still running (it has not exited).
    pub fn alive(&mut self) -> bool {
        self.child
            .as_mut()
            .is_some_and(|c| c.try_wait().expect("wait").is_none())
    }

    /// The whole stderr log of the current run.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// SIGKILL, and waits for the process to go.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// SIGTERM; waits (bounded) for the exit and returns its status.
    pub fn terminate(&mut self) -> ExitStatus {
        let ok = Command::new("kill")
            .args(["-TERM", &self.pid().to_string()])
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "kill -TERM failed");
        self.wait_exit("SIGTERM")
    }

    /// Waits (bounded) for the process to exit after `what`, and returns its status.
    pub fn wait_exit(&mut self, what: &str) -> ExitStatus {
        let mut child = self.child.take().expect("running");
        let end = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(status) = child.try_wait().expect("wait") {
                return status;
            }
            if Instant::now() > end {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "no exit within 10 s of {what}\n--- daemon log ---\n{}",
                    log_tail(&self.log)
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Starts the daemon again with the same config and state folder.
    pub fn restart(&mut self) {
        assert!(self.child.is_none(), "stop it first");
        if let Err(e) = self.spawn() {
            panic!("the daemon did not restart: {e}");
        }
    }

    /// [`Daemon::restart`], calling `at_first_frame` with the process id as soon as the
    /// restarted daemon's first frames are on the wire (before it answers OSC).
    pub fn restart_with_first_frames(&mut self, at_first_frame: impl FnOnce(u32)) {
        assert!(self.child.is_none(), "stop it first");
        let started = Instant::now();
        self.launch_child();
        self.wire.wait_frames_after(started, "the restart");
        at_first_frame(self.pid());
        if let Err(e) = self.await_ready() {
            panic!("the daemon did not restart: {e}");
        }
    }
}

impl Osc for Daemon {
    fn send_packet(&mut self, p: &OscPacket) {
        self.osc.send_packet(p);
    }
    fn next(&mut self, wait: Duration) -> Option<OscMessage> {
        self.osc.next(wait)
    }
    fn log(&self) -> String {
        log_tail(&self.log)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.kill();
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

fn udp_client(from: IpAddr, to: SocketAddr, log: &Path) -> Udp {
    Udp {
        sock: UdpSocket::bind((from, 0)).expect("bind a client"),
        to,
        queue: VecDeque::new(),
        log: log.to_path_buf(),
    }
}

/// A TCP connection to `to` from `ip` (std cannot bind before connecting; tokio can).
pub fn connect_from(ip: IpAddr, to: SocketAddr) -> std::io::Result<TcpStream> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()?;
    let stream = rt.block_on(async {
        let sock = match ip {
            IpAddr::V4(_) => tokio::net::TcpSocket::new_v4()?,
            IpAddr::V6(_) => tokio::net::TcpSocket::new_v6()?,
        };
        sock.bind(SocketAddr::new(ip, 0))?;
        sock.connect(to).await?.into_std()
    })?;
    stream.set_nonblocking(false)?;
    Ok(stream)
}

fn config_text(port: u16, setup: &Setup, wire: &Wire) -> String {
    // Only when set: the default config stays as short as a person would write it (and a
    // test may add its own allow line).
    let allow = if setup.allow.is_empty() {
        String::new()
    } else {
        let quoted: Vec<String> = setup.allow.iter().map(|a| format!("{a:?}")).collect();
        format!("allow = [{}]\n", quoted.join(", "))
    };
    format!(
        r#"scene = "scene"
references = "refs"
state_dir = "state"

[osc]
udp = "{udp}"
tcp = "{tcp}"
{allow}
[output]
rate_hz = {RATE_HZ}
fade_s = 0.0

[[output.sacn]]
destination = "127.0.0.1"
port = {sacn}
bind = "127.0.0.1:0"
priority = 100
source_name = "visobjd test"

{artnet}
[generate]
count = {COUNT}
clusters = {CLUSTERS}
"#,
        udp = SocketAddr::new(setup.udp, port),
        tcp = SocketAddr::new(setup.tcp, port),
        sacn = setup.sacn_port.unwrap_or(wire.sacn_port),
        artnet = if setup.artnet {
            format!(
                "[[output.artnet]]\ndestination = \"127.0.0.1\"\nport = {}\nbind = \"127.0.0.1:0\"\nuniverse_offset = {ARTNET_OFFSET}\n",
                wire.artnet_port
            )
        } else {
            String::new()
        },
    )
}
