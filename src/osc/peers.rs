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

use serde::Deserialize;

use super::framing::Framing;
use crate::config::Cidr;

/// How a peer wants its replies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PeerFraming {
    /// Datagrams to `address:reply_port`.
    Udp,
    /// TCP, OSC 1.0 (32-bit big-endian length prefix).
    Tcp,
    /// TCP, OSC 1.1 (SLIP).
    Slip,
}

/// One `[[osc.peer]]` entry.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeerConfig {
    /// A name for the log and errors ("tablet", "eos").
    pub name: String,
    /// The peer's IP address (no port: any source port of it matches).
    pub address: String,
    /// Where it listens: the UDP port, or the TCP port visobjd connects to.
    pub reply_port: u16,
    /// How it wants replies.
    pub framing: PeerFraming,
}

impl PeerConfig {
    fn ip(&self) -> Option<IpAddr> {
        self.address
            .trim()
            .parse::<IpAddr>()
            .ok()
            .map(|a| a.to_canonical())
    }
}

/// Checks the entries: names present and unique, addresses IPs, unique, and heard (on
/// `allow`, or loopback when it is empty), reply ports not 0. Err is one sentence naming
/// the entry and the key.
pub fn validate(peers: &[PeerConfig], allow: &[Cidr]) -> Result<(), String> {
    for (i, p) in peers.iter().enumerate() {
        let at = format!("osc.peer[{i}] (`{}`)", p.name);
        if p.name.trim().is_empty() {
            return Err(format!(
                "osc.peer[{i}]: name is empty; give every peer a name"
            ));
        }
        let ip = p.ip().ok_or_else(|| {
            format!(
                "{at}: address `{}` is not an IP address such as 10.101.0.20 (no port: reply_port says where it listens)",
                p.address
            )
        })?;
        if p.reply_port == 0 {
            return Err(format!("{at}: reply_port must be 1..=65535"));
        }
        if !crate::config::permits(allow, ip) {
            return Err(format!(
                "{at}: {ip} is not on osc.allow, so visobjd would never hear it"
            ));
        }
        if let Some(q) = peers[..i].iter().find(|q| q.name.trim() == p.name.trim()) {
            return Err(format!("{at}: the name `{}` is used twice", q.name));
        }
        if let Some(q) = peers[..i].iter().find(|q| q.ip() == Some(ip)) {
            return Err(format!(
                "{at}: address {ip} is also peer `{}`; one entry per address",
                q.name
            ));
        }
    }
    Ok(())
}

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

    fn peer(name: &str, address: &str, framing: PeerFraming) -> PeerConfig {
        PeerConfig {
            name: name.into(),
            address: address.into(),
            reply_port: 9000,
            framing,
        }
    }

    #[test]
    fn entries_are_checked() {
        let ok = [
            peer("tablet", "127.0.0.2", PeerFraming::Udp),
            peer("eos", "127.0.0.3", PeerFraming::Tcp),
        ];
        assert_eq!(validate(&ok, &[]), Ok(()));
        let dup = [
            ok[0].clone(),
            peer("tablet", "127.0.0.4", PeerFraming::Slip),
        ];
        assert!(validate(&dup, &[]).unwrap_err().contains("used twice"));
        let same = [ok[0].clone(), peer("eos", "127.0.0.2", PeerFraming::Udp)];
        assert!(
            validate(&same, &[])
                .unwrap_err()
                .contains("also peer `tablet`")
        );
        let port = [peer("eos", "127.0.0.1:3032", PeerFraming::Tcp)];
        assert!(
            validate(&port, &[])
                .unwrap_err()
                .contains("not an IP address")
        );
        let far = [peer("eos", "10.0.0.5", PeerFraming::Tcp)];
        assert!(validate(&far, &[]).unwrap_err().contains("osc.allow"));
        let allow = [Cidr::parse("10.0.0.0/8").unwrap()];
        assert_eq!(validate(&far, &allow), Ok(()));
    }

    #[test]
    fn peers_are_found_by_ip_whatever_the_source_port() {
        let routes = Routes::new(&[
            peer("tablet", "127.0.0.2", PeerFraming::Udp),
            peer("eos", "127.0.0.3", PeerFraming::Slip),
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
