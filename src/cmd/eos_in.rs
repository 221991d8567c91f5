//! What an ETC Eos console sends with its OSC TX pointed at visobjd, and its selection:
//! `/eos/out/...` (accepted without a reply; `/eos/out/active/chan` read, the command
//! line echo and read-backs handed to a running export),
//! `/vo/console/selection`, `/vo/console/selection/lock`, `/vo/console/selection/key` (the
//! addresses say "console" for history's sake; the selection is always Eos's).
//!
//! Eos sends its implicit output (command line, active channel, wheels, cues, ping...) to
//! its TX target all the time; none of it asks for an answer, so none gets one, not even
//! an error. `/eos/out/active/chan` carries the selected channels as text ("12 [100]",
//! "1-5 [50]", "1 Thru 10", "3 + 7 Source Four LED [62]"): the channels of the scene in it
//! become the Eos selection, which the designer can lock or make the key lights of
//! the next generate (the paper's prototype's "Get Eos Selection").

use rosc::{OscMessage, OscType};

use super::{Context, int, switch_arg};
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::Request;
use visobjd_scene::Scene;

pub enum Cmd {
    /// An implicit Eos message; `Some` for an active-channel report (its channel ranges).
    EosOut(Option<Vec<(u32, u32)>>),
    /// A command line echo or a read-back: what an export over UDP waits for
    /// (src/eos/record.rs).
    EosAnswer(OscMessage),
    Selection,
    Lock(bool),
    Key(bool),
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        if req.segments.len() >= 2 && req.segments[0] == "eos" && req.segments[1] == "out" {
            if req
                .segments
                .get(2)
                .is_some_and(|s| s == "user" || s == "get")
            {
                return Ok(Some(Cmd::EosAnswer(req.message())));
            }
            let active = req.matches("/eos/out/active/chan").is_some();
            let text = req.args().iter().find_map(|a| match a {
                OscType::String(s) => Some(s.as_str()),
                _ => None,
            });
            return Ok(Some(Cmd::EosOut(match (active, text) {
                (true, Some(t)) => Some(channel_ranges(t)),
                // No text: nothing selected.
                (true, None) => Some(Vec::new()),
                _ => None,
            })));
        }
        Ok(Some(if req.matches("/vo/console/selection").is_some() {
            Cmd::Selection
        } else if req.matches("/vo/console/selection/lock").is_some() {
            Cmd::Lock(switch_arg(req, "lock")?)
        } else if req.matches("/vo/console/selection/key").is_some() {
            Cmd::Key(switch_arg(req, "key")?)
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let stage = cx.engine.stage();
        let scene = &stage.scene;
        match self {
            Cmd::EosOut(None) => Ok(Vec::new()),
            Cmd::EosAnswer(m) => {
                cx.engine.eos_heard(m);
                Ok(Vec::new())
            }
            Cmd::EosOut(Some(ranges)) => {
                let lights = lights_in(scene, &ranges);
                cx.commit(|s| {
                    s.eos_selection = lights;
                    Ok(Outcome::replies(Vec::new()))
                })
            }
            Cmd::Selection => cx.commit(|s| {
                let channels = s
                    .eos_selection
                    .iter()
                    .map(|&l| int(scene.lights[l].channel as usize));
                Ok(Outcome::reply(msg(
                    "/vo/console/selection",
                    channels.collect(),
                )))
            }),
            Cmd::Lock(on) => cx.commit(|s| {
                let lights = selected(s.eos_selection.clone())?;
                for &l in &lights {
                    s.locked_lights[l] = on;
                }
                Ok(Outcome::reply(msg(
                    "/vo/console/selection/lock",
                    vec![int(on.into()), int(lights.len())],
                ))
                .saved())
            }),
            Cmd::Key(on) => cx.commit(|s| {
                let lights = selected(s.eos_selection.clone())?;
                // Keys are designated per group (the sampler draws one value per group):
                // the groups of the selected lights.
                for (g, group) in scene.groups.iter().enumerate() {
                    if group.lights.iter().any(|l| lights.contains(l)) {
                        s.key_groups[g] = on;
                    }
                }
                Ok(Outcome::reply(msg(
                    "/vo/console/selection/key",
                    vec![int(on.into()), int(lights.len())],
                ))
                .saved())
            }),
        }
    }
}

/// The selection, or the sentence saying there is none.
fn selected(lights: Vec<usize>) -> Result<Vec<usize>, Refusal> {
    if lights.is_empty() {
        return Err(Refusal::conflict(
            "Eos has no light of the scene selected (visobjd reads the selection from Eos's \
             /eos/out/active/chan: point Eos's OSC TX at visobjd)",
        ));
    }
    Ok(lights)
}

/// The lights (indices, in scene order) whose channel is in one of `ranges`.
fn lights_in(scene: &Scene, ranges: &[(u32, u32)]) -> Vec<usize> {
    scene
        .lights
        .iter()
        .enumerate()
        .filter(|(_, l)| ranges.iter().any(|&(a, b)| (a..=b).contains(&l.channel)))
        .map(|(i, _)| i)
        .collect()
}

/// The channel ranges (inclusive) of an Eos active-channel text: channels and ranges
/// (`5`, `1-10`, `1 Thru 10`, a part `12.1` as channel 12) separated by spaces, `+` or
/// `,`, up to the first other word (the fixture type) or the `[level]`.
pub fn channel_ranges(text: &str) -> Vec<(u32, u32)> {
    let text = text.split('[').next().unwrap_or_default();
    let channel = |t: &str| t.split('.').next().and_then(|n| n.parse::<u32>().ok());
    let mut out: Vec<(u32, u32)> = Vec::new();
    let mut thru = false;
    for token in text
        .split(|c: char| c.is_whitespace() || c == '+' || c == ',')
        .filter(|t| !t.is_empty())
    {
        if token.eq_ignore_ascii_case("thru") {
            thru = !out.is_empty();
            continue;
        }
        let range = match token.split_once('-') {
            Some((a, b)) => channel(a).zip(channel(b)),
            None => channel(token).map(|c| (c, c)),
        };
        let Some((a, b)) = range else {
            break;
        };
        match out.last_mut() {
            Some(last) if thru => last.1 = b.max(last.0),
            _ => out.push((a.min(b), a.max(b))),
        }
        thru = false;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eos_active_channel_texts() {
        assert_eq!(channel_ranges("12 [100]"), [(12, 12)]);
        assert_eq!(channel_ranges("1-10 [100]"), [(1, 10)]);
        assert_eq!(channel_ranges("1 3 5-10 [50]"), [(1, 1), (3, 3), (5, 10)]);
        assert_eq!(channel_ranges("1 Thru 10"), [(1, 10)]);
        assert_eq!(
            channel_ranges("3 + 7 Source Four LED 2 [62]"),
            [(3, 3), (7, 7)]
        );
        assert_eq!(channel_ranges("12.1 [0]"), [(12, 12)]);
        assert_eq!(channel_ranges(""), []);
        assert_eq!(channel_ranges("[0]"), []);
        assert_eq!(channel_ranges("Thru 5"), [(5, 5)]);
    }
}
