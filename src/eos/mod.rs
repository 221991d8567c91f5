//! Export to an ETC Eos console: a look becomes channel levels and colours on Eos's
//! command line, recorded as a preset or a cue, so the programmer keeps the result in the
//! show file (paper 5.3), and each record is confirmed by what Eos answers.
//!
//! Everything goes through Eos's documented OSC command line as a user of its own
//! (`/eos/user/<n>/newcmd`, one command each, terminated with `Enter`), so the
//! programmer's command line is never touched. [`commands`] writes the lines,
//! [`record`] sends them and waits for Eos's answer, [`link`] is the TCP connection (the
//! live import reads the patch over it too).

pub mod commands;
pub mod link;
pub mod palettes;
pub mod record;

use std::net::SocketAddr;

use serde::Deserialize;

/// The Eos users an OSC command may run as: Eos devices take user IDs 1..=99.
const USERS: std::ops::RangeInclusive<u32> = 1..=99;

/// How long Eos may take to answer a record, by default.
const TIMEOUT_S: f64 = 5.0;

/// How Eos is reached (its OSC settings: UDP, or TCP with either framing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Protocol {
    /// OSC over UDP (Eos "OSC UDP RX port"); Eos answers to its OSC TX address, which
    /// must be visobjd's `osc.udp` port.
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
    /// How long Eos may take to confirm a record before it counts as failed, in seconds.
    pub timeout_s: f64,
}

impl Default for EosConfig {
    fn default() -> Self {
        EosConfig {
            address: String::new(),
            protocol: Protocol::Tcp,
            user: 90,
            timeout_s: TIMEOUT_S,
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
        if !(self.timeout_s.is_finite() && (0.1..=60.0).contains(&self.timeout_s)) {
            return Err(format!(
                "eos.timeout_s must be 0.1..=60 (seconds Eos may take to confirm a record), got {}",
                self.timeout_s
            ));
        }
        self.target().map(drop)
    }

    /// The Eos console's address, None when export is off; Err names the bad value.
    pub fn target(&self) -> Result<Option<SocketAddr>, String> {
        crate::osc::address("eos.address", &self.address, "10.101.0.5:8000")
    }

    /// The OSC address every command line is sent to.
    pub fn command_address(&self) -> String {
        format!("/eos/user/{}/newcmd", self.user)
    }

    /// The address Eos echoes the user's command line on (with "Error:" when it refused).
    pub fn echo_address(&self) -> String {
        format!("/eos/out/user/{}/cmd", self.user)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn users_and_timeouts_are_checked() {
        let bad = EosConfig {
            user: 0,
            ..EosConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("eos.user"));
        let bad = EosConfig {
            timeout_s: f64::NAN,
            ..EosConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("eos.timeout_s"));
        assert_eq!(
            EosConfig::default().command_address(),
            "/eos/user/90/newcmd"
        );
        assert_eq!(EosConfig::default().echo_address(), "/eos/out/user/90/cmd");
    }
}
