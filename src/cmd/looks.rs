//! Saved looks: `/vo/look/save`, `/vo/look/recall`, `/vo/look/delete`, `/vo/looks`.
//! Saved looks are on disk before the reply goes out.

use rosc::OscMessage;

use super::{Context, int, int_arg, text};
use crate::engine::session::{Change, MAX_LABEL, MAX_LOOKS, Session};
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::{self, Request};
use visobjd_scene::look::LookFile;

/// Largest look number (docs/osc.md).
const MAX_LOOK: i64 = 9999;

pub enum Cmd {
    Save { n: u32, label: Option<String> },
    Recall(u32),
    Delete(u32),
    List,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        let n = |req: &Request| int_arg(req, 0, "look number", 1, MAX_LOOK).map(|n| n as u32);
        Ok(Some(if req.matches("/vo/look/save").is_some() {
            let label = match req.arg(1) {
                Some(a) => Some(label(args::string(a, "label")?)?),
                None => None,
            };
            Cmd::Save { n: n(req)?, label }
        } else if req.matches("/vo/look/recall").is_some() {
            Cmd::Recall(n(req)?)
        } else if req.matches("/vo/look/delete").is_some() {
            Cmd::Delete(n(req)?)
        } else if req.matches("/vo/looks").is_some() {
            Cmd::List
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        match self {
            Cmd::Save { n, label } => {
                let label = label.unwrap_or_else(|| format!("Look {n}"));
                cx.change_looks(|s, looks| {
                    if looks.len() >= MAX_LOOKS && !looks.contains_key(&n) {
                        return Err(Refusal::conflict(format!(
                            "there are already {MAX_LOOKS} saved looks, the most a session \
                             keeps: save over one, or delete one first (/vo/look/delete n)"
                        )));
                    }
                    looks.insert(n, LookFile::from_look(scene, &s.live, &label));
                    Ok(())
                })
                .map_err(|err| err.after(&format!("look {n} was not saved")))?;
                Ok(vec![msg("/vo/look/saved", vec![int(n as usize)])])
            }
            Cmd::Recall(n) => cx.commit(|s| {
                let file = s.looks.get(&n).ok_or_else(|| missing(n))?;
                let look = file.to_look(scene).map_err(Refusal::conflict)?;
                s.set_base(look, Change::Step);
                s.entry = None;
                Ok(
                    Outcome::reply(msg("/vo/look/recalled", vec![int(n as usize)]))
                        .show_look(s.fade_s)
                        .saved()
                        .pushed(),
                )
            }),
            Cmd::Delete(n) => {
                cx.change_looks(|_, looks| looks.remove(&n).map(drop).ok_or_else(|| missing(n)))
                    .map_err(|err| err.after(&format!("look {n} was not deleted")))?;
                Ok(vec![msg("/vo/look/deleted", vec![int(n as usize)])])
            }
            Cmd::List => cx.commit(|s| Ok(Outcome::replies(list(s)))),
        }
    }
}

/// A look's label, refused past [`MAX_LABEL`] characters.
fn label(text: &str) -> Result<String, String> {
    let n = text.chars().count();
    if n > MAX_LABEL {
        return Err(format!(
            "a look's label is at most {MAX_LABEL} characters, got {n}"
        ));
    }
    Ok(text.to_string())
}

/// One `/vo/look n label` per saved look, then `/vo/looks/end count`.
pub fn list(s: &Session) -> Vec<OscMessage> {
    let mut out: Vec<OscMessage> = s
        .looks
        .iter()
        .map(|(n, f)| msg("/vo/look", vec![int(*n as usize), text(&f.label)]))
        .collect();
    out.push(msg("/vo/looks/end", vec![int(s.looks.len())]));
    out
}

fn missing(n: u32) -> Refusal {
    Refusal::conflict(format!("there is no saved look {n}"))
}
