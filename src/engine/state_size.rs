//! The largest `/vo/backup/state` a main can send on a scene (docs/reliability.md,
//! "Backup"): what the limits of a session allow (session.rs: labels, saved looks,
//! objectives, palettes, the undo history, the gallery's size; rules.rs: pins), written as
//! the JSON of src/engine/handover.rs and then as one OSC message. A backup takes frames up
//! to this from its main and refuses larger ones (src/backup.rs): a state over it is not one
//! a main of the same scene can hold, and a frame limit known beforehand bounds what the
//! connection may make the backup allocate.
//!
//! Each figure is an upper bound of what serde_json writes (compact) for the structure it
//! names; the test below builds a session with every limit reached and checks that its
//! encoded state fits, so a field added to a state file without its share here fails it.

use visobjd_scene::Scene;

use super::rules::MAX_PINS;
use super::session::{
    CLUSTERS, COUNT, HISTORY, MAX_IMAGE_NAME, MAX_LABEL, MAX_LOOKS, MAX_OBJECTIVES, MAX_PALETTE,
};

/// The most bytes serde_json writes for an f32: ryu's shortest form takes at most 16
/// (sign, 9 digits, point, exponent); a number that is not finite is `null`.
const FLOAT: usize = 16;
const BOOL: usize = 5;
const U32: usize = 10;
const U64: usize = 20;
const USIZE: usize = 20;

/// The bytes of the largest `/vo/backup/state` message (its OSC encoding, without the
/// stream's framing) a main running `scene` can send within the session's limits.
pub fn max_state_message(scene: &Scene) -> usize {
    let rig = Rig::of(scene);
    // The address and type tags (",ssss"), then each part as an OSC string: its bytes, a
    // terminating NUL and padding to a multiple of 4.
    let parts = [rig.session(), rig.live(), rig.looks(), rig.working()];
    osc_string("/vo/backup/state".len())
        + osc_string(",ssss".len())
        + parts.map(osc_string).iter().sum::<usize>()
}

/// The bytes of an OSC string of `len` bytes.
fn osc_string(len: usize) -> usize {
    (len + 1).next_multiple_of(4)
}

/// `"name":` and the comma that separates it from the next field.
fn key(name: &str) -> usize {
    name.len() + 4
}

/// A string a user wrote, of at most `chars` characters: at most 6 bytes each (`\u001f`),
/// and the quotes.
fn text(chars: usize) -> usize {
    2 + 6 * chars
}

/// A list of `n` items of at most `item` bytes each (brackets and commas).
fn list(n: usize, item: usize) -> usize {
    2 + n * (item + 1)
}

/// A list of items of the given sizes.
fn list_of(items: impl IntoIterator<Item = usize>) -> usize {
    2 + items.into_iter().map(|i| i + 1).sum::<usize>()
}

/// What the bounds need of a scene: the JSON sizes of its channels and group names.
struct Rig {
    /// Per light: its channel's digits, whether it has colour, and whether it moves (a
    /// look file gives its focus palette).
    lights: Vec<(usize, bool, bool)>,
    /// Per group: its name as a JSON string.
    groups: Vec<usize>,
}

impl Rig {
    fn of(scene: &Scene) -> Rig {
        Rig {
            lights: scene
                .lights
                .iter()
                .enumerate()
                .map(|(i, l)| {
                    let digits = l.channel.to_string().len();
                    (digits, scene.profile(i).has_colour(), l.is_moving())
                })
                .collect(),
            groups: scene
                .groups
                .iter()
                .map(|g| {
                    serde_json::to_string(&g.name).map_or(text(g.name.chars().count()), |s| s.len())
                })
                .collect(),
        }
    }

    fn longest_group(&self) -> usize {
        self.groups.iter().copied().max().unwrap_or(0)
    }

    /// Every light's channel, as a list of numbers.
    fn channels(&self) -> usize {
        list_of(self.lights.iter().map(|&(digits, ..)| digits))
    }

    /// Every group's name, as a list of strings.
    fn group_names(&self) -> usize {
        list_of(self.groups.iter().copied())
    }

    /// A look file (`LookFile`) of every light, its label at most `label` characters.
    fn look(&self, label: usize) -> usize {
        let entry = |&(digits, colour, moving): &(usize, bool, bool)| {
            2 + key("channel")
                + digits
                + key("intensity")
                + FLOAT
                + if colour {
                    key("color") + list(3, FLOAT)
                } else {
                    0
                }
                + if moving { key("position") + U32 } else { 0 }
        };
        2 + key("label") + text(label) + key("lights") + list_of(self.lights.iter().map(entry))
    }

    /// `session.json` (`SessionFile`).
    fn session(&self) -> usize {
        let colour = 2 + key("color") + list(3, FLOAT) + key("weight") + FLOAT;
        let objective = 2
            + key("id")
            + U32
            + key("image")
            + text(MAX_IMAGE_NAME)
            + key("aspects")
            + "\"intensity\"".len()
            + key("region")
            + list(4, FLOAT)
            + key("mean_l")
            + FLOAT
            + key("key_l")
            + FLOAT
            + key("bright")
            + FLOAT
            + key("palette")
            + list(MAX_PALETTE, colour);
        2 + key("objectives")
            + list(MAX_OBJECTIVES, objective)
            + key("next_id")
            + U32
            + key("key_groups")
            + self.group_names()
            + key("locked_groups")
            + self.group_names()
            + key("locked_lights")
            + self.channels()
            + key("count")
            + U32
            + key("clusters")
            + U32
            + key("seed")
            + U64
            + key("fade_s")
            + FLOAT
            + key("rules")
            + self.rules()
    }

    /// The constraints of `session.json` (`RulesFile`): at most one ratio, saturation
    /// range and exclusion per group and per light, and [`MAX_PINS`] pins of every light.
    fn rules(&self) -> usize {
        let longest = self.longest_group();
        let ratio =
            |name: usize| 2 + key("group") + name + key("of") + longest + key("ratio") + FLOAT;
        let range = key("min") + FLOAT + key("max") + FLOAT;
        let mode = key("mode") + "\"ignore\"".len();
        let by_group = |each: usize| {
            self.groups
                .iter()
                .map(move |&name| 2 + key("group") + name + each)
        };
        let by_light = |each: usize| {
            self.lights
                .iter()
                .map(move |&(digits, ..)| 2 + key("channel") + digits + each)
        };
        let pin = 2
            + key("id")
            + U32
            + key("region")
            + list(4, FLOAT)
            + key("channels")
            + self.channels();
        2 + key("ratios")
            + list_of(self.groups.iter().map(|&name| ratio(name)))
            + key("saturation")
            + list_of(by_group(range).chain(by_light(range)))
            + key("exclude")
            + list_of(by_group(mode).chain(by_light(mode)))
            + key("pins")
            + list(MAX_PINS, pin)
            + key("next_pin")
            + U32
    }

    /// `live.json` (`LiveFile`).
    fn live(&self) -> usize {
        2 + key("live")
            + self.look(0)
            + key("base")
            + self.look(0)
            + key("master")
            + FLOAT
            + key("blackout")
            + BOOL
    }

    /// `looks.json` (`LooksFile`): [`MAX_LOOKS`] looks of every light, each keyed by its
    /// number (restored files may hold any u32) and labelled with [`MAX_LABEL`] characters.
    fn looks(&self) -> usize {
        let each = 2 + U32 + 1 + self.look(MAX_LABEL);
        2 + key("looks") + list(MAX_LOOKS, each)
    }

    /// The working state (`WorkingFile`): a gallery of the most candidates in the most
    /// entries, the undo and redo history, every light selected.
    fn working(&self) -> usize {
        let (candidates, entries) = (*COUNT.end() as usize, *CLUSTERS.end() as usize);
        let index = (candidates - 1).to_string().len();
        let gallery = 2
            + key("seed")
            + U64
            + key("candidates")
            + list(candidates, self.look(0))
            + key("entries")
            + 2
            + entries * 3
            + candidates * (index + 1)
            + key("threshold")
            + FLOAT
            + key("draws")
            + USIZE
            + key("exhausted")
            + BOOL;
        2 + key("gallery")
            + gallery
            + key("entry")
            + list(2, USIZE)
            + key("undo")
            + list(HISTORY, self.look(0))
            + key("redo")
            + list(HISTORY, self.look(0))
            + key("last_change")
            + "\"follow\"".len()
            + key("eos_selection")
            + self.channels()
            + key("following")
            + BOOL
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use rosc::{OscPacket, OscType};
    use visobjd_method::gallery::Generation;
    use visobjd_method::objective::{
        Analysis, Aspects, IntensityStats, Objective, PaletteColor, Region,
    };
    use visobjd_scene::look::{Level, Look, LookFile};

    use super::super::handover::state_json;
    use super::super::msg;
    use super::super::rules::{Exclude, Pin};
    use super::super::session::{Change, Entry, Gallery, Session};
    use super::*;
    use visobjd_method::constrain::Saturation;

    /// A scene with long group names, large channel numbers, and lights with and
    /// without colour.
    fn scene(lights: u32) -> Scene {
        let mut toml = String::from(
            "[[profile]]\nname = \"spot\"\nchannels = [\"red\", \"green\", \"blue\", \"pan\", \"tilt\"]\n",
        );
        for i in 0..lights {
            let group = format!("group \\\"{i}\\\" {}", "\u{e9}".repeat(30));
            // Every fourth light a mover, in palette 9999 (the longest number).
            let (profile, basis) = match i % 4 {
                3 => ("spot", String::new()),
                _ if i % 3 == 0 => ("dimmer", "basis = \"b.exr\"\n".to_string()),
                _ => ("rgb", "basis = \"b.exr\"\n".to_string()),
            };
            toml += &format!(
                "[[group]]\nname = \"{group}\"\n[[light]]\nchannel = {}\n{basis}profile = \"{profile}\"\nuniverse = {}\naddress = 1\ngroup = \"{group}\"\n",
                4_000_000_000 - i,
                i + 1
            );
            if profile == "spot" {
                toml += "[[light.position]]\npalette = 1\npan = 0\ntilt = 0\nbasis = \"a.exr\"\n\
                         [[light.position]]\npalette = 9999\npan = 1\ntilt = 1\nbasis = \"b.exr\"\n";
            }
        }
        Scene::parse(std::path::Path::new("."), &toml).unwrap()
    }

    /// f32s whose shortest forms are long (within 0..1, as levels are).
    const LONG: [f32; 3] = [f32::MIN_POSITIVE, 0.123_456_79, 1.000_000_1e-7];

    fn look(scene: &Scene, k: usize) -> Look {
        Look {
            levels: (0..scene.lights.len())
                .map(|i| Level {
                    intensity: LONG[(i + k) % 3],
                    color: [LONG[(i + k + 1) % 3], LONG[(i + k + 2) % 3], LONG[k % 3]],
                    position: scene.lights[i].is_moving().then_some(9999),
                })
                .collect(),
        }
    }

    /// A session with every limit reached: what a main can hold at most.
    fn full(scene: &Scene) -> Session {
        let lights = scene.lights.len();
        let groups = scene.groups.len();
        let mut s = Session::new(scene, *COUNT.end(), *CLUSTERS.end(), f32::MIN_POSITIVE);
        // Names of control characters: the longest JSON escapes.
        let worst = |n: usize| "\u{1}".repeat(n);
        let colour = PaletteColor {
            color: LONG,
            weight: f32::MIN_POSITIVE,
        };
        s.objectives = (0..MAX_OBJECTIVES)
            .map(|i| Entry {
                id: u32::MAX - i as u32,
                objective: Objective {
                    image: worst(MAX_IMAGE_NAME),
                    aspects: Aspects::Intensity,
                    region: Region::new(f32::MIN_POSITIVE, 1e-7, 0.9, 0.99).unwrap(),
                    analysis: Analysis {
                        stats: IntensityStats {
                            mean_l: f32::MIN_POSITIVE,
                            key_l: 1.000_000_1e-7,
                            bright: 0.123_456_79,
                        },
                        palette: vec![colour; MAX_PALETTE],
                    },
                },
            })
            .collect();
        s.next_id = u32::MAX;
        s.key_groups = vec![true; groups];
        s.locked_groups = vec![true; groups];
        s.locked_lights = vec![true; lights];
        s.eos_selection = (0..lights).collect();
        for g in 0..groups {
            s.rules.ratios[g] = Some(((g + 1) % groups, f32::MIN_POSITIVE));
        }
        let range = Saturation {
            min: f32::MIN_POSITIVE,
            max: 0.123_456_79,
        };
        s.rules.group_saturation = vec![range; groups];
        s.rules.light_saturation = vec![range; lights];
        s.rules.group_exclude = vec![Exclude::Ignore; groups];
        s.rules.light_exclude = vec![Exclude::Ignore; lights];
        s.rules.pins = (0..MAX_PINS)
            .map(|i| Pin {
                id: u32::MAX - i as u32,
                region: Region::new(f32::MIN_POSITIVE, 1e-7, 0.9, 0.99).unwrap(),
                lights: (0..lights).collect(),
            })
            .collect();
        s.rules.next_pin = u32::MAX;
        s.seed = u64::MAX;
        s.live = look(scene, 1);
        s.base = look(scene, 2);
        s.master = f32::MIN_POSITIVE;
        s.looks = (0..MAX_LOOKS as u32)
            .map(|n| {
                let label = worst(MAX_LABEL);
                (
                    u32::MAX - n,
                    LookFile::from_look(scene, &look(scene, n as usize), &label),
                )
            })
            .collect::<BTreeMap<_, _>>();
        let candidates = *COUNT.end() as usize;
        let entries = *CLUSTERS.end() as usize;
        let per = candidates / entries;
        s.gallery = Some(Gallery {
            generation: Generation {
                candidates: (0..candidates).map(|k| look(scene, k)).collect(),
                entries: (0..entries)
                    .map(|e| {
                        let end = if e + 1 == entries {
                            candidates
                        } else {
                            (e + 1) * per
                        };
                        (e * per..end).rev().collect()
                    })
                    .collect(),
                threshold: f32::MIN_POSITIVE,
                draws: usize::MAX,
                exhausted: false,
                lit_for_color: Vec::new(),
                thumbnails: std::sync::Arc::new([]),
                turned_down: 0,
            },
            seed: u64::MAX,
            serial: 1,
        });
        s.entry = Some((usize::MAX, usize::MAX));
        let history: Vec<Look> = (0..HISTORY).map(|k| look(scene, k)).collect();
        s.set_history(history.clone(), history, Some(Change::Follow));
        s.following = true;
        s
    }

    fn encoded(scene: &Scene, s: &Session) -> usize {
        let state = state_json(scene, s).unwrap();
        let m = msg("/vo/backup/state", state.map(OscType::String).into());
        rosc::encoder::encode(&OscPacket::Message(m)).unwrap().len()
    }

    #[test]
    fn the_fullest_state_a_main_can_hold_fits_the_bound() {
        for lights in [1, 7] {
            let scene = scene(lights);
            let s = full(&scene);
            let (bytes, bound) = (encoded(&scene, &s), max_state_message(&scene));
            eprintln!("{lights} lights: the fullest state {bytes} bytes, the bound {bound}");
            assert!(
                bytes <= bound,
                "{lights} lights: {bytes} bytes over the bound {bound}"
            );
            // A bound, not a guess: within a small factor of the real thing (floats are
            // counted at 16 bytes, the longest labels' characters at 6).
            assert!(
                bound < bytes + bytes / 2,
                "{lights} lights: the bound {bound} is far above the fullest state, {bytes} bytes"
            );
        }
    }

    #[test]
    fn an_empty_session_is_far_under_it() {
        let scene = scene(3);
        let s = Session::new(&scene, 100, 12, 2.0);
        assert!(encoded(&scene, &s) * 100 < max_state_message(&scene));
    }
}
