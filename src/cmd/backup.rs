//! `/vo/backup/subscribe` (a backup asks its main for the state and the commands it
//! accepts) and `/vo/backup/state` (the state, applied by a backup). See src/backup.rs.

use std::sync::Arc;

use rosc::OscMessage;

use crate::engine::Engine;
use crate::osc::Peer;
use crate::osc::args;
use crate::osc::args::Request;

pub enum Cmd {
    Subscribe,
    /// The main's `session.json`, `live.json` and `looks.json`, as JSON text.
    State([String; 3]),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/backup/subscribe").is_some() {
            Cmd::Subscribe
        } else if req.matches("/vo/backup/state").is_some() {
            let part = |i: usize, what: &str| -> Result<String, String> {
                Ok(args::string(args::required(&req.args, i, what)?, what)?.to_string())
            };
            Cmd::State([
                part(0, "session")?,
                part(1, "live look")?,
                part(2, "looks")?,
            ])
        } else {
            return Ok(None);
        }))
    }

    /// A state replaces the session; a subscription changes nothing a backup mirrors.
    pub fn changes_state(&self) -> bool {
        matches!(self, Cmd::State(_))
    }

    pub fn apply(self, e: &Arc<Engine>, peer: &Peer) -> Result<Vec<OscMessage>, String> {
        match self {
            Cmd::Subscribe => {
                e.attach_backup(peer)?;
                Ok(Vec::new())
            }
            Cmd::State(parts) => {
                if e.main().is_none() {
                    return Err(
                        "only a backup takes a state, from its main: this daemon has no [backup]"
                            .into(),
                    );
                }
                e.install_state(&parts)?;
                Ok(Vec::new())
            }
        }
    }
}
