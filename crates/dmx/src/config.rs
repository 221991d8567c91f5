//! The `[output]` and `[input]` sections of the config file (docs/config.md), with their
//! defaults and checks.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};

use serde::Deserialize;

/// Where and how fast DMX goes out. Embedded as `[output]` by the config loader; every
/// key has the default docs/config.md lists.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// DMX refresh rate, 1..=44 frames per second per universe.
    pub rate_hz: u32,
    /// Default crossfade in seconds when the live look changes (the engine passes it to
    /// [`crate::Output::set_look`]).
    pub fade_s: f32,
    /// Unchanged universes drop to a keep-alive: three repeats, then once a second.
    pub idle_keepalive: bool,
    /// sACN destinations (zero or more).
    pub sacn: Vec<SacnDest>,
    /// Art-Net destinations (zero or more).
    pub artnet: Vec<ArtnetDest>,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            rate_hz: 44,
            fade_s: 2.0,
            idle_keepalive: false,
            sacn: Vec::new(),
            artnet: Vec::new(),
        }
    }
}

/// One `[[output.sacn]]` destination.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacnDest {
    /// An IP address (unicast), or `"multicast"` for 239.255.hi.lo per universe.
    pub destination: String,
    /// Destination UDP port.
    pub port: u16,
    /// Local address the packets leave from (port 0: ephemeral).
    pub bind: SocketAddr,
    /// E1.31 priority, 0..=200.
    pub priority: u8,
    /// Source name shown by receivers (at most 63 bytes of UTF-8).
    pub source_name: String,
    /// Synchronization universe; 0 sends no synchronization packets.
    pub sync_universe: u16,
}

impl Default for SacnDest {
    fn default() -> Self {
        SacnDest {
            destination: "127.0.0.1".into(),
            port: 5568,
            bind: SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 0),
            priority: 100,
            source_name: "visobjd".into(),
            sync_universe: 0,
        }
    }
}

/// One `[[output.artnet]]` destination.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArtnetDest {
    /// An IP address; a directed broadcast address is allowed.
    pub destination: String,
    /// Destination UDP port.
    pub port: u16,
    /// Local address the packets leave from (Art-Net gear expects source port 6454).
    pub bind: SocketAddr,
    /// Art-Net port-address = scene universe + this.
    pub universe_offset: i32,
    /// Find the nodes: ArtPoll goes to `destination` (a broadcast address) every 3 s and
    /// ArtDmx goes unicast to each node that reported the universe in its ArtPollReply,
    /// never to `destination` itself (Art-Net 3 and later forbid broadcasting ArtDmx).
    pub discover: bool,
}

impl Default for ArtnetDest {
    fn default() -> Self {
        ArtnetDest {
            destination: "127.0.0.1".into(),
            port: 6454,
            bind: SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 0),
            universe_offset: -1,
            discover: false,
        }
    }
}

/// Where an sACN destination sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SacnTarget {
    /// 239.255.hi.lo per universe.
    Multicast,
    /// One host (or a broadcast address).
    Unicast(IpAddr),
}

impl SacnDest {
    /// The destination as sent to; `Err` names the problem.
    pub(crate) fn target(&self) -> Result<SacnTarget, String> {
        if self.destination == "multicast" {
            return Ok(SacnTarget::Multicast);
        }
        self.destination
            .parse()
            .map(SacnTarget::Unicast)
            .map_err(|_| {
                format!(
                    "destination `{}` is neither an IP address nor \"multicast\"",
                    self.destination
                )
            })
    }
}

impl ArtnetDest {
    /// The destination address; `Err` names the problem.
    pub(crate) fn address(&self) -> Result<IpAddr, String> {
        self.destination
            .parse()
            .map_err(|_| format!("destination `{}` is not an IP address", self.destination))
    }

    /// The Art-Net port-address of scene universe `universe`, if it fits in 15 bits.
    pub fn port_address(&self, universe: u16) -> Option<u16> {
        let pa = i64::from(universe) + i64::from(self.universe_offset);
        u16::try_from(pa).ok().filter(|&pa| pa <= 0x7fff)
    }
}

impl OutputConfig {
    /// Checks ranges and addresses, and that every patched `universes` entry maps to a valid
    /// Art-Net port-address, so a bad config is refused at load time rather than on air.
    /// The message names the key (`output.artnet[0].universe_offset: ...`).
    pub fn validate(&self, universes: &[u16]) -> Result<(), String> {
        if !(1..=44).contains(&self.rate_hz) {
            return Err(format!(
                "output.rate_hz: {} is out of range (1..=44)",
                self.rate_hz
            ));
        }
        if !self.fade_s.is_finite() || self.fade_s < 0.0 {
            return Err(format!(
                "output.fade_s: {} is not a duration in seconds",
                self.fade_s
            ));
        }
        for (i, d) in self.sacn.iter().enumerate() {
            let key = format!("output.sacn[{i}]");
            let target = d.target().map_err(|e| format!("{key}: {e}"))?;
            if target == SacnTarget::Multicast && !d.bind.is_ipv4() {
                return Err(format!(
                    "{key}: multicast sACN is IPv4 (239.255.x.y): bind an IPv4 address"
                ));
            }
            if let SacnTarget::Unicast(ip) = target
                && ip.is_ipv4() != d.bind.is_ipv4()
            {
                return Err(format!(
                    "{key}: destination {ip} and bind {} are not the same IP version",
                    d.bind
                ));
            }
            if d.priority > 200 {
                return Err(format!(
                    "{key}.priority: {} is out of range (0..=200)",
                    d.priority
                ));
            }
            if d.source_name.len() > 63 {
                return Err(format!(
                    "{key}.source_name: longer than 63 bytes (E1.31 has a 64-byte, NUL-terminated field)"
                ));
            }
            if d.sync_universe > 63999 {
                return Err(format!(
                    "{key}.sync_universe: {} is out of range (0 for none, or 1..=63999)",
                    d.sync_universe
                ));
            }
        }
        for (i, d) in self.artnet.iter().enumerate() {
            let key = format!("output.artnet[{i}]");
            let ip = d.address().map_err(|e| format!("{key}: {e}"))?;
            if ip.is_ipv4() != d.bind.is_ipv4() {
                return Err(format!(
                    "{key}: destination {ip} and bind {} are not the same IP version",
                    d.bind
                ));
            }
            if let Some(&u) = universes.iter().find(|&&u| d.port_address(u).is_none()) {
                return Err(format!(
                    "{key}.universe_offset: scene universe {u} + {} is outside the Art-Net port-addresses 0..=32767",
                    d.universe_offset
                ));
            }
        }
        Ok(())
    }
}

/// The `[input]` section: what visobjd listens to (docs/config.md).
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InputConfig {
    /// The console's sACN (`[input.sacn]`); absent: no input.
    pub sacn: Option<SacnInput>,
}

/// `[input.sacn]`: the console's universes, received and merged as an E1.31 receiver does.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacnInput {
    /// `HOST:PORT` the receiver binds; multicast needs the wildcard address.
    pub bind: String,
    /// The universes received (1..=63999); packets of others are ignored.
    pub universes: Vec<u16>,
    /// An IPv4 address of the interface multicast groups are joined on; empty: unicast
    /// only.
    pub interface: String,
    /// Who may feed the input (addresses or CIDR blocks, as `osc.allow`); `None`: the
    /// `osc.allow` list. Packets from anyone else are dropped before they are read.
    pub allow: Option<Vec<String>>,
}

impl Default for SacnInput {
    fn default() -> Self {
        SacnInput {
            bind: "0.0.0.0:5568".into(),
            universes: Vec::new(),
            interface: String::new(),
            allow: None,
        }
    }
}

impl SacnInput {
    /// The bind address, and the interface when multicast is on; `Err` names the key
    /// (`input.sacn.bind: ...`), so a bad config is refused at load time.
    pub fn addresses(&self) -> Result<(SocketAddr, Option<Ipv4Addr>), String> {
        let bind: SocketAddr = self.bind.parse().map_err(|_| {
            format!(
                "input.sacn.bind: `{}` is not an address:port such as 0.0.0.0:5568",
                self.bind
            )
        })?;
        if self.universes.is_empty() {
            return Err(
                "input.sacn.universes: list the console's universes to receive, such as [1, 2]"
                    .into(),
            );
        }
        if let Some(u) = self.universes.iter().find(|u| !(1..=63999).contains(*u)) {
            return Err(format!(
                "input.sacn.universes: {u} is not an sACN universe (1..=63999)"
            ));
        }
        let mut sorted = self.universes.clone();
        sorted.sort_unstable();
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("input.sacn.universes: {} is listed twice", w[0]));
        }
        if self.interface.is_empty() {
            return Ok((bind, None));
        }
        let interface: Ipv4Addr = self.interface.parse().map_err(|_| {
            format!(
                "input.sacn.interface: `{}` is not an IPv4 address (the address of the interface multicast is joined on)",
                self.interface
            )
        })?;
        if bind.ip() != IpAddr::V4(Ipv4Addr::UNSPECIFIED) {
            return Err(format!(
                "input.sacn.bind: multicast (input.sacn.interface is set) needs bind = \"0.0.0.0:{}\": a socket bound to {} does not receive group traffic",
                bind.port(),
                bind.ip()
            ));
        }
        Ok((bind, Some(interface)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_section_takes_config_md_defaults() {
        let c: OutputConfig = toml::from_str("").expect("empty parses");
        assert_eq!(c, OutputConfig::default());
        assert_eq!((c.rate_hz, c.fade_s, c.idle_keepalive), (44, 2.0, false));
        let c: OutputConfig = toml::from_str("[[sacn]]\n[[artnet]]\n").expect("empty tables parse");
        assert_eq!(c.sacn, vec![SacnDest::default()]);
        assert_eq!(c.artnet, vec![ArtnetDest::default()]);
        assert_eq!(c.sacn[0].bind.to_string(), "127.0.0.1:0");
        assert_eq!(c.artnet[0].universe_offset, -1);
        assert!(c.validate(&[1, 2]).is_ok());
    }

    #[test]
    fn unknown_keys_are_refused() {
        assert!(toml::from_str::<OutputConfig>("rate = 4").is_err());
        assert!(toml::from_str::<OutputConfig>("[[sacn]]\nprio = 4").is_err());
    }

    #[test]
    fn validation_names_the_key() {
        let mut c = OutputConfig {
            artnet: vec![ArtnetDest::default()],
            ..OutputConfig::default()
        };
        let e = c.validate(&[0x8001]).expect_err("maps to 32768");
        assert!(e.contains("output.artnet[0].universe_offset"), "{e}");
        c.artnet[0].universe_offset = -2;
        assert!(c.validate(&[1]).is_err(), "maps to -1");
        c.artnet[0].universe_offset = 0;
        assert!(c.validate(&[32767]).is_ok());
        c.rate_hz = 45;
        assert!(c.validate(&[1]).is_err());
        let c = OutputConfig {
            sacn: vec![SacnDest {
                priority: 201,
                ..SacnDest::default()
            }],
            ..OutputConfig::default()
        };
        assert!(c.validate(&[1]).is_err());
        let c = OutputConfig {
            sacn: vec![SacnDest {
                destination: "lights.local".into(),
                ..SacnDest::default()
            }],
            ..OutputConfig::default()
        };
        assert!(c.validate(&[1]).is_err());
    }

    #[test]
    fn input_names_the_key() {
        let c: InputConfig = toml::from_str("").expect("empty parses");
        assert_eq!(c.sacn, None);
        let ok: InputConfig =
            toml::from_str("[sacn]\nbind = \"127.0.0.1:6000\"\nuniverses = [1, 2]\n")
                .expect("parses");
        let s = ok.sacn.expect("present");
        assert_eq!(
            s.addresses(),
            Ok(("127.0.0.1:6000".parse().expect("addr"), None))
        );
        let bad = |text: &str| {
            let c: InputConfig = toml::from_str(text).expect("parses");
            c.sacn.expect("present").addresses().expect_err("refused")
        };
        assert!(bad("[sacn]\nbind = \"6000\"\nuniverses = [1]").contains("input.sacn.bind"));
        assert!(bad("[sacn]\n").contains("input.sacn.universes"));
        assert!(bad("[sacn]\nuniverses = [0]").contains("input.sacn.universes"));
        assert!(bad("[sacn]\nuniverses = [64000]").contains("63999"));
        assert!(bad("[sacn]\nuniverses = [3, 3]").contains("twice"));
        assert!(
            bad("[sacn]\nuniverses = [1]\ninterface = \"eth0\"").contains("input.sacn.interface")
        );
        assert!(
            bad("[sacn]\nbind = \"127.0.0.1:5568\"\nuniverses = [1]\ninterface = \"127.0.0.1\"")
                .contains("0.0.0.0")
        );
        assert!(toml::from_str::<InputConfig>("[sacn]\nport = 1").is_err());
        let multicast: InputConfig =
            toml::from_str("[sacn]\nuniverses = [1]\ninterface = \"10.0.0.5\"").expect("parses");
        let (bind, interface) = multicast.sacn.expect("present").addresses().expect("valid");
        assert_eq!(
            (bind.port(), interface),
            (5568, Some(Ipv4Addr::new(10, 0, 0, 5)))
        );
    }
}
