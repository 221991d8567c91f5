//! A look: an intensity and a colour for every light of a scene.
//!
//! Everything downstream (the compositor, DMX, saved look files) reads the same
//! [`Look`], so what the gallery shows is what the stage is told to do.

use serde::{Deserialize, Serialize};

use crate::Scene;
use crate::srgb::srgb_to_linear;

/// One light's setting. `color` is sRGB 0..1 with the brightness carried by
/// `intensity`; lights without colour keep white.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Level {
    /// Fraction of the fixture's full output, 0..1.
    pub intensity: f32,
    /// sRGB colour, 0..1 per channel.
    pub color: [f32; 3],
    /// A moving light's focus palette (its number); `None`, or a palette the light does
    /// not have, is its first position. Fixed lights ignore it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<u32>,
}

impl Level {
    /// A light that is off and white: the state of every light missing from a look file.
    pub const OFF: Level = Level {
        intensity: 0.0,
        color: [1.0, 1.0, 1.0],
        position: None,
    };

    /// Of a light's positions `held` (in scene order, `palette` naming each one's focus
    /// palette), the one this level puts it in: its palette if held, else the first;
    /// `None` when none is held (a fixed light). The one reading of a look's position, for
    /// the DMX output, the preview, the sampler and the preference model alike.
    pub fn position_in<'a, T>(&self, held: &'a [T], palette: impl Fn(&T) -> u32) -> Option<&'a T> {
        self.position
            .and_then(|n| held.iter().find(|h| palette(h) == n))
            .or(held.first())
    }

    /// A level of a fixed light (or a mover in its first position).
    pub const fn new(intensity: f32, color: [f32; 3]) -> Level {
        Level {
            intensity,
            color,
            position: None,
        }
    }

    /// The plain linear RGB multiplier of this level: the decoded colour times the
    /// intensity. What a light without additive emitters (a dimmer, a CMY fixture) applies
    /// to its basis image; a light with emitters goes through its
    /// [`crate::emitter::ColourModel`], which equals this for the sRGB primaries.
    pub fn multiplier(&self) -> [f32; 3] {
        let c = self.color.map(srgb_to_linear);
        [
            c[0] * self.intensity,
            c[1] * self.intensity,
            c[2] * self.intensity,
        ]
    }
}

/// One [`Level`] per light, indexed like `Scene::lights` (channel order).
#[derive(Debug, Clone, PartialEq)]
pub struct Look {
    /// The levels, one per scene light.
    pub levels: Vec<Level>,
}

impl Look {
    /// Every light off: the default base look.
    pub fn off(lights: usize) -> Look {
        Look {
            levels: vec![Level::OFF; lights],
        }
    }
}

/// One light as look files and replies list it: channel, intensity, and colour for lights
/// that have one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightEntry {
    /// Console channel.
    pub channel: u32,
    /// 0..1.
    pub intensity: f32,
    /// sRGB 0..1; omitted for lights without colour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<[f32; 3]>,
    /// A moving light's focus palette; omitted for fixed lights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<u32>,
}

/// A look file (docs/cli.md): what `render --look` reads and the daemon saves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LookFile {
    /// Human label.
    #[serde(default)]
    pub label: String,
    /// Lights; a light missing from the file is off.
    pub lights: Vec<LightEntry>,
}

impl LookFile {
    /// Every light of `look`, in channel order.
    pub fn from_look(scene: &Scene, look: &Look, label: &str) -> LookFile {
        LookFile {
            label: label.to_string(),
            lights: entries(scene, look),
        }
    }

    /// The look this file describes on `scene`; refuses channels the scene lacks and
    /// values out of range, naming the first.
    pub fn to_look(&self, scene: &Scene) -> Result<Look, String> {
        let (look, mut refused) = self.fit(scene);
        if refused.is_empty() {
            Ok(look)
        } else {
            Err(refused.swap_remove(0))
        }
    }

    /// The look this file describes on `scene`, leaving out (off) each light it cannot
    /// take, with a sentence for each: what a restore uses, so one bad entry does not
    /// take the rest of the stage with it.
    pub fn fit(&self, scene: &Scene) -> (Look, Vec<String>) {
        let mut look = Look::off(scene.lights.len());
        let mut refused = Vec::new();
        for e in &self.lights {
            let Some(i) = scene.light_index(e.channel) else {
                refused.push(format!(
                    "light {} is not in the scene ({})",
                    e.channel,
                    scene.channel_range()
                ));
                continue;
            };
            if let Err(why) = e.check() {
                refused.push(why);
                continue;
            }
            let light = &scene.lights[i];
            if let Some(n) = e.position
                && light.is_moving()
                && light.position_index(n).is_none()
            {
                refused.push(format!(
                    "light {} has no palette {n} (it has {})",
                    e.channel,
                    light.palette_list()
                ));
                continue;
            }
            look.levels[i] = Level {
                intensity: e.intensity,
                color: match (scene.profile(i).has_colour(), e.color) {
                    (true, Some(c)) => c,
                    _ => [1.0; 3],
                },
                position: e.position.filter(|_| light.is_moving()),
            };
        }
        (look, refused)
    }

    /// Leaves out the entries whose numbers are not levels ([`LightEntry::check`]), with
    /// a sentence for each; the channels are not checked (a saved look outlives a patch).
    pub fn drop_invalid(&mut self) -> Vec<String> {
        let mut refused = Vec::new();
        self.lights.retain(|e| match e.check() {
            Ok(()) => true,
            Err(why) => {
                refused.push(why);
                false
            }
        });
        refused
    }
}

impl LightEntry {
    /// Why this entry's numbers are not a level (intensity and colour finite, in 0..1),
    /// naming the light and the value.
    pub fn check(&self) -> Result<(), String> {
        let problem = |v: f32| match v {
            v if !v.is_finite() => Some("is not a finite number"),
            v if !(0.0..=1.0).contains(&v) => Some("is outside 0..1"),
            _ => None,
        };
        if let Some(p) = problem(self.intensity) {
            return Err(format!(
                "light {}: intensity {} {p}",
                self.channel, self.intensity
            ));
        }
        if let Some(c) = self.color
            && let Some(p) = c.iter().find_map(|&v| problem(v))
        {
            return Err(format!("light {}: colour {c:?} {p}", self.channel));
        }
        Ok(())
    }
}

/// Every light of `look` as an entry, colour omitted for lights that have none.
pub fn entries(scene: &Scene, look: &Look) -> Vec<LightEntry> {
    scene
        .lights
        .iter()
        .zip(&look.levels)
        .enumerate()
        .map(|(i, (light, lv))| LightEntry {
            channel: light.channel,
            intensity: lv.intensity,
            color: scene.profile(i).has_colour().then_some(lv.color),
            position: light.position_of(lv).map(|p| p.palette),
        })
        .collect()
}
