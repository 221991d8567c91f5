//! The live look by hand: faders for lights and groups (no fade, live and base at once),
//! `/vo/live`, `/vo/fade`, `/vo/master`, `/vo/blackout`.

use rosc::{OscMessage, OscType};

use super::{
    Context, Named, group, int, int_arg, look_messages, num_arg, one_light, rgb_args, switch_arg,
    text,
};
use crate::engine::session::{Change, FADE_S};
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::Request;
use visobjd_scene::{MAX_PALETTE, Scene};

/// What a fader sets.
#[derive(Clone, Copy)]
pub enum Set {
    Intensity(f32),
    Color([f32; 3]),
    /// A moving light's focus palette.
    Position(u32),
}

pub enum Cmd {
    /// A light's or a group's fader.
    Fader(Named, Set),
    Live,
    Fade(f32),
    Master(f32),
    Blackout(bool),
}

fn set(req: &Request, what: &str) -> Result<Option<Set>, String> {
    Ok(Some(match what {
        "intensity" => Set::Intensity(num_arg(req, 0, "intensity", 0.0, 1.0)?),
        "level" => Set::Intensity(num_arg(req, 0, "level (percent)", 0.0, 100.0)? / 100.0),
        "color" | "colour" => Set::Color(rgb_args(req, 0)?),
        "position" => {
            Set::Position(int_arg(req, 0, "focus palette", 1, i64::from(MAX_PALETTE))? as u32)
        }
        _ => return Ok(None),
    }))
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        if let Some(c) = req.matches("/vo/light/*/*") {
            return Ok(set(req, c[1])?.map(|v| Cmd::Fader(Named::Light(c[0].into()), v)));
        }
        if let Some(c) = req.matches("/vo/group/*/*") {
            return Ok(set(req, c[1])?.map(|v| Cmd::Fader(Named::Group(c[0].into()), v)));
        }
        Ok(Some(if req.matches("/vo/live").is_some() {
            Cmd::Live
        } else if req.matches("/vo/fade").is_some() {
            Cmd::Fade(num_arg(
                req,
                0,
                "fade seconds",
                f64::from(*FADE_S.start()),
                f64::from(*FADE_S.end()),
            )?)
        } else if req.matches("/vo/master").is_some() {
            Cmd::Master(num_arg(req, 0, "master", 0.0, 1.0)?)
        } else if req.matches("/vo/blackout").is_some() {
            Cmd::Blackout(switch_arg(req, "blackout")?)
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        cx.commit(|s| {
            Ok(match self {
                Cmd::Fader(target, value) => {
                    let lights = target.lights(scene)?;
                    let coloured: Vec<usize> = match value {
                        Set::Color(_) => lights
                            .iter()
                            .copied()
                            .filter(|&l| scene.profile(l).has_colour())
                            .collect(),
                        Set::Intensity(_) => lights.clone(),
                        Set::Position(n) => lights
                            .iter()
                            .copied()
                            .filter(|&l| scene.lights[l].position_index(n).is_some())
                            .collect(),
                    };
                    if let (true, Set::Position(n)) = (coloured.is_empty(), value) {
                        return Err(Refusal::conflict(no_palette(scene, &target, &lights, n)));
                    }
                    if coloured.is_empty() {
                        return Err(Refusal::conflict(match &target {
                            Named::Light(_) => format!(
                                "light {} is a `{}` and has no colour",
                                scene.lights[lights[0]].channel,
                                scene.profile(lights[0]).name
                            ),
                            Named::Group(name) => {
                                format!("group `{name}` has no light with colour")
                            }
                        }));
                    }
                    let mut look = s.live.clone();
                    for &l in &coloured {
                        match value {
                            Set::Intensity(v) => look.levels[l].intensity = v,
                            Set::Color(c) => look.levels[l].color = c,
                            Set::Position(n) => look.levels[l].position = Some(n),
                        }
                    }
                    s.set_base(look, Change::Fader);
                    s.entry = None;
                    let reply = match (target, value) {
                        (Named::Light(_), Set::Position(n)) => msg(
                            "/vo/light/position",
                            vec![
                                int(scene.lights[coloured[0]].channel as usize),
                                int(n as usize),
                            ],
                        ),
                        (Named::Group(name), Set::Position(n)) => {
                            let g = group(scene, &name)?;
                            msg(
                                "/vo/group/position",
                                vec![
                                    text(&scene.groups[g].name),
                                    int(n as usize),
                                    int(coloured.len()),
                                ],
                            )
                        }
                        (Named::Light(_), _) => {
                            let l = coloured[0];
                            msg(
                                "/vo/light",
                                one_light(scene.lights[l].channel, &s.live.levels[l]).to_vec(),
                            )
                        }
                        (Named::Group(name), _) => {
                            let g = group(scene, &name)?;
                            msg(
                                "/vo/group",
                                vec![text(&scene.groups[g].name), int(coloured.len())],
                            )
                        }
                    };
                    // A flood of fader moves costs one write per moment, not one per move.
                    Outcome::reply(reply).show_look(0.0).saved_later().pushed()
                }
                Cmd::Live => Outcome::replies(look_messages("/vo/live", vec![], scene, &s.live)),
                Cmd::Fade(v) => {
                    s.fade_s = v;
                    Outcome::reply(msg("/vo/fade", vec![OscType::Float(v)]))
                        .saved()
                        .echoed()
                }
                Cmd::Master(v) => {
                    s.master = v;
                    Outcome::reply(msg("/vo/master", vec![OscType::Float(v)]))
                        .show_master()
                        .saved_later()
                        .echoed()
                }
                Cmd::Blackout(on) => {
                    s.blackout = on;
                    Outcome::reply(msg("/vo/blackout", vec![int(on.into())]))
                        .show_master()
                        .saved()
                        .echoed()
                }
            })
        })
    }
}

/// Why no light of `target` (`lights`) can take focus palette `n`.
fn no_palette(scene: &Scene, target: &Named, lights: &[usize], n: u32) -> String {
    match target {
        Named::Light(_) => {
            let light = &scene.lights[lights[0]];
            if light.is_moving() {
                format!(
                    "light {} has no palette {n} (it has {})",
                    light.channel,
                    light.palette_list()
                )
            } else {
                format!(
                    "light {} is not a moving light (it has no positions)",
                    light.channel
                )
            }
        }
        Named::Group(name) => format!("group `{name}` has no moving light with palette {n}"),
    }
}
