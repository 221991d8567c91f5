//! grandMA3: a look stored as a preset or a cue through MA3's OSC input, one command per
//! message (`/<prefix>/cmd`, with "Receive Command" on; MA3 takes no bundles), or as a
//! plugin the desk runs (`visobjd export ma3`). MA3 answers nothing over OSC, so a command
//! sent is not a command confirmed: docs/ma3.md gives the checked way, the plugin.

pub mod commands;

use std::net::SocketAddr;

use rosc::{OscMessage, OscPacket, OscType};
use serde::Deserialize;

/// The `[ma3]` config section; no address means no MA3 export.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ma3Config {
    /// The desk's OSC input (an OSC data line with "Receive" and "Receive Command" on),
    /// e.g. "10.101.0.8:8000"; "" turns the export off.
    pub address: String,
    /// The data line's prefix: commands go to `/<prefix>/cmd`.
    pub prefix: String,
}

impl Default for Ma3Config {
    fn default() -> Self {
        Ma3Config {
            address: String::new(),
            prefix: "gma3".to_string(),
        }
    }
}

impl Ma3Config {
    /// Checks every key; Err names the bad one.
    pub fn validate(&self) -> Result<(), String> {
        let prefix = self.prefix.trim_matches('/');
        if prefix.is_empty()
            || !prefix
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(format!(
                "ma3.prefix must be the OSC data line's prefix (letters, digits, '_' or '-'), got `{}`",
                self.prefix
            ));
        }
        self.target().map(drop)
    }

    /// The desk's address, None when the export is off; Err names the bad value.
    pub fn target(&self) -> Result<Option<SocketAddr>, String> {
        crate::osc::address("ma3.address", &self.address, "10.101.0.8:8000")
    }

    /// The OSC address every command goes to.
    pub fn command_address(&self) -> String {
        format!("/{}/cmd", self.prefix.trim_matches('/'))
    }
}

/// Sends the commands to the desk over UDP, one message each, in order.
pub fn send(config: &Ma3Config, to: SocketAddr, commands: &[String]) -> Result<(), String> {
    let addr = config.command_address();
    let socket = crate::desk::udp_socket(to)?;
    for c in commands {
        let packet = rosc::encoder::encode(&OscPacket::Message(OscMessage {
            addr: addr.clone(),
            args: vec![OscType::String(c.clone())],
        }))
        .map_err(|e| format!("cannot encode `{c}`: {e}"))?;
        socket
            .send_to(&packet, to)
            .map_err(|e| format!("grandMA3 at {to}: cannot send: {e}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_are_checked() {
        assert_eq!(Ma3Config::default().command_address(), "/gma3/cmd");
        let bad = Ma3Config {
            prefix: "a b".into(),
            ..Ma3Config::default()
        };
        assert!(bad.validate().unwrap_err().contains("ma3.prefix"));
    }
}
