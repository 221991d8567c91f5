//! Look to slot levels: where each light's slots sit, and what a look asks of them.
//!
//! Levels stay `f32` 0..1 until the last step so that crossfades and master act on the
//! exact value, and a 16-bit intensity fades as one 16-bit number rather than as a coarse
//! byte that jumps and a fine byte that saws.

use visobjd_scene::Scene;
use visobjd_scene::emitter::ColourModel;
use visobjd_scene::look::{Level, Look};
use visobjd_scene::profile::{Profile, Slot};
use visobjd_scene::srgb::linear_to_srgb;

/// Slots in a DMX universe.
pub const SLOTS: usize = 512;

/// How the grand master acts on one slot's level. Every rule is affine in the level, so
/// mastering commutes with a crossfade: a fade can run on unmastered levels while the
/// master moves at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rule {
    /// Not an intensity: colour at full behind a dimmer, `uv`, `fixed:N`, unused slots.
    Keep,
    /// Carries intensity: a dimmer, or an emitter with intensity folded in.
    Scale,
    /// A subtractive flag with intensity folded in (no dimmer): `1 - (1 - v) * master`.
    Complement,
}

/// One light's place in the patch.
#[derive(Debug, Clone)]
struct Placed {
    /// Index into [`Patch::universes`].
    universe: usize,
    /// 0-based slot of the light's first channel.
    offset: usize,
    slots: Vec<Slot>,
    has_intensity: bool,
    /// How the light's additive emitters mix a colour.
    colour: ColourModel,
    /// A moving light's positions as (focus palette, pan level, tilt level), DMX levels
    /// through its profile's ranges; empty for a fixed light (its pan and tilt, if it has
    /// them, stay at centre).
    positions: Vec<(u32, [f32; 2])>,
    /// For a light with pan or tilt slots: the global indices ([`SlotLevels`]) of its
    /// slots that carry intensity, with their rule, and of its pan and tilt slots, so a
    /// fade can tell a dark mover and move it at once.
    aim: Option<Aim>,
}

/// Where a light with pan or tilt slots keeps its intensity and its aim in a frame.
#[derive(Debug, Clone)]
struct Aim {
    intensity: Vec<(usize, Rule)>,
    position: Vec<usize>,
}

impl Aim {
    /// Whether the light gives no light in `levels` (every intensity slot at its dark
    /// end; a light whose slots carry no intensity is never dark).
    fn dark(&self, levels: &[f32]) -> bool {
        !self.intensity.is_empty()
            && self.intensity.iter().all(|&(i, rule)| match rule {
                Rule::Complement => levels[i] >= 1.0,
                _ => levels[i] <= 0.0,
            })
    }
}

impl Placed {
    /// Writes this light's slots into `frame`: `value(slot, k)` per slot in order, `k` the
    /// slot's place among the light's additive emitters (`None` for other slots); `None`
    /// leaves the slot as it is. Slots past the universe's end are dropped.
    fn write(
        &self,
        frame: &mut SlotLevels,
        mut value: impl FnMut(Slot, Option<usize>) -> Option<f32>,
    ) {
        let base = self.universe * SLOTS;
        let (mut at, mut emitters) = (self.offset, 0);
        for &slot in &self.slots {
            let k = slot.is_emitter().then(|| {
                emitters += 1;
                emitters - 1
            });
            if let Some(v) = value(slot, k)
                && at < SLOTS
            {
                frame.levels[base + at] = v;
            }
            at += slot.width();
        }
    }
}

/// The scene's DMX patch: which universes exist and where every light's slots are.
#[derive(Debug, Clone)]
pub struct Patch {
    universes: Vec<u16>,
    lights: Vec<Placed>,
    /// Per universe, per slot: how master applies.
    rules: Vec<Vec<Rule>>,
    /// Per universe: 0-based coarse slots of 16-bit pairs (the fine slot follows).
    wide: Vec<Vec<usize>>,
}

/// Levels (0..1) of every slot of every patched universe, in [`Patch::universes`] order,
/// before quantisation. The coarse slot of a 16-bit pair holds the pair's whole level;
/// its fine slot is unused until [`Patch::quantise`].
#[derive(Debug, Clone, PartialEq)]
pub struct SlotLevels {
    levels: Vec<f32>,
}

impl SlotLevels {
    /// The levels of universe number `index` (an index into [`Patch::universes`]).
    pub fn universe(&self, index: usize) -> &[f32] {
        &self.levels[index * SLOTS..(index + 1) * SLOTS]
    }

    /// Linear crossfade of every slot: `from` at `t = 0`, `to` at `t = 1`.
    pub fn crossfade(from: &SlotLevels, to: &SlotLevels, t: f32) -> SlotLevels {
        let t = unit(t);
        SlotLevels {
            levels: from
                .levels
                .iter()
                .zip(&to.levels)
                .map(|(a, b)| a + (b - a) * t)
                .collect(),
        }
    }
}

/// `v` clamped to 0..1, with NaN as 0, so no outside value can reach the wire as garbage.
fn unit(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

impl Patch {
    /// The patch of a validated scene (which guarantees footprints fit and never overlap).
    pub fn new(scene: &Scene) -> Patch {
        let mut universes: Vec<u16> = scene.lights.iter().map(|l| l.universe).collect();
        universes.sort_unstable();
        universes.dedup();
        let mut rules = vec![vec![Rule::Keep; SLOTS]; universes.len()];
        let mut wide = vec![Vec::new(); universes.len()];
        let mut lights = Vec::with_capacity(scene.lights.len());
        for (i, light) in scene.lights.iter().enumerate() {
            let profile = scene.profile(i);
            let universe = universes.binary_search(&light.universe).unwrap_or_default();
            let offset = usize::from(light.address.max(1)) - 1;
            let has_intensity = profile.has_intensity();
            let mut at = offset;
            let mut aim = Aim {
                intensity: Vec::new(),
                position: Vec::new(),
            };
            for &slot in &profile.slots {
                let rule = match slot {
                    Slot::Intensity | Slot::Intensity16 => Rule::Scale,
                    emitter if emitter.is_emitter() && !has_intensity => Rule::Scale,
                    Slot::Cyan | Slot::Magenta | Slot::Yellow if !has_intensity => Rule::Complement,
                    _ => Rule::Keep,
                };
                if at + slot.width() <= SLOTS {
                    rules[universe][at] = rule;
                    if slot.is_wide() {
                        wide[universe].push(at);
                    }
                    if slot.is_position() {
                        aim.position.push(universe * SLOTS + at);
                    } else if rule != Rule::Keep {
                        aim.intensity.push((universe * SLOTS + at, rule));
                    }
                }
                at += slot.width();
            }
            let positions = light
                .positions
                .iter()
                .map(|p| {
                    let pan = Profile::position_level(p.pan, profile.pan_range);
                    let tilt = Profile::position_level(p.tilt, profile.tilt_range);
                    (p.palette, [pan, tilt])
                })
                .collect();
            lights.push(Placed {
                universe,
                offset,
                slots: profile.slots.clone(),
                has_intensity,
                colour: scene.colour_model(i),
                positions,
                aim: (!aim.position.is_empty()).then_some(aim),
            });
        }
        Patch {
            universes,
            lights,
            rules,
            wide,
        }
    }

    /// The universes the scene patches, ascending; frames and byte buffers follow this order.
    pub fn universes(&self) -> &[u16] {
        &self.universes
    }

    /// Every slot 0, fixed slots included: what blackout sends.
    pub fn blackout(&self) -> SlotLevels {
        SlotLevels {
            levels: vec![0.0; self.universes.len() * SLOTS],
        }
    }

    /// The slot levels `look` asks for with the grand master at `master`.
    pub fn levels(&self, look: &Look, master: f32) -> SlotLevels {
        self.mastered(&self.unmastered(look), master)
    }

    /// The slot levels of `look` at master 1. Fades run on these so the master can move
    /// at once, independently of a fade in progress ([`Patch::mastered`] applies it).
    ///
    /// Per light: `intensity` slots get the intensity; the additive emitters (red, green,
    /// blue, white, amber, lime, `emitter:NAME`) get the light's [`ColourModel::solve`] of
    /// the colour, with a dimmer as they are, without one at the intensity
    /// (`Solution::at`); `cyan`/`magenta`/`yellow` are 1 - r/g/b of the linear colour (the
    /// intensity folded in without a dimmer); `uv` is 0 and `fixed:N` is N. A light missing
    /// from the look is off.
    pub fn unmastered(&self, look: &Look) -> SlotLevels {
        let mut frame = self.blackout();
        for (i, light) in self.lights.iter().enumerate() {
            let level = look.levels.get(i).copied().unwrap_or(Level::OFF);
            let intensity = unit(level.intensity);
            let color = level.color.map(unit);
            let fold = if light.has_intensity { 1.0 } else { intensity };
            let [pan, tilt] = level
                .position_in(&light.positions, |&(n, _)| n)
                .map_or([0.5; 2], |&(_, aim)| aim);
            let solution = light.colour.solve(color).at(f64::from(fold));
            let emitters = solution.levels();
            let flags = Level {
                intensity: fold,
                color,
                position: None,
            }
            .multiplier()
            .map(unit);
            light.write(&mut frame, |slot, emitter| {
                Some(unit(match emitter {
                    Some(k) => emitters.get(k).map_or(0.0, |&v| v as f32),
                    None => match slot {
                        Slot::Intensity | Slot::Intensity16 => intensity,
                        Slot::Cyan => 1.0 - flags[0],
                        Slot::Magenta => 1.0 - flags[1],
                        Slot::Yellow => 1.0 - flags[2],
                        Slot::Fixed(n) => f32::from(n) / 255.0,
                        Slot::Pan | Slot::Pan16 => pan,
                        Slot::Tilt | Slot::Tilt16 => tilt,
                        _ => 0.0,
                    },
                }))
            });
        }
        frame
    }

    /// The frame `t` (0..1) of the way through a fade from `from` to `to` (unmastered
    /// levels): every slot linearly ([`SlotLevels::crossfade`]), but a moving light that
    /// is dark in both takes its new pan and tilt at once, so nobody sees it sweep
    /// ("move in dark"); one that is lit in either moves with the fade.
    pub fn crossfade(&self, from: &SlotLevels, to: &SlotLevels, t: f32) -> SlotLevels {
        let mut frame = SlotLevels::crossfade(from, to, t);
        for aim in self.lights.iter().filter_map(|l| l.aim.as_ref()) {
            if aim.dark(&from.levels) && aim.dark(&to.levels) {
                for &i in &aim.position {
                    frame.levels[i] = to.levels[i];
                }
            }
        }
        frame
    }

    /// The slot levels of `look` at master 1 with light `light`'s additive emitter
    /// `emitter` (slot order) alone at full and its other emitters at 0, its dimmer (if it
    /// has one) at full: how capture shoots one emitter's basis image.
    pub fn emitter_alone(&self, look: &Look, light: usize, emitter: usize) -> SlotLevels {
        let mut frame = self.unmastered(look);
        if let Some(placed) = self.lights.get(light) {
            placed.write(&mut frame, |slot, k| match k {
                Some(k) => Some(if k == emitter { 1.0 } else { 0.0 }),
                None => matches!(slot, Slot::Intensity | Slot::Intensity16).then_some(1.0),
            });
        }
        frame
    }

    /// `frame` (unmastered levels) with the grand master applied to the slots that carry
    /// intensity.
    pub fn mastered(&self, frame: &SlotLevels, master: f32) -> SlotLevels {
        let m = unit(master);
        let levels = frame
            .levels
            .iter()
            .zip(self.rules.iter().flatten())
            .map(|(&v, rule)| match rule {
                Rule::Keep => v,
                Rule::Scale => v * m,
                Rule::Complement => 1.0 - (1.0 - v) * m,
            })
            .collect();
        SlotLevels { levels }
    }

    /// DMX bytes, one 512-slot buffer per universe: 8-bit slots round `level * 255`; a
    /// 16-bit pair takes `v = round(level * 65535)` as coarse `v >> 8`, fine `v & 255`.
    pub fn quantise(&self, frame: &SlotLevels) -> Vec<[u8; SLOTS]> {
        (0..self.universes.len())
            .map(|u| {
                let levels = frame.universe(u);
                let mut out = [0u8; SLOTS];
                for (byte, &v) in out.iter_mut().zip(levels) {
                    *byte = coarse(v);
                }
                for &o in &self.wide[u] {
                    let v = fine(levels[o]);
                    out[o] = (v >> 8) as u8;
                    out[o + 1] = (v & 0xff) as u8;
                }
                out
            })
            .collect()
    }
}

/// An 8-bit slot's byte for `level`.
fn coarse(level: f32) -> u8 {
    (unit(level) * 255.0).round() as u8
}

/// A 16-bit pair's value for `level`.
fn fine(level: f32) -> u16 {
    (unit(level) * 65535.0).round() as u16
}

impl Patch {
    /// Per light (scene order), each of its slots with the level the wire carries for it
    /// in `frame` (unmastered levels), at DMX precision: `byte / 255`, or `value / 65535`
    /// for a 16-bit pair. What a console export writes, so its preset and the wire can
    /// never disagree.
    pub fn light_slots(&self, frame: &SlotLevels) -> Vec<Vec<(Slot, f32)>> {
        self.lights
            .iter()
            .map(|light| {
                let levels = frame.universe(light.universe);
                let mut at = light.offset;
                light
                    .slots
                    .iter()
                    .map(|&slot| {
                        let v = levels.get(at).copied().unwrap_or(0.0);
                        at += slot.width();
                        let v = if slot.is_wide() {
                            f32::from(fine(v)) / 65535.0
                        } else {
                            f32::from(coarse(v)) / 255.0
                        };
                        (slot, v)
                    })
                    .collect()
            })
            .collect()
    }
}

impl Patch {
    /// What the DMX in `bytes` (one 512-slot buffer per universe, in
    /// [`Patch::universes`] order) asks of each light: the linear RGB multiplier of its
    /// basis image (the light the emitters make relative to the light's white, times the
    /// dimmer), the inverse of [`Patch::unmastered`] then [`Patch::quantise`] at master 1:
    /// what a simulated camera renders the rig with.
    pub fn multipliers(&self, bytes: &[[u8; SLOTS]]) -> Vec<[f32; 3]> {
        self.multipliers_as(bytes, &[])
    }

    /// [`Patch::multipliers`] of a rig whose emitters are not what the profiles say: light
    /// `i`'s emitter levels make the light of `real[i]` (its fixture as it is; `None` or
    /// missing: as its profile says), shown relative to the profile's white, which is what
    /// its white basis image was captured at. A simulated camera's truth.
    pub fn multipliers_as(
        &self,
        bytes: &[[u8; SLOTS]],
        real: &[Option<ColourModel>],
    ) -> Vec<[f32; 3]> {
        self.lights
            .iter()
            .enumerate()
            .map(|(i, light)| {
                let (dimmer, colour) = read(light, bytes);
                let model = real
                    .get(i)
                    .and_then(Option::as_ref)
                    .unwrap_or(&light.colour);
                let full = match colour {
                    Read::Emitters(levels) => light
                        .colour
                        .relative(model.reached(&levels))
                        .map(|v| v as f32),
                    Read::Linear(c) => c,
                };
                full.map(|v| v * dimmer.unwrap_or(1.0))
            })
            .collect()
    }

    /// The look the DMX in `bytes` (one 512-slot buffer per universe, in
    /// [`Patch::universes`] order) shows: the inverse of [`Patch::unmastered`] then
    /// [`Patch::quantise`], so a console's output can become a visobjd look. The emitters
    /// read back through [`ColourModel::read`] as a colour and its brightness. A light with a
    /// dimmer: intensity is the dimmer, colour the emitters' colour at their brightness.
    /// Without one: intensity is the brightness and colour the emitters' colour (white
    /// when dark). CMY flags read as `1 - level`; a light without colour slots is white.
    /// Colours are sRGB, as looks keep them. A moving light is in the position nearest its
    /// pan and tilt (as the paper's prototype showed a mover).
    pub fn look(&self, bytes: &[[u8; SLOTS]]) -> Look {
        let levels = self
            .lights
            .iter()
            .map(|light| {
                let (dimmer, colour) = read(light, bytes);
                let (brightness, linear) = match colour {
                    Read::Emitters(levels) => {
                        let (t, c) = light.colour.read(&levels);
                        (t as f32, c.map(|v| v as f32))
                    }
                    Read::Linear(c) => {
                        let peak = c.iter().copied().fold(0.0f32, f32::max);
                        if peak > 0.0 {
                            (peak, c.map(|v| v / peak))
                        } else {
                            (0.0, [1.0; 3])
                        }
                    }
                };
                let (intensity, linear) = match dimmer {
                    Some(d) => (d, linear.map(|v| v * brightness)),
                    None => (brightness, linear),
                };
                // A mover is read as the palette nearest its pan and tilt.
                let position = aim(light, bytes).and_then(|[pan, tilt]| {
                    light
                        .positions
                        .iter()
                        .map(|&(n, p)| (n, (p[0] - pan).powi(2) + (p[1] - tilt).powi(2)))
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .map(|(n, _)| n)
                });
                Level {
                    intensity: unit(intensity),
                    color: linear.map(|v| unit(linear_to_srgb(unit(v)))),
                    position,
                }
            })
            .collect();
        Look { levels }
    }
}

impl Patch {
    /// Per light (scene order), the pan and tilt levels (0..1, at DMX precision) the DMX
    /// in `bytes` (one buffer per universe, in [`Patch::universes`] order) sets, or `None`
    /// for a light without both: where a console aims its movers, for learning their
    /// positions (the inverse of the aim [`Patch::levels`] writes).
    pub fn aims(&self, bytes: &[[u8; SLOTS]]) -> Vec<Option<[f32; 2]>> {
        self.lights.iter().map(|light| aim(light, bytes)).collect()
    }

    /// The index in [`Patch::universes`] of light `light`'s universe.
    pub fn universe_of(&self, light: usize) -> usize {
        self.lights[light].universe
    }
}

/// A light's colour slots read back.
enum Read {
    /// Its additive emitters' levels, in slot order.
    Emitters(Vec<f64>),
    /// A linear colour: the CMY flags as `1 - level`, or white without colour slots.
    Linear([f32; 3]),
}

/// Each of a light's slots with its level (0..1) in `bytes`: `byte / 255`, or
/// `value / 65535` for a 16-bit pair. A missing universe reads as zeros.
fn read_slots<'a>(
    light: &'a Placed,
    bytes: &'a [[u8; SLOTS]],
) -> impl Iterator<Item = (Slot, f32)> + 'a {
    let dmx = bytes.get(light.universe);
    let byte = move |i: usize| dmx.and_then(|d| d.get(i)).copied().map_or(0.0, f32::from);
    let mut at = light.offset;
    light.slots.iter().map(move |&slot| {
        let v = if slot.is_wide() {
            (byte(at) * 256.0 + byte(at + 1)) / 65535.0
        } else {
            byte(at) / 255.0
        };
        at += slot.width();
        (slot, v)
    })
}

/// A light's pan and tilt levels in `bytes` (its first slot of each), or `None` without
/// both.
fn aim(light: &Placed, bytes: &[[u8; SLOTS]]) -> Option<[f32; 2]> {
    let (mut pan, mut tilt) = (None, None);
    for (slot, v) in read_slots(light, bytes) {
        match slot {
            Slot::Pan | Slot::Pan16 => pan = pan.or(Some(v)),
            Slot::Tilt | Slot::Tilt16 => tilt = tilt.or(Some(v)),
            _ => {}
        }
    }
    Some([pan?, tilt?])
}

/// One light's DMX read back: its dimmer level if it has one, and its colour slots. A
/// missing universe reads as zeros.
fn read(light: &Placed, bytes: &[[u8; SLOTS]]) -> (Option<f32>, Read) {
    let mut dimmer = None;
    let mut emitters = Vec::with_capacity(light.colour.emitters());
    let mut flags = None::<[f32; 3]>;
    for (slot, v) in read_slots(light, bytes) {
        match slot {
            s if s.is_emitter() => emitters.push(f64::from(v)),
            Slot::Cyan => flags.get_or_insert([1.0; 3])[0] = 1.0 - v,
            Slot::Magenta => flags.get_or_insert([1.0; 3])[1] = 1.0 - v,
            Slot::Yellow => flags.get_or_insert([1.0; 3])[2] = 1.0 - v,
            Slot::Intensity | Slot::Intensity16 => dimmer = Some(v),
            _ => {}
        }
    }
    let colour = if emitters.is_empty() {
        Read::Linear(flags.unwrap_or([1.0; 3]))
    } else {
        Read::Emitters(emitters)
    };
    (dimmer.filter(|_| light.has_intensity), colour)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// One light per profile, in universe 1 at 10-slot spacing (and one in universe 3),
    /// so every light's bytes can be read at a known place.
    fn scene() -> Scene {
        let mut text = String::from(
            "[[profile]]\nname = \"custom\"\nchannels = [\"fixed:255\", \"intensity16\", \"cyan\", \"magenta\", \"yellow\", \"uv\", \"fixed:7\"]\n",
        );
        text += "[[profile]]\nname = \"seven\"\nchannels = [\"red\", \"green\", \"blue\", \"amber\", \"lime\", \"emitter:cyan\", \"emitter:indigo\"]\n";
        let profiles = [
            "dimmer", "dimmer16", "rgb", "irgb", "rgbw", "irgbw", "rgba", "custom", "seven",
        ];
        for (i, p) in profiles.iter().enumerate() {
            text += &format!(
                "[[light]]\nchannel = {}\nbasis = \"b.exr\"\nprofile = \"{p}\"\nuniverse = 1\naddress = {}\n",
                i + 1,
                i * 10 + 1
            );
        }
        text += "[[light]]\nchannel = 20\nbasis = \"b.exr\"\nprofile = \"dimmer\"\nuniverse = 3\naddress = 512\n";
        Scene::parse(Path::new("/nonexistent"), &text).expect("test scene parses")
    }

    /// Every light at `intensity` with sRGB colour `color`.
    fn look(scene: &Scene, intensity: f32, color: [f32; 3]) -> Look {
        Look {
            levels: vec![
                Level {
                    intensity,
                    color,
                    position: None
                };
                scene.lights.len()
            ],
        }
    }

    /// The bytes of the light at profile index `i` (its address is `i * 10 + 1`).
    fn bytes_of(bytes: &[[u8; SLOTS]], i: usize, width: usize) -> Vec<u8> {
        bytes[0][i * 10..i * 10 + width].to_vec()
    }

    #[test]
    fn universes_are_sorted_and_unused_slots_zero() {
        let scene = scene();
        let patch = Patch::new(&scene);
        assert_eq!(patch.universes(), &[1, 3]);
        let bytes = patch.quantise(&patch.levels(&look(&scene, 1.0, [1.0; 3]), 1.0));
        assert_eq!(bytes.len(), 2);
        assert_eq!(bytes[1][511], 255);
        assert!(bytes[1][..511].iter().all(|&b| b == 0));
        assert_eq!(bytes[0][1..10], [0; 9]);
        assert!(bytes[0][90..].iter().all(|&b| b == 0));
    }

    #[test]
    fn built_in_profiles_bytes() {
        let scene = scene();
        let patch = Patch::new(&scene);
        // sRGB 0.5 decodes to linear 0.21404 (byte 55); intensity 0.5 is byte 128.
        let b = patch.quantise(&patch.levels(&look(&scene, 0.5, [1.0, 0.5, 0.0]), 1.0));
        assert_eq!(bytes_of(&b, 0, 1), [128], "dimmer");
        assert_eq!(bytes_of(&b, 1, 2), [128, 0], "dimmer16");
        assert_eq!(bytes_of(&b, 2, 3), [128, 27, 0], "rgb folds intensity in");
        assert_eq!(
            bytes_of(&b, 3, 4),
            [128, 255, 55, 0],
            "irgb: colour at full"
        );
    }

    #[test]
    fn white_emitter_takes_the_common_part_at_the_most_light() {
        let scene = scene();
        let patch = Patch::new(&scene);
        // By hand: with the default emitters, linear R, G and B at full add up to the
        // white emitter's D65 at Y = 1, so in linear sRGB units W = R + G + B. Linear
        // (1, 1, w) with w = 0.21404 (sRGB 0.5) at the most light: R = G = 1, B = 0 and
        // W = w / (1 - w) = 0.27233 (each channel is 1 + W, blue is W, in the ratio asked).
        let w = 0.214_041_14f64;
        let white = w / (1.0 - w);
        let b = patch.quantise(&patch.levels(&look(&scene, 0.6, [1.0, 1.0, 0.5]), 1.0));
        let byte = |v: f64| (v * 255.0).round() as u8;
        let want_rgbw = [byte(0.6), byte(0.6), 0, byte(0.6 * white)];
        let want_irgbw = [153, 255, 255, 0, byte(white)];
        for (got, want) in [
            (bytes_of(&b, 4, 4), want_rgbw.to_vec()),
            (bytes_of(&b, 5, 5), want_irgbw.to_vec()),
        ] {
            for (g, w) in got.iter().zip(&want) {
                assert!(g.abs_diff(*w) <= 1, "{got:?} vs {want:?}");
            }
        }
        // White is every emitter at full: twice the light of R, G and B alone.
        let white = patch.quantise(&patch.levels(&look(&scene, 1.0, [1.0; 3]), 1.0));
        assert_eq!(bytes_of(&white, 4, 4), [255, 255, 255, 255]);
        assert_eq!(bytes_of(&white, 5, 5), [255, 255, 255, 255, 255]);
    }

    /// The emitter levels the colour solve gives the light at profile index `i` for the
    /// sRGB `color` at its most light, straight from `emitter::solve`.
    fn solved(scene: &Scene, i: usize, color: [f32; 3]) -> Vec<f64> {
        let linear = color.map(|c| f64::from(visobjd_scene::srgb::srgb_to_linear(c)));
        let peak = linear.iter().copied().fold(0.0, f64::max);
        let target = visobjd_scene::emitter::colour::linear_srgb_to_xyz(linear);
        visobjd_scene::emitter::solve(&scene.profile(i).emitters_xyz(), target)
            .at(peak)
            .levels()
            .to_vec()
    }

    #[test]
    fn emitters_send_the_solves_levels() {
        let scene = scene();
        let patch = Patch::new(&scene);
        for color in [[1.0, 0.5, 0.0], [0.2, 0.4, 1.0], [1.0; 3], [0.0, 1.0, 0.9]] {
            for intensity in [1.0, 0.6] {
                let b = patch.quantise(&patch.levels(&look(&scene, intensity, color), 1.0));
                let again = patch.quantise(&patch.levels(&look(&scene, intensity, color), 1.0));
                assert_eq!(b, again, "the same bytes every time");
                // rgbw, rgba and the seven-colour light have no dimmer: the intensity is
                // folded in; irgbw has one.
                for (i, width, dimmer) in
                    [(4, 4, false), (5, 5, true), (6, 4, false), (8, 7, false)]
                {
                    let want: Vec<u8> = solved(&scene, i, color)
                        .iter()
                        .map(|l| {
                            assert!((0.0..=1.0).contains(l), "{l}");
                            let fold = if dimmer { 1.0 } else { f64::from(intensity) };
                            (l * fold * 255.0).round() as u8
                        })
                        .collect();
                    let got = bytes_of(&b, i, width);
                    let got = if dimmer { &got[1..] } else { &got[..] };
                    assert_eq!(got.len(), want.len());
                    for (g, w) in got.iter().zip(&want) {
                        assert!(
                            g.abs_diff(*w) <= 1,
                            "light {i} {color:?} at {intensity}: {got:?} vs {want:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn extra_emitters_carry_light() {
        let scene = scene();
        let patch = Patch::new(&scene);
        // White on the seven-colour light needs every emitter, cyan and indigo too.
        let b = patch.quantise(&patch.levels(&look(&scene, 1.0, [1.0; 3]), 1.0));
        let seven = bytes_of(&b, 8, 7);
        assert!(seven[5] > 0 && seven[6] > 0, "{seven:?}");
        // A cyan beyond what green and blue make reaches for the cyan emitter.
        let b = patch.quantise(&patch.levels(&look(&scene, 1.0, [0.0, 1.0, 1.0]), 1.0));
        assert!(bytes_of(&b, 8, 7)[5] > 0, "{:?}", bytes_of(&b, 8, 7));
    }

    #[test]
    fn sixteen_bit_split() {
        let scene = scene();
        let patch = Patch::new(&scene);
        // 0.75 * 65535 = 49151.25 -> 49151 = 191 * 256 + 255.
        let b = patch.quantise(&patch.levels(&look(&scene, 0.75, [1.0; 3]), 1.0));
        assert_eq!(bytes_of(&b, 1, 2), [191, 255]);
        let b = patch.quantise(&patch.levels(&look(&scene, 1.0, [1.0; 3]), 1.0));
        assert_eq!(bytes_of(&b, 1, 2), [255, 255]);
    }

    #[test]
    fn custom_profile_with_fixed_slots() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let b = patch.quantise(&patch.levels(&look(&scene, 0.5, [1.0, 0.5, 0.0]), 1.0));
        // fixed:255, intensity16 (0.5 -> 32768), C = 1 - 1, M = 1 - 0.214, Y = 1 - 0, uv, fixed:7
        assert_eq!(bytes_of(&b, 7, 8), [255, 128, 0, 0, 200, 255, 0, 7]);
        let off = patch.quantise(&patch.levels(&look(&scene, 0.0, [1.0, 0.5, 0.0]), 1.0));
        assert_eq!(bytes_of(&off, 7, 8), [255, 0, 0, 0, 200, 255, 0, 7]);
    }

    #[test]
    fn master_scales_intensity_only() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let b = patch.quantise(&patch.levels(&look(&scene, 1.0, [1.0, 0.5, 0.0]), 0.5));
        assert_eq!(bytes_of(&b, 0, 1), [128]);
        assert_eq!(bytes_of(&b, 1, 2), [128, 0]);
        assert_eq!(bytes_of(&b, 2, 3), [128, 27, 0], "folded emitters scale");
        assert_eq!(
            bytes_of(&b, 3, 4),
            [128, 255, 55, 0],
            "colour behind a dimmer stays"
        );
        assert_eq!(bytes_of(&b, 7, 8)[0], 255, "fixed slots stay");
    }

    #[test]
    fn master_commutes_with_crossfade() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let a = patch.unmastered(&look(&scene, 0.2, [0.3, 0.9, 1.0]));
        let b = patch.unmastered(&look(&scene, 0.9, [1.0, 0.2, 0.4]));
        let x = patch.mastered(&SlotLevels::crossfade(&a, &b, 0.3), 0.6);
        let y = SlotLevels::crossfade(&patch.mastered(&a, 0.6), &patch.mastered(&b, 0.6), 0.3);
        for (p, q) in x.levels.iter().zip(&y.levels) {
            assert!((p - q).abs() < 1e-6);
        }
    }

    #[test]
    fn crossfade_midpoint() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let on = patch.levels(&look(&scene, 1.0, [1.0; 3]), 1.0);
        let mid = patch.quantise(&SlotLevels::crossfade(&patch.blackout(), &on, 0.5));
        assert_eq!(bytes_of(&mid, 0, 1), [128]);
        // The 16-bit pair fades as one number: 0.5 -> 32768, not (128, 128).
        assert_eq!(bytes_of(&mid, 1, 2), [128, 0]);
        assert_eq!(SlotLevels::crossfade(&patch.blackout(), &on, 1.0), on);
        assert_eq!(
            SlotLevels::crossfade(&patch.blackout(), &on, 0.0),
            patch.blackout()
        );
    }

    #[test]
    fn blackout_is_all_zeros() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let b = patch.quantise(&patch.blackout());
        assert!(b.iter().all(|u| u.iter().all(|&v| v == 0)));
    }

    #[test]
    fn every_profile_reads_back_the_look_it_was_sent_within_a_step() {
        let scene = scene();
        let patch = Patch::new(&scene);
        // A small seeded generator, so a failure can be replayed.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for round in 0..200 {
            let levels = (0..scene.lights.len())
                .map(|_| {
                    // Looks keep a colour's largest component at 1.
                    let mut color = [next(), next(), next()];
                    color[round % 3] = 1.0;
                    Level {
                        intensity: next(),
                        color,
                        position: None,
                    }
                })
                .collect();
            let sent = Look { levels };
            let bytes = patch.quantise(&patch.unmastered(&sent));
            let multipliers = patch.multipliers(&bytes);
            for (i, (s, m)) in sent.levels.iter().zip(&multipliers).enumerate() {
                let profile = scene.profile(i);
                let step = 1.0 / 255.0 + 1e-4;
                if profile.has_colour() {
                    // The multiplier each emitter carries, to a DMX step per emitter.
                    let want = ColourModel::new(profile).multiplier(s);
                    for k in 0..3 {
                        assert!(
                            (m[k] - want[k]).abs() <= 3.0 * step,
                            "light {i} ({}) round {round}: sent {s:?} -> {m:?}, want {want:?}",
                            profile.name
                        );
                    }
                } else if profile.has_intensity() {
                    // A dimmer is white whatever the look's colour.
                    assert!(
                        m.iter().all(|v| (v - s.intensity).abs() <= step),
                        "light {i} ({}): {} -> {m:?}",
                        profile.name,
                        s.intensity
                    );
                }
            }
        }
    }

    #[test]
    fn light_slots_are_the_wire_bytes() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let frame = patch.unmastered(&look(&scene, 0.6237, [1.0, 0.8, 0.3]));
        let bytes = patch.quantise(&frame);
        for (light, slots) in patch.lights.iter().zip(patch.light_slots(&frame)) {
            let mut at = light.offset;
            for (slot, v) in slots {
                let dmx = &bytes[light.universe];
                let want = if slot == Slot::Intensity16 {
                    (f32::from(dmx[at]) * 256.0 + f32::from(dmx[at + 1])) / 65535.0
                } else {
                    f32::from(dmx[at]) / 255.0
                };
                assert_eq!(v, want, "{slot:?} at {at}");
                at += slot.width();
            }
        }
    }

    #[test]
    fn a_missing_universe_is_dark() {
        let scene = scene();
        let patch = Patch::new(&scene);
        assert!(patch.multipliers(&[]).iter().all(|v| *v == [0.0; 3]));
    }

    #[test]
    fn dmx_to_look_to_dmx_is_the_same_dmx_within_a_step_for_every_profile() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for name in visobjd_scene::profile::Profile::built_in_names() {
            assert!(
                (0..scene.lights.len()).any(|i| scene.profile(i).name == name),
                "the test scene lacks the built-in profile {name}"
            );
        }
        for round in 0..300 {
            let levels = (0..scene.lights.len())
                .map(|_| {
                    let mut color = [next(), next(), next()];
                    color[round % 3] = 1.0;
                    // Dark lights and black colours too.
                    let intensity = if round % 7 == 0 { 0.0 } else { next() };
                    if round % 11 == 0 {
                        color = [0.0; 3];
                    }
                    Level {
                        intensity,
                        color,
                        position: None,
                    }
                })
                .collect();
            let sent = patch.quantise(&patch.unmastered(&Look { levels }));
            let read = patch.look(&sent);
            assert!(
                read.levels
                    .iter()
                    .all(|l| (0.0..=1.0).contains(&l.intensity)
                        && l.color.iter().all(|c| (0.0..=1.0).contains(c)))
            );
            let again = patch.quantise(&patch.unmastered(&read));
            for (u, (a, b)) in sent.iter().zip(&again).enumerate() {
                for (slot, (x, y)) in a.iter().zip(b).enumerate() {
                    assert!(
                        x.abs_diff(*y) <= 1,
                        "round {round}, universe index {u} slot {}: {x} became {y}",
                        slot + 1
                    );
                }
            }
        }
    }

    #[test]
    fn dmx_reads_as_intensity_and_colour() {
        let scene = scene();
        let patch = Patch::new(&scene);
        let mut bytes = [[0u8; SLOTS]; 2];
        bytes[0][0] = 128; // dimmer
        bytes[0][20..23].copy_from_slice(&[255, 55, 0]); // rgb: full red, linear 0.214 green
        bytes[0][30..34].copy_from_slice(&[51, 255, 0, 0]); // irgb at 20%, red
        let look = patch.look(&bytes);
        let l = &look.levels;
        assert!((l[0].intensity - 128.0 / 255.0).abs() < 1e-6 && l[0].color == [1.0; 3]);
        assert!((l[2].intensity - 1.0).abs() < 1e-6);
        assert!(
            (l[2].color[1] - 0.5).abs() < 0.01,
            "sRGB 0.5 is linear 0.214: {:?}",
            l[2]
        );
        assert_eq!(l[3].intensity, 0.2);
        assert!(
            (l[3].color[0] - 1.0).abs() < 1e-6 && l[3].color[1..].iter().all(|v| v.abs() < 1e-6),
            "{:?}",
            l[3]
        );
        assert_eq!(
            (l[4].intensity, l[4].color),
            (0.0, [1.0; 3]),
            "dark rgbw is white at 0"
        );
        assert_eq!(l[9].intensity, 0.0, "universe 3 is missing: dark");
    }

    /// Two movers (16-bit and 8-bit pan/tilt) and a fixed light with pan/tilt slots.
    fn movers() -> Scene {
        let mut text = String::from(
            "[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n\
             [[profile]]\nname = \"wash\"\nchannels = [\"red\", \"green\", \"blue\", \"pan\", \"tilt\"]\npan_range = 360\ntilt_range = 180\n",
        );
        for (ch, profile, address) in [(1, "spot", 1), (2, "wash", 11)] {
            text += &format!(
                "[[light]]\nchannel = {ch}\nprofile = \"{profile}\"\nuniverse = 1\naddress = {address}\n\
                 [[light.position]]\npalette = 1\npan = -90.0\ntilt = 45.0\nbasis = \"a.exr\"\n\
                 [[light.position]]\npalette = 2\npan = 90.0\ntilt = -45.0\nbasis = \"b.exr\"\n"
            );
        }
        text += "[[light]]\nchannel = 3\nbasis = \"c.exr\"\nprofile = \"spot\"\nuniverse = 1\naddress = 21\n";
        Scene::parse(Path::new("/nonexistent"), &text).expect("test scene parses")
    }

    fn aimed(scene: &Scene, intensity: f32, position: Option<u32>) -> Look {
        Look {
            levels: vec![
                Level {
                    intensity,
                    color: [1.0; 3],
                    position,
                };
                scene.lights.len()
            ],
        }
    }

    #[test]
    fn pan_and_tilt_go_out_from_degrees_through_the_range() {
        let scene = movers();
        let patch = Patch::new(&scene);
        let wire = |look: &Look| patch.quantise(&patch.unmastered(look))[0];
        let b = wire(&aimed(&scene, 1.0, Some(2)));
        let word = |at: usize| u16::from(b[at]) << 8 | u16::from(b[at + 1]);
        // Spot: pan 90 of 540 -> 0.5 + 1/6; tilt -45 of 270 -> 0.5 - 1/6, 16-bit.
        assert_eq!(word(1), (65535.0f64 * (0.5 + 90.0 / 540.0)).round() as u16);
        assert_eq!(word(3), (65535.0f64 * (0.5 - 45.0 / 270.0)).round() as u16);
        // Wash: 8-bit, pan 90 of 360 -> 0.75, tilt -45 of 180 -> 0.25.
        assert_eq!(b[13..15], [191, 64]);
        // No position, or one it lacks: the first; the master never moves a light.
        let first = wire(&aimed(&scene, 1.0, None));
        assert_eq!(first, wire(&aimed(&scene, 1.0, Some(9))));
        assert_eq!(first[13..15], [64, 191]);
        let dim = patch.quantise(&patch.levels(&aimed(&scene, 1.0, None), 0.2))[0];
        assert_eq!(dim[1..5], first[1..5]);
        assert_eq!(dim[13..15], first[13..15]);
        // A fixed light with pan and tilt slots stays at centre.
        assert_eq!(first[21..25], [128, 0, 128, 0]);
        // Read back, the aim is the position's, to DMX precision (16- and 8-bit).
        let aims = patch.aims(std::slice::from_ref(&b));
        let spot = aims[0].expect("the spot has pan and tilt");
        assert!(
            (spot[0] - (0.5 + 90.0 / 540.0)).abs() <= 0.5 / 65535.0,
            "{spot:?}"
        );
        assert!(
            (spot[1] - (0.5 - 45.0 / 270.0)).abs() <= 0.5 / 65535.0,
            "{spot:?}"
        );
        assert_eq!(aims[1], Some([191.0 / 255.0, 64.0 / 255.0]));
        assert_eq!(aims[2], Some([32768.0 / 65535.0, 32768.0 / 65535.0]));
        assert_eq!(
            patch.aims(&[])[0],
            Some([0.0, 0.0]),
            "a missing universe is zeros"
        );
        // Read back as a look, the wire is in the palettes it was sent to, or the nearest.
        let back = patch.look(&[b]);
        assert_eq!(
            [back.levels[0].position, back.levels[1].position],
            [Some(2); 2]
        );
        let mut near = b;
        // The spot's pan and tilt most of the way back towards palette 1's.
        (near[1], near[3]) = (100, 160);
        assert_eq!(patch.look(&[near]).levels[0].position, Some(1));
        assert_eq!(back.levels[2].position, None, "a fixed light has none");
    }

    #[test]
    fn a_fade_moves_a_lit_mover_and_a_dark_one_at_once() {
        let scene = movers();
        let patch = Patch::new(&scene);
        let pan = |f: &SlotLevels| f.universe(0)[1];
        let at =
            |a: &Look, b: &Look, t| patch.crossfade(&patch.unmastered(a), &patch.unmastered(b), t);
        let (lit1, lit2) = (aimed(&scene, 1.0, Some(1)), aimed(&scene, 1.0, Some(2)));
        let (dark1, dark2) = (aimed(&scene, 0.0, Some(1)), aimed(&scene, 0.0, Some(2)));
        let (p1, p2) = (pan(&patch.unmastered(&lit1)), pan(&patch.unmastered(&lit2)));
        for t in [0.0, 0.25, 0.5, 1.0] {
            let want = p1 + (p2 - p1) * t;
            assert!(
                (pan(&at(&lit1, &lit2, t)) - want).abs() < 1e-6,
                "lit at {t}"
            );
            assert!(
                (pan(&at(&lit1, &dark2, t)) - want).abs() < 1e-6,
                "fading out at {t}"
            );
            assert!(
                (pan(&at(&dark1, &lit2, t)) - want).abs() < 1e-6,
                "fading in at {t}"
            );
            assert_eq!(pan(&at(&dark1, &dark2, t)), p2, "dark at {t}");
        }
        // The wash has no dimmer: its emitters carry its intensity.
        let wash = |f: &SlotLevels| f.universe(0)[13];
        assert_eq!(wash(&at(&dark1, &dark2, 0.3)), 0.75);
        assert!(wash(&at(&lit1, &lit2, 0.3)) < 0.75);
    }
}
