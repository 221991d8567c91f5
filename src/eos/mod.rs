//! Export to an ETC Eos console: the live look becomes channel levels and colours on
//! Eos's command line, recorded as a preset, so the programmer keeps the result in the
//! show file (paper 5.3).
//!
//! Everything goes through Eos's documented OSC command line as a user of its own
//! (`/eos/user/<n>/newcmd`, one command each, terminated with `Enter`), so the
//! programmer's command line is never touched:
//!
//! ```text
//! Chan 12 At 62.375 Enter                   intensity, percent (16-bit: three decimals)
//! Chan 12 Red 100 Green 21.6 Blue 0 White 5.1 Enter    every colour parameter the patch drives
//! Chan 1 Thru 44 Record Preset 5 Enter      the lights of the look, recorded
//! ```
//!
//! The levels are the DMX output's own ([`Patch::light_slots`] at master 1), so recalling
//! the preset puts the same slots on the wire as visobjd did.

use std::io::Write;
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::Duration;

use rosc::{OscMessage, OscPacket, OscType};
use serde::Deserialize;

use crate::osc::framing::{self, Framing};
use visobjd_dmx::patch::Patch;
use visobjd_scene::Scene;
use visobjd_scene::look::Look;
use visobjd_scene::profile::Slot;

/// How long connecting to and writing to Eos may take.
const TIMEOUT: Duration = Duration::from_secs(3);

/// The Eos users an OSC command may run as: Eos devices take user IDs 1..=99.
const USERS: std::ops::RangeInclusive<u32> = 1..=99;

/// How Eos is reached (its OSC settings: UDP, or TCP with either framing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Protocol {
    /// OSC over UDP (Eos "OSC UDP RX port").
    Udp,
    /// OSC 1.0 over TCP: length-prefixed packets (Eos "OSC TCP Mode 1.0").
    Tcp,
    /// OSC 1.1 over TCP: SLIP-framed packets (Eos "OSC TCP Mode 1.1").
    TcpSlip,
}

/// The `[eos]` config section; no address means no export.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EosConfig {
    /// Eos's OSC address and port, e.g. "10.101.0.5:8000"; "" turns export off.
    pub address: String,
    /// How to reach it.
    pub protocol: Protocol,
    /// The Eos user the export types as: one nobody works on, so no command line in use
    /// is cleared or added to.
    pub user: u32,
}

impl Default for EosConfig {
    fn default() -> Self {
        EosConfig {
            address: String::new(),
            protocol: Protocol::Tcp,
            user: 90,
        }
    }
}

impl EosConfig {
    /// Checks every key; Err names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if !USERS.contains(&self.user) {
            return Err(format!(
                "eos.user must be {}..={} (an Eos user ID), got {}",
                USERS.start(),
                USERS.end(),
                self.user
            ));
        }
        self.target().map(drop)
    }

    /// The Eos console's address, None when export is off; Err names the bad value.
    pub fn target(&self) -> Result<Option<SocketAddr>, String> {
        if self.address.trim().is_empty() {
            return Ok(None);
        }
        self.address.trim().parse().map(Some).map_err(|_| {
            format!(
                "eos.address `{}` is not an address:port such as 10.101.0.5:8000",
                self.address
            )
        })
    }

    /// The OSC address every command line is sent to.
    pub fn command_address(&self) -> String {
        format!("/eos/user/{}/newcmd", self.user)
    }
}

/// The Eos parameter a slot drives, None for slots the export leaves out (intensity has
/// its own `At`; `uv` is always 0, `fixed:N` is the fixture's, not the look's).
fn parameter(slot: Slot) -> Option<&'static str> {
    Some(match slot {
        Slot::Red => "Red",
        Slot::Green => "Green",
        Slot::Blue => "Blue",
        Slot::White => "White",
        Slot::Amber => "Amber",
        Slot::Lime => "Lime",
        Slot::Cyan => "Cyan",
        Slot::Magenta => "Magenta",
        Slot::Yellow => "Yellow",
        // An extra emitter (`emitter:NAME`) carries the colour solve's level on DMX, but
        // which Eos parameter it is (Indigo, Cyan, Deep Red...) is not mapped yet: it is
        // left out of the export (docs/eos.md).
        Slot::Intensity | Slot::Intensity16 | Slot::Uv | Slot::Fixed(_) | Slot::Emitter(_) => {
            return None;
        }
    })
}

/// The command lines that put `look` on Eos and record it as preset `n`: per
/// light its intensity (`At 100` for a light without a dimmer, whose emitters carry its
/// intensity) and every colour parameter its profile drives, at the levels the DMX output
/// sends at master 1.
pub fn preset_commands(scene: &Scene, look: &Look, n: u32) -> Vec<String> {
    let patch = Patch::new(scene);
    let slots = patch.light_slots(&patch.unmastered(look));
    let mut cmds = Vec::with_capacity(scene.lights.len() * 2 + 1);
    for (light, slots) in scene.lights.iter().zip(&slots) {
        let ch = light.channel;
        let dimmer = slots.iter().find_map(|&(s, v)| match s {
            Slot::Intensity => Some(percent(v, 1)),
            Slot::Intensity16 => Some(percent(v, 3)),
            _ => None,
        });
        let colour: Vec<String> = slots
            .iter()
            .filter_map(|&(s, v)| parameter(s).map(|p| format!("{p} {}", percent(v, 1))))
            .collect();
        match (dimmer, colour.is_empty()) {
            (Some(at), _) => cmds.push(format!("Chan {ch} At {at} Enter")),
            (None, false) => cmds.push(format!("Chan {ch} At 100 Enter")),
            (None, true) => {}
        }
        if !colour.is_empty() {
            cmds.push(format!("Chan {ch} {} Enter", colour.join(" ")));
        }
    }
    let channels: Vec<u32> = scene.lights.iter().map(|l| l.channel).collect();
    cmds.push(format!(
        "Chan {} Record Preset {n} Enter",
        channel_list(&channels)
    ));
    cmds
}

/// A level as Eos takes it: percent with at most `decimals` decimals, no trailing zeros.
/// One decimal is within a tenth of an 8-bit step (0.39%), three within a third of a
/// 16-bit step (0.0015%), so Eos's own rounding lands on the same DMX value.
fn percent(v: f32, decimals: usize) -> String {
    let p = format!("{:.*}", decimals, f64::from(v.clamp(0.0, 1.0)) * 100.0);
    let p = if p.contains('.') {
        p.trim_end_matches('0').trim_end_matches('.')
    } else {
        &p
    };
    p.to_string()
}

/// Ascending channels as an Eos selection: runs become `Thru`, the rest are joined by `+`.
pub fn channel_list(channels: &[u32]) -> String {
    visobjd_rig::channel_runs(channels)
        .iter()
        .map(|&(start, end)| {
            if end > start {
                format!("{start} Thru {end}")
            } else {
                start.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(" + ")
}

/// Sends the command lines to Eos as `/eos/user/<n>/newcmd` messages, in order.
pub fn push(config: &EosConfig, to: SocketAddr, commands: &[String]) -> Result<(), String> {
    let addr = config.command_address();
    let packets = commands
        .iter()
        .map(|c| {
            rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: addr.clone(),
                args: vec![OscType::String(c.clone())],
            }))
            .map_err(|e| format!("cannot encode `{c}`: {e}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let fail = |e: std::io::Error| format!("Eos console at {to}: {e}");
    match config.protocol {
        Protocol::Udp => {
            let local: SocketAddr = if to.is_ipv4() {
                "0.0.0.0:0".parse().expect("literal address")
            } else {
                "[::]:0".parse().expect("literal address")
            };
            let socket = UdpSocket::bind(local).map_err(fail)?;
            for p in &packets {
                socket.send_to(p, to).map_err(fail)?;
            }
        }
        Protocol::Tcp | Protocol::TcpSlip => {
            let framing = if config.protocol == Protocol::Tcp {
                Framing::LengthPrefix
            } else {
                Framing::Slip
            };
            let mut stream = TcpStream::connect_timeout(&to, TIMEOUT).map_err(fail)?;
            stream.set_write_timeout(Some(TIMEOUT)).map_err(fail)?;
            let bytes: Vec<u8> = packets
                .iter()
                .flat_map(|p| framing::encode(framing, p))
                .collect();
            stream.write_all(&bytes).map_err(fail)?;
            stream.flush().map_err(fail)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_lists_use_thru_for_runs() {
        assert_eq!(channel_list(&[1, 2, 3, 4]), "1 Thru 4");
        assert_eq!(channel_list(&[1, 3, 4, 5, 9]), "1 + 3 Thru 5 + 9");
        assert_eq!(channel_list(&[7]), "7");
    }

    #[test]
    fn percents_have_their_decimals_without_trailing_zeros() {
        assert_eq!(percent(0.62, 1), "62");
        assert_eq!(percent(0.625, 1), "62.5");
        assert_eq!(percent(1.0, 1), "100");
        assert_eq!(percent(0.0, 3), "0");
        assert_eq!(percent(2.0, 1), "100");
        assert_eq!(percent(40_876.0 / 65_535.0, 3), "62.373");
    }

    #[test]
    fn users_are_checked() {
        let bad = EosConfig {
            user: 0,
            ..EosConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("eos.user"));
        assert_eq!(
            EosConfig::default().command_address(),
            "/eos/user/90/newcmd"
        );
    }
}
