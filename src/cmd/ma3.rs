//! Storing into a grandMA3: `/vo/ma3/preset pool.n [label]` and `/vo/ma3/cue sequence cue
//! [label]` (docs/ma3.md). Answered once the commands are sent: MA3 answers nothing over
//! OSC, so nothing here can say the desk took them.

use rosc::{OscMessage, OscType};

use super::{Context, int_arg};
use crate::engine::Refusal;
use crate::eos::commands::trimmed;
use crate::ma3::commands::Target;
use crate::osc::args::{self, Request};

pub struct Cmd {
    target: Target,
    label: Option<String>,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        let label = |req: &Request, i| match req.arg(i) {
            Some(a) => args::string(a, "label").map(|s| Some(s.to_string())),
            None => Ok(None),
        };
        Ok(Some(if req.matches("/vo/ma3/preset").is_some() {
            // Text keeps `21.10` as written; a number is read to three decimals (a
            // float's 21.1 is 21.100000381...), so 21.10 as a number is 21.1.
            let preset = match req.required(0, "preset (POOL.NUMBER)")? {
                OscType::String(s) => s.clone(),
                a => trimmed(args::number(a, "preset (POOL.NUMBER)")?, 3),
            };
            Cmd {
                target: Target::preset(&preset)?,
                label: label(req, 1)?,
            }
        } else if req.matches("/vo/ma3/cue").is_some() {
            Cmd {
                target: Target::Cue {
                    sequence: int_arg(req, 0, "sequence", 1, 9999)? as u32,
                    cue: int_arg(req, 1, "cue", 1, 9999)? as u32,
                },
                label: label(req, 2)?,
            }
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        Ok(vec![cx.engine.ma3_store(self.target, self.label)?])
    }
}
