//! `/vo/transfer k region x0 y0 x1 y1` and `/vo/transfer k group NAME`: the prototype's
//! "transfer area" and "transfer system", taking part of gallery entry k onto the live look.

use rosc::OscMessage;

use super::{Context, group, int, int_arg, num_arg};
use crate::engine::session::Change;
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::{self, Request};
use visobjd_method::constrain::transfer;
use visobjd_method::objective::Region;

/// Which lights of the entry are taken.
pub enum Part {
    /// The lights the region selects, by the objectives' rule.
    Region(Region),
    /// One group's lights.
    Group(String),
}

pub struct Cmd {
    entry: usize,
    part: Part,
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        if req.matches("/vo/transfer").is_none() {
            return Ok(None);
        }
        let entry = int_arg(req, 0, "entry", 1, 1_000_000)? as usize;
        let kind = args::string(req.required(1, "region or group")?, "region or group")?;
        let part = match kind.to_ascii_lowercase().as_str() {
            "region" => Part::Region(Region::new(
                num_arg(req, 2, "x0", 0.0, 1.0)?,
                num_arg(req, 3, "y0", 0.0, 1.0)?,
                num_arg(req, 4, "x1", 0.0, 1.0)?,
                num_arg(req, 5, "y1", 0.0, 1.0)?,
            )?),
            "group" => {
                Part::Group(args::string(req.required(2, "group name")?, "group name")?.to_string())
            }
            other => {
                return Err(format!(
                    "transfer takes `region x0 y0 x1 y1` or `group NAME` after the entry, got `{other}`"
                ));
            }
        };
        Ok(Some(Cmd { entry, part }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        cx.commit(|s| {
            let from = s.gallery_look(self.entry, 1)?;
            let lights = match &self.part {
                Part::Region(r) => stage.footprints.select(*r),
                Part::Group(name) => {
                    let g = group(scene, name)?;
                    let mut on = vec![false; scene.lights.len()];
                    for &l in &scene.groups[g].lights {
                        on[l] = true;
                    }
                    on
                }
            };
            if !lights.contains(&true) {
                return Err(Refusal::conflict(
                    "the region selects no light: there is nothing to transfer",
                ));
            }
            let look = transfer(&s.live, &from, &lights);
            s.set_base(look, Change::Step);
            s.entry = None;
            let mut a = vec![int(self.entry)];
            a.extend(
                (lights.iter().enumerate())
                    .filter(|(_, on)| **on)
                    .map(|(l, _)| int(scene.lights[l].channel as usize)),
            );
            Ok(Outcome::reply(msg("/vo/transferred", a))
                .show_look(s.fade_s)
                .saved()
                .pushed())
        })
    }
}
