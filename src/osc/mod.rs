//! OSC transport (docs/osc.md): sockets, framing, the argument rules, and the handler the engine
//! implements. The address space itself is the engine's.
//!
//! Wiring, inside the daemon's tokio runtime:
//!
//! ```text
//! let server = osc::Server::start(&config.osc, Arc::new(engine_handler))?;
//! let push = server.sender();            // subscriptions: push.send(addr, &msg)
//! // Handler::handle(req, &peer): the message read once by osc::args::Request::new
//! //   if let Some(ch) = req.matches("/vo/light/*/level") { ... args::number_in(..) ... }
//! //   long work: keep peer.clone(), answer later with peer.reply(&[...]).
//! ```

pub mod args;
pub mod framing;
pub mod packet;
pub mod peers;
pub mod server;

pub use server::{Handler, Limits, Peer, Sender, Server, Transport};
