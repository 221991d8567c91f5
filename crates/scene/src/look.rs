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
}

impl Level {
    /// A light that is off and white: the state of every light missing from a look file.
    pub const OFF: Level = Level {
        intensity: 0.0,
        color: [1.0, 1.0, 1.0],
    };

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
    /// values out of range, naming them.
    pub fn to_look(&self, scene: &Scene) -> Result<Look, String> {
        let mut look = Look::off(scene.lights.len());
        for e in &self.lights {
            let i = scene.light_index(e.channel).ok_or_else(|| {
                format!(
                    "light {} is not in the scene ({})",
                    e.channel,
                    scene.channel_range()
                )
            })?;
            if !(0.0..=1.0).contains(&e.intensity) {
                return Err(format!(
                    "light {}: intensity {} is outside 0..1",
                    e.channel, e.intensity
                ));
            }
            let color = e.color.unwrap_or([1.0; 3]);
            if color.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return Err(format!(
                    "light {}: colour {:?} is outside 0..1",
                    e.channel, color
                ));
            }
            look.levels[i] = Level {
                intensity: e.intensity,
                color: if scene.profile(i).has_colour() {
                    color
                } else {
                    [1.0; 3]
                },
            };
        }
        Ok(look)
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
        })
        .collect()
}
