//! Where the output's packets go: the destinations of an `[output]` config bound to
//! their sockets for one patch, with their counters. Built whole before it is used (by
//! [`crate::Output::start`], and by a reload while the clock keeps sending the old one),
//! so a bind that fails changes nothing.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::config::SacnTarget;
use crate::{Counters, OutputConfig, OutputError, Patch};
use visobjd_throttle::Throttle;

/// One patch's destinations: what the clock sends through.
#[derive(Debug)]
pub(crate) struct Wiring {
    pub(crate) period: Duration,
    pub(crate) keepalive: bool,
    pub(crate) patch: Patch,
    pub(crate) sockets: Vec<UdpSocket>,
    pub(crate) sacn: Vec<SacnSink>,
    pub(crate) artnet: Vec<ArtnetSink>,
    /// The sockets Art-Net destinations send from, each once: where polls and replies
    /// arrive (fixed with the wiring, so the clock never rebuilds the list).
    pub(crate) art_sockets: Vec<usize>,
    pub(crate) traffic: Arc<Traffic>,
}

/// Per wiring, what [`crate::Output::stats`] reads: frames per universe, failed sends per
/// destination.
#[derive(Debug)]
pub(crate) struct Traffic {
    pub(crate) universes: Vec<u16>,
    pub(crate) frames: Vec<AtomicU64>,
    /// Per destination (sACN ones first, in config order): its label and failed sends.
    pub(crate) destinations: Vec<(String, AtomicU64)>,
}

impl Traffic {
    /// Takes over `old`'s counts of the universes and destinations both have, so the
    /// figures a status shows go on across a reload.
    pub(crate) fn carry(&self, old: &Traffic) {
        for (u, n) in self.universes.iter().zip(&self.frames) {
            if let Some(i) = old.universes.iter().position(|o| o == u) {
                n.store(old.frames[i].load(Ordering::Relaxed), Ordering::Relaxed);
            }
        }
        for (label, n) in &self.destinations {
            if let Some((_, o)) = old.destinations.iter().find(|(l, _)| l == label) {
                n.store(o.load(Ordering::Relaxed), Ordering::Relaxed);
            }
        }
    }
}

impl Wiring {
    /// Validates `config` for `patch` and binds its sockets.
    pub(crate) fn new(config: &OutputConfig, patch: Patch) -> Result<Wiring, OutputError> {
        config
            .validate(patch.universes())
            .map_err(OutputError::Config)?;
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
        let traffic = Arc::new(Traffic {
            frames: universes.iter().map(|_| AtomicU64::new(0)).collect(),
            universes,
            destinations,
        });
        Ok(Wiring {
            period: Duration::from_secs_f64(1.0 / f64::from(config.rate_hz)),
            keepalive: config.idle_keepalive,
            patch,
            sockets: sockets.list,
            sacn,
            artnet,
            art_sockets,
            traffic,
        })
    }
}

/// Sockets by bind address: destinations with the same fixed `bind` (e.g. port 6454)
/// share one socket, since binding it twice would fail without SO_REUSEPORT.
#[derive(Debug, Default)]
pub(crate) struct Sockets {
    pub(crate) list: Vec<UdpSocket>,
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
/// [`Traffic::destinations`], its rate-limited log.
#[derive(Debug)]
pub(crate) struct Route {
    pub(crate) socket: usize,
    errors: usize,
    protocol: &'static str,
    log: Throttle,
}

impl Route {
    /// Sends one encoded packet; a failure (encoding or socket) is counted and logged at a
    /// rate-limited pace, never fatal: the clock goes on.
    pub(crate) fn send(
        &mut self,
        sockets: &[UdpSocket],
        counters: &Counters,
        traffic: &Traffic,
        now: Instant,
        to: SocketAddr,
        packet: Result<&[u8], String>,
    ) {
        let socket = &sockets[self.socket];
        let result =
            packet.and_then(|p| socket.send_to(p, to).map(drop).map_err(|e| e.to_string()));
        if let Err(e) = result {
            counters.send_errors.fetch_add(1, Ordering::Relaxed);
            traffic.destinations[self.errors]
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

#[derive(Debug)]
pub(crate) struct SacnSink {
    pub(crate) route: Route,
    pub(crate) target: SacnTarget,
    pub(crate) port: u16,
    pub(crate) source_name: String,
    pub(crate) priority: u8,
    pub(crate) sync_universe: u16,
    pub(crate) sync_sequence: u8,
}

impl SacnSink {
    pub(crate) fn address(&self, universe: u16) -> SocketAddr {
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

#[derive(Debug)]
pub(crate) struct ArtnetSink {
    pub(crate) route: Route,
    pub(crate) to: SocketAddr,
    /// Per patched universe.
    pub(crate) port_addresses: Vec<u16>,
    /// ArtPoll to `to`, ArtDmx unicast to [`ArtnetSink::nodes`] (`discover = true`).
    pub(crate) discover: bool,
    pub(crate) nodes: Vec<Node>,
}

/// An Art-Net node that answered ArtPoll: where it is and what it outputs.
#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub(crate) ip: IpAddr,
    /// Its reply's BindIndex: a node with many ports answers once per group of four.
    pub(crate) bind_index: u8,
    /// The port-addresses its output ports take from the network.
    pub(crate) outputs: Vec<u16>,
    pub(crate) seen: Instant,
}

/// How often a discovering Art-Net destination polls (Art-Net 4: every 2.5 to 3 s).
pub(crate) const POLL_EVERY: Duration = Duration::from_secs(3);
/// A node silent this long (three polls and a margin) is gone.
pub(crate) const NODE_GONE: Duration = Duration::from_secs(10);
/// How often E1.31 universe discovery goes out (E1.31-2018 8: every 10 s).
pub(crate) const DISCOVERY_EVERY: Duration = Duration::from_secs(10);
/// The universe whose multicast group carries E1.31 universe discovery.
pub(crate) const DISCOVERY_UNIVERSE: u16 = 64214;

impl ArtnetSink {
    /// Records (or refreshes) a node's ArtPollReply.
    pub(crate) fn found(&mut self, ip: IpAddr, bind_index: u8, outputs: &[u16], now: Instant) {
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
pub(crate) fn route_to(peer: SocketAddr) -> Ipv4Addr {
    UdpSocket::bind((Ipv4Addr::UNSPECIFIED, 0))
        .and_then(|s| s.connect(peer).and_then(|()| s.local_addr()))
        .ok()
        .and_then(|a| match a.ip() {
            IpAddr::V4(ip) => Some(ip),
            IpAddr::V6(_) => None,
        })
        .unwrap_or(Ipv4Addr::UNSPECIFIED)
}
