//! DMX: how a look becomes slot values ([`patch`], through the scene's profiles), and the
//! sACN and Art-Net senders on their own clock (docs/dmx.md). It knows scenes and looks,
//! never a session.
//!
//! The engine hands over the desired state through a `tokio::sync::watch` channel and
//! never waits on the sender; a dedicated OS thread ticks at `rate_hz` with absolute
//! deadlines, computes the frame (crossfade, master, blackout) and sends one packet per
//! universe per destination. Nothing on the OSC or generate side can delay a frame, and
//! nothing here waits on the async runtime.

mod cid;
mod config;
pub mod input;
pub mod patch;
mod wire;

pub use patch::{Patch, SlotLevels};

pub use config::{ArtnetDest, InputConfig, OutputConfig, SacnDest, SacnInput};
pub use input::Input;

use std::collections::HashMap;
use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use tokio::sync::watch;
use uuid::Uuid;

use crate::patch::SLOTS;
use config::SacnTarget;
use visobjd_scene::look::Look;
use visobjd_throttle::Throttle;
use wire::SacnSource;

/// Why the output could not start.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The `[output]` section is invalid for this scene (the message names the key).
    #[error("{0}")]
    Config(String),
    /// A `bind` address could not be bound.
    #[error("output: cannot bind {addr}: {error}")]
    Bind {
        /// The configured `bind`.
        addr: SocketAddr,
        /// What the OS said.
        error: io::Error,
    },
    /// The sACN CID in `state_dir` could not be read or written.
    #[error("output: sACN CID in {dir}: {error}")]
    Cid {
        /// The state folder.
        dir: String,
        /// What the OS said.
        error: io::Error,
    },
    /// The sender thread could not be started.
    #[error("output: cannot start the sender thread: {0}")]
    Thread(io::Error),
}

/// The desired state, as the engine last set it.
#[derive(Debug, Clone)]
struct Desired {
    look: Arc<Look>,
    /// Slot levels that stand for the look (`Output::set_frame`: capture shooting one
    /// emitter alone, which no look asks for); `None`: the look's own.
    frame: Option<Arc<SlotLevels>>,
    /// Bumped by every `set_look`, so the clock sees a new target even if equal.
    generation: u64,
    fade: Duration,
    since: Instant,
    master: f32,
    blackout: bool,
}

/// Counters the clock thread updates; read by [`Output::stats`].
#[derive(Debug)]
struct Counters {
    frames: Vec<AtomicU64>,
    send_errors: AtomicU64,
    worst_late_us: AtomicU64,
    /// Ticks of the clock since start: the watchdog pings only while this advances.
    ticks: AtomicU64,
    /// Ticks that woke more than half a period after their deadline.
    late_ticks: AtomicU64,
    /// Ticks per second over the last whole second, as `f32` bits.
    tick_rate: AtomicU32,
    /// Per destination (sACN ones first, in config order): its label and failed sends.
    destinations: Vec<(String, AtomicU64)>,
    hooks: Hooks,
}

/// Faults a test can inject into the clock (the daemon enables them only under
/// `VISOBJD_TEST_HOOKS`), to check that the watchdog and the service manager notice.
#[derive(Debug, Default)]
struct Hooks {
    /// While set, the clock sends nothing and its tick count stands still.
    stall: AtomicBool,
    /// When set, the clock thread panics at its next tick.
    panic: AtomicBool,
}

/// A snapshot of the output's counters, for status and benchmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputStats {
    /// (scene universe, frames sent): a frame counts once however many destinations got it.
    pub frames: Vec<(u16, u64)>,
    /// Failed sends (packets) since start, all destinations together.
    pub send_errors: u64,
    /// The latest any tick woke after its deadline.
    pub worst_lateness: Duration,
    /// Ticks of the clock since start (one computed frame each, sent or idled).
    pub ticks: u64,
    /// Ticks that woke more than half a period after their deadline.
    pub late_ticks: u64,
    /// Ticks per second over the last whole second (0 until a second has passed).
    pub tick_rate: f32,
    /// Per destination: a label such as `sACN 10.101.0.5:5568` and its failed sends.
    pub destinations: Vec<(String, u64)>,
}

impl OutputStats {
    /// One phrase for a status line: `DMX 44 fps`, with the late frames and failed sends
    /// when there are any.
    pub fn summary(&self) -> String {
        let mut out = format!("DMX {:.0} fps", self.tick_rate);
        if self.late_ticks > 0 {
            out += &format!(", {} late", self.late_ticks);
        }
        if self.send_errors > 0 {
            out += &format!(", {} send errors", self.send_errors);
        }
        out
    }
}

/// The running output. Dropping it stops the clock like [`Output::shutdown`].
#[derive(Debug)]
pub struct Output {
    desired: watch::Sender<Desired>,
    counters: Arc<Counters>,
    universes: Vec<u16>,
    cid: Uuid,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Output {
    /// Validates `config` for `patch`, loads or makes the sACN CID in `state_dir`, binds
    /// the sockets and starts sending `initial` at once (master 1, no blackout).
    pub fn start(
        config: &OutputConfig,
        patch: Patch,
        state_dir: &Path,
        initial: Look,
    ) -> Result<Output, OutputError> {
        config
            .validate(patch.universes())
            .map_err(OutputError::Config)?;
        let cid = cid::load_or_create(state_dir).map_err(|error| OutputError::Cid {
            dir: state_dir.display().to_string(),
            error,
        })?;
        let mut sockets = Sockets::default();
        let mut sacn = Vec::new();
        let mut destinations = Vec::new();
        for d in &config.sacn {
            let target = d.target().map_err(OutputError::Config)?;
            destinations.push((
                format!("sACN {}:{}", d.destination, d.port),
                AtomicU64::new(0),
            ));
            sacn.push(SacnSink {
                route: Route {
                    socket: sockets.bind(d.bind)?,
                    errors: destinations.len() - 1,
                    protocol: "sACN",
                    log: Throttle::default(),
                },
                target,
                port: d.port,
                source_name: d.source_name.clone(),
                priority: d.priority,
                sync_universe: d.sync_universe,
                sync_sequence: 0,
            });
        }
        let mut artnet = Vec::new();
        for d in &config.artnet {
            let ip = d.address().map_err(OutputError::Config)?;
            let port_addresses = patch
                .universes()
                .iter()
                .map(|&u| d.port_address(u))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| OutputError::Config("output.artnet: bad universe_offset".into()))?;
            destinations.push((
                format!("Art-Net {}:{}", d.destination, d.port),
                AtomicU64::new(0),
            ));
            artnet.push(ArtnetSink {
                route: Route {
                    socket: sockets.bind(d.bind)?,
                    errors: destinations.len() - 1,
                    protocol: "Art-Net",
                    log: Throttle::default(),
                },
                to: SocketAddr::new(ip, d.port),
                port_addresses,
                discover: d.discover,
                nodes: Vec::new(),
            });
        }

        let mut art_sockets: Vec<usize> = artnet.iter().map(|s| s.route.socket).collect();
        art_sockets.sort_unstable();
        art_sockets.dedup();
        let universes = patch.universes().to_vec();
        let counters = Arc::new(Counters {
            frames: universes.iter().map(|_| AtomicU64::new(0)).collect(),
            send_errors: AtomicU64::new(0),
            worst_late_us: AtomicU64::new(0),
            ticks: AtomicU64::new(0),
            late_ticks: AtomicU64::new(0),
            tick_rate: AtomicU32::new(0),
            destinations,
            hooks: Hooks::default(),
        });
        let now = Instant::now();
        let initial = Arc::new(initial);
        let (desired, rx) = watch::channel(Desired {
            look: initial.clone(),
            frame: None,
            generation: 0,
            fade: Duration::ZERO,
            since: now,
            master: 1.0,
            blackout: false,
        });
        let target = patch.unmastered(&initial);
        let n = universes.len();
        let stop = Arc::new(AtomicBool::new(false));
        let clock = Clock {
            period: Duration::from_secs_f64(1.0 / f64::from(config.rate_hz)),
            keepalive: config.idle_keepalive,
            rx,
            generation: 0,
            from: target.clone(),
            target,
            fade_start: now,
            fade: Duration::ZERO,
            master: 1.0,
            blackout: false,
            patch,
            sockets: sockets.list,
            sacn,
            artnet,
            cid,
            sacn_sequence: vec![0; n],
            artnet_sequence: vec![0; n],
            idle: vec![Idle::default(); n],
            last: vec![[0; SLOTS]; n],
            counters: counters.clone(),
            stop: stop.clone(),
            buf: Vec::with_capacity(700),
            art_sockets,
            poll_due: now,
            discovery_due: now,
        };
        let thread = thread::Builder::new()
            .name("dmx-output".into())
            .spawn(move || {
                // A clock that died would leave a dark stage behind a live process (and
                // its OSC answering): end the process instead, so the service manager
                // restarts it and the saved live look is back on the wire at once.
                if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| clock.run())).is_err() {
                    tracing::error!(
                        "the DMX output clock panicked: aborting so that the service restarts"
                    );
                    std::process::abort();
                }
            })
            .map_err(OutputError::Thread)?;
        Ok(Output {
            desired,
            counters,
            universes,
            cid,
            stop,
            thread: Some(thread),
        })
    }

    /// Crossfades from what is on the wire now to `look` over `fade_s` seconds (0, less or
    /// not finite: at once; at most an hour). Never blocks on the sender.
    pub fn set_look(&self, look: Look, fade_s: f32) {
        let fade = if fade_s.is_finite() && fade_s > 0.0 {
            Duration::from_secs_f32(fade_s.min(3600.0))
        } else {
            Duration::ZERO
        };
        let look = Arc::new(look);
        self.desired.send_modify(|d| {
            d.look = look;
            d.frame = None;
            d.generation += 1;
            d.fade = fade;
            d.since = Instant::now();
        });
    }

    /// Puts `frame` (unmastered slot levels of this output's patch, as
    /// [`Patch::emitter_alone`] makes them) on the wire at once, standing for `look`
    /// until the next [`Output::set_look`]: what capture uses to light one emitter alone,
    /// or a look solved through another patch.
    pub fn set_frame(&self, look: Look, frame: SlotLevels) {
        let (look, frame) = (Arc::new(look), Arc::new(frame));
        self.desired.send_modify(|d| {
            d.look = look;
            d.frame = Some(frame);
            d.generation += 1;
            d.fade = Duration::ZERO;
            d.since = Instant::now();
        });
    }

    /// Sets the grand master (0..1); applies at once, including during a fade.
    pub fn set_master(&self, master: f32) {
        self.desired.send_modify(|d| d.master = master);
    }

    /// Blackout on: every slot 0 at once. Off: back at once to the (possibly fading) look.
    pub fn set_blackout(&self, on: bool) {
        self.desired.send_modify(|d| d.blackout = on);
    }

    /// The sACN CID this output sends (for status and the `check` command).
    pub fn cid(&self) -> Uuid {
        self.cid
    }

    /// The counters so far.
    pub fn stats(&self) -> OutputStats {
        let c = &*self.counters;
        OutputStats {
            frames: self
                .universes
                .iter()
                .zip(&c.frames)
                .map(|(&u, n)| (u, n.load(Ordering::Relaxed)))
                .collect(),
            send_errors: c.send_errors.load(Ordering::Relaxed),
            worst_lateness: Duration::from_micros(c.worst_late_us.load(Ordering::Relaxed)),
            ticks: c.ticks.load(Ordering::Relaxed),
            late_ticks: c.late_ticks.load(Ordering::Relaxed),
            tick_rate: f32::from_bits(c.tick_rate.load(Ordering::Relaxed)),
            destinations: c
                .destinations
                .iter()
                .map(|(name, n)| (name.clone(), n.load(Ordering::Relaxed)))
                .collect(),
        }
    }

    /// Test hook: holds the clock still (nothing sent, no ticks) while `on`.
    pub fn stall(&self, on: bool) {
        self.counters.hooks.stall.store(on, Ordering::Relaxed);
        if let Some(t) = &self.thread {
            t.thread().unpark();
        }
    }

    /// Test hook: makes the clock thread panic at its next tick (the process then aborts).
    pub fn panic_clock(&self) {
        self.counters.hooks.panic.store(true, Ordering::Relaxed);
    }

    /// Orderly stop: the clock finishes its tick, sends three Stream_Terminated packets per
    /// universe to every sACN destination, and its thread is joined.
    pub fn shutdown(mut self) {
        self.stop_clock();
    }

    fn stop_clock(&mut self) {
        if let Some(thread) = self.thread.take() {
            self.stop.store(true, Ordering::Release);
            thread.thread().unpark();
            // Never an unwound panic: the clock aborts the process instead.
            let _ = thread.join();
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        self.stop_clock();
    }
}

/// Sockets by bind address: destinations with the same fixed `bind` (e.g. port 6454)
/// share one socket, since binding it twice would fail without SO_REUSEPORT.
#[derive(Default)]
struct Sockets {
    list: Vec<UdpSocket>,
    fixed: HashMap<SocketAddr, usize>,
}

impl Sockets {
    fn bind(&mut self, addr: SocketAddr) -> Result<usize, OutputError> {
        if addr.port() != 0
            && let Some(&i) = self.fixed.get(&addr)
        {
            return Ok(i);
        }
        let err = |error| OutputError::Bind { addr, error };
        let socket = UdpSocket::bind(addr).map_err(err)?;
        // Never let a full send buffer stall the clock: such a packet is an error, not a wait.
        socket.set_nonblocking(true).map_err(err)?;
        // Art-Net may go to a directed broadcast address.
        socket.set_broadcast(true).map_err(err)?;
        self.list.push(socket);
        if addr.port() != 0 {
            self.fixed.insert(addr, self.list.len() - 1);
        }
        Ok(self.list.len() - 1)
    }
}

/// Where a destination's packets leave from, and its failures: the socket, its counter in
/// [`Counters::destinations`], its rate-limited log.
struct Route {
    socket: usize,
    errors: usize,
    protocol: &'static str,
    log: Throttle,
}

impl Route {
    /// Sends one encoded packet; a failure (encoding or socket) is counted and logged at a
    /// rate-limited pace, never fatal: the clock goes on.
    fn send(
        &mut self,
        sockets: &[UdpSocket],
        counters: &Counters,
        now: Instant,
        to: SocketAddr,
        packet: Result<&[u8], String>,
    ) {
        let socket = &sockets[self.socket];
        let result =
            packet.and_then(|p| socket.send_to(p, to).map(drop).map_err(|e| e.to_string()));
        if let Err(e) = result {
            counters.send_errors.fetch_add(1, Ordering::Relaxed);
            counters.destinations[self.errors]
                .1
                .fetch_add(1, Ordering::Relaxed);
            send_failed(&mut self.log, now, self.protocol, to, &e);
        }
    }
}

/// Logs a failed send to `to` through its destination's throttle: one line per 10 s at
/// most, with the count of failures left out since the last.
fn send_failed(log: &mut Throttle, now: Instant, protocol: &str, to: SocketAddr, error: &str) {
    if let Some(suppressed) = log.allow(now) {
        tracing::warn!(
            protocol,
            destination = %to,
            error,
            suppressed,
            "DMX send failed (further failures to this destination are logged at most every 10 s)"
        );
    }
}

struct SacnSink {
    route: Route,
    target: SacnTarget,
    port: u16,
    source_name: String,
    priority: u8,
    sync_universe: u16,
    sync_sequence: u8,
}

impl SacnSink {
    fn address(&self, universe: u16) -> SocketAddr {
        match self.target {
            SacnTarget::Unicast(ip) => SocketAddr::new(ip, self.port),
            SacnTarget::Multicast => SocketAddr::new(
                IpAddr::V4(Ipv4Addr::new(
                    239,
                    255,
                    (universe >> 8) as u8,
                    (universe & 0xff) as u8,
                )),
                self.port,
            ),
        }
    }
}

struct ArtnetSink {
    route: Route,
    to: SocketAddr,
    /// Per patched universe.
    port_addresses: Vec<u16>,
    /// ArtPoll to `to`, ArtDmx unicast to [`ArtnetSink::nodes`] (`discover = true`).
    discover: bool,
    nodes: Vec<Node>,
}

/// An Art-Net node that answered ArtPoll: where it is and what it outputs.
#[derive(Debug, Clone)]
struct Node {
    ip: IpAddr,
    /// Its reply's BindIndex: a node with many ports answers once per group of four.
    bind_index: u8,
    /// The port-addresses its output ports take from the network.
    outputs: Vec<u16>,
    seen: Instant,
}

/// How often a discovering Art-Net destination polls (Art-Net 4: every 2.5 to 3 s).
const POLL_EVERY: Duration = Duration::from_secs(3);
/// A node silent this long (three polls and a margin) is gone.
const NODE_GONE: Duration = Duration::from_secs(10);
/// How often E1.31 universe discovery goes out (E1.31-2018 8: every 10 s).
const DISCOVERY_EVERY: Duration = Duration::from_secs(10);
/// The universe whose multicast group carries E1.31 universe discovery.
const DISCOVERY_UNIVERSE: u16 = 64214;

impl ArtnetSink {
    /// Records (or refreshes) a node's ArtPollReply.
    fn found(&mut self, ip: IpAddr, bind_index: u8, outputs: &[u16], now: Instant) {
        match self
            .nodes
            .iter_mut()
            .find(|n| n.ip == ip && n.bind_index == bind_index)
        {
            Some(node) => {
                node.outputs = outputs.to_vec();
                node.seen = now;
            }
            None => {
                tracing::info!(node = %ip, bind_index, ?outputs, "Art-Net node found");
                self.nodes.push(Node {
                    ip,
                    bind_index,
                    outputs: outputs.to_vec(),
                    seen: now,
                });
            }
        }
    }
}

/// The local IPv4 address the system would send to `peer` from (for an ArtPollReply from
/// a socket bound to the wildcard address); unspecified when there is no route.
fn route_to(peer: SocketAddr) -> Ipv4Addr {
    UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
        .and_then(|s| s.connect(peer).and_then(|()| s.local_addr()))
        .ok()
        .and_then(|a| match a.ip() {
            IpAddr::V4(ip) => Some(ip),
            IpAddr::V6(_) => None,
        })
        .unwrap_or(Ipv4Addr::UNSPECIFIED)
}

/// Keep-alive bookkeeping of one universe.
#[derive(Debug, Clone, Copy, Default)]
struct Idle {
    /// Repeats of unchanged data sent so far (up to 3).
    repeats: u8,
    last_sent: Option<Instant>,
}

/// The sender thread's state.
struct Clock {
    period: Duration,
    keepalive: bool,
    rx: watch::Receiver<Desired>,
    generation: u64,
    from: SlotLevels,
    target: SlotLevels,
    fade_start: Instant,
    fade: Duration,
    master: f32,
    blackout: bool,
    patch: Patch,
    sockets: Vec<UdpSocket>,
    sacn: Vec<SacnSink>,
    artnet: Vec<ArtnetSink>,
    cid: Uuid,
    /// Per universe, shared by all sACN destinations (one stream per universe per CID).
    sacn_sequence: Vec<u8>,
    /// Per universe, shared by all Art-Net destinations.
    artnet_sequence: Vec<u8>,
    idle: Vec<Idle>,
    /// The bytes last sent per universe.
    last: Vec<[u8; SLOTS]>,
    counters: Arc<Counters>,
    stop: Arc<AtomicBool>,
    buf: Vec<u8>,
    /// The sockets Art-Net destinations send from, each once: where polls and replies
    /// arrive (fixed at start, so the clock never rebuilds the list).
    art_sockets: Vec<usize>,
    /// When discovering Art-Net destinations poll next.
    poll_due: Instant,
    /// When E1.31 universe discovery goes out next.
    discovery_due: Instant,
}

impl Clock {
    fn run(mut self) {
        let mut next = Instant::now();
        let mut first = true;
        let mut window = (next, 0u64);
        loop {
            // Wait for the deadline; an unpark from shutdown ends the wait early.
            loop {
                if self.stop.load(Ordering::Acquire) {
                    self.terminate();
                    return;
                }
                let now = Instant::now();
                if now >= next {
                    break;
                }
                thread::park_timeout(next - now);
            }
            self.test_hooks();
            let now = Instant::now();
            let late = now.saturating_duration_since(next);
            let c = &*self.counters;
            c.worst_late_us
                .fetch_max(late.as_micros() as u64, Ordering::Relaxed);
            if late > self.period / 2 {
                c.late_ticks.fetch_add(1, Ordering::Relaxed);
            }
            let ticks = c.ticks.fetch_add(1, Ordering::Relaxed) + 1;
            let span = now.duration_since(window.0);
            if span >= Duration::from_secs(1) {
                let rate = (ticks - window.1) as f64 / span.as_secs_f64();
                c.tick_rate
                    .store((rate as f32).to_bits(), Ordering::Relaxed);
                window = (now, ticks);
            }
            if late > self.period {
                // Too late to catch up frame by frame: restart the schedule from now.
                next = now;
            }
            self.tick(now, first);
            first = false;
            next += self.period;
        }
    }

    /// The faults a test asked for: a panic, or a stall until released (or stopped).
    fn test_hooks(&self) {
        let hooks = &self.counters.hooks;
        if hooks.panic.load(Ordering::Relaxed) {
            panic!("test hook: the DMX output clock panics");
        }
        while hooks.stall.load(Ordering::Relaxed) && !self.stop.load(Ordering::Acquire) {
            thread::park_timeout(Duration::from_millis(10));
        }
    }

    /// The unmastered levels at `now`.
    fn levels_at(&self, now: Instant) -> SlotLevels {
        let elapsed = now.saturating_duration_since(self.fade_start);
        if self.fade.is_zero() || elapsed >= self.fade {
            self.target.clone()
        } else {
            let t = elapsed.as_secs_f32() / self.fade.as_secs_f32();
            SlotLevels::crossfade(&self.from, &self.target, t)
        }
    }

    /// Takes in the engine's latest state, if it changed.
    fn update(&mut self, now: Instant) {
        if !self.rx.has_changed().unwrap_or(false) {
            return;
        }
        let d = self.rx.borrow_and_update().clone();
        if d.generation != self.generation {
            self.from = self.levels_at(now);
            self.target = match &d.frame {
                Some(f) => (**f).clone(),
                None => self.patch.unmastered(&d.look),
            };
            self.fade_start = d.since;
            self.fade = d.fade;
            self.generation = d.generation;
        }
        self.master = d.master;
        self.blackout = d.blackout;
    }

    fn tick(&mut self, now: Instant, first: bool) {
        self.update(now);
        let wire = if self.blackout {
            self.patch.blackout()
        } else {
            self.patch.mastered(&self.levels_at(now), self.master)
        };
        let bytes = self.patch.quantise(&wire);
        let mut sent_any = false;
        for (u, data) in bytes.iter().enumerate() {
            if !self.due(u, data, now, first) {
                continue;
            }
            self.send_universe(u, data, false, now);
            self.last[u] = *data;
            self.counters.frames[u].fetch_add(1, Ordering::Relaxed);
            sent_any = true;
        }
        if sent_any {
            self.send_syncs(now);
        }
        self.discovery(now);
    }

    /// Art-Net's poll and reply and E1.31's universe discovery: what arrived on the
    /// Art-Net sockets (non-blocking: one call that finds nothing on a quiet network), and
    /// the periodic announcements when due.
    fn discovery(&mut self, now: Instant) {
        self.receive_artnet(now);
        if now >= self.poll_due {
            self.poll_due = now + POLL_EVERY;
            let poll = wire::artpoll();
            for sink in self.artnet.iter_mut().filter(|s| s.discover) {
                sink.nodes
                    .retain(|n| now.duration_since(n.seen) < NODE_GONE);
                let packet = poll.as_deref().map_err(Clone::clone);
                sink.route
                    .send(&self.sockets, &self.counters, now, sink.to, packet);
            }
        }
        if now >= self.discovery_due {
            self.discovery_due = now + DISCOVERY_EVERY;
            self.send_universe_discovery(now);
        }
    }

    /// Answers ArtPolls and records the nodes' ArtPollReplies, from every socket an
    /// Art-Net destination sends from.
    fn receive_artnet(&mut self, now: Instant) {
        let mut packet = [0u8; 600];
        for k in 0..self.art_sockets.len() {
            let i = self.art_sockets[k];
            // A bounded drain: a flood cannot hold the clock.
            for _ in 0..64 {
                let Ok((n, from)) = self.sockets[i].recv_from(&mut packet) else {
                    break;
                };
                match wire::parse_artnet_in(&packet[..n]) {
                    Some(wire::ArtIn::Poll) => self.answer_poll(i, from, now),
                    Some(wire::ArtIn::Reply {
                        bind_index,
                        outputs,
                    }) => {
                        for sink in self
                            .artnet
                            .iter_mut()
                            .filter(|s| s.discover && s.route.socket == i)
                        {
                            sink.found(from.ip(), bind_index, &outputs, now);
                        }
                    }
                    None => {}
                }
            }
        }
    }

    /// ArtPollReply to whoever polled socket `i`, for every destination sending from it,
    /// back to the poller's address and port (6454 for Art-Net gear, which sends from it).
    fn answer_poll(&mut self, i: usize, from: SocketAddr, now: Instant) {
        let ip = match self.sockets[i].local_addr().map(|a| a.ip()) {
            Ok(IpAddr::V4(ip)) if !ip.is_unspecified() => ip,
            _ => route_to(from),
        };
        for sink in self.artnet.iter_mut().filter(|s| s.route.socket == i) {
            match wire::artpollreplies(ip, &sink.port_addresses) {
                Ok(replies) => {
                    for reply in &replies {
                        sink.route
                            .send(&self.sockets, &self.counters, now, from, Ok(reply));
                    }
                }
                Err(e) => sink
                    .route
                    .send(&self.sockets, &self.counters, now, from, Err(e)),
            }
        }
    }

    /// E1.31 universe discovery (E1.31-2018 8): every universe this source sends, in
    /// pages of 512, to each sACN destination: the discovery universe's multicast group,
    /// or the unicast receiver.
    fn send_universe_discovery(&mut self, now: Instant) {
        let universes = self.patch.universes().to_vec();
        let pages: Vec<&[u16]> = universes.chunks(wire::DISCOVERY_PAGE).collect();
        let last = (pages.len().max(1) - 1).min(255) as u8;
        for sink in &mut self.sacn {
            let to = sink.address(DISCOVERY_UNIVERSE);
            for (page, list) in pages.iter().enumerate().take(256) {
                let packet = wire::sacn_discovery(
                    self.cid,
                    &sink.source_name,
                    page as u8,
                    last,
                    list,
                    &mut self.buf,
                )
                .map(|()| self.buf.as_slice());
                sink.route
                    .send(&self.sockets, &self.counters, now, to, packet);
            }
        }
    }

    /// Whether universe `u` goes out this tick (always, unless keep-alive is idling it).
    fn due(&mut self, u: usize, data: &[u8; SLOTS], now: Instant, first: bool) -> bool {
        let idle = &mut self.idle[u];
        let send = if !self.keepalive || first || *data != self.last[u] {
            idle.repeats = 0;
            true
        } else if idle.repeats < 3 {
            idle.repeats += 1;
            true
        } else {
            idle.last_sent
                .is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1))
        };
        if send {
            idle.last_sent = Some(now);
        }
        send
    }

    fn send_universe(&mut self, u: usize, data: &[u8; SLOTS], terminated: bool, now: Instant) {
        let universe = self.patch.universes()[u];
        self.sacn_sequence[u] = wire::next_sacn_sequence(self.sacn_sequence[u]);
        let seq = self.sacn_sequence[u];
        for sink in &mut self.sacn {
            let to = sink.address(universe);
            let src = SacnSource {
                cid: self.cid,
                source_name: &sink.source_name,
                priority: sink.priority,
                sync_universe: sink.sync_universe,
            };
            let packet = wire::sacn_data(&src, universe, seq, terminated, data, &mut self.buf)
                .map(|()| self.buf.as_slice());
            sink.route
                .send(&self.sockets, &self.counters, now, to, packet);
        }
        if terminated || self.artnet.is_empty() {
            return;
        }
        self.artnet_sequence[u] = wire::next_artnet_sequence(self.artnet_sequence[u]);
        let seq = self.artnet_sequence[u];
        for sink in &mut self.artnet {
            let pa = sink.port_addresses[u];
            let packet = wire::artdmx(pa, seq, data);
            let packet = packet.as_deref().map_err(Clone::clone);
            let mut to_node = |to| {
                sink.route
                    .send(&self.sockets, &self.counters, now, to, packet.clone())
            };
            if sink.discover {
                for node in sink.nodes.iter().filter(|n| n.outputs.contains(&pa)) {
                    to_node(SocketAddr::new(node.ip, sink.to.port()));
                }
            } else {
                to_node(sink.to);
            }
        }
    }

    /// One synchronization packet per sACN destination with a sync universe, after a frame.
    fn send_syncs(&mut self, now: Instant) {
        for sink in self.sacn.iter_mut().filter(|s| s.sync_universe != 0) {
            sink.sync_sequence = wire::next_sacn_sequence(sink.sync_sequence);
            let to = sink.address(sink.sync_universe);
            let packet = wire::sacn_sync(
                self.cid,
                sink.sync_universe,
                sink.sync_sequence,
                &mut self.buf,
            )
            .map(|()| self.buf.as_slice());
            sink.route
                .send(&self.sockets, &self.counters, now, to, packet);
        }
    }

    /// E1.31 6.2.6: three packets with Stream_Terminated per universe, so receivers
    /// release the universe at once instead of holding the last look for 2.5 s.
    fn terminate(&mut self) {
        let now = Instant::now();
        for _ in 0..3 {
            for u in 0..self.last.len() {
                let data = self.last[u];
                self.send_universe(u, &data, true, now);
            }
        }
    }
}

/// When the kernel received `sock`'s last packet, as an `Instant` (`now` where the kernel
/// cannot tell). For receivers that time our frames (the bench, the tests): a receiver
/// thread that runs late on a busy machine must not make the sender look late.
pub fn kernel_arrival(sock: &UdpSocket, now: Instant) -> Instant {
    use std::os::fd::AsRawFd;
    use std::time::{SystemTime, UNIX_EPOCH};
    /// Linux's "time stamp of the last packet received" socket ioctl.
    const SIOCGSTAMP: u64 = 0x8906;
    let mut tv = libc::timeval {
        tv_sec: 0,
        tv_usec: 0,
    };
    // SAFETY: SIOCGSTAMP writes one timeval into `tv`, which outlives the call.
    let r = unsafe { libc::ioctl(sock.as_raw_fd(), SIOCGSTAMP as _, &mut tv) };
    let stamp = UNIX_EPOCH + Duration::new(tv.tv_sec as u64, tv.tv_usec as u32 * 1000);
    match SystemTime::now().duration_since(stamp) {
        Ok(age) if r == 0 && age < Duration::from_secs(5) => now.checked_sub(age).unwrap_or(now),
        _ => now,
    }
}
