//! `/vo/group/<name>/key`, `/vo/group/<name>/lock`, `/vo/light/<ch>/lock`: the designer's
//! constraints on generation.

use std::sync::Arc;

use rosc::OscMessage;

use super::{group, int, light, switch_arg, text};
use crate::engine::{Engine, Outcome, msg};
use crate::osc::args::Request;

pub enum Cmd {
    GroupKey { name: String, on: bool },
    GroupLock { name: String, on: bool },
    LightLock { channel: String, on: bool },
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        if let Some(c) = req.matches("/vo/group/*/key") {
            return Ok(Some(Cmd::GroupKey {
                name: c[0].to_string(),
                on: switch_arg(req, "key")?,
            }));
        }
        if let Some(c) = req.matches("/vo/group/*/lock") {
            return Ok(Some(Cmd::GroupLock {
                name: c[0].to_string(),
                on: switch_arg(req, "lock")?,
            }));
        }
        if let Some(c) = req.matches("/vo/light/*/lock") {
            return Ok(Some(Cmd::LightLock {
                channel: c[0].to_string(),
                on: switch_arg(req, "lock")?,
            }));
        }
        Ok(None)
    }

    pub fn apply(self, e: &Arc<Engine>) -> Result<Vec<OscMessage>, String> {
        let scene = &e.stage.scene;
        e.commit(|s| {
            let reply = match self {
                Cmd::GroupKey { name, on } => {
                    let g = group(scene, &name)?;
                    s.key_groups[g] = on;
                    msg(
                        "/vo/group/key",
                        vec![text(&scene.groups[g].name), int(on.into())],
                    )
                }
                Cmd::GroupLock { name, on } => {
                    let g = group(scene, &name)?;
                    s.locked_groups[g] = on;
                    msg(
                        "/vo/group/lock",
                        vec![text(&scene.groups[g].name), int(on.into())],
                    )
                }
                Cmd::LightLock { channel, on } => {
                    let l = light(scene, &channel)?;
                    s.locked_lights[l] = on;
                    msg(
                        "/vo/light/lock",
                        vec![int(scene.lights[l].channel as usize), int(on.into())],
                    )
                }
            };
            Ok(Outcome::reply(reply).saved())
        })
    }
}
