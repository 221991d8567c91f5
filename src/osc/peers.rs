//! `[[osc.peer]]`: where each known client (a tablet, an Eos console, a second tablet)
//! listens, so replies and pushes reach every one of them at its own port and in its own
//! transport, while senders without an entry keep the global rule (`osc.reply_port`, or
//! the source port).
//!
//! A peer is recognised by its IP address. A `udp` peer gets datagrams at
//! `address:reply_port`. A `tcp` (OSC 1.0, length prefix) or `slip` (OSC 1.1) peer gets
//! its replies and pushes on the TCP connection it opened to visobjd, if it has one open;
//! otherwise visobjd opens one to `address:reply_port` on its own task (a few seconds'
//! timeout, messages queued meanwhile), never holding up the handler, and serves that
//! connection like any other (what the peer sends on it is heard).

use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};

use super::framing::Framing;
use crate::config::{PeerConfig, PeerFraming};

/// A configured peer at run time.
#[derive(Debug)]
pub(super) struct Route {
    pub name: String,
    pub ip: IpAddr,
    pub port: u16,
    /// `None`: UDP.
    pub framing: Option<Framing>,
    /// Its open TCP connection's way back (its own or one visobjd opened), if any.
    pub link: Mutex<Option<super::server::Link>>,
}

/// Every configured peer, looked up by the sender's IP.
#[derive(Debug, Default)]
pub(super) struct Routes {
    routes: Vec<Arc<Route>>,
}

impl Routes {
    /// The runtime table of validated entries (invalid ones, already refused at load, are
    /// left out).
    pub fn new(peers: &[PeerConfig]) -> Routes {
        Routes {
            routes: peers
                .iter()
                .filter_map(|p| {
                    Some(Arc::new(Route {
                        name: p.name.clone(),
                        ip: p.ip()?,
                        port: p.reply_port,
                        framing: match p.framing {
                            PeerFraming::Udp => None,
                            PeerFraming::Tcp => Some(Framing::LengthPrefix),
                            PeerFraming::Slip => Some(Framing::Slip),
                        },
                        link: Mutex::new(None),
                    }))
                })
                .collect(),
        }
    }

    /// The entry for `ip`, if it has one.
    pub fn get(&self, ip: IpAddr) -> Option<&Arc<Route>> {
        let ip = ip.to_canonical();
        self.routes.iter().find(|r| r.ip == ip)
    }

    /// The entry for `ip` if it wants its replies over TCP.
    pub fn tcp(&self, ip: IpAddr) -> Option<&Arc<Route>> {
        self.get(ip).filter(|r| r.framing.is_some())
    }

    /// Where replies to `from` go when it has an entry: its address at its reply port.
    pub fn reply_addr(&self, from: SocketAddr) -> Option<SocketAddr> {
        self.get(from.ip()).map(|r| SocketAddr::new(r.ip, r.port))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peers_are_found_by_ip_whatever_the_source_port() {
        let routes = Routes::new(&[
            PeerConfig::listening_at_9000("tablet", "127.0.0.2", PeerFraming::Udp),
            PeerConfig::listening_at_9000("eos", "127.0.0.3", PeerFraming::Slip),
        ]);
        let from = |s: &str| s.parse::<SocketAddr>().unwrap();
        assert_eq!(
            routes.reply_addr(from("127.0.0.2:51000")),
            Some(from("127.0.0.2:9000"))
        );
        assert!(routes.tcp(from("127.0.0.2:1").ip()).is_none());
        assert_eq!(
            routes.tcp(from("[::ffff:127.0.0.3]:1").ip()).unwrap().name,
            "eos"
        );
        assert!(routes.get(from("127.0.0.9:1").ip()).is_none());
    }
}
