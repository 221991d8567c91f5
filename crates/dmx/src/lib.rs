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
mod clock;
mod config;
pub mod input;
pub mod patch;
mod wire;
mod wiring;

pub use patch::{Patch, SlotLevels};

pub use config::{ArtnetDest, InputConfig, OutputConfig, SacnDest, SacnInput};
pub use input::Input;

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use tokio::sync::watch;
use uuid::Uuid;

use clock::Clock;
use visobjd_scene::look::Look;
use wiring::{Traffic, Wiring};

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
    /// Bumped by every [`Output::rewire`]: the clock takes the new wiring in with the look.
    rewire: u64,
}

/// Counters the clock thread updates; read by [`Output::stats`]. Those of a wiring (frames
/// per universe, failures per destination) are its [`Traffic`].
#[derive(Debug)]
struct Counters {
    send_errors: AtomicU64,
    worst_late_us: AtomicU64,
    /// Ticks of the clock since start: the watchdog pings only while this advances.
    ticks: AtomicU64,
    /// Ticks that woke more than half a period after their deadline.
    late_ticks: AtomicU64,
    /// Ticks per second over the last whole second, as `f32` bits.
    tick_rate: AtomicU32,
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
    /// The traffic of the wiring last handed to the clock.
    traffic: Mutex<Arc<Traffic>>,
    /// Where [`Output::rewire`] leaves a wiring for the clock.
    pending: Arc<Mutex<Option<Wiring>>>,
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
        let cid = cid::load_or_create(state_dir).map_err(|error| OutputError::Cid {
            dir: state_dir.display().to_string(),
            error,
        })?;
        let wiring = Wiring::new(config, patch)?;
        let counters = Arc::new(Counters {
            send_errors: AtomicU64::new(0),
            worst_late_us: AtomicU64::new(0),
            ticks: AtomicU64::new(0),
            late_ticks: AtomicU64::new(0),
            tick_rate: AtomicU32::new(0),
            hooks: Hooks::default(),
        });
        let initial = Arc::new(initial);
        let (desired, rx) = watch::channel(Desired {
            look: initial.clone(),
            frame: None,
            generation: 0,
            fade: Duration::ZERO,
            since: Instant::now(),
            master: 1.0,
            blackout: false,
            rewire: 0,
        });
        let traffic = Mutex::new(wiring.traffic.clone());
        let pending = Arc::new(Mutex::new(None));
        let stop = Arc::new(AtomicBool::new(false));
        let clock = Clock::new(
            rx,
            wiring,
            &initial,
            pending.clone(),
            cid,
            counters.clone(),
            stop.clone(),
        );
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
            traffic,
            pending,
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

    /// Sends through `config`'s destinations and `patch` from the next tick on, showing
    /// `look` (a look of the new patch's lights) at once: a reload. The new sockets are
    /// bound here, so an error (a bind that fails, a bad destination) changes nothing;
    /// the clock never stops, the streams both wirings send go on (same CID, sequence
    /// numbers continued) and those no longer sent are terminated.
    pub fn rewire(
        &self,
        config: &OutputConfig,
        patch: Patch,
        look: Look,
    ) -> Result<(), OutputError> {
        let wiring = Wiring::new(config, patch)?;
        *lock(&self.traffic) = wiring.traffic.clone();
        *lock(&self.pending) = Some(wiring);
        let look = Arc::new(look);
        self.desired.send_modify(|d| {
            d.look = look;
            d.frame = None;
            d.generation += 1;
            d.fade = Duration::ZERO;
            d.since = Instant::now();
            d.rewire += 1;
        });
        Ok(())
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
        let traffic = lock(&self.traffic).clone();
        OutputStats {
            frames: traffic
                .universes
                .iter()
                .zip(&traffic.frames)
                .map(|(&u, n)| (u, n.load(Ordering::Relaxed)))
                .collect(),
            send_errors: c.send_errors.load(Ordering::Relaxed),
            worst_lateness: Duration::from_micros(c.worst_late_us.load(Ordering::Relaxed)),
            ticks: c.ticks.load(Ordering::Relaxed),
            late_ticks: c.late_ticks.load(Ordering::Relaxed),
            tick_rate: f32::from_bits(c.tick_rate.load(Ordering::Relaxed)),
            destinations: traffic
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

/// `m` locked; a panic elsewhere never leaves it unusable (what it guards is replaced
/// whole, never left half-written).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
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
