//! The console's sACN output as a look: `/vo/console/grab`, `/vo/console/follow` (the base
//! then follows it: `Engine::follow_console`).

use rosc::OscMessage;

use super::{Context, int, switch_arg};
use crate::engine::session::Change;
use crate::engine::{Outcome, Refusal, msg};
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

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        if let Cmd::Follow(false) = self {
            return cx.commit(|s| {
                s.following = false;
                Ok(Outcome::reply(msg("/vo/console/follow", vec![int(0)])).echoed())
            });
        }
        // Read outside the session's lock: the input has its own.
        let (look, sources) = cx.engine.console_look()?;
        cx.commit(|s| {
            s.fits(&look)?;
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
