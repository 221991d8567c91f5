//! The designer's constraints on generation: keys and locks (`/vo/group/<name>/key`,
//! `/vo/group/<name>/lock`, `/vo/light/<ch>/lock`), ratios (`/vo/group/<B>/ratio`),
//! saturation ranges and exclusions of groups and lights, pins (`/vo/pin/add`,
//! `/vo/pin/<id>/remove`, `/vo/pins`) and the listing of them all (`/vo/constraints`).

use rosc::{OscMessage, OscType};

use super::{Context, Named, group, int, light, num_arg, switch_arg, text};
use crate::engine::rules::{Exclude, MAX_PINS, MAX_RATIO, Pin, check_saturation};
use crate::engine::session::Session;
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::{self, Request};
use visobjd_method::constrain::Saturation;
use visobjd_method::objective::Region;
use visobjd_scene::Scene;

pub enum Cmd {
    GroupKey {
        name: String,
        on: bool,
    },
    GroupLock {
        name: String,
        on: bool,
    },
    LightLock {
        channel: String,
        on: bool,
    },
    Ratio {
        name: String,
        of: String,
        ratio: f32,
    },
    Saturation {
        target: Named,
        range: Saturation,
    },
    Exclude {
        target: Named,
        mode: Exclude,
    },
    PinAdd(Region),
    PinRemove(String),
    Pins,
    List,
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
        if let Some(c) = req.matches("/vo/group/*/ratio") {
            return Ok(Some(Cmd::Ratio {
                name: c[0].to_string(),
                of: args::string(req.required(0, "group to follow")?, "group to follow")?
                    .to_string(),
                ratio: num_arg(req, 1, "ratio", 0.0, f64::from(MAX_RATIO))?,
            }));
        }
        let target = |kind: &str, seg: &str| match kind {
            "group" => Named::Group(seg.to_string()),
            _ => Named::Light(seg.to_string()),
        };
        for kind in ["group", "light"] {
            if let Some(c) = req.matches(&format!("/vo/{kind}/*/saturation")) {
                let range = Saturation {
                    min: num_arg(req, 0, "saturation min", 0.0, 1.0)?,
                    max: num_arg(req, 1, "saturation max", 0.0, 1.0)?,
                };
                check_saturation(range)?;
                return Ok(Some(Cmd::Saturation {
                    target: target(kind, c[0]),
                    range,
                }));
            }
            if let Some(c) = req.matches(&format!("/vo/{kind}/*/exclude")) {
                let mode = Exclude::parse(args::string(
                    req.required(0, "exclude (ignore, off or none)")?,
                    "exclude",
                )?)?;
                return Ok(Some(Cmd::Exclude {
                    target: target(kind, c[0]),
                    mode,
                }));
            }
        }
        if let Some(c) = req.matches("/vo/pin/*/remove") {
            return Ok(Some(Cmd::PinRemove(c[0].to_string())));
        }
        Ok(Some(if req.matches("/vo/pin/add").is_some() {
            Cmd::PinAdd(Region::new(
                num_arg(req, 0, "x0", 0.0, 1.0)?,
                num_arg(req, 1, "y0", 0.0, 1.0)?,
                num_arg(req, 2, "x1", 0.0, 1.0)?,
                num_arg(req, 3, "y1", 0.0, 1.0)?,
            )?)
        } else if req.matches("/vo/pins").is_some() {
            Cmd::Pins
        } else if req.matches("/vo/constraints").is_some() {
            Cmd::List
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        cx.commit(|s| {
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
                Cmd::Ratio { name, of, ratio } => {
                    let (b, a) = (group(scene, &name)?, group(scene, &of)?);
                    s.rules
                        .set_ratio(scene, b, a, ratio)
                        .map_err(Refusal::conflict)?;
                    msg(
                        "/vo/group/ratio",
                        vec![
                            text(&scene.groups[b].name),
                            text(&scene.groups[a].name),
                            OscType::Float(ratio),
                        ],
                    )
                }
                Cmd::Saturation { target, range } => {
                    let (slot, who) = match &target {
                        Named::Group(name) => {
                            let g = group(scene, name)?;
                            if !scene.groups[g].lights.iter().any(|&l| has_colour(scene, l)) {
                                return Err(Refusal::conflict(format!(
                                    "group `{name}` has no light with colour, so no saturation"
                                )));
                            }
                            (
                                &mut s.rules.group_saturation[g],
                                text(&scene.groups[g].name),
                            )
                        }
                        Named::Light(ch) => {
                            let l = light(scene, ch)?;
                            if !has_colour(scene, l) {
                                return Err(Refusal::conflict(format!(
                                    "light {} is a `{}` and has no colour, so no saturation",
                                    scene.lights[l].channel,
                                    scene.profile(l).name
                                )));
                            }
                            (
                                &mut s.rules.light_saturation[l],
                                int(scene.lights[l].channel as usize),
                            )
                        }
                    };
                    *slot = range;
                    msg(
                        &format!("/vo/{}/saturation", target.kind()),
                        vec![who, OscType::Float(range.min), OscType::Float(range.max)],
                    )
                }
                Cmd::Exclude { target, mode } => {
                    let who = match &target {
                        Named::Group(name) => {
                            let g = group(scene, name)?;
                            s.rules.group_exclude[g] = mode;
                            text(&scene.groups[g].name)
                        }
                        Named::Light(ch) => {
                            let l = light(scene, ch)?;
                            s.rules.light_exclude[l] = mode;
                            int(scene.lights[l].channel as usize)
                        }
                    };
                    msg(
                        &format!("/vo/{}/exclude", target.kind()),
                        vec![who, text(mode.name())],
                    )
                }
                Cmd::PinAdd(region) => {
                    if s.rules.pins.len() >= MAX_PINS {
                        return Err(Refusal::conflict(format!(
                            "there are already {MAX_PINS} pins: remove one with /vo/pin/<id>/remove"
                        )));
                    }
                    let lights: Vec<usize> = (cx.engine.stage().footprints.select(region).iter())
                        .enumerate()
                        .filter(|(_, on)| **on)
                        .map(|(l, _)| l)
                        .collect();
                    if lights.is_empty() {
                        return Err(Refusal::conflict(format!(
                            "region {} {} {} {} selects no light: there is nothing to pin",
                            region.x0, region.y0, region.x1, region.y1
                        )));
                    }
                    let id = s.rules.next_pin;
                    s.rules.next_pin += 1;
                    s.rules.pins.push(Pin { id, region, lights });
                    let pin = &s.rules.pins[s.rules.pins.len() - 1];
                    let mut a = vec![int(id as usize)];
                    a.extend(channels(scene, &pin.lights));
                    msg("/vo/pin/added", a)
                }
                Cmd::PinRemove(id) => {
                    let at = id
                        .parse::<u32>()
                        .ok()
                        .and_then(|id| s.rules.pins.iter().position(|p| p.id == id))
                        .ok_or_else(|| {
                            Refusal::conflict(format!(
                                "pin {id} does not exist (pins: {})",
                                match s.rules.pins.is_empty() {
                                    true => "none".to_string(),
                                    false => s
                                        .rules
                                        .pins
                                        .iter()
                                        .map(|p| p.id.to_string())
                                        .collect::<Vec<_>>()
                                        .join(", "),
                                }
                            ))
                        })?;
                    let pin = s.rules.pins.remove(at);
                    msg("/vo/pin/removed", vec![int(pin.id as usize)])
                }
                Cmd::Pins => {
                    let mut out = pins(scene, s);
                    out.push(msg("/vo/pins/end", vec![int(out.len())]));
                    return Ok(Outcome::replies(out));
                }
                Cmd::List => {
                    let mut out = list(scene, s);
                    out.push(msg("/vo/constraints/end", vec![int(out.len())]));
                    return Ok(Outcome::replies(out));
                }
            };
            // Another tablet's constraint controls follow.
            Ok(Outcome::reply(reply).saved().echoed())
        })
    }
}

fn has_colour(scene: &Scene, l: usize) -> bool {
    scene.profile(l).has_colour()
}

/// The channels of lights, as OSC ints.
fn channels<'a>(scene: &'a Scene, lights: &'a [usize]) -> impl Iterator<Item = OscType> + 'a {
    lights
        .iter()
        .map(|&l| int(scene.lights[l].channel as usize))
}

/// One `/vo/pin id x0 y0 x1 y1 ch...` per pin.
fn pins(scene: &Scene, s: &Session) -> Vec<OscMessage> {
    s.rules
        .pins
        .iter()
        .map(|p| {
            let r = p.region;
            let mut a = vec![int(p.id as usize)];
            a.extend([r.x0, r.y0, r.x1, r.y1].map(OscType::Float));
            a.extend(channels(scene, &p.lights));
            msg("/vo/pin", a)
        })
        .collect()
}

/// Every constraint as `/vo/constraint address args...`, the message that sets it (groups
/// in scene order, then lights in channel order), then the pins as `/vo/pins` lists them.
fn list(scene: &Scene, s: &Session) -> Vec<OscMessage> {
    let mut out = Vec::new();
    let mut add = |addr: String, mut args: Vec<OscType>| {
        args.insert(0, text(&addr));
        out.push(msg("/vo/constraint", args));
    };
    let r = &s.rules;
    for (g, group) in scene.groups.iter().enumerate() {
        let at = |what: &str| format!("/vo/group/{}/{what}", group.address());
        if s.key_groups[g] {
            add(at("key"), vec![int(1)]);
        }
        if s.locked_groups[g] {
            add(at("lock"), vec![int(1)]);
        }
        if let Some((a, ratio)) = r.ratios[g] {
            add(
                at("ratio"),
                vec![text(&scene.groups[a].name), OscType::Float(ratio)],
            );
        }
        let sat = r.group_saturation[g];
        if !sat.is_any() {
            add(
                at("saturation"),
                vec![OscType::Float(sat.min), OscType::Float(sat.max)],
            );
        }
        if r.group_exclude[g] != Exclude::None {
            add(at("exclude"), vec![text(r.group_exclude[g].name())]);
        }
    }
    for (l, light) in scene.lights.iter().enumerate() {
        let at = |what: &str| format!("/vo/light/{}/{what}", light.channel);
        if s.locked_lights[l] {
            add(at("lock"), vec![int(1)]);
        }
        let sat = r.light_saturation[l];
        if !sat.is_any() {
            add(
                at("saturation"),
                vec![OscType::Float(sat.min), OscType::Float(sat.max)],
            );
        }
        if r.light_exclude[l] != Exclude::None {
            add(at("exclude"), vec![text(r.light_exclude[l].name())]);
        }
    }
    out.extend(pins(scene, s));
    out
}
