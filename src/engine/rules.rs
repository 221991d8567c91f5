//! The prototype's constraints beyond locks and keys, as the session keeps them (by group
//! and light, so `/vo/constraints` lists what was set) and as `session.json` stores them
//! (by name and channel, like locks): ratios, saturation ranges, exclusions and pins.
//! [`Rules::apply`] turns them into the sampler's per-light [`Constraints`].

use serde::{Deserialize, Serialize};

use visobjd_method::constrain::{Ratio, Saturation, ratio_cycle};
use visobjd_method::objective::Region;
use visobjd_method::sampler::Constraints;
use visobjd_scene::Scene;

/// How generation treats an excluded group or light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Exclude {
    /// Generated as usual.
    #[default]
    None,
    /// Left alone: keeps its base values, like a lock.
    Ignore,
    /// Held at intensity 0 in every candidate.
    Off,
}

impl Exclude {
    /// `ignore`, `off` or `none` (any case).
    pub fn parse(s: &str) -> Result<Exclude, String> {
        match s.to_ascii_lowercase().as_str() {
            "none" => Ok(Exclude::None),
            "ignore" => Ok(Exclude::Ignore),
            "off" => Ok(Exclude::Off),
            _ => Err(format!("exclude must be ignore, off or none, got `{s}`")),
        }
    }

    /// The word OSC uses.
    pub fn name(self) -> &'static str {
        match self {
            Exclude::None => "none",
            Exclude::Ignore => "ignore",
            Exclude::Off => "off",
        }
    }
}

/// A region of the stage whose lights keep their base values in every candidate.
#[derive(Debug, Clone, PartialEq)]
pub struct Pin {
    /// 1-based, never reused within a session.
    pub id: u32,
    /// Where it was drawn.
    pub region: Region,
    /// The lights the region selected when it was added (the objectives' rule).
    pub lights: Vec<usize>,
}

/// Ratios, saturation ranges, exclusions and pins.
#[derive(Debug, Clone, PartialEq)]
pub struct Rules {
    /// Per group: the group it follows and the ratio.
    pub ratios: Vec<Option<(usize, f32)>>,
    /// Per group: its lights' saturation range.
    pub group_saturation: Vec<Saturation>,
    /// Per light: its own saturation range (wins over its group's).
    pub light_saturation: Vec<Saturation>,
    /// Per group: excluded.
    pub group_exclude: Vec<Exclude>,
    /// Per light: excluded (anything but `none` wins over its group's).
    pub light_exclude: Vec<Exclude>,
    /// Pinned regions, in the order they were added.
    pub pins: Vec<Pin>,
    /// The next pin id.
    pub next_pin: u32,
}

impl Rules {
    /// No constraint.
    pub fn new(scene: &Scene) -> Rules {
        let (groups, lights) = (scene.groups.len(), scene.lights.len());
        Rules {
            ratios: vec![None; groups],
            group_saturation: vec![Saturation::ANY; groups],
            light_saturation: vec![Saturation::ANY; lights],
            group_exclude: vec![Exclude::None; groups],
            light_exclude: vec![Exclude::None; lights],
            pins: Vec::new(),
            next_pin: 1,
        }
    }

    /// The ratios as the sampler takes them.
    pub fn ratio_list(&self) -> Vec<Ratio> {
        self.ratios
            .iter()
            .enumerate()
            .filter_map(|(follower, r)| {
                r.map(|(leader, ratio)| Ratio {
                    follower,
                    leader,
                    ratio,
                })
            })
            .collect()
    }

    /// Sets (r > 0) or removes (r = 0) group `follower`'s ratio to `leader`; refuses a group
    /// following itself and a loop of ratios, with a sentence naming the groups.
    pub fn set_ratio(
        &mut self,
        scene: &Scene,
        follower: usize,
        leader: usize,
        ratio: f32,
    ) -> Result<(), String> {
        if ratio <= 0.0 {
            self.ratios[follower] = None;
            return Ok(());
        }
        let name = |g: usize| scene.groups[g].name.as_str();
        let others: Vec<Ratio> = self
            .ratio_list()
            .into_iter()
            .filter(|r| r.follower != follower)
            .collect();
        if let Some(cycle) = ratio_cycle(&others, follower, leader) {
            return Err(if cycle.len() == 1 {
                format!("group `{}` cannot follow itself", name(follower))
            } else {
                format!(
                    "group `{}` cannot follow `{}`: `{}` already, which would make a loop of ratios (remove one with ratio 0)",
                    name(follower),
                    name(leader),
                    cycle
                        .iter()
                        .map(|&g| name(g))
                        .collect::<Vec<_>>()
                        .join("` follows `")
                )
            });
        }
        self.ratios[follower] = Some((leader, ratio));
        Ok(())
    }

    /// Adds these constraints to the sampler's: excluded `ignore` and pinned lights are
    /// locked, `off` ones held at 0; a light's own saturation range or exclusion wins over
    /// its group's.
    pub fn apply(&self, scene: &Scene, c: &mut Constraints) {
        for (g, group) in scene.groups.iter().enumerate() {
            for &l in &group.lights {
                let exclude = match self.light_exclude[l] {
                    Exclude::None => self.group_exclude[g],
                    own => own,
                };
                match exclude {
                    Exclude::None => {}
                    Exclude::Ignore => c.locked[l] = true,
                    Exclude::Off => c.off[l] = true,
                }
                if scene.profile(l).has_colour() {
                    c.saturation[l] = if self.light_saturation[l].is_any() {
                        self.group_saturation[g]
                    } else {
                        self.light_saturation[l]
                    };
                }
            }
        }
        for pin in &self.pins {
            for &l in &pin.lights {
                c.locked[l] = true;
            }
        }
        c.ratios = self.ratio_list();
    }

    /// What `session.json` keeps.
    pub fn record(&self, scene: &Scene) -> RulesFile {
        let group = |g: usize| scene.groups[g].name.clone();
        let channel = |l: usize| scene.lights[l].channel;
        RulesFile {
            ratios: self
                .ratio_list()
                .into_iter()
                .map(|r| RatioRecord {
                    group: group(r.follower),
                    of: group(r.leader),
                    ratio: r.ratio,
                })
                .collect(),
            saturation: (self.group_saturation.iter().enumerate())
                .filter(|(_, s)| !s.is_any())
                .map(|(g, s)| SaturationRecord {
                    group: Some(group(g)),
                    channel: None,
                    min: s.min,
                    max: s.max,
                })
                .chain(
                    (self.light_saturation.iter().enumerate())
                        .filter(|(_, s)| !s.is_any())
                        .map(|(l, s)| SaturationRecord {
                            group: None,
                            channel: Some(channel(l)),
                            min: s.min,
                            max: s.max,
                        }),
                )
                .collect(),
            exclude: (self.group_exclude.iter().enumerate())
                .filter(|(_, e)| **e != Exclude::None)
                .map(|(g, &mode)| ExcludeRecord {
                    group: Some(group(g)),
                    channel: None,
                    mode,
                })
                .chain(
                    (self.light_exclude.iter().enumerate())
                        .filter(|(_, e)| **e != Exclude::None)
                        .map(|(l, &mode)| ExcludeRecord {
                            group: None,
                            channel: Some(channel(l)),
                            mode,
                        }),
                )
                .collect(),
            pins: self
                .pins
                .iter()
                .map(|p| PinRecord {
                    id: p.id,
                    region: [p.region.x0, p.region.y0, p.region.x1, p.region.y1],
                    channels: p.lights.iter().map(|&l| channel(l)).collect(),
                })
                .collect(),
            next_pin: self.next_pin,
        }
    }

    /// Restores what `f` holds; a sentence for each thing this scene cannot take.
    pub fn restore(&mut self, scene: &Scene, f: &RulesFile) -> Vec<String> {
        let mut lost = Vec::new();
        let group = |name: &str, what: &str, lost: &mut Vec<String>| {
            let g = scene.group_index(name);
            if g.is_none() {
                lost.push(format!(
                    "the {what} of group `{name}`: the scene has no such group"
                ));
            }
            g
        };
        let light = |ch: u32, what: &str, lost: &mut Vec<String>| {
            let l = scene.light_index(ch);
            if l.is_none() {
                lost.push(format!(
                    "the {what} of light {ch}: the scene has no such light"
                ));
            }
            l
        };
        for r in &f.ratios {
            let (Some(b), Some(a)) = (
                group(&r.group, "ratio", &mut lost),
                group(&r.of, "ratio", &mut lost),
            ) else {
                continue;
            };
            if !(r.ratio.is_finite() && r.ratio > 0.0 && r.ratio <= MAX_RATIO) {
                lost.push(format!(
                    "the ratio of group `{}`: {} is not in 0..{MAX_RATIO}",
                    r.group, r.ratio
                ));
            } else if let Err(e) = self.set_ratio(scene, b, a, r.ratio) {
                lost.push(format!("the ratio of group `{}`: {e}", r.group));
            }
        }
        for s in &f.saturation {
            let range = Saturation {
                min: s.min,
                max: s.max,
            };
            let valid = check_saturation(range);
            let coloured = |lights: &[usize]| lights.iter().any(|&l| scene.profile(l).has_colour());
            let (slot, what, coloured) = match (&s.group, s.channel) {
                (Some(name), _) => match group(name, "saturation range", &mut lost) {
                    Some(g) => (
                        &mut self.group_saturation[g],
                        format!("group `{name}`"),
                        coloured(&scene.groups[g].lights),
                    ),
                    None => continue,
                },
                (None, Some(ch)) => match light(ch, "saturation range", &mut lost) {
                    Some(l) => (
                        &mut self.light_saturation[l],
                        format!("light {ch}"),
                        coloured(&[l]),
                    ),
                    None => continue,
                },
                (None, None) => {
                    lost.push("a saturation range with neither group nor channel".into());
                    continue;
                }
            };
            match valid {
                Ok(()) if coloured => *slot = range,
                Ok(()) => lost.push(format!(
                    "the saturation range of {what}: it has no light with colour"
                )),
                Err(e) => lost.push(format!("the saturation range of {what}: {e}")),
            }
        }
        for e in &f.exclude {
            match (&e.group, e.channel) {
                (Some(name), _) => {
                    if let Some(g) = group(name, "exclusion", &mut lost) {
                        self.group_exclude[g] = e.mode;
                    }
                }
                (None, Some(ch)) => {
                    if let Some(l) = light(ch, "exclusion", &mut lost) {
                        self.light_exclude[l] = e.mode;
                    }
                }
                (None, None) => lost.push("an exclusion with neither group nor channel".into()),
            }
        }
        if f.pins.len() > MAX_PINS {
            lost.push(format!(
                "{} pins past the {MAX_PINS} a session keeps were left out",
                f.pins.len() - MAX_PINS
            ));
        }
        for p in f.pins.iter().take(MAX_PINS) {
            let [x0, y0, x1, y1] = p.region;
            let region = match Region::new(x0, y0, x1, y1) {
                Ok(r) => r,
                Err(e) => {
                    lost.push(format!("pin {}: {e}", p.id));
                    continue;
                }
            };
            let mut lights: Vec<usize> = p
                .channels
                .iter()
                .filter_map(|&ch| light(ch, &format!("pin {}", p.id), &mut lost))
                .collect();
            // Each light once, in light order, as a pin added here holds them.
            lights.sort_unstable();
            lights.dedup();
            self.pins.push(Pin {
                id: p.id,
                region,
                lights,
            });
        }
        self.next_pin = f
            .next_pin
            .max(self.pins.iter().map(|p| p.id + 1).max().unwrap_or(1));
        lost
    }
}

/// Pins kept at most: each is a few bytes, but a flood must not grow the state file (nor
/// the state a backup takes, src/engine/state_size.rs).
pub const MAX_PINS: usize = 64;

/// The largest ratio `/vo/group/<B>/ratio` takes.
pub const MAX_RATIO: f32 = 100.0;

/// A saturation range's sentence if it is not one: 0 <= min <= max <= 1.
pub fn check_saturation(s: Saturation) -> Result<(), String> {
    let ok = |v: f32| v.is_finite() && (0.0..=1.0).contains(&v);
    if !ok(s.min) || !ok(s.max) {
        return Err(format!(
            "saturation {} {} must be two numbers in 0..1",
            s.min, s.max
        ));
    }
    if s.min > s.max {
        return Err(format!(
            "saturation min {} is above max {}: give min then max",
            s.min, s.max
        ));
    }
    Ok(())
}

/// The constraints of `session.json` beyond locks and keys; absent in older files.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RulesFile {
    #[serde(default)]
    ratios: Vec<RatioRecord>,
    #[serde(default)]
    saturation: Vec<SaturationRecord>,
    #[serde(default)]
    exclude: Vec<ExcludeRecord>,
    #[serde(default)]
    pins: Vec<PinRecord>,
    #[serde(default)]
    next_pin: u32,
}

/// `group` follows `of` at `ratio`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct RatioRecord {
    group: String,
    of: String,
    ratio: f32,
}

/// A saturation range of a group or a light.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct SaturationRecord {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    group: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    channel: Option<u32>,
    min: f32,
    max: f32,
}

/// An exclusion of a group or a light.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct ExcludeRecord {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    group: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    channel: Option<u32>,
    mode: Exclude,
}

/// A pin: its region and the lights it selected, by channel.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct PinRecord {
    id: u32,
    region: [f32; 4],
    channels: Vec<u32>,
}

#[cfg(test)]
mod tests;
