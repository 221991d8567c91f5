//! `/vo/reload`: re-reads the config and the scene, as `SIGHUP` does (docs/osc.md). Each
//! daemon reloads its own files, so a backup takes it from any allowed sender and it is
//! never forwarded.

use rosc::{OscMessage, OscType};

use super::Context;
use crate::engine::{Refusal, msg};
use crate::osc::args::Request;

pub enum Cmd {
    Reload,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(req.matches("/vo/reload").map(|_| Cmd::Reload))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        match self {
            Cmd::Reload => {
                // The answer comes once the images are read and the change is made.
                cx.engine.reload_then(cx.later(), |done| {
                    vec![msg("/vo/reloaded", vec![OscType::String(done)])]
                })?;
                Ok(Vec::new())
            }
        }
    }
}
