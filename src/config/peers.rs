//! The `[[osc.peer]]` entries (docs/config.md): where each known client listens and in which
//! framing, checked when the config is read; the OSC server routes replies by them
//! (src/osc/peers.rs). With `osc.backups` they are the hosts the main knows, whose TCP
//! connections always get a slot (src/slots.rs).

use std::net::IpAddr;

use serde::Deserialize;

use super::Cidr;

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
    /// The peer's address, canonical (an IPv4-mapped IPv6 address as IPv4); None when it
    /// is not an IP address.
    pub fn ip(&self) -> Option<IpAddr> {
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
pub fn validate_peers(peers: &[PeerConfig], allow: &[Cidr]) -> Result<(), String> {
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
        if !super::permits(allow, ip) {
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

/// Checks `osc.backups` (the addresses this main's backups connect from): IPs, heard (on
/// `allow`, or loopback when it is empty). Ok is the addresses, canonical (an IPv4-mapped
/// IPv6 address as IPv4); Err is one sentence naming the entry.
pub fn validate_backups(backups: &[String], allow: &[Cidr]) -> Result<Vec<IpAddr>, String> {
    backups
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let ip = b.trim().parse::<IpAddr>().map_err(|_| {
                format!(
                    "osc.backups[{i}]: `{b}` is not an IP address such as 10.101.0.11 (a backup's address, no port)"
                )
            })?;
            if !super::permits(allow, ip) {
                return Err(format!(
                    "osc.backups[{i}]: {ip} is not on osc.allow, so the backup could never connect"
                ));
            }
            Ok(ip.to_canonical())
        })
        .collect()
}

/// A peer listening on port 9000, for the tests of the config and of the routes.
#[cfg(test)]
impl PeerConfig {
    pub(crate) fn listening_at_9000(name: &str, address: &str, framing: PeerFraming) -> PeerConfig {
        PeerConfig {
            name: name.into(),
            address: address.into(),
            reply_port: 9000,
            framing,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(name: &str, address: &str, framing: PeerFraming) -> PeerConfig {
        PeerConfig::listening_at_9000(name, address, framing)
    }

    #[test]
    fn entries_are_checked() {
        let ok = [
            peer("tablet", "127.0.0.2", PeerFraming::Udp),
            peer("eos", "127.0.0.3", PeerFraming::Tcp),
        ];
        assert_eq!(validate_peers(&ok, &[]), Ok(()));
        let dup = [
            ok[0].clone(),
            peer("tablet", "127.0.0.4", PeerFraming::Slip),
        ];
        assert!(
            validate_peers(&dup, &[])
                .unwrap_err()
                .contains("used twice")
        );
        let same = [ok[0].clone(), peer("eos", "127.0.0.2", PeerFraming::Udp)];
        assert!(
            validate_peers(&same, &[])
                .unwrap_err()
                .contains("also peer `tablet`")
        );
        let port = [peer("eos", "127.0.0.1:3032", PeerFraming::Tcp)];
        assert!(
            validate_peers(&port, &[])
                .unwrap_err()
                .contains("not an IP address")
        );
        let far = [peer("eos", "10.0.0.5", PeerFraming::Tcp)];
        assert!(validate_peers(&far, &[]).unwrap_err().contains("osc.allow"));
        let allow = [Cidr::parse("10.0.0.0/8").unwrap()];
        assert_eq!(validate_peers(&far, &allow), Ok(()));
    }

    #[test]
    fn backups_are_addresses_on_the_allow_list() {
        let list = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let ok = validate_backups(&list(&["127.0.0.3", "::ffff:127.0.0.4"]), &[]);
        assert_eq!(
            ok,
            Ok(vec![
                "127.0.0.3".parse().unwrap(),
                "127.0.0.4".parse().unwrap()
            ])
        );
        let e = validate_backups(&list(&["10.0.0.2:8000"]), &[]).unwrap_err();
        assert!(
            e.starts_with("osc.backups[0]: `10.0.0.2:8000` is not an IP"),
            "{e}"
        );
        let e = validate_backups(&list(&["10.0.0.2"]), &[]).unwrap_err();
        assert!(e.contains("not on osc.allow"), "{e}");
        let allow = [Cidr::parse("10.0.0.0/8").unwrap()];
        assert!(validate_backups(&list(&["10.0.0.2"]), &allow).is_ok());
    }
}
