//! The console input (`[input.sacn]`, docs/dmx.md): an E1.31 receiver on its own thread that
//! owns its socket, reads packets itself ([`packet`]) and merges sources as E1.31 receivers
//! do ([`merge`], pure). The engine reads the merged console output when it needs it and
//! hears of changes through a watch channel; nothing here waits on the engine or on the
//! DMX output clock.
//!
//! The `sacn` crate's receiver is not used: it merges only synchronised data (consoles
//! mostly send unsynchronised), passes 0xDD packets through as levels, and its `recv`
//! recurses while idle.

mod merge;
mod packet;

pub use merge::{Merger, SAMPLE, SOURCE_LOSS, SourceInfo, Verdict};
pub use packet::{DataPacket, PER_ADDRESS_PRIORITY, parse};

use std::collections::HashSet;
use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use tokio::sync::watch;
use uuid::Uuid;
use visobjd_throttle::Throttle;

use crate::config::SacnInput;
use crate::patch::SLOTS;

/// How often the receiver wakes without packets, to notice lost and newly sampled sources
/// and a stop.
const IDLE_WAKE: Duration = Duration::from_millis(100);

/// The merged console output for some universes.
#[derive(Debug, Clone, PartialEq)]
pub struct Console {
    /// One 512-slot buffer per universe asked for (zeros where no source counts).
    pub dmx: Vec<[u8; SLOTS]>,
    /// Sources that count in the merge of those universes now.
    pub sources: usize,
    /// Per universe asked for, whether a source counts on it now: a zero there is the
    /// console's only when it does (learning positions reads only those).
    pub received: Vec<bool>,
}

/// The input's socket, bound and joined, not yet read ([`Input::open`]).
#[derive(Debug)]
pub struct InputSocket {
    socket: UdpSocket,
    bind: SocketAddr,
    interface: Option<Ipv4Addr>,
}

/// The running receiver. Dropping it stops the thread like [`Input::shutdown`].
#[derive(Debug)]
pub struct Input {
    merger: Arc<Mutex<Merger>>,
    changes: watch::Receiver<u64>,
    bind: SocketAddr,
    universes: Vec<u16>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Input {
    /// Binds `config.bind` and joins the universes' multicast groups on
    /// `config.interface` (if set): the daemon binds every socket before its first DMX
    /// frame. The error is a sentence naming the key.
    pub fn open(config: &SacnInput) -> Result<InputSocket, String> {
        let (bind, interface) = config.addresses()?;
        let socket = UdpSocket::bind(bind)
            .map_err(|e| format!("input.sacn.bind: cannot bind {bind}: {e}"))?;
        if let Some(interface) = interface {
            for &u in &config.universes {
                let [hi, lo] = u.to_be_bytes();
                let group = Ipv4Addr::new(239, 255, hi, lo);
                socket.join_multicast_v4(&group, &interface).map_err(|e| {
                    format!(
                        "input.sacn.interface: cannot join {group} (universe {u}) on {interface}: {e}"
                    )
                })?;
            }
        }
        socket
            .set_read_timeout(Some(IDLE_WAKE))
            .map_err(|e| format!("input.sacn: cannot set a read timeout: {e}"))?;
        Ok(InputSocket {
            socket,
            bind,
            interface,
        })
    }

    /// Starts receiving on `socket` (from [`Input::open`] with the same `config`).
    /// Packets from `own` (visobjd's output CID) are ignored, and so are, before anything
    /// else is done with them, packets from senders `permits` refuses (each logged once).
    pub fn start(
        config: &SacnInput,
        socket: InputSocket,
        own: Uuid,
        permits: Permits,
    ) -> Result<Input, String> {
        let InputSocket {
            socket,
            bind,
            interface,
        } = socket;
        let merger = Arc::new(Mutex::new(Merger::new(own, &config.universes)));
        let (tx, changes) = watch::channel(0u64);
        let stop = Arc::new(AtomicBool::new(false));
        let receiver = Receiver {
            permits,
            socket,
            merger: merger.clone(),
            universes: config.universes.clone(),
            changes: tx,
            stop: stop.clone(),
        };
        let thread = thread::Builder::new()
            .name("sacn-input".into())
            .spawn(move || receiver.run())
            .map_err(|e| format!("input.sacn: cannot start the receiver thread: {e}"))?;
        tracing::info!(
            "sACN input on {bind}{}, universes {:?}",
            interface.map_or(String::new(), |i| format!(" (multicast on {i})")),
            config.universes
        );
        Ok(Input {
            merger,
            changes,
            bind,
            universes: config.universes.clone(),
            stop,
            thread: Some(thread),
        })
    }

    fn merger(&self) -> MutexGuard<'_, Merger> {
        lock(&self.merger)
    }

    /// The merged console output of `universes` (a patch's, in its order) now.
    pub fn console(&self, universes: &[u16]) -> Console {
        let now = Instant::now();
        let m = self.merger();
        let merged: Vec<Option<[u8; SLOTS]>> =
            universes.iter().map(|&u| m.merged(u, now)).collect();
        let received = merged.iter().map(Option::is_some).collect();
        let dmx = merged
            .into_iter()
            .map(|d| d.unwrap_or([0; SLOTS]))
            .collect();
        let sources = m
            .sources(now)
            .iter()
            .filter(|s| s.active && s.universes.iter().any(|u| universes.contains(u)))
            .count();
        Console {
            dmx,
            sources,
            received,
        }
    }

    /// The sources seen now (sampled or counting; lost ones are gone).
    pub fn sources(&self) -> Vec<SourceInfo> {
        let now = Instant::now();
        let mut m = self.merger();
        m.expire(now);
        m.sources(now)
    }

    /// A counter bumped whenever the merged output of any universe changes.
    pub fn changes(&self) -> watch::Receiver<u64> {
        self.changes.clone()
    }

    /// Where it listens, for messages.
    pub fn bind(&self) -> SocketAddr {
        self.bind
    }

    /// The universes it receives.
    pub fn universes(&self) -> &[u16] {
        &self.universes
    }

    /// Stops the receiver thread (it wakes within [`IDLE_WAKE`]).
    pub fn shutdown(mut self) {
        self.stop_thread();
    }

    fn stop_thread(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            tracing::error!("the sACN input thread panicked");
        }
    }
}

impl Drop for Input {
    fn drop(&mut self) {
        self.stop_thread();
    }
}

fn lock(m: &Mutex<Merger>) -> MutexGuard<'_, Merger> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Who may feed the input: the daemon's allow-list rule for `[input.sacn] allow`.
pub type Permits = Box<dyn Fn(IpAddr) -> bool + Send>;

/// How many refused senders are each named in the log; past them, refusals are counted
/// in a line at most every 10 s.
const NAMED_REFUSALS: usize = 64;

/// The receiver thread's state.
struct Receiver {
    permits: Permits,
    socket: UdpSocket,
    merger: Arc<Mutex<Merger>>,
    universes: Vec<u16>,
    changes: watch::Sender<u64>,
    stop: Arc<AtomicBool>,
}

impl Receiver {
    fn run(self) {
        // An E1.31 data packet is 638 bytes at most; a larger datagram is cut and refused.
        let mut buf = [0u8; 2048];
        let mut malformed = Throttle::default();
        let mut failed = Throttle::default();
        let mut last: Vec<Option<[u8; SLOTS]>> = Vec::new();
        let mut refused: HashSet<IpAddr> = HashSet::new();
        let mut refused_more = Throttle::default();
        let mut too_many = Throttle::default();
        while !self.stop.load(Ordering::Acquire) {
            let got = self.socket.recv_from(&mut buf);
            let now = Instant::now();
            // A refused sender costs one address check: no parse, no lock, no merge.
            if let Ok((_, from)) = &got
                && !(self.permits)(from.ip())
            {
                if refused.len() < NAMED_REFUSALS {
                    if refused.insert(from.ip()) {
                        tracing::warn!(
                            "sACN input: refused {}, not in input.sacn.allow (logged once per sender)",
                            from.ip()
                        );
                    }
                } else if let Some(suppressed) = refused_more.allow(now) {
                    tracing::warn!(
                        suppressed,
                        "sACN input: refused {}, not in input.sacn.allow (more senders than are named)",
                        from.ip()
                    );
                }
                continue;
            }
            let mut m = lock(&self.merger);
            match got {
                Ok((n, from)) => match parse(&buf[..n]) {
                    Ok(Some(p)) => {
                        if m.receive(&p, now) == merge::Verdict::TooMany
                            && let Some(suppressed) = too_many.allow(now)
                        {
                            tracing::warn!(
                                from = %from,
                                suppressed,
                                "sACN input: dropped a new source: {} streams are tracked already",
                                merge::MAX_STREAMS
                            );
                        }
                    }
                    Ok(None) => {}
                    Err(why) => {
                        if let Some(suppressed) = malformed.allow(now) {
                            tracing::warn!(
                                from = %from,
                                suppressed,
                                "sACN input: dropped a malformed packet: {why} (further ones are logged at most every 10 s)"
                            );
                        }
                    }
                },
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => {
                    if let Some(suppressed) = failed.allow(now) {
                        tracing::warn!(suppressed, "sACN input: receive failed: {e}");
                    }
                }
            }
            m.expire(now);
            let merged: Vec<_> = self.universes.iter().map(|&u| m.merged(u, now)).collect();
            drop(m);
            if merged != last {
                last = merged;
                self.changes.send_modify(|n| *n += 1);
            }
        }
    }
}
