//! Picking from the gallery and stepping through the base-look history: `/vo/pick`,
//! `/vo/next`, `/vo/prev`, `/vo/undo`, `/vo/redo`, `/vo/candidate`, `/vo/gallery`.

use rosc::OscMessage;

use super::{Context, int, int_arg, look_messages, opt_int_arg};
use crate::engine::session::{Change, Session};
use crate::engine::{Outcome, Refusal, gallery_sizes, msg};
use crate::osc::args::Request;

pub enum Cmd {
    Pick {
        k: usize,
        m: usize,
    },
    Step {
        forward: bool,
    },
    /// `/vo/undo [steps]` (back) or `/vo/redo [steps]`: one change however many steps.
    History {
        back: bool,
        steps: usize,
    },
    Candidate {
        k: usize,
        m: usize,
    },
    Gallery,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        let entry = |req: &Request| -> Result<(usize, usize), String> {
            Ok((
                int_arg(req, 0, "entry", 1, 1_000_000)? as usize,
                opt_int_arg(req, 1, "member", 1, 1_000_000, 1)? as usize,
            ))
        };
        Ok(Some(if req.matches("/vo/pick").is_some() {
            let (k, m) = entry(req)?;
            Cmd::Pick { k, m }
        } else if req.matches("/vo/next").is_some() {
            Cmd::Step { forward: true }
        } else if req.matches("/vo/prev").is_some() {
            Cmd::Step { forward: false }
        } else if req.matches("/vo/undo").is_some() {
            Cmd::History {
                back: true,
                steps: opt_int_arg(req, 0, "undo steps", 1, i64::from(i32::MAX), 1)? as usize,
            }
        } else if req.matches("/vo/redo").is_some() {
            Cmd::History {
                back: false,
                steps: opt_int_arg(req, 0, "redo steps", 1, i64::from(i32::MAX), 1)? as usize,
            }
        } else if req.matches("/vo/candidate").is_some() {
            let (k, m) = entry(req)?;
            Cmd::Candidate { k, m }
        } else if req.matches("/vo/gallery").is_some() {
            Cmd::Gallery
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        cx.commit(|s| match self {
            Cmd::Pick { k, m } => pick(s, k, m),
            Cmd::Step { forward } => {
                let n = s.gallery.as_ref().map_or(0, |g| g.len());
                if n == 0 {
                    return Err(Refusal::conflict(
                        "there is no gallery yet: send /vo/generate first",
                    ));
                }
                let k = match (s.entry, forward) {
                    (Some((k, _)), true) => k % n + 1,
                    (Some((k, _)), false) => (k + n - 2) % n + 1,
                    (None, true) => 1,
                    (None, false) => n,
                };
                pick(s, k, 1)
            }
            Cmd::History { back, steps } => {
                let (word, addr) = if back {
                    ("undo", "/vo/undone")
                } else {
                    ("redo", "/vo/redone")
                };
                let depth = if back { s.undo(steps) } else { s.redo(steps) };
                let depth = depth.map_err(|there| {
                    Refusal::conflict(match there {
                        0 => format!("nothing to {word}"),
                        1 => format!("cannot {word} {steps} steps: there is 1 step to {word}"),
                        n => format!("cannot {word} {steps} steps: there are {n} steps to {word}"),
                    })
                })?;
                Ok(Outcome::reply(msg(addr, vec![int(depth)]))
                    .show_look(s.fade_s)
                    .saved()
                    .pushed())
            }
            Cmd::Candidate { k, m } => {
                let look = s.gallery_look(k, m)?;
                let head = vec![int(k), int(m)];
                Ok(Outcome::replies(look_messages(
                    "/vo/candidate",
                    head,
                    scene,
                    &look,
                )))
            }
            Cmd::Gallery => Ok(Outcome::reply(gallery_sizes(s))),
        })
    }
}

/// Puts entry `k`, member `m` live with the fade and makes it the base.
fn pick(s: &mut Session, k: usize, m: usize) -> Result<Outcome, Refusal> {
    let look = s.gallery_look(k, m)?;
    s.set_base(look, Change::Step);
    s.entry = Some((k, m));
    Ok(Outcome::reply(msg("/vo/picked", vec![int(k), int(m)]))
        .show_look(s.fade_s)
        .saved()
        .echoed())
}
