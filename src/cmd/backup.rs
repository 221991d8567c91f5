//! `/vo/backup/subscribe` (a backup asks its main for the state and the commands it
//! accepts), `/vo/backup/state` (the state, applied by a backup) and `/vo/backup/gallery`
//! (a gallery the main's generate installed, applied by a backup). The main's side is
//! src/engine/backups.rs, the backup's connection src/backup.rs.

use std::sync::Arc;

use rosc::OscMessage;

use super::Context;
use crate::engine::{Engine, Refusal};
use crate::osc::Transport;
use crate::osc::args::{self, Request};

pub enum Cmd {
    Subscribe,
    /// The main's `session.json`, `live.json`, `looks.json` and what its session holds
    /// besides (gallery, history, Eos selection), as JSON text.
    State([String; 4]),
    /// The gallery a generate installed on the main, as JSON text.
    Gallery(String),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/backup/subscribe").is_some() {
            Cmd::Subscribe
        } else if req.matches("/vo/backup/state").is_some() {
            Cmd::State([
                part(req, 0, "session")?,
                part(req, 1, "live look")?,
                part(req, 2, "looks")?,
                part(req, 3, "working state")?,
            ])
        } else if req.matches("/vo/backup/gallery").is_some() {
            Cmd::Gallery(part(req, 0, "gallery")?)
        } else {
            return Ok(None);
        }))
    }

    /// A state or gallery changes the session; a subscription changes nothing a backup
    /// mirrors.
    pub fn changes_state(&self) -> bool {
        !matches!(self, Cmd::Subscribe)
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let e = cx.engine;
        match self {
            Cmd::Subscribe => {
                if cx.peer.transport() == Transport::Udp {
                    return Err(Refusal::input(
                        "a backup subscribes over TCP (osc.tcp): it needs every command, in order",
                    ));
                }
                e.attach_backup(Arc::new(cx.peer.clone()))?;
            }
            Cmd::State(parts) => {
                only_a_backup(e, "state")?;
                e.install_state(&parts)?;
            }
            Cmd::Gallery(text) => {
                only_a_backup(e, "gallery")?;
                e.take_gallery(&text)?;
            }
        }
        Ok(Vec::new())
    }
}

/// Argument `i`, a JSON text, named `what` in errors.
fn part(req: &Request, i: usize, what: &str) -> Result<String, String> {
    Ok(args::string(req.required(i, what)?, what)?.to_string())
}

/// Err unless this daemon is a backup (which takes `what` only from its main:
/// [`super::Runner::run`] refuses changes from anyone else).
fn only_a_backup(e: &Engine, what: &str) -> Result<(), Refusal> {
    match e.main() {
        Some(_) => Ok(()),
        None => Err(Refusal::conflict(format!(
            "only a backup takes a {what}, from its main: this daemon has no [backup]"
        ))),
    }
}
