//! OSC transport (osc.md): sockets, framing, the argument rules, and the handler the engine
//! implements. The address space itself is the engine's.

pub mod args;
pub mod framing;
pub mod packet;
pub mod server;

pub use server::{Handler, Limits, Peer, Sender, Server, Transport};
