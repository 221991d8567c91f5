//! The command lines that put a look on Eos and record it, as Eos's command line reads
//! them:
//!
//! ```text
//! Chan 12 At 62.375 Enter                   intensity, percent (16-bit: three decimals)
//! Chan 3 At 05 Enter                        under 10 %: a leading zero (Eos reads `At 5` as 50 %)
//! Chan 12 Red 100 Green 21.6 Blue 0 White 05.1 Enter   every colour parameter the patch drives
//! Chan 7 Focus_Palette 3 Enter              a mover's position: the focus palette, where
//!                                           the console has it (OSC's `_` for the space),
//! Chan 7 Pan -12.5 Tilt 41 Enter            else pan and tilt in degrees from centre
//! Chan 8 Pan 05 Tilt -07.25 Enter           (a one-digit whole part: a leading zero)
//! Chan 1 Thru 44 Record Preset 5 Enter      the lights of the look, recorded as a preset
//! Chan 1 Thru 44 Record Cue 2/7 Enter       ... or as a cue, then its time and label:
//! Cue 2/7 Time 3 Enter
//! Cue 2/7 Label Dusk Enter
//! ```
//!
//! The levels are the DMX output's own ([`Patch::light_slots`] at master 1), so recalling
//! the preset or cue puts the same slots on the wire as visobjd did. A position is the
//! scene's (`[[light.position]]` pan and tilt, degrees from the centre of the profile's
//! range, as Eos shows them); which palettes the console has is asked before recording
//! ([`super::palettes`]).

use std::collections::BTreeSet;
use std::fmt;

use visobjd_dmx::patch::Patch;
use visobjd_scene::look::{Level, Look};
use visobjd_scene::profile::Slot;
use visobjd_scene::{Light, Scene};

/// The longest label sent to Eos (a look's label is at most as long).
pub const MAX_LABEL: usize = 100;

/// A cue of an Eos cue list: `list/number`, as Eos's command line writes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cue {
    /// The cue list (1..=999).
    pub list: u32,
    /// The cue's number: positive, at most three decimals (`5`, `5.5`, `12.125`).
    pub number: f64,
}

impl Cue {
    /// A cue list Eos has (1..=999) and a cue number it takes (0.001..=9999.999, three
    /// decimals at most); Err says which is wrong.
    pub fn new(list: i64, number: f64) -> Result<Cue, String> {
        if !(1..=999).contains(&list) {
            return Err(format!("the cue list must be 1..=999, got {list}"));
        }
        let thousandths = number * 1000.0;
        if !(number.is_finite() && (0.001..=9999.999).contains(&number))
            || (thousandths - thousandths.round()).abs() > 1e-6
        {
            return Err(format!(
                "the cue number must be 0.001..=9999.999 with at most three decimals, got {number}"
            ));
        }
        Ok(Cue {
            list: list as u32,
            number: thousandths.round() / 1000.0,
        })
    }

    /// The cue `steps` whole numbers after this one (`/vo/eos/cues` records in a row).
    pub fn after(self, steps: usize) -> Result<Cue, String> {
        Cue::new(i64::from(self.list), self.number + steps as f64)
    }
}

impl fmt::Display for Cue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.list, trimmed(self.number, 3))
    }
}

/// The Eos parameter a slot drives, None for slots the export leaves out (intensity has
/// its own `At`; `uv` is always 0, `fixed:N` is the fixture's, not the look's).
fn parameter(slot: Slot) -> Option<&'static str> {
    Some(match slot {
        Slot::Red => "Red",
        Slot::Green => "Green",
        Slot::Blue => "Blue",
        Slot::White => "White",
        Slot::Amber => "Amber",
        Slot::Lime => "Lime",
        Slot::Cyan => "Cyan",
        Slot::Magenta => "Magenta",
        Slot::Yellow => "Yellow",
        // An extra emitter (`emitter:NAME`) carries the colour solve's level on DMX, but
        // which Eos parameter it is (Indigo, Cyan, Deep Red...) is not mapped yet: it is
        // left out of the export (docs/eos.md).
        Slot::Intensity | Slot::Intensity16 | Slot::Uv | Slot::Fixed(_) | Slot::Emitter(_) => {
            return None;
        }
        // A mover's position goes as a whole ([`position_line`]), not slot by slot.
        Slot::Pan | Slot::Pan16 | Slot::Tilt | Slot::Tilt16 => return None,
    })
}

/// The command line that puts a moving light in the position `level` gives it: its focus
/// palette if the console has it (`console`: the palette numbers it has), else its pan and
/// tilt in degrees ([`degrees`]). None for a fixed light.
fn position_line(light: &Light, level: &Level, console: &BTreeSet<u32>) -> Option<String> {
    let p = light.position_of(level)?;
    let ch = light.channel;
    Some(if console.contains(&p.palette) {
        format!("Chan {ch} Focus_Palette {} Enter", p.palette)
    } else {
        format!(
            "Chan {ch} Pan {} Tilt {} Enter",
            degrees(p.pan),
            degrees(p.tilt)
        )
    })
}

/// The command lines that put `look` on Eos: per light its intensity (`At 100` for a
/// light without a dimmer, whose emitters carry its intensity), every colour parameter
/// its profile drives, at the levels the DMX output sends at master 1, and a mover's
/// position ([`position_line`]).
fn look_lines(scene: &Scene, look: &Look, console: &BTreeSet<u32>) -> Vec<String> {
    let patch = Patch::new(scene);
    let slots = patch.light_slots(&patch.unmastered(look));
    let mut cmds = Vec::with_capacity(scene.lights.len() * 3 + 3);
    for ((light, slots), level) in scene.lights.iter().zip(&slots).zip(&look.levels) {
        let ch = light.channel;
        let dimmer = slots.iter().find_map(|&(s, v)| match s {
            Slot::Intensity => Some(percent(v, 1)),
            Slot::Intensity16 => Some(percent(v, 3)),
            _ => None,
        });
        let colour: Vec<String> = slots
            .iter()
            .filter_map(|&(s, v)| parameter(s).map(|p| format!("{p} {}", percent(v, 1))))
            .collect();
        match (dimmer, colour.is_empty()) {
            (Some(at), _) => cmds.push(format!("Chan {ch} At {at} Enter")),
            (None, false) => cmds.push(format!("Chan {ch} At 100 Enter")),
            (None, true) => {}
        }
        if !colour.is_empty() {
            cmds.push(format!("Chan {ch} {} Enter", colour.join(" ")));
        }
        cmds.extend(position_line(light, level, console));
    }
    cmds
}

/// The scene's channels as one Eos selection.
fn all_channels(scene: &Scene) -> String {
    let channels: Vec<u32> = scene.lights.iter().map(|l| l.channel).collect();
    channel_list(&channels)
}

/// The command lines that put `look` on Eos and record it as preset `n`; `console`: the
/// focus palettes the console has.
pub fn preset_commands(scene: &Scene, look: &Look, n: u32, console: &BTreeSet<u32>) -> Vec<String> {
    let mut cmds = look_lines(scene, look, console);
    cmds.push(format!(
        "Chan {} Record Preset {n} Enter",
        all_channels(scene)
    ));
    cmds
}

/// The command lines that put `look` on Eos, record it as `cue`, and give the cue its
/// time (`time_s`, the session's fade) and, if any, a label; `console`: the focus
/// palettes the console has.
pub fn cue_commands(
    scene: &Scene,
    look: &Look,
    cue: Cue,
    time_s: f32,
    label: Option<&str>,
    console: &BTreeSet<u32>,
) -> Vec<String> {
    let mut cmds = look_lines(scene, look, console);
    cmds.push(format!(
        "Chan {} Record Cue {cue} Enter",
        all_channels(scene)
    ));
    cmds.push(format!(
        "Cue {cue} Time {} Enter",
        trimmed(f64::from(time_s.max(0.0)), 2)
    ));
    if let Some(label) = label.map(label_text).filter(|l| !l.is_empty()) {
        cmds.push(format!("Cue {cue} Label {label} Enter"));
    }
    cmds
}

/// A label as it can be typed on Eos's command line: one line, no `#` (Eos's own
/// terminator), at most [`MAX_LABEL`] characters.
pub fn label_text(label: &str) -> String {
    let one_line: String = label
        .chars()
        .map(|c| if c.is_control() || c == '#' { ' ' } else { c })
        .take(MAX_LABEL)
        .collect();
    one_line.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// `v` with at most `decimals` decimals and no trailing zeros (`62.5`, `3`).
pub fn trimmed(v: f64, decimals: usize) -> String {
    let p = format!("{v:.decimals$}");
    if p.contains('.') {
        p.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        p
    }
}

/// A level as Eos takes it: percent with at most `decimals` decimals, no trailing zeros.
/// One decimal is within a tenth of an 8-bit step (0.39%), three within a third of a
/// 16-bit step (0.0015%), so Eos's own rounding lands on the same DMX value. Eos reads a
/// single digit as tens (`At 5` is 50 %), so a level under 10 % gets a leading zero
/// (`05`, `07.5`); 0 is 0 either way.
pub fn percent(v: f32, decimals: usize) -> String {
    two_digits(trimmed(f64::from(v.clamp(0.0, 1.0)) * 100.0, decimals))
}

/// Pan or tilt in degrees as Eos takes them: at most three decimals (a 16-bit step of
/// 540 degrees is 0.008), and a leading zero on a one-digit whole part (`05`, `-07.5`),
/// as levels have: should Eos read a single digit as tens there too, `05` is 5 either way.
pub fn degrees(v: f64) -> String {
    let d = two_digits(trimmed(v.abs(), 3));
    if v < 0.0 && d != "0" {
        format!("-{d}")
    } else {
        d
    }
}

/// A non-negative number as typed (`5`, `7.5`) with a leading zero on a one-digit whole
/// part (`05`, `07.5`); 0 stays 0.
fn two_digits(p: String) -> String {
    if p != "0" && p.split('.').next().is_some_and(|whole| whole.len() == 1) {
        format!("0{p}")
    } else {
        p
    }
}

/// Ascending channels as an Eos selection: runs become `Thru`, the rest are joined by `+`.
pub fn channel_list(channels: &[u32]) -> String {
    visobjd_rig::channel_runs(channels)
        .iter()
        .map(|&(start, end)| {
            if end > start {
                format!("{start} Thru {end}")
            } else {
                start.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join(" + ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_lists_use_thru_for_runs() {
        assert_eq!(channel_list(&[1, 2, 3, 4]), "1 Thru 4");
        assert_eq!(channel_list(&[1, 3, 4, 5, 9]), "1 + 3 Thru 5 + 9");
        assert_eq!(channel_list(&[7]), "7");
    }

    #[test]
    fn percents_have_their_decimals_and_two_whole_digits() {
        assert_eq!(percent(0.62, 1), "62");
        assert_eq!(percent(0.625, 1), "62.5");
        assert_eq!(percent(1.0, 1), "100");
        assert_eq!(percent(0.0, 3), "0");
        assert_eq!(percent(2.0, 1), "100");
        assert_eq!(percent(40_876.0 / 65_535.0, 3), "62.373");
        // Eos reads `At 5` as 50 %.
        assert_eq!(percent(0.05, 1), "05");
        assert_eq!(percent(0.075, 1), "07.5");
        assert_eq!(percent(0.1, 1), "10");
        assert_eq!(percent(1.0 / 255.0, 1), "00.4");
        assert_eq!(percent(0.0001, 1), "0");
    }

    #[test]
    fn degrees_have_three_decimals_and_two_whole_digits() {
        assert_eq!(degrees(-12.5), "-12.5");
        assert_eq!(degrees(5.0), "05");
        assert_eq!(degrees(-7.25), "-07.25");
        assert_eq!(degrees(0.0), "0");
        assert_eq!(degrees(-0.0001), "0");
        assert_eq!(degrees(269.99999), "270");
        assert_eq!(degrees(0.0083), "00.008");
    }

    #[test]
    fn cues_are_numbered_as_eos_writes_them() {
        assert_eq!(Cue::new(2, 7.0).unwrap().to_string(), "2/7");
        assert_eq!(Cue::new(1, 5.5).unwrap().to_string(), "1/5.5");
        assert_eq!(Cue::new(1, 0.125).unwrap().to_string(), "1/0.125");
        assert_eq!(
            Cue::new(1, 5.5).unwrap().after(2).unwrap().to_string(),
            "1/7.5"
        );
        assert!(Cue::new(0, 1.0).unwrap_err().contains("cue list"));
        assert!(Cue::new(1, 1.0005).unwrap_err().contains("three decimals"));
        assert!(Cue::new(1, 0.0).is_err());
        assert!(Cue::new(1, 9999.0).unwrap().after(1).is_err());
    }

    #[test]
    fn labels_are_one_line_without_terminators() {
        assert_eq!(label_text("Act 2\n dusk #3"), "Act 2 dusk 3");
        assert_eq!(label_text(&"x".repeat(300)).len(), MAX_LABEL);
    }
}
