//! `/vo/test/stall 0|1`, `/vo/test/panic dmx|generate`, `/vo/test/slow_disk ms`: fault
//! injection for the tests of the watchdog and of recovery. Refused unless the daemon was
//! started with `VISOBJD_TEST_HOOKS` set (see [`crate::engine::TEST_HOOKS`]).

use rosc::OscMessage;

use super::{Context, switch_arg, text};
use crate::engine::{Refusal, TestHook, msg};
use crate::osc::args::{self, Request};

pub struct Cmd(TestHook);

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/test/stall").is_some() {
            Cmd(TestHook::StallDmx(switch_arg(req, "stall")?))
        } else if req.matches("/vo/test/panic").is_some() {
            match args::string(req.required(0, "where")?, "where")? {
                "dmx" => Cmd(TestHook::PanicDmx),
                "generate" => Cmd(TestHook::PanicGenerate),
                other => return Err(format!("where must be dmx or generate, got `{other}`")),
            }
        } else if req.matches("/vo/test/slow_disk").is_some() {
            Cmd(TestHook::SlowDisk(
                super::int_arg(req, 0, "milliseconds", 0, 10_000)? as u64,
            ))
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        cx.engine.test_hook(self.0)?;
        Ok(vec![msg("/vo/test", vec![text(&format!("{:?}", self.0))])])
    }
}
