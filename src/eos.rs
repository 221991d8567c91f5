//! Export to an ETC Eos console: the live look becomes channel levels and colours on the
//! console's command line, recorded as a preset, so the programmer keeps the result in the
//! show file (paper 5.3).
//!
//! Everything goes through Eos's documented OSC command line (`/eos/newcmd`, one command
//! each, terminated with `Enter`):
//!
//! ```text
//! Chan 12 At 62 Enter                       intensity, percent (one decimal)
//! Chan 12 Red 100 Green 55 Blue 20 Enter    colour lights: emitter levels, percent
//! Chan 1 Thru 44 Record Preset 5 Enter      the lights of the look, recorded
//! ```

use std::io::Write;
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::Duration;

use rosc::{OscMessage, OscPacket, OscType};
use serde::Deserialize;

use crate::osc::framing::{self, Framing};
use visobjd_scene::Scene;
use visobjd_scene::look::Look;

/// How long connecting to and writing to the console may take.
const TIMEOUT: Duration = Duration::from_secs(3);

/// How the console is reached (its OSC settings: UDP, or TCP with either framing).
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

/// The `[eos]` config section; no address means no console.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EosConfig {
    /// The console's OSC address and port, e.g. "10.101.0.5:8000"; "" turns export off.
    pub address: String,
    /// How to reach it.
    pub protocol: Protocol,
}

impl Default for EosConfig {
    fn default() -> Self {
        EosConfig {
            address: String::new(),
            protocol: Protocol::Tcp,
        }
    }
}

impl EosConfig {
    /// The console's address, None when export is off; Err names the bad value.
    pub fn console(&self) -> Result<Option<SocketAddr>, String> {
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
}

/// The command lines that put `look` on the console and record it as preset `n`.
pub fn preset_commands(scene: &Scene, look: &Look, n: u32) -> Vec<String> {
    let mut cmds = Vec::with_capacity(scene.lights.len() * 2 + 1);
    for (l, (light, level)) in scene.lights.iter().zip(&look.levels).enumerate() {
        cmds.push(format!(
            "Chan {} At {} Enter",
            light.channel,
            percent(level.intensity)
        ));
        if scene.profile(l).has_colour() {
            // Emitter levels at full: the same linear multiplier the DMX output uses.
            let c = visobjd_scene::look::Level {
                intensity: 1.0,
                ..*level
            }
            .multiplier();
            cmds.push(format!(
                "Chan {} Red {} Green {} Blue {} Enter",
                light.channel,
                percent(c[0]),
                percent(c[1]),
                percent(c[2])
            ));
        }
    }
    let channels: Vec<u32> = scene.lights.iter().map(|l| l.channel).collect();
    cmds.push(format!(
        "Chan {} Record Preset {n} Enter",
        channel_list(&channels)
    ));
    cmds
}

/// A level as Eos takes it: percent with at most one decimal, no trailing ".0".
fn percent(v: f32) -> String {
    let p = (v.clamp(0.0, 1.0) * 1000.0).round() / 10.0;
    if p.fract() == 0.0 {
        format!("{}", p as u32)
    } else {
        format!("{p:.1}")
    }
}

/// Ascending channels as an Eos selection: runs become `Thru`, the rest are joined by `+`.
pub fn channel_list(channels: &[u32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < channels.len() {
        let start = channels[i];
        let mut end = start;
        while i + 1 < channels.len() && channels[i + 1] == end + 1 {
            i += 1;
            end = channels[i];
        }
        parts.push(if end > start {
            format!("{start} Thru {end}")
        } else {
            start.to_string()
        });
        i += 1;
    }
    parts.join(" + ")
}

/// Sends the command lines to the console as `/eos/newcmd` messages, in order.
pub fn push(config: &EosConfig, to: SocketAddr, commands: &[String]) -> Result<(), String> {
    let packets = commands
        .iter()
        .map(|c| {
            rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: "/eos/newcmd".into(),
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
    fn percents_have_at_most_one_decimal() {
        assert_eq!(percent(0.62), "62");
        assert_eq!(percent(0.625), "62.5");
        assert_eq!(percent(1.0), "100");
        assert_eq!(percent(0.0), "0");
        assert_eq!(percent(2.0), "100");
    }
}
