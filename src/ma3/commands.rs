//! The grandMA3 commands that put a look in the programmer and store it, in MA3's
//! attribute names (GDTF's) and units (percent):
//!
//! ```text
//! Fixture 12 Attribute "Dimmer" At 62.4
//! Fixture 12 Attribute "ColorAdd_R" At 100
//! Fixture 12 Attribute "ColorAdd_W" At 5.1
//! Fixture 7 At Preset 2.3                   a mover's position: its Position preset
//! Fixture 1 Thru 44
//! Store Preset 21.5 /Overwrite              or: Store Sequence 901 Cue 3 /Overwrite
//! Label Preset 21.5 "Dusk"                      Label Sequence 901 Cue 3 "Dusk"
//!                                               Set Sequence 901 Cue 3 Property "CueInFade" 3
//! Off Fixture 1 Thru 44                     takes out of the programmer what it set
//! ```
//!
//! The levels are the DMX output's own ([`Patch::light_slots`] at master 1). MA3 fixture
//! IDs are the lights' `ma3_id`, by default their channel numbers (an MVR's `FixtureID`).
//! A moving light's position is its palette's preset in pool 2 (MA3's Position presets):
//! MA3 answers nothing over OSC, so which presets the desk has cannot be asked, and the
//! scene's palette numbers are taken to be the desk's (docs/ma3.md).

use std::fmt;

use crate::eos::commands::{channel_list, trimmed};
use visobjd_dmx::patch::Patch;
use visobjd_scene::Scene;
use visobjd_scene::look::Look;
use visobjd_scene::profile::Slot;

/// MA3's preset pool of Position presets.
const POSITION_POOL: u32 = 2;

/// Where a look is stored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Target {
    /// Preset `pool.n`.
    Preset { pool: u32, n: u32 },
    /// Cue `cue` of sequence `sequence`.
    Cue { sequence: u32, cue: u32 },
}

impl Target {
    /// A preset as MA3 writes it (`21.5`): pool 1..=9999 and number 1..=99999.
    pub fn preset(text: &str) -> Result<Target, String> {
        let parsed = text
            .split_once('.')
            .and_then(|(p, n)| Some((p.trim().parse().ok()?, n.trim().parse().ok()?)));
        match parsed {
            Some((pool, n)) if (1..=9999).contains(&pool) && (1..=99_999).contains(&n) => {
                Ok(Target::Preset { pool, n })
            }
            _ => Err(format!(
                "a preset is POOL.NUMBER as MA3 writes it (21.5: pool 21, preset 5), got `{text}`"
            )),
        }
    }

    /// The one after this (the next preset of the pool, the next cue).
    pub fn next(self, steps: u32) -> Target {
        match self {
            Target::Preset { pool, n } => Target::Preset { pool, n: n + steps },
            Target::Cue { sequence, cue } => Target::Cue {
                sequence,
                cue: cue + steps,
            },
        }
    }
}

impl fmt::Display for Target {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Target::Preset { pool, n } => write!(f, "Preset {pool}.{n}"),
            Target::Cue { sequence, cue } => write!(f, "Sequence {sequence} Cue {cue}"),
        }
    }
}

/// MA3's name for the attribute a slot drives (GDTF's attribute names), None for slots
/// left out (`uv` is always 0, `fixed:N` is the fixture's, an extra emitter has no
/// mapping yet).
fn attribute(slot: Slot) -> Option<&'static str> {
    Some(match slot {
        Slot::Intensity | Slot::Intensity16 => "Dimmer",
        Slot::Red => "ColorAdd_R",
        Slot::Green => "ColorAdd_G",
        Slot::Blue => "ColorAdd_B",
        Slot::White => "ColorAdd_W",
        Slot::Amber => "ColorAdd_RY",
        Slot::Lime => "ColorAdd_GY",
        Slot::Cyan => "ColorSub_C",
        Slot::Magenta => "ColorSub_M",
        Slot::Yellow => "ColorSub_Y",
        Slot::Uv | Slot::Fixed(_) | Slot::Emitter(_) => return None,
        // A mover's position goes as its Position preset (`store_commands`), not as a
        // slot level.
        Slot::Pan | Slot::Pan16 | Slot::Tilt | Slot::Tilt16 => return None,
    })
}

/// The commands that store `look` as `target`, labelled `label` (a cue also gets
/// `time_s` as its fade), then take the lights out of the programmer again.
pub fn store_commands(
    scene: &Scene,
    look: &Look,
    target: Target,
    label: Option<&str>,
    time_s: f32,
) -> Vec<String> {
    let patch = Patch::new(scene);
    let slots = patch.light_slots(&patch.unmastered(look));
    let mut cmds = Vec::with_capacity(scene.lights.len() * 5 + 5);
    for ((light, slots), level) in scene.lights.iter().zip(&slots).zip(&look.levels) {
        for &(slot, v) in slots {
            if let Some(a) = attribute(slot) {
                let decimals = if slot == Slot::Intensity16 { 3 } else { 1 };
                cmds.push(format!(
                    "Fixture {} Attribute \"{a}\" At {}",
                    light.ma3_id,
                    percent(v, decimals)
                ));
            }
        }
        if let Some(p) = light.position_of(level) {
            cmds.push(format!(
                "Fixture {} At Preset {POSITION_POOL}.{}",
                light.ma3_id, p.palette
            ));
        }
    }
    let ids: Vec<u32> = scene.lights.iter().map(|l| l.ma3_id).collect();
    let fixtures = channel_list(&ids);
    cmds.push(format!("Fixture {fixtures}"));
    cmds.push(format!("Store {target} /Overwrite"));
    if let Some(label) = label.map(quoted).filter(|l| !l.is_empty()) {
        cmds.push(format!("Label {target} \"{label}\""));
    }
    if let Target::Cue { .. } = target {
        cmds.push(format!(
            "Set {target} Property \"CueInFade\" {}",
            trimmed(f64::from(time_s.max(0.0)), 2)
        ));
    }
    cmds.push(format!("Off Fixture {fixtures}"));
    cmds
}

/// A label inside MA3's double quotes: one line, no `"`, at most 100 characters.
fn quoted(label: &str) -> String {
    let one_line: String = label
        .chars()
        .map(|c| if c.is_control() || c == '"' { ' ' } else { c })
        .take(100)
        .collect();
    one_line.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// `v` (0..1) as percent with at most `decimals` decimals, no trailing zeros (MA3 reads
/// `At 5` as 5 %).
fn percent(v: f32, decimals: usize) -> String {
    trimmed(f64::from(v.clamp(0.0, 1.0)) * 100.0, decimals)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_read_as_ma3_writes_them() {
        assert_eq!(
            Target::preset("21.5").unwrap(),
            Target::Preset { pool: 21, n: 5 }
        );
        assert_eq!(
            Target::preset("21.5").unwrap().next(2).to_string(),
            "Preset 21.7"
        );
        assert!(Target::preset("21").is_err());
        assert!(Target::preset("0.5").is_err());
        assert_eq!(
            Target::Cue {
                sequence: 901,
                cue: 3
            }
            .to_string(),
            "Sequence 901 Cue 3"
        );
    }

    #[test]
    fn labels_fit_in_quotes() {
        assert_eq!(quoted("Act \"2\"\ndusk"), "Act 2 dusk");
        assert_eq!(percent(0.05, 1), "5");
        assert_eq!(percent(0.025, 2), "2.5");
    }
}
