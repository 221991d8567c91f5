//! The OSC listeners: UDP and TCP sockets on the `[osc]` addresses, the sender allow-list,
//! stream framing, and routing of replies back to whoever asked.
//!
//! Everything the commands see goes through [`Handler`]; everything between the socket and
//! the handler lives here. Limits ([`Limits`]) keep one misbehaving host from costing
//! others anything: connection slots shared out by host (`crate::slots`: a share per host,
//! the oldest idle connection of the host with the most closed for a newcomer, the
//! configured backups and peers always let in), an idle timeout, a frame size limit, a
//! bounded queue for replies sent after the fact, and a bounded backlog per UDP sending
//! host (all its ports together), each sender (address and port) and each connection
//! handled in order on a blocking thread of its own.

use std::collections::{HashMap, VecDeque};
use std::net::{IpAddr, SocketAddr};
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use rosc::{OscMessage, OscPacket, OscType};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::runtime::Handle;
use tokio::sync::{Notify, mpsc};
use tokio::task::{JoinHandle, JoinSet};
use tracing::{debug, error, info, trace, warn};
use visobjd_throttle::Throttle;

use super::args::Request;
use super::framing::{self, Decoder, Framing, StreamFrame};
use super::packet::{self, Item, PacketError};
use super::peers::{Route as PeerRoute, Routes};
use crate::config::{Cidr, OscConfig};
use crate::slots::{self, Slot, Slots};

/// What answers OSC (in the daemon, `crate::cmd::Runner`).
///
/// Called once per message, in arrival order per sender (bundles flattened, run at once), on
/// a blocking thread that serves only that sender (a UDP source address or a TCP
/// connection) for the moment: it may wait on the disk without holding up anyone else, but
/// long work (a second or more) belongs elsewhere, answered later through a clone of the
/// [`Peer`]. It never sees messages
/// from senders outside the allow-list, packets that are not OSC, or button releases
/// ([`Request::is_button_release`]). The returned messages are sent to the sender, in
/// order. A panic in the handler is caught and answered with `/vo/error`.
pub trait Handler: Send + Sync + 'static {
    /// Answers one message, read once by the argument rules ([`Request::new`]).
    fn handle(&self, req: Request, peer: &Peer) -> Vec<OscMessage>;
}

impl<F> Handler for F
where
    F: Fn(Request, &Peer) -> Vec<OscMessage> + Send + Sync + 'static,
{
    fn handle(&self, req: Request, peer: &Peer) -> Vec<OscMessage> {
        self(req, peer)
    }
}

/// Robustness limits; [`Limits::default`] is what the daemon runs with (tests shrink them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// TCP connections open at once, all hosts together. When all are taken, a newcomer
    /// takes the slot of the oldest idle connection of the host with the most, if that host
    /// has more than the newcomer's (for a configured backup or peer: any host but the
    /// reserved ones); otherwise it is closed as soon as it is accepted.
    pub max_connections: usize,
    /// TCP connections one host may have open (one more closes its own oldest idle one, or
    /// is closed when none is idle), and UDP ports of one host served at once (datagrams
    /// from a further port are dropped until one has caught up).
    pub per_host: usize,
    /// A TCP connection that completes no frame for this long is closed.
    pub idle_timeout: Duration,
    /// The largest frame a TCP stream may carry; larger ones are skipped unbuffered and
    /// answered with `/vo/error`.
    pub max_frame: usize,
    /// Replies a connection may have queued ([`Peer::reply`]) before it is dropped as too
    /// slow.
    pub reply_queue: usize,
    /// Bytes of datagrams one UDP sending host (all its ports together) may have waiting
    /// while its earlier ones are handled; more are dropped (and counted), so a flood costs
    /// only its host.
    pub udp_backlog: usize,
    /// UDP sending hosts (IP addresses: a host's ports are one) whose datagrams are waiting
    /// or being handled at once; datagrams from further hosts are dropped until one has
    /// caught up.
    pub udp_senders: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_connections: 64,
            per_host: 8,
            idle_timeout: Duration::from_secs(60),
            max_frame: framing::MAX_FRAME,
            reply_queue: 256,
            udp_backlog: 256 * 1024,
            udp_senders: 64,
        }
    }
}

/// How a message arrived.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transport {
    /// A datagram.
    Udp,
    /// A TCP connection, in the framing its client chose.
    Tcp(Framing),
}

/// Who sent a message and the way back to them. Cloneable so a handler can answer long
/// work later with [`Peer::reply`].
#[derive(Clone, Debug)]
pub struct Peer {
    addr: SocketAddr,
    reply_addr: SocketAddr,
    route: Route,
}

#[derive(Clone, Debug)]
enum Route {
    Udp(Sender),
    Tcp(Link),
    Capture(std::sync::mpsc::Sender<OscMessage>),
}

impl Peer {
    /// A peer whose replies are collected in a channel instead of sent: for testing a
    /// handler without sockets.
    pub fn capture(addr: SocketAddr) -> (Peer, std::sync::mpsc::Receiver<OscMessage>) {
        let (tx, rx) = std::sync::mpsc::channel();
        let peer = Peer {
            addr,
            reply_addr: addr,
            route: Route::Capture(tx),
        };
        (peer, rx)
    }

    /// The sender's address and source port.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Where UDP replies to this sender go: its address at `osc.reply_port`, or its source
    /// port when that is 0. The default target for subscriptions.
    pub fn reply_addr(&self) -> SocketAddr {
        self.reply_addr
    }

    /// How the message arrived.
    pub fn transport(&self) -> Transport {
        match &self.route {
            Route::Tcp(link) => Transport::Tcp(link.framing),
            Route::Udp(_) | Route::Capture(_) => Transport::Udp,
        }
    }

    /// Sends messages to this sender the way it reached us (UDP to [`Peer::reply_addr`], or
    /// its TCP connection), without waiting. False if they could not all go: the
    /// connection is gone, or too slow (its queue overflowed, so it is being dropped).
    pub fn reply(&self, msgs: &[OscMessage]) -> bool {
        msgs.iter().all(|m| match &self.route {
            Route::Udp(sender) => sender.send(self.reply_addr, m).is_ok(),
            Route::Tcp(link) => link.send(m),
            Route::Capture(tx) => tx.send(m.clone()).is_ok(),
        })
    }
}

/// Sends OSC from the server's UDP socket (so replies come from the port clients talk to),
/// to any address: for pushes such as subscriptions. A `[[osc.peer]]` that takes TCP gets
/// them on its connection instead ([`super::peers`]).
#[derive(Clone, Debug)]
pub struct Sender {
    socket: Arc<UdpSocket>,
    /// Weak: the engine holds a sender to push through, and the server state holds the
    /// handler.
    shared: Weak<Shared>,
}

impl Sender {
    /// Sends one message now, without waiting; an error says why it did not go (including
    /// a full socket buffer).
    pub fn send(&self, to: SocketAddr, msg: &OscMessage) -> Result<(), String> {
        if let Some(shared) = self.shared.upgrade()
            && let Some(route) = shared.rules.now().routes.tcp(to.ip()).cloned()
        {
            return shared.send_tcp(&route, msg);
        }
        let bytes = encode_datagram(msg)?;
        self.socket
            .try_send_to(&bytes, to)
            .map(drop)
            .map_err(|e| format!("OSC to {to}: {}", plain(&e)))
    }
}

/// One TCP connection's way back: a bounded queue drained by the connection's task.
#[derive(Clone, Debug)]
pub(super) struct Link {
    queue: mpsc::Sender<Vec<u8>>,
    framing: Framing,
    kill: Arc<Notify>,
}

impl Link {
    fn send(&self, msg: &OscMessage) -> bool {
        let Ok(bytes) = encode(msg) else {
            return false;
        };
        match self.queue.try_send(framing::encode(self.framing, &bytes)) {
            Ok(()) => true,
            Err(mpsc::error::TrySendError::Full(_)) => {
                self.kill.notify_one();
                false
            }
            Err(mpsc::error::TrySendError::Closed(_)) => false,
        }
    }

    /// Whether `self` and `other` are the same connection's.
    fn same(&self, other: &Link) -> bool {
        Arc::ptr_eq(&self.kill, &other.kill)
    }
}

impl PeerRoute {
    /// Makes `link` the connection the peer's replies and pushes go on.
    fn attach(&self, link: &Link) {
        *self.link.lock().unwrap_or_else(|p| p.into_inner()) = Some(link.clone());
    }

    /// Forgets `link` if it is still the peer's connection (it closed or never opened).
    fn detach(&self, link: &Link) {
        let mut slot = self.link.lock().unwrap_or_else(|p| p.into_inner());
        if slot.as_ref().is_some_and(|l| l.same(link)) {
            *slot = None;
        }
    }
}

/// A TCP connection's reply queue before its task runs: the way in (for a [`Link`]), the
/// way out (drained by the task) and its kill switch.
struct Queue {
    queue: mpsc::Sender<Vec<u8>>,
    queued: mpsc::Receiver<Vec<u8>>,
    kill: Arc<Notify>,
}

impl Queue {
    fn new(limits: &Limits) -> Queue {
        let (queue, queued) = mpsc::channel::<Vec<u8>>(limits.reply_queue.max(1));
        Queue {
            queue,
            queued,
            kill: Arc::new(Notify::new()),
        }
    }

    fn link(&self, framing: Framing) -> Link {
        Link {
            queue: self.queue.clone(),
            framing,
            kill: self.kill.clone(),
        }
    }
}

/// How long visobjd tries to open a TCP connection to a `[[osc.peer]]`.
const PEER_CONNECT: Duration = Duration::from_secs(3);

/// The running listeners. Dropping it (or [`Server::stop`]) stops them; [`Sender`] handles
/// keep the UDP socket open until they are dropped too.
pub struct Server {
    udp_addr: Option<SocketAddr>,
    tcp_addr: Option<SocketAddr>,
    sender: Option<Sender>,
    shared: Arc<Shared>,
    tasks: Vec<JoinHandle<()>>,
}

/// The `[osc]` sockets bound but not yet served, with the allow-list and peers checked:
/// the daemon binds every socket it needs before its first DMX frame, so a second
/// instance on taken ports stops before it sends anything.
pub struct Listeners {
    udp: Option<std::net::UdpSocket>,
    tcp: Option<std::net::TcpListener>,
    allowed: Allowed,
    reply_port: u16,
}

/// Who may send (`osc.allow`), where peers' replies go (`[[osc.peer]]`) and whose TCP
/// connections always get a slot (the peers and `osc.backups`), checked together and
/// replaced whole.
struct Allowed {
    allow: Vec<Cidr>,
    routes: Routes,
    backups: Vec<IpAddr>,
}

impl Allowed {
    fn of(config: &OscConfig) -> Result<Allowed, String> {
        let allow = config
            .allow
            .iter()
            .map(|a| Cidr::parse(a).map_err(|e| format!("osc.allow: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        crate::config::validate_peers(&config.peer, &allow)?;
        let backups = crate::config::validate_backups(&config.backups, &allow)?;
        Ok(Allowed {
            allow,
            routes: Routes::new(&config.peer),
            backups,
        })
    }

    /// Whether `host` is one the config names (a peer, a backup): its connections are never
    /// refused for want of a slot, nor closed for another host's.
    fn reserved(&self, host: IpAddr) -> bool {
        self.routes.get(host).is_some() || self.backups.contains(&host.to_canonical())
    }
}

/// The serving server's allow-list and peers, which a reload replaces ([`Server::rules`]).
/// Connections already open stay; new packets are checked against the new list.
#[derive(Clone)]
pub struct Rules(Arc<std::sync::RwLock<Arc<Allowed>>>);

impl Rules {
    /// Replaces the allow-list and peers with `config`'s; an invalid one changes nothing.
    pub fn set(&self, config: &OscConfig) -> Result<(), String> {
        let allowed = Arc::new(Allowed::of(config)?);
        *self.0.write().unwrap_or_else(|p| p.into_inner()) = allowed;
        Ok(())
    }

    fn now(&self) -> Arc<Allowed> {
        Arc::clone(&self.0.read().unwrap_or_else(|p| p.into_inner()))
    }
}

impl Listeners {
    /// Checks `config` and binds its addresses ("" leaves one off). Errors name the config
    /// key and address: "osc.udp 127.0.0.1:8000: address already in use".
    pub fn bind(config: &OscConfig) -> Result<Listeners, String> {
        let allowed = Allowed::of(config)?;
        let udp = super::address("osc.udp", &config.udp, "127.0.0.1:8000")?
            .map(|addr| bind_udp(addr).map_err(|e| format!("osc.udp {addr}: {}", plain(&e))))
            .transpose()?;
        let tcp = super::address("osc.tcp", &config.tcp, "127.0.0.1:8000")?
            .map(|addr| {
                std::net::TcpListener::bind(addr)
                    .and_then(|l| l.set_nonblocking(true).map(|()| l))
                    .map_err(|e| format!("osc.tcp {addr}: {}", plain(&e)))
            })
            .transpose()?;
        Ok(Listeners {
            udp,
            tcp,
            allowed,
            reply_port: config.reply_port,
        })
    }
}

impl Server {
    /// Binds the `[osc]` addresses and starts serving with default [`Limits`]. Must be
    /// called inside a tokio runtime.
    pub fn start(config: &OscConfig, handler: Arc<dyn Handler>) -> Result<Server, String> {
        Server::start_with_limits(config, handler, Limits::default())
    }

    /// [`Server::start`] with chosen limits.
    pub fn start_with_limits(
        config: &OscConfig,
        handler: Arc<dyn Handler>,
        limits: Limits,
    ) -> Result<Server, String> {
        Server::serve(Listeners::bind(config)?, handler, limits)
    }

    /// Serves sockets bound earlier. Must be called inside a tokio runtime.
    pub fn serve(
        listeners: Listeners,
        handler: Arc<dyn Handler>,
        limits: Limits,
    ) -> Result<Server, String> {
        tokio::runtime::Handle::try_current()
            .map_err(|_| "osc: the server must be started inside a tokio runtime".to_string())?;
        let Listeners {
            udp,
            tcp,
            allowed,
            reply_port,
        } = listeners;
        let shared = Arc::new(Shared {
            slots: Slots::new(slots::Limits {
                total: limits.max_connections,
                per_host: limits.per_host,
                // OSC has no streams.
                streams_per_host: limits.per_host,
            }),
            handler,
            rules: Rules(Arc::new(std::sync::RwLock::new(Arc::new(allowed)))),
            runtime: Handle::current(),
            reply_port,
            limits,
            refused: AtomicU64::new(0),
            not_osc: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            dropped_log: Mutex::default(),
            refused_log: Mutex::default(),
            not_osc_log: Mutex::default(),
            busy_log: Mutex::default(),
            room_log: Mutex::default(),
            peer_log: Mutex::default(),
        });
        let mut server = Server {
            udp_addr: None,
            tcp_addr: None,
            sender: None,
            shared: shared.clone(),
            tasks: Vec::new(),
        };
        if let Some(socket) = udp {
            let local = socket
                .local_addr()
                .map_err(|e| format!("osc.udp: {}", plain(&e)))?;
            let socket = UdpSocket::from_std(socket)
                .map_err(|e| format!("osc.udp {local}: {}", plain(&e)))?;
            info!("OSC over UDP on {local}");
            let sender = Sender {
                socket: Arc::new(socket),
                shared: Arc::downgrade(&shared),
            };
            server.udp_addr = Some(local);
            server.sender = Some(sender.clone());
            server
                .tasks
                .push(tokio::spawn(udp_loop(sender, shared.clone())));
        }
        if let Some(listener) = tcp {
            let local = listener
                .local_addr()
                .map_err(|e| format!("osc.tcp: {}", plain(&e)))?;
            let listener = TcpListener::from_std(listener)
                .map_err(|e| format!("osc.tcp {local}: {}", plain(&e)))?;
            info!("OSC over TCP on {local}");
            server.tcp_addr = Some(local);
            server.tasks.push(tokio::spawn(tcp_loop(listener, shared)));
        }
        Ok(server)
    }

    /// The bound UDP address (the real port when configured with port 0), if UDP is on.
    pub fn udp_addr(&self) -> Option<SocketAddr> {
        self.udp_addr
    }

    /// The bound TCP address, if TCP is on.
    pub fn tcp_addr(&self) -> Option<SocketAddr> {
        self.tcp_addr
    }

    /// A handle on the allow-list and peers, for a reload.
    pub fn rules(&self) -> Rules {
        self.shared.rules.clone()
    }

    /// A handle for pushing OSC from the UDP socket, if UDP is on.
    pub fn sender(&self) -> Option<Sender> {
        self.sender.clone()
    }

    /// Packets and connections refused by the allow-list so far.
    pub fn refused(&self) -> u64 {
        self.shared.refused.load(Ordering::Relaxed)
    }

    /// Datagrams and frames that were not OSC (or nested too deep) so far.
    pub fn not_osc(&self) -> u64 {
        self.shared.not_osc.load(Ordering::Relaxed)
    }

    /// Datagrams dropped because their sender was too far behind, or too many senders were.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Stops listening and closes every connection; returns once the tasks are gone (the
    /// TCP port is free; the UDP port once no [`Sender`] is left).
    pub async fn stop(mut self) {
        let tasks = std::mem::take(&mut self.tasks);
        for t in &tasks {
            t.abort();
        }
        for t in tasks {
            // A cancelled task's error is the expected outcome.
            let _ = t.await;
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.tasks.iter().for_each(JoinHandle::abort);
    }
}

/// State every listener task shares.
struct Shared {
    /// The TCP connections open, by host.
    slots: Arc<Slots>,
    handler: Arc<dyn Handler>,
    rules: Rules,
    runtime: Handle,
    reply_port: u16,
    limits: Limits,
    refused: AtomicU64,
    not_osc: AtomicU64,
    dropped: AtomicU64,
    dropped_log: Mutex<Throttle>,
    refused_log: Mutex<Throttle>,
    not_osc_log: Mutex<Throttle>,
    busy_log: Mutex<Throttle>,
    room_log: Mutex<Throttle>,
    peer_log: Mutex<Throttle>,
}

impl Shared {
    /// The allow-list check, done before anything from the sender is decoded.
    fn permits(&self, from: SocketAddr) -> bool {
        let ok = crate::config::permits(&self.rules.now().allow, from.ip());
        if !ok {
            self.refused.fetch_add(1, Ordering::Relaxed);
            if let Some(n) = throttled(&self.refused_log) {
                warn!("OSC: refused {from}, not in osc.allow ({n} refused since the last report)");
            }
        }
        ok
    }

    /// Where UDP replies and pushes to `from` go: its `[[osc.peer]]` port, else the
    /// global rule.
    fn reply_addr(&self, from: SocketAddr) -> SocketAddr {
        if let Some(to) = self.rules.now().routes.reply_addr(from) {
            return to;
        }
        match self.reply_port {
            0 => from,
            port => SocketAddr::new(from.ip(), port),
        }
    }

    /// Sends to a TCP peer on its open connection, or opens one (on a task of its own, the
    /// message queued meanwhile). Never waits.
    fn send_tcp(self: &Arc<Self>, route: &Arc<PeerRoute>, msg: &OscMessage) -> Result<(), String> {
        let framing = route.framing.unwrap_or(Framing::LengthPrefix);
        let mut slot = route.link.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(link) = slot.as_ref() {
            if link.send(msg) {
                return Ok(());
            }
            *slot = None;
        }
        let queue = Queue::new(&self.limits);
        let link = queue.link(framing);
        if !link.send(msg) {
            return Err(format!(
                "cannot encode {} for peer `{}`",
                msg.addr, route.name
            ));
        }
        *slot = Some(link);
        drop(slot);
        self.runtime
            .spawn(outgoing(route.clone(), queue, framing, self.clone()));
        Ok(())
    }

    /// Runs one packet's messages through the handler, returning the replies in order.
    fn dispatch(&self, bytes: &[u8], peer: &Peer) -> Vec<OscMessage> {
        let items = match packet::decode_items(bytes) {
            Ok(items) => items,
            Err(e) => {
                // A packet that nests too deep but names its address is OSC: say why.
                if e == PacketError::TooDeep
                    && let Some(addr) = packet::first_address(bytes)
                {
                    debug!("OSC: {addr} from {} is nested too deep", peer.addr);
                    return vec![super::error(
                        &addr,
                        &format!(
                            "the packet nests bundles or arrays deeper than {}; nothing in it ran",
                            packet::MAX_DEPTH
                        ),
                    )];
                }
                self.not_osc.fetch_add(1, Ordering::Relaxed);
                if let Some(n) = throttled(&self.not_osc_log) {
                    warn!(
                        "OSC: ignored {} bytes from {}: {e} ({n} ignored since the last report)",
                        bytes.len(),
                        peer.addr
                    );
                }
                return Vec::new();
            }
        };
        let mut replies = Vec::new();
        for item in items {
            let msg = match item {
                Item::Message(msg) => msg,
                Item::Malformed { addr, why } => {
                    debug!("OSC: malformed {addr} from {}: {why}", peer.addr);
                    replies.push(super::error(
                        &addr,
                        &format!("the message is cut short or corrupt ({why}); nothing changed"),
                    ));
                    continue;
                }
            };
            let req = Request::new(msg);
            if req.is_button_release() {
                trace!("OSC: button release {} from {}", req.addr, peer.addr);
                continue;
            }
            let addr = req.addr.clone();
            match std::panic::catch_unwind(AssertUnwindSafe(|| self.handler.handle(req, peer))) {
                Ok(r) => replies.extend(r),
                Err(_) => {
                    error!("OSC: the handler panicked on {addr} from {}", peer.addr);
                    replies.push(super::error(&addr, "internal error; see the daemon's log"));
                }
            }
        }
        replies
    }

    /// The answer to a stream frame over the size limit: a `/vo/error` naming its address
    /// when its head has one (a frame with no readable address is garbage: nothing).
    fn oversize(&self, len: usize, head: &[u8], from: SocketAddr) -> Option<OscMessage> {
        let limit = self.limits.max_frame;
        let Some(addr) = packet::first_address(head) else {
            self.not_osc.fetch_add(1, Ordering::Relaxed);
            if let Some(n) = throttled(&self.not_osc_log) {
                warn!(
                    "OSC over TCP: skipped a frame of {len} bytes from {from} that is not OSC ({n} ignored since the last report)"
                );
            }
            return None;
        };
        debug!("OSC over TCP: skipped {addr}, a frame of {len} bytes from {from}");
        Some(super::error(
            &addr,
            &format!(
                "the packet is {len} bytes, over the {limit}-byte limit; it was dropped and nothing changed"
            ),
        ))
    }
}

/// Datagrams waiting per UDP sending host: per port, and their total size. A port is in
/// the map exactly while a worker task serves it, a host while one of its ports is.
type Backlogs = Arc<Mutex<HashMap<IpAddr, Waiting>>>;

/// One UDP sending host's datagrams waiting, by port, and their total size.
#[derive(Default)]
struct Waiting {
    ports: HashMap<SocketAddr, VecDeque<Vec<u8>>>,
    bytes: usize,
}

/// Datagrams the kernel is asked to hold for the OSC socket. At 20,000 small datagrams a
/// second (a flood, or every fader of several tablets at once) its default of 208 KiB is
/// about 10 ms of them, so any stall of the receiving task longer than that (a busy or
/// shared host) drops datagrams from every sender alike, a console's included. 4 MiB is
/// about 200 ms. The kernel caps it at `net.core.rmem_max`.
const UDP_RECV_BUFFER: usize = 4 << 20;

/// The OSC UDP socket, non-blocking, with the receive buffer [`UDP_RECV_BUFFER`] asks for
/// (or the most the kernel allows, said in the log).
fn bind_udp(addr: SocketAddr) -> std::io::Result<std::net::UdpSocket> {
    let socket = std::net::UdpSocket::bind(addr)?;
    socket.set_nonblocking(true)?;
    let sock = socket2::SockRef::from(&socket);
    // Linux reports twice what it granted (its bookkeeping share).
    match sock
        .set_recv_buffer_size(UDP_RECV_BUFFER)
        .and_then(|()| sock.recv_buffer_size())
    {
        Ok(got) if got / 2 < UDP_RECV_BUFFER => info!(
            "OSC over UDP: the kernel holds {} KiB of waiting datagrams, not the {} KiB asked \
             for; raise net.core.rmem_max to ride out longer bursts",
            got / 2 / 1024,
            UDP_RECV_BUFFER / 1024
        ),
        Ok(_) => {}
        Err(e) => warn!(
            "OSC over UDP: cannot size the receive buffer: {}",
            plain(&e)
        ),
    }
    Ok(socket)
}

/// Receives datagrams and hands them to one worker per sender (address and port): a sender
/// whose messages wait on the disk (saves) or flood in delays only itself, never a
/// well-behaved client. The limits count hosts (IP addresses), whatever ports they send
/// from: at most [`Limits::udp_senders`] hosts at once, [`Limits::per_host`] ports of one
/// host served at once, and [`Limits::udp_backlog`] bytes waiting for all of a host's ports
/// together, so one host sending from many ports costs only itself.
async fn udp_loop(sender: Sender, shared: Arc<Shared>) {
    let socket = sender.socket.clone();
    let mut buf = vec![0u8; 65536];
    let mut error_log = Throttle::default();
    let backlogs = Backlogs::default();
    loop {
        let (n, from) = match socket.recv_from(&mut buf).await {
            Ok(got) => got,
            Err(e) => {
                if let Some(n) = hit(&mut error_log) {
                    debug!("OSC over UDP: receive failed: {e} ({n} since the last report)");
                }
                continue;
            }
        };
        if !shared.permits(from) {
            continue;
        }
        let host = from.ip().to_canonical();
        let mut map = backlogs.lock().unwrap_or_else(|p| p.into_inner());
        let known = map.contains_key(&host);
        let why = if !known && map.len() >= shared.limits.udp_senders {
            Some("too many hosts are")
        } else {
            let waiting = map.entry(host).or_default();
            let new_port = !waiting.ports.contains_key(&from);
            if waiting.bytes + n > shared.limits.udp_backlog {
                Some("its host is")
            } else if new_port && waiting.ports.len() >= shared.limits.per_host {
                Some("its host's other ports are")
            } else {
                waiting.bytes += n;
                let queue = waiting.ports.entry(from).or_default();
                queue.push_back(buf[..n].to_vec());
                if new_port {
                    tokio::spawn(serve_sender(
                        from,
                        backlogs.clone(),
                        sender.clone(),
                        shared.clone(),
                    ));
                }
                None
            }
        };
        if why.is_some() && !known {
            // Entered for this datagram alone: no port of it is served.
            map.remove(&host);
        }
        drop(map);
        if let Some(why) = why {
            shared.dropped.fetch_add(1, Ordering::Relaxed);
            if let Some(n) = throttled(&shared.dropped_log) {
                warn!(
                    "OSC over UDP: dropped a datagram from {from}: {why} too far behind ({n} dropped since the last report)"
                );
            }
        }
    }
}

/// Serves one UDP sender's backlog in order until it is empty, handling on a blocking
/// thread and answering from the server's socket.
async fn serve_sender(from: SocketAddr, backlogs: Backlogs, sender: Sender, shared: Arc<Shared>) {
    let host = from.ip().to_canonical();
    let peer = Peer {
        addr: from,
        reply_addr: shared.reply_addr(from),
        route: Route::Udp(sender.clone()),
    };
    loop {
        let batch: Vec<Vec<u8>> = {
            let mut map = backlogs.lock().unwrap_or_else(|p| p.into_inner());
            let Some(waiting) = map.get_mut(&host) else {
                return;
            };
            match waiting.ports.get_mut(&from) {
                Some(queue) if !queue.is_empty() => {
                    let batch: Vec<Vec<u8>> = queue.drain(..).collect();
                    waiting.bytes -= batch.iter().map(Vec::len).sum::<usize>();
                    batch
                }
                _ => {
                    // Empty: done. Checked and removed under the lock the receiver pushes
                    // under, so nothing is left behind.
                    waiting.ports.remove(&from);
                    if waiting.ports.is_empty() {
                        map.remove(&host);
                    }
                    return;
                }
            }
        };
        // Each packet's replies go out before the next packet is handled, so they precede
        // anything its handler answers later (Peer::reply from another thread).
        let (handler_shared, handler_peer, runtime) =
            (shared.clone(), peer.clone(), Handle::current());
        let socket = sender.socket.clone();
        let handled = tokio::task::spawn_blocking(move || {
            let to_tcp = handler_shared
                .rules
                .now()
                .routes
                .tcp(handler_peer.reply_addr.ip())
                .cloned();
            for bytes in batch {
                for reply in handler_shared.dispatch(&bytes, &handler_peer) {
                    if let Some(route) = &to_tcp {
                        if let Err(e) = handler_shared.send_tcp(route, &reply) {
                            debug!("OSC: reply to peer `{}` not sent: {e}", route.name);
                        }
                        continue;
                    }
                    let bytes = match encode_datagram(&reply) {
                        Ok(bytes) => bytes,
                        Err(e) => {
                            debug!("OSC: reply to {} not sent: {e}", handler_peer.reply_addr);
                            continue;
                        }
                    };
                    let sent = runtime.block_on(socket.send_to(&bytes, handler_peer.reply_addr));
                    if let Err(e) = sent {
                        debug!("OSC: reply to {} failed: {e}", handler_peer.reply_addr);
                    }
                }
            }
        })
        .await;
        if handled.is_err() {
            error!("OSC: handling datagrams from {from} failed");
        }
    }
}

async fn tcp_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut conns = JoinSet::new();
    loop {
        tokio::select! {
            biased;
            Some(_) = conns.join_next(), if !conns.is_empty() => {}
            accepted = listener.accept() => match accepted {
                Ok((stream, from)) => {
                    if !shared.permits(from) {
                        continue;
                    }
                    let host = from.ip().to_canonical();
                    let reserved = shared.rules.now().reserved(host);
                    let admitted = match shared.slots.admit(host, reserved, Instant::now()) {
                        Ok(a) => a,
                        Err(why) => {
                            if let Some(n) = throttled(&shared.busy_log) {
                                warn!(
                                    "OSC over TCP: closed {from}: {why} ({n} closed since the last report)"
                                );
                            }
                            continue;
                        }
                    };
                    if let Some(gave) = admitted.made_room
                        && let Some(n) = throttled(&shared.room_log)
                    {
                        info!(
                            "OSC over TCP: closed the oldest idle connection of {gave} to make room for {from} ({n} closed since the last report)"
                        );
                    }
                    let queue = Queue::new(&shared.limits);
                    let slot = Some(admitted.slot);
                    conns.spawn(connection(stream, from, shared.clone(), queue, None, slot));
                }
                Err(e) => {
                    if let Some(n) = throttled(&shared.busy_log) {
                        warn!("OSC over TCP: accept failed: {e} ({n} since the last report)");
                    }
                    // Out of descriptors or similar: back off instead of spinning.
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            },
        }
    }
}

/// Opens visobjd's own connection to a TCP `[[osc.peer]]` and serves it like one the peer
/// opened (what it sends is heard), replies going out in the peer's framing.
async fn outgoing(route: Arc<PeerRoute>, queue: Queue, framing: Framing, shared: Arc<Shared>) {
    let to = SocketAddr::new(route.ip, route.port);
    match tokio::time::timeout(PEER_CONNECT, TcpStream::connect(to)).await {
        Ok(Ok(stream)) => {
            debug!("OSC over TCP: connected to peer `{}` at {to}", route.name);
            connection(stream, to, shared, queue, Some(framing), None).await;
        }
        failed => {
            let why = match failed {
                Ok(Err(e)) => plain(&e),
                _ => format!("no answer within {PEER_CONNECT:?}"),
            };
            if let Some(n) = throttled(&shared.peer_log) {
                warn!(
                    "OSC: cannot reach peer `{}` at {to} ({why}); its replies and pushes are lost until it connects or visobjd reaches it ({n} failed since the last report)",
                    route.name
                );
            }
            route.detach(&queue.link(framing));
        }
    }
}

/// Serves one TCP connection until it closes, idles out, lets its reply queue overflow, or
/// gives its `slot` up to another host (`None`: visobjd opened it, it takes no slot).
/// `framing` is the replies' when visobjd opened it (a peer's); otherwise the client's
/// first byte decides. A `[[osc.peer]]` that takes TCP gets its pushes on it meanwhile.
async fn connection(
    stream: TcpStream,
    from: SocketAddr,
    shared: Arc<Shared>,
    queue: Queue,
    framing: Option<Framing>,
    slot: Option<Arc<Slot>>,
) {
    debug!("OSC over TCP: {from} connected");
    // Small replies should not wait for Nagle; failing to set it only costs latency.
    let _ = stream.set_nodelay(true);
    let (mut rd, mut wr) = stream.into_split();
    let limits = shared.limits;
    let route = shared.rules.now().routes.tcp(from.ip()).cloned();
    let mut link = framing.map(|f| queue.link(f));
    if let (Some(route), Some(link)) = (&route, &link) {
        route.attach(link);
    }
    let Queue {
        queue: tx,
        mut queued,
        kill,
    } = queue;
    let mut decoder = Decoder::new(limits.max_frame);
    let mut buf = vec![0u8; 8192];
    let mut frames = Vec::new();
    let mut deadline = tokio::time::Instant::now() + limits.idle_timeout;
    let why = loop {
        tokio::select! {
            biased;
            () = kill.notified() => break "its reply queue overflowed (it does not read)".to_string(),
            () = given_up(slot.as_deref()) => break "its slot went to another host's connection (it was the oldest idle one)".to_string(),
            Some(bytes) = queued.recv() => {
                if let Err(e) = write(&mut wr, &bytes, deadline).await {
                    break e;
                }
            }
            read = tokio::time::timeout_at(deadline, rd.read(&mut buf)) => {
                let n = match read {
                    Err(_) => break format!("idle for {:?}", limits.idle_timeout),
                    Ok(Err(e)) => break e.to_string(),
                    Ok(Ok(0)) => {
                        // Flush what is queued for a client that half-closed and waits.
                        while let Ok(bytes) = queued.try_recv() {
                            if write(&mut wr, &bytes, deadline).await.is_err() {
                                break;
                            }
                        }
                        break "closed by the client".to_string();
                    }
                    Ok(Ok(n)) => n,
                };
                decoder.feed(&buf[..n], &mut frames);
                if link.is_none()
                    && let Some(framing) = decoder.framing()
                {
                    let new = Link { queue: tx.clone(), framing, kill: kill.clone() };
                    // A TCP peer's own connection carries its pushes from now on.
                    if let Some(route) = &route {
                        route.attach(&new);
                    }
                    link = Some(new);
                }
                let Some(link) = link.clone() else { continue };
                let framing = link.framing;
                if frames.is_empty() {
                    continue;
                }
                deadline = tokio::time::Instant::now() + limits.idle_timeout;
                // In a request until its replies are written: never closed for another.
                let _busy = slot.as_ref().map(Slot::busy);
                let peer = Peer {
                    addr: from,
                    reply_addr: shared.reply_addr(from),
                    route: Route::Tcp(link.clone()),
                };
                // Handled on a blocking thread: a save waiting on the disk holds only this
                // connection, not the runtime's workers.
                let batch = std::mem::take(&mut frames);
                let handler_shared = shared.clone();
                let out = tokio::task::spawn_blocking(move || {
                    let mut out = Vec::new();
                    for frame in batch {
                        let replies = match frame {
                            StreamFrame::Packet(p) => handler_shared.dispatch(&p, &peer),
                            StreamFrame::Oversize { len, head } => {
                                handler_shared.oversize(len, &head, from).into_iter().collect()
                            }
                        };
                        for reply in replies {
                            if let Ok(bytes) = encode(&reply) {
                                out.extend(framing::encode(framing, &bytes));
                            }
                        }
                    }
                    out
                })
                .await
                .unwrap_or_default();
                // Pushes queued while these were handled (a subscription's state) go
                // first, in the order they were made, as they would over UDP.
                let mut pushed = Vec::new();
                while let Ok(bytes) = queued.try_recv() {
                    pushed.extend(bytes);
                }
                pushed.extend(out);
                let out = pushed;
                if let Err(e) = write(&mut wr, &out, deadline).await {
                    break e;
                }
            }
        }
    };
    if let (Some(route), Some(link)) = (&route, &link) {
        route.detach(link);
    }
    debug!("OSC over TCP: {from} disconnected: {why}");
}

/// Resolves when `slot` was given to another connection; never without one.
async fn given_up(slot: Option<&Slot>) {
    match slot {
        Some(s) => s.closed().await,
        None => std::future::pending().await,
    }
}

/// Writes all of `bytes`, giving up at the connection's idle deadline (a client that never
/// reads cannot hold the task forever).
async fn write(
    wr: &mut tokio::net::tcp::OwnedWriteHalf,
    bytes: &[u8],
    deadline: tokio::time::Instant,
) -> Result<(), String> {
    if bytes.is_empty() {
        return Ok(());
    }
    match tokio::time::timeout_at(deadline, wr.write_all(bytes)).await {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(e.to_string()),
        Err(_) => Err("a reply could not be written before the idle timeout".into()),
    }
}

fn encode(msg: &OscMessage) -> Result<Vec<u8>, String> {
    rosc::encoder::encode(&OscPacket::Message(msg.clone()))
        .map_err(|e| format!("cannot encode {}: {e}", msg.addr))
}

/// The largest UDP payload (IPv4; IPv6 allows a few bytes more).
const MAX_DATAGRAM: usize = 65_507;

/// Encodes a message for one datagram, halving its longest strings (marked with "…") until
/// it fits: an error that echoes a near-64 KiB address or name must still arrive, or the
/// message would go unanswered.
fn encode_datagram(msg: &OscMessage) -> Result<Vec<u8>, String> {
    let mut bytes = encode(msg)?;
    let mut cut = msg.clone();
    while bytes.len() > MAX_DATAGRAM {
        let longest = cut
            .args
            .iter_mut()
            .filter_map(|a| match a {
                OscType::String(s) if s.len() > 64 => Some(s),
                _ => None,
            })
            .max_by_key(|s| s.len());
        let Some(s) = longest else {
            return Err(format!(
                "{} is {} bytes, over the {MAX_DATAGRAM}-byte datagram limit",
                msg.addr,
                bytes.len()
            ));
        };
        let mut keep = s.len() / 2;
        while !s.is_char_boundary(keep) {
            keep -= 1;
        }
        s.truncate(keep);
        s.push('…');
        bytes = encode(&cut)?;
    }
    Ok(bytes)
}

/// An I/O error as a lowercase phrase without the OS error number.
fn plain(e: &std::io::Error) -> String {
    let s = e.to_string();
    let s = s.split(" (os error").next().unwrap_or(&s);
    let mut chars = s.chars();
    chars
        .next()
        .map(|c| c.to_lowercase().chain(chars).collect())
        .unwrap_or_default()
}

/// Counts an event on `t` at the time of the call: `Some(events since the last line, this
/// one included)`, the count the OSC lines report, when a line should be logged now.
fn hit(t: &mut Throttle) -> Option<u64> {
    t.allow(Instant::now()).map(|left_out| left_out + 1)
}

/// [`hit`] on a throttle the server's tasks share.
fn throttled(t: &Mutex<Throttle>) -> Option<u64> {
    hit(&mut t.lock().unwrap_or_else(|e| e.into_inner()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_udp_socket_holds_bursts() {
        let socket = bind_udp("127.0.0.1:0".parse().unwrap()).unwrap();
        let got = socket2::SockRef::from(&socket).recv_buffer_size().unwrap();
        // As much as asked, or as the kernel allows; Linux reports twice what it granted.
        let rmem_max = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
            .ok()
            .and_then(|s| s.trim().parse::<usize>().ok())
            .unwrap_or(UDP_RECV_BUFFER);
        assert!(
            got >= 2 * UDP_RECV_BUFFER.min(rmem_max),
            "{got} bytes (rmem_max {rmem_max})"
        );
    }

    #[test]
    fn io_errors_read_as_phrases() {
        let e = std::io::Error::from_raw_os_error(98);
        assert_eq!(plain(&e), "address already in use");
    }

    #[test]
    fn datagram_replies_are_cut_to_fit() {
        let long = "é".repeat(40_000);
        let m = crate::osc::error(&long, &long);
        let bytes = encode_datagram(&m).unwrap();
        assert!(bytes.len() <= MAX_DATAGRAM, "{}", bytes.len());
        let (_, p) = rosc::decoder::decode_udp(&bytes).unwrap();
        let OscPacket::Message(back) = p else {
            panic!("{p:?}")
        };
        assert!(back.args.iter().all(|a| match a {
            OscType::String(s) => s.starts_with("éé") && s.ends_with('…'),
            _ => false,
        }));
        let small = OscMessage {
            addr: "/vo/pong".into(),
            args: vec![OscType::Int(1)],
        };
        assert_eq!(encode_datagram(&small).unwrap(), encode(&small).unwrap());
    }

    #[test]
    fn captured_peers_collect_replies() {
        let (peer, rx) = Peer::capture("127.0.0.1:9".parse().unwrap());
        let m = OscMessage {
            addr: "/x".into(),
            args: vec![],
        };
        assert!(peer.reply(std::slice::from_ref(&m)));
        assert_eq!(rx.try_recv(), Ok(m));
        assert_eq!(peer.transport(), Transport::Udp);
    }
}
