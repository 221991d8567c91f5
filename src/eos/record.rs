//! A record sent to Eos and confirmed: the command lines go to the export's user, then a
//! read-back (`/eos/get/preset/<n>`, `/eos/get/cue/<list>/<cue>`); the record counts only
//! when Eos answers the read-back with the target (and its label), and fails with Eos's
//! words when the user's command line echo (`/eos/out/user/<n>/cmd`) carries an error,
//! or when nothing answers within `[eos] timeout_s`.
//!
//! Over TCP, Eos answers on the connection; over UDP it answers to its OSC TX address,
//! visobjd's own OSC port, and the engine hands those messages on (`heard`).

use std::net::{SocketAddr, UdpSocket};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use rosc::{OscMessage, OscType};

use super::commands::{Cue, label_text};
use super::link::{Link, packets};
use super::{EosConfig, Protocol};
use crate::osc::framing::Framing;

/// How long connecting to and writing to Eos may take.
const CONNECT: Duration = Duration::from_secs(3);

/// What a record stores, so its read-back can be checked.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// Preset `n`.
    Preset(u32),
    /// A cue, with the label it was given.
    Cue(Cue, Option<String>),
}

impl Target {
    /// "preset 5", "cue 2/7".
    pub fn name(&self) -> String {
        match self {
            Target::Preset(n) => format!("preset {n}"),
            Target::Cue(cue, _) => format!("cue {cue}"),
        }
    }

    /// The read-back request.
    fn query(&self) -> String {
        match self {
            Target::Preset(n) => format!("/eos/get/preset/{n}"),
            Target::Cue(cue, _) => format!("/eos/get/cue/{cue}"),
        }
    }

    /// Whether `addr` is the read-back's answer: `/eos/out/get/preset/<n>/list/...` or
    /// `/eos/out/get/cue/<list>/<cue>/<part>/list/...` (numbers compared as numbers).
    fn answered_by(&self, addr: &str) -> bool {
        let parts: Vec<&str> = addr.trim_start_matches('/').split('/').collect();
        let same = |a: &str, b: f64| a.parse::<f64>().is_ok_and(|a| (a - b).abs() < 1e-6);
        match (self, parts.as_slice()) {
            (Target::Preset(n), ["eos", "out", "get", "preset", p, "list", ..]) => {
                same(p, f64::from(*n))
            }
            (Target::Cue(cue, _), ["eos", "out", "get", "cue", l, c, _, "list", ..]) => {
                same(l, f64::from(cue.list)) && same(c, cue.number)
            }
            _ => false,
        }
    }

    /// The read-back's verdict: the target exists (the answer carries its index, UID and
    /// label) with the label it was given.
    fn check(&self, m: &OscMessage) -> Result<(), String> {
        if m.args.len() < 3 {
            return Err(format!(
                "Eos has no {} after the record (its read-back is empty)",
                self.name()
            ));
        }
        if let Target::Cue(_, Some(label)) = self {
            let want = label_text(label);
            let got = match &m.args[2] {
                OscType::String(s) => s.as_str(),
                _ => "",
            };
            if !want.is_empty() && got != want {
                return Err(format!(
                    "Eos recorded {} but its label reads `{got}`, not `{want}`",
                    self.name()
                ));
            }
        }
        Ok(())
    }
}

/// One record: the command lines and what they store.
pub struct Record {
    pub commands: Vec<String>,
    pub target: Target,
}

/// The way to the console and back.
pub enum Channel {
    Tcp(Link),
    Udp {
        socket: UdpSocket,
        to: SocketAddr,
        heard: Receiver<OscMessage>,
    },
}

impl Channel {
    /// Connects (TCP) or binds a socket (UDP, whose answers arrive on `heard`).
    pub fn open(
        config: &EosConfig,
        to: SocketAddr,
        heard: Receiver<OscMessage>,
    ) -> Result<Channel, String> {
        let framing = match config.protocol {
            Protocol::Udp => {
                let socket = crate::desk::udp_socket(to)?;
                return Ok(Channel::Udp { socket, to, heard });
            }
            Protocol::Tcp => Framing::LengthPrefix,
            Protocol::TcpSlip => Framing::Slip,
        };
        Link::connect(to, framing, CONNECT).map(Channel::Tcp)
    }

    fn send(&mut self, messages: &[OscMessage]) -> Result<(), String> {
        match self {
            Channel::Tcp(link) => link.send(messages),
            Channel::Udp { socket, to, .. } => {
                for p in packets(messages)? {
                    socket
                        .send_to(&p, *to)
                        .map_err(|e| format!("Eos at {to}: cannot send: {e}"))?;
                }
                Ok(())
            }
        }
    }

    fn next(&mut self, deadline: Instant) -> Result<Option<OscMessage>, String> {
        match self {
            Channel::Tcp(link) => link.next(deadline),
            Channel::Udp { heard, .. } => {
                let left = deadline.saturating_duration_since(Instant::now());
                Ok(heard.recv_timeout(left).ok())
            }
        }
    }

    /// Sends the record's command lines as `config`'s user, then its read-back, and waits
    /// for Eos's verdict.
    pub fn record(&mut self, config: &EosConfig, record: &Record) -> Result<(), String> {
        let addr = config.command_address();
        let mut messages: Vec<OscMessage> = record
            .commands
            .iter()
            .map(|c| OscMessage {
                addr: addr.clone(),
                args: vec![OscType::String(c.clone())],
            })
            .collect();
        messages.push(OscMessage {
            addr: record.target.query(),
            args: Vec::new(),
        });
        self.send(&messages)?;
        let echo = config.echo_address();
        let deadline = Instant::now() + Duration::from_secs_f64(config.timeout_s);
        let what = record.target.name();
        loop {
            let Some(m) = self.next(deadline)? else {
                return Err(format!(
                    "Eos did not confirm {what} within {} s (check [eos] address and protocol, \
                     and for udp that Eos's OSC TX goes to visobjd's OSC port)",
                    config.timeout_s
                ));
            };
            if m.addr == echo {
                if let Some(why) = refusal(&m) {
                    return Err(format!("Eos refused {what}: {why}"));
                }
            } else if record.target.answered_by(&m.addr) {
                return record.target.check(&m);
            }
        }
    }
}

impl super::palettes::Exchange for Channel {
    fn send(&mut self, messages: &[OscMessage]) -> Result<(), String> {
        Channel::send(self, messages)
    }

    fn next(&mut self, deadline: Instant) -> Result<Option<OscMessage>, String> {
        Channel::next(self, deadline)
    }
}

/// The text of a command line echo that reports an error, None for any other echo. Eos
/// writes the mode, then `Error:` and why, on the command line of a command it refused
/// (`LIVE: Error: Cue List Does Not Exist`); a label that merely holds the word is not one.
pub fn refusal(m: &OscMessage) -> Option<String> {
    let text = m.args.iter().find_map(|a| match a {
        OscType::String(s) => Some(s.trim()),
        _ => None,
    })?;
    let after_mode = match text.split_once(':') {
        Some((mode, rest)) if !mode.is_empty() && mode.chars().all(|c| c.is_ascii_uppercase()) => {
            rest.trim_start()
        }
        _ => text,
    };
    after_mode.starts_with("Error:").then(|| text.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(addr: &str, args: Vec<OscType>) -> OscMessage {
        OscMessage {
            addr: addr.to_string(),
            args,
        }
    }

    #[test]
    fn read_backs_are_matched_by_number() {
        let cue = Target::Cue(Cue::new(2, 7.0).unwrap(), None);
        assert_eq!(cue.query(), "/eos/get/cue/2/7");
        assert!(cue.answered_by("/eos/out/get/cue/2/7/0/list/0/5"));
        assert!(cue.answered_by("/eos/out/get/cue/2/7.0/0/list/0/5"));
        assert!(!cue.answered_by("/eos/out/get/cue/2/7.5/0/list/0/5"));
        assert!(!cue.answered_by("/eos/out/get/cue/1/7/0/list/0/5"));
        let preset = Target::Preset(5);
        assert_eq!(preset.query(), "/eos/get/preset/5");
        assert!(preset.answered_by("/eos/out/get/preset/5/list/0/5"));
        assert!(!preset.answered_by("/eos/out/get/preset/5/channels/x"));
    }

    #[test]
    fn a_read_back_checks_existence_and_label() {
        let label = Target::Cue(Cue::new(1, 3.0).unwrap(), Some("Dusk".into()));
        let s = |t: &str| OscType::String(t.into());
        let addr = "/eos/out/get/cue/1/3/0/list/0/5";
        assert!(
            label
                .check(&m(addr, vec![OscType::Int(0), s("uid"), s("Dusk")]))
                .is_ok()
        );
        let wrong = label.check(&m(addr, vec![OscType::Int(0), s("uid"), s("Dawn")]));
        assert!(wrong.unwrap_err().contains("`Dawn`"));
        assert!(
            label
                .check(&m(addr, vec![]))
                .unwrap_err()
                .contains("no cue 1/3")
        );
    }

    #[test]
    fn an_echo_with_an_error_is_a_refusal() {
        let s = |t: &str| OscType::String(t.into());
        let echo = "/eos/out/user/90/cmd";
        assert_eq!(
            refusal(&m(echo, vec![s("LIVE: Error: Cue List Does Not Exist")])).as_deref(),
            Some("LIVE: Error: Cue List Does Not Exist")
        );
        assert_eq!(refusal(&m(echo, vec![s("LIVE: Chan 1 At 50 #")])), None);
        assert_eq!(
            refusal(&m(echo, vec![s("LIVE: Cue 1/2 Label Terror #")])),
            None
        );
        assert!(refusal(&m(echo, vec![s("Error: Syntax Error")])).is_some());
    }
}
