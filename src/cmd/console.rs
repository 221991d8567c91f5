//! The console's output as a look: `/vo/console/grab`, `/vo/console/follow`, and the task
//! that keeps the base following the console ([`follow`]).

use std::sync::Arc;

use rosc::OscMessage;

use super::{int, switch_arg};
use crate::engine::session::Change;
use crate::engine::{Engine, Outcome, msg};
use crate::osc::args::Request;

pub enum Cmd {
    Grab,
    Follow(bool),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/console/grab").is_some() {
            Cmd::Grab
        } else if req.matches("/vo/console/follow").is_some() {
            Cmd::Follow(switch_arg(req, "follow")?)
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, e: &Arc<Engine>) -> Result<Vec<OscMessage>, String> {
        if let Cmd::Follow(false) = self {
            return e.commit(|s| {
                s.following = false;
                Ok(Outcome::reply(msg("/vo/console/follow", vec![int(0)])).echoed())
            });
        }
        // Read outside the session's lock: the input has its own.
        let (look, sources) = e.console_look()?;
        e.commit(|s| {
            s.set_base(look, Change::Grab);
            s.entry = None;
            let reply = match self {
                Cmd::Grab => msg("/vo/console/grabbed", vec![int(sources)]),
                Cmd::Follow(_) => {
                    s.following = true;
                    msg("/vo/console/follow", vec![int(1)])
                }
            };
            Ok(Outcome::reply(reply).show_look(s.fade_s).saved().echoed())
        })
    }
}

/// Runs for the daemon's life when `[input.sacn]` is configured: every change of the
/// console's merged output becomes the base and live look at once while the session
/// follows the console. While no source counts (the console went away) the base stays.
pub async fn follow(e: Arc<Engine>, mut changes: tokio::sync::watch::Receiver<u64>) {
    while changes.changed().await.is_ok() {
        if !e.session().following {
            continue;
        }
        let Ok((look, _)) = e.console_look() else {
            continue;
        };
        let followed = e.commit(|s| {
            if !s.following || s.base == look {
                return Ok(Outcome::replies(Vec::new()));
            }
            s.set_base(look, Change::Follow);
            s.entry = None;
            // Like a fader: at once, written a moment later.
            Ok(Outcome::replies(Vec::new())
                .show_look(0.0)
                .saved_later()
                .pushed())
        });
        if let Err(err) = followed {
            tracing::warn!("following the console: {err}");
        }
    }
}
