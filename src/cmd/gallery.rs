//! Picking from the gallery and stepping through the base-look history: `/vo/pick`,
//! `/vo/next`, `/vo/prev`, `/vo/undo`, `/vo/redo`, `/vo/candidate`, `/vo/gallery`.

use std::sync::Arc;

use rosc::OscMessage;

use super::{int, int_arg, light_args, opt_int_arg};
use crate::engine::session::Change;
use crate::engine::{Engine, gallery_look, msg};
use crate::osc::args::Request;

pub enum Cmd {
    Pick { k: usize, m: usize },
    Step { forward: bool },
    Undo,
    Redo,
    Candidate { k: usize, m: usize },
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
            Cmd::Undo
        } else if req.matches("/vo/redo").is_some() {
            Cmd::Redo
        } else if req.matches("/vo/candidate").is_some() {
            let (k, m) = entry(req)?;
            Cmd::Candidate { k, m }
        } else if req.matches("/vo/gallery").is_some() {
            Cmd::Gallery
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, e: &Arc<Engine>) -> Result<Vec<OscMessage>, String> {
        let mut s = e.session();
        match self {
            Cmd::Pick { k, m } => pick(e, s, k, m),
            Cmd::Step { forward } => {
                let n = s.gallery.as_ref().map_or(0, |g| g.len());
                if n == 0 {
                    return Err("there is no gallery yet: send /vo/generate first".into());
                }
                let k = match (s.entry, forward) {
                    (Some((k, _)), true) => k % n + 1,
                    (Some((k, _)), false) => (k + n - 2) % n + 1,
                    (None, true) => 1,
                    (None, false) => n,
                };
                pick(e, s, k, 1)
            }
            Cmd::Undo | Cmd::Redo => {
                let undo = matches!(self, Cmd::Undo);
                let depth = if undo { s.undo() } else { s.redo() };
                let depth = depth.ok_or(if undo {
                    "nothing to undo"
                } else {
                    "nothing to redo"
                })?;
                e.show(&s, s.fade_s);
                let feedback = e.feedback(&s);
                let saved = e.persist(s, true);
                e.notify(&feedback);
                saved?;
                let addr = if undo { "/vo/undone" } else { "/vo/redone" };
                Ok(vec![msg(addr, vec![int(depth)])])
            }
            Cmd::Candidate { k, m } => {
                let look = gallery_look(&s, k, m)?;
                let mut a = vec![int(k), int(m)];
                a.extend(light_args(&e.stage.scene, &look));
                Ok(vec![msg("/vo/candidate", a)])
            }
            Cmd::Gallery => Ok(vec![sizes(&s)]),
        }
    }
}

/// Puts entry `k`, member `m` live with the fade and makes it the base.
fn pick(
    e: &Arc<Engine>,
    mut s: std::sync::MutexGuard<'_, crate::engine::session::Session>,
    k: usize,
    m: usize,
) -> Result<Vec<OscMessage>, String> {
    let look = gallery_look(&s, k, m)?;
    s.set_base(look, Change::Step);
    s.entry = Some((k, m));
    e.show(&s, s.fade_s);
    let picked = msg("/vo/picked", vec![int(k), int(m)]);
    let feedback = e.feedback(&s);
    let saved = e.persist(s, true);
    e.notify(&[std::slice::from_ref(&picked), feedback.as_slice()].concat());
    saved?;
    Ok(vec![picked])
}

/// `/vo/gallery clusters size_1 ... size_c` (just `0` before the first generate).
pub fn sizes(s: &crate::engine::session::Session) -> OscMessage {
    let sizes: Vec<usize> = s
        .gallery
        .as_ref()
        .map(|g| g.generation.entries.iter().map(Vec::len).collect())
        .unwrap_or_default();
    let mut a = vec![int(sizes.len())];
    a.extend(sizes.into_iter().map(int));
    msg("/vo/gallery", a)
}
