//! Recording into an Eos console: `/vo/eos/preset n`, `/vo/eos/cue list cue [label]` and
//! `/vo/eos/cues list first` (docs/eos.md). Each is answered once Eos confirmed the
//! record, or with `/vo/error` carrying Eos's words or saying it did not answer.

use rosc::OscMessage;

use super::{Context, int_arg};
use crate::engine::EosRecord;
use crate::engine::Refusal;
use crate::eos::commands::Cue;
use crate::osc::args::{self, Request};

pub struct Cmd(EosRecord);

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        let cue = |req: &Request| {
            let list = int_arg(req, 0, "cue list", 1, 999)?;
            let number = args::number(req.required(1, "cue number")?, "cue number")?;
            Cue::new(list, number)
        };
        Ok(Some(Cmd(if req.matches("/vo/eos/preset").is_some() {
            EosRecord::Preset(int_arg(req, 0, "preset number", 1, 9999)? as u32)
        } else if req.matches("/vo/eos/cue").is_some() {
            let cue = cue(req)?;
            let label = match req.arg(2) {
                Some(a) => Some(args::string(a, "label")?.to_string()),
                None => None,
            };
            EosRecord::Cue { cue, label }
        } else if req.matches("/vo/eos/cues").is_some() {
            EosRecord::Cues { first: cue(req)? }
        } else {
            return Ok(None);
        })))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        // The answer goes to the sender once Eos has confirmed (or refused) the record.
        cx.engine.eos_record(self.0, cx.later())?;
        Ok(Vec::new())
    }
}
