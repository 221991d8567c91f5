//! The handler the transports call (mini-redis's `server::Handler`): a message parsed once
//! into a [`Command`] and applied with its [`Context`], and a refusal rendered as
//! `/vo/error` ([`render`], the one place a command's failure becomes OSC). Here too is how
//! the engine reaches the transport without knowing it: a backup's connection is its
//! [`Follower`], the OSC socket its [`Pusher`].

use std::net::SocketAddr;
use std::sync::Arc;

use rosc::OscMessage;

use super::{Command, Context};
use crate::engine::{Engine, Follower, Pusher, Refusal};
use crate::osc::args::Request;
use crate::osc::{self, Peer};

/// Runs messages as commands on an engine (cheap to clone: one per transport).
#[derive(Clone)]
pub struct Runner {
    engine: Arc<Engine>,
}

impl Runner {
    /// A runner for `engine`.
    pub fn new(engine: Arc<Engine>) -> Runner {
        Runner { engine }
    }

    /// The engine it runs on.
    pub fn engine(&self) -> &Arc<Engine> {
        &self.engine
    }

    /// Parses and applies one message from `peer`: its replies, or why nothing changed. A
    /// backup answers queries but refuses changes: they come from its main.
    pub fn run(&self, req: &Request, peer: &Peer) -> Result<Vec<OscMessage>, Refusal> {
        self.engine.renew(peer.addr().ip());
        let command = Command::parse(req).map_err(Refusal::input)?;
        if let Some(main) = self.engine.main()
            && command.changes_state()
        {
            return Err(Refusal::conflict(format!(
                "this is a backup of {main}; send to the main"
            )));
        }
        self.apply(command, req, peer)
    }

    /// One message this backup's main sent it (`crate::backup`): as [`Runner::run`], but
    /// changes are taken.
    pub fn run_from_main(&self, req: &Request, main: &Peer) -> Result<Vec<OscMessage>, Refusal> {
        let command = Command::parse(req).map_err(Refusal::input)?;
        self.apply(command, req, main)
    }

    fn apply(
        &self,
        command: Command,
        req: &Request,
        peer: &Peer,
    ) -> Result<Vec<OscMessage>, Refusal> {
        // A daemon whose scene did not load answers queries and changes nothing.
        if command.changes_state() {
            self.engine.scene_loaded()?;
        }
        let forward = command.forwarded().then(|| OscMessage {
            addr: req.path(),
            args: req.args().to_vec(),
        });
        command.apply(&Context {
            engine: &self.engine,
            peer,
            addr: &req.addr,
            forward,
        })
    }
}

impl osc::Handler for Runner {
    fn handle(&self, req: Request, peer: &Peer) -> Vec<OscMessage> {
        render(&req.addr, peer, self.run(&req, peer))
    }
}

/// A command's result as OSC for the sender of `addr`: its replies, or its refusal as one
/// `/vo/error <address> <sentence>` (logged).
pub(super) fn render(
    addr: &str,
    peer: &Peer,
    result: Result<Vec<OscMessage>, Refusal>,
) -> Vec<OscMessage> {
    result.unwrap_or_else(|e| {
        tracing::info!("{addr} from {}: {e}", peer.addr());
        vec![osc::error(addr, &e.sentence)]
    })
}

/// A backup's connection, as the engine keeps it.
impl Follower for Peer {
    fn send(&self, msgs: &[OscMessage]) -> bool {
        self.reply(msgs)
    }

    fn addr(&self) -> SocketAddr {
        Peer::addr(self)
    }
}

/// The OSC server's UDP socket, as the engine pushes through it.
impl Pusher for osc::Sender {
    fn push(&self, to: SocketAddr, m: &OscMessage) -> Result<(), String> {
        self.send(to, m)
    }
}
