//! Who hears of a change without asking: subscribers (`/vo/subscribe`: tablets, pushed the
//! feedback of every change from the OSC port) and the web pages' event streams (every
//! batch through a broadcast channel). Pushes go out in the order the session changed
//! ([`Engine::publish`]).

use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::AtomicUsize;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use rosc::OscMessage;
use tokio::sync::broadcast;

use super::Engine;
use super::session::Session;

/// How long a subscription lasts without a message from its subscriber (docs/osc.md).
const SUBSCRIPTION: Duration = Duration::from_secs(600);

/// Subscriptions one sending host may hold (a tablet needs one, a few apps on one machine
/// a few): each change is pushed to every subscription, so one host's thousands would
/// delay every change for everyone. A further one ends that host's oldest.
pub const SUBSCRIPTIONS_PER_HOST: usize = 8;

/// Change batches kept for a slow web page before it is told it fell behind.
const CHANGES_KEPT: usize = 256;

/// Sends a message to any address from the OSC port (pushes, not replies). The transport
/// implements it over its UDP socket.
pub trait Pusher: Send + Sync + 'static {
    /// Sends `m` to `to`; Err is a sentence (no socket, not encodable, unreachable).
    fn push(&self, to: SocketAddr, m: &OscMessage) -> Result<(), String>;
}

/// A client that asked for state changes.
#[derive(Debug, Clone)]
struct Subscriber {
    /// Who subscribed (its messages renew the subscription).
    from: IpAddr,
    /// Where pushes go.
    to: SocketAddr,
    last_seen: Instant,
}

/// The subscribers, the socket pushes go out of, and the web pages' channel.
pub(super) struct Pushes {
    subscribers: Mutex<Vec<Subscriber>>,
    pusher: OnceLock<Box<dyn Pusher>>,
    /// Every batch pushed to subscribers, for the web page's event stream (src/http/); an
    /// empty batch is a change tablets are not told of (a saved look).
    changes: broadcast::Sender<Arc<[OscMessage]>>,
    /// How many `/vo/entry/<k>/lit` were last pushed, so a smaller gallery turns the
    /// buttons past its end off.
    pub(super) lit_span: AtomicUsize,
}

impl Default for Pushes {
    fn default() -> Pushes {
        Pushes {
            subscribers: Mutex::new(Vec::new()),
            pusher: OnceLock::new(),
            changes: broadcast::channel(CHANGES_KEPT).0,
            lit_span: AtomicUsize::new(0),
        }
    }
}

impl Pushes {
    fn subscribers(&self) -> MutexGuard<'_, Vec<Subscriber>> {
        self.subscribers.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Engine {
    /// Gives the engine the socket subscription pushes go out of (the OSC server's UDP
    /// socket, when it has one).
    pub fn set_pusher(&self, pusher: impl Pusher) {
        let _ = self.pushes.pusher.set(Box::new(pusher));
    }

    /// Adds or renews a subscription from `from`, pushing to `to`. When `from` already
    /// holds [`SUBSCRIPTIONS_PER_HOST`] others, its oldest ends: `Some(where it pushed to)`.
    pub fn subscribe(&self, from: IpAddr, to: SocketAddr) -> Option<SocketAddr> {
        let mut subs = self.pushes.subscribers();
        subs.retain(|s| s.to != to);
        // Kept in the order they were made: the host's first is its oldest.
        let ended = (subs.iter().filter(|s| s.from == from).count() >= SUBSCRIPTIONS_PER_HOST)
            .then(|| subs.iter().position(|s| s.from == from))
            .flatten()
            .map(|i| subs.remove(i).to);
        subs.push(Subscriber {
            from,
            to,
            last_seen: Instant::now(),
        });
        ended
    }

    /// Ends the subscriptions of `from`.
    pub fn unsubscribe(&self, from: IpAddr) {
        self.pushes.subscribers().retain(|s| s.from != from);
    }

    /// A message from `from` arrived: its subscriptions last another [`SUBSCRIPTION`].
    pub fn renew(&self, from: IpAddr) {
        let mut subs = self.pushes.subscribers();
        for s in subs.iter_mut().filter(|s| s.from == from) {
            s.last_seen = Instant::now();
        }
    }

    /// Sends messages to `to` from the OSC port (pushes, not replies).
    pub fn push_to(&self, to: SocketAddr, msgs: &[OscMessage]) -> Result<(), String> {
        let pusher = self
            .pushes
            .pusher
            .get()
            .ok_or("subscriptions need OSC over UDP (osc.udp is off)")?;
        msgs.iter().try_for_each(|m| pusher.push(to, m))
    }

    /// Every change from now on, as the batches [`Engine::notify`] pushes (the web page's
    /// event stream).
    pub fn changes(&self) -> broadcast::Receiver<Arc<[OscMessage]>> {
        self.pushes.changes.subscribe()
    }

    /// Pushes messages to every live subscriber (expired or unreachable ones are dropped)
    /// and to the web pages' event streams.
    pub fn notify(&self, msgs: &[OscMessage]) {
        let subs = self.pushes.subscribers();
        self.push_all(subs, msgs);
    }

    /// Releases the session, then pushes `msgs` as [`Engine::notify`] does, in the order the
    /// session changed: the pushes' lock is taken before the session's is let go, so two
    /// changes' pushes never cross (a tablet would be left showing the older state).
    pub(super) fn publish(&self, s: MutexGuard<'_, Session>, msgs: &[OscMessage]) {
        let subs = self.pushes.subscribers();
        drop(s);
        self.push_all(subs, msgs);
    }

    fn push_all(&self, mut subs: MutexGuard<'_, Vec<Subscriber>>, msgs: &[OscMessage]) {
        // No page listening is no error (and then no copy of the batch is made).
        if self.pushes.changes.receiver_count() > 0 {
            let _ = self.pushes.changes.send(msgs.into());
        }
        subs.retain(|s| {
            s.last_seen.elapsed() < SUBSCRIPTION
                && match self.push_to(s.to, msgs) {
                    Ok(()) => true,
                    Err(e) => {
                        tracing::info!("dropped the subscription of {}: {e}", s.to);
                        false
                    }
                }
        });
    }
}
