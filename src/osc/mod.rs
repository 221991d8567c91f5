//! OSC transport (docs/osc.md): the UDP and TCP listeners with the sender allow-list and
//! the reply routes (`server`, `peers`), stream framing (`framing`), packet decoding
//! (`packet`) and the argument rules (`args`). It knows nothing of commands: the server
//! hands each message, read once into an [`args::Request`], to a [`Handler`]
//! (`crate::cmd::Runner` in the daemon) with the [`Peer`] it came from, and sends back what
//! the handler returns; a handler answers later through a clone of the peer.
//!
//! The codecs (`framing`, `packet`, `args`) are leaves: the backup's link to its main and
//! the Eos export use them too.

pub mod args;
pub mod framing;
pub mod packet;
pub mod peers;
pub mod server;

pub use server::{Handler, Limits, Peer, Sender, Server, Transport};

use std::net::SocketAddr;

use rosc::{OscMessage, OscType};

/// The address of every error answer.
pub const ERROR: &str = "/vo/error";

/// `/vo/error <address> <sentence>`: how every refusal and transport error is answered,
/// naming the address received.
pub fn error(addr: &str, sentence: &str) -> OscMessage {
    OscMessage {
        addr: ERROR.into(),
        args: vec![
            OscType::String(addr.to_string()),
            OscType::String(sentence.to_string()),
        ],
    }
}

/// A config key holding an address:port (a listener's, or a console's to send to): None
/// when empty (off), Err naming `key` when it is not one such as `example`.
pub fn address(key: &str, value: &str, example: &str) -> Result<Option<SocketAddr>, String> {
    if value.trim().is_empty() {
        return Ok(None);
    }
    value
        .trim()
        .parse()
        .map(Some)
        .map_err(|_| format!("{key} `{value}` is not an address:port such as {example}"))
}
