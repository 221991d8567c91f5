//! Fixture profiles: which DMX slots a light has, what each one means, and the colour of
//! each additive emitter (docs/scene.md).
//!
//! A profile is data: the built-in ones are written in the same slot names a scene's
//! `[[profile]]` uses, and an importer (GDTF, MVR, the Open Fixture Library) produces the
//! same thing. Every additive emitter carries its CIE 1931 xy chromaticity and relative
//! output, so a colour solver can mix in the fixture's real colour space instead of
//! assuming the sRGB primaries.

use std::fmt;

use serde::{Deserialize, Serialize};

/// What one slot (or, for `Intensity16`, two slots) of a fixture controls.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// 8-bit dimmer.
    Intensity,
    /// 16-bit dimmer: coarse then fine slot.
    Intensity16,
    /// Additive emitters.
    Red,
    /// Additive emitter.
    Green,
    /// Additive emitter.
    Blue,
    /// White emitter.
    White,
    /// Amber emitter.
    Amber,
    /// Lime emitter.
    Lime,
    /// Any other additive emitter (a 7-colour LED's cyan, indigo, deep red...): an index
    /// into [`Profile::emitters`], written `emitter:NAME` in scene.toml.
    Emitter(usize),
    /// Ultraviolet: always written 0 (no visible contribution to model).
    Uv,
    /// Subtractive cyan flag (CMY mixing).
    Cyan,
    /// Subtractive magenta flag.
    Magenta,
    /// Subtractive yellow flag.
    Yellow,
    /// A constant value, e.g. a strobe "open" or a mode channel.
    Fixed(u8),
    /// 8-bit pan of a moving light: degrees through [`Profile::pan_range`], 0 at DMX centre.
    Pan,
    /// 16-bit pan: coarse then fine slot.
    Pan16,
    /// 8-bit tilt, through [`Profile::tilt_range`].
    Tilt,
    /// 16-bit tilt: coarse then fine slot.
    Tilt16,
}

/// The slot names of the fixed-meaning slots, in the order error messages list them.
const NAMED: &[(&str, Slot)] = &[
    ("intensity", Slot::Intensity),
    ("intensity16", Slot::Intensity16),
    ("red", Slot::Red),
    ("green", Slot::Green),
    ("blue", Slot::Blue),
    ("white", Slot::White),
    ("amber", Slot::Amber),
    ("lime", Slot::Lime),
    ("uv", Slot::Uv),
    ("cyan", Slot::Cyan),
    ("magenta", Slot::Magenta),
    ("yellow", Slot::Yellow),
    ("pan", Slot::Pan),
    ("pan16", Slot::Pan16),
    ("tilt", Slot::Tilt),
    ("tilt16", Slot::Tilt16),
];

/// A profile's full pan travel in degrees when it does not say (`pan_range`).
pub const DEFAULT_PAN_RANGE: f64 = 540.0;
/// A profile's full tilt travel in degrees when it does not say (`tilt_range`).
pub const DEFAULT_TILT_RANGE: f64 = 270.0;

impl Slot {
    /// How many DMX slots this takes.
    pub fn width(self) -> usize {
        if self.is_wide() { 2 } else { 1 }
    }

    /// Whether this is a 16-bit pair (coarse, fine).
    pub fn is_wide(self) -> bool {
        matches!(self, Slot::Intensity16 | Slot::Pan16 | Slot::Tilt16)
    }

    /// Whether this slot aims the light (pan or tilt, 8- or 16-bit).
    pub fn is_position(self) -> bool {
        matches!(self, Slot::Pan | Slot::Pan16 | Slot::Tilt | Slot::Tilt16)
    }

    /// Whether this slot changes the light's colour (so the sampler may colour it).
    pub fn is_colour(self) -> bool {
        self.is_emitter() || matches!(self, Slot::Cyan | Slot::Magenta | Slot::Yellow)
    }

    /// Whether this slot drives an additive emitter (one entry of [`Profile::emitters`]).
    pub fn is_emitter(self) -> bool {
        matches!(
            self,
            Slot::Red
                | Slot::Green
                | Slot::Blue
                | Slot::White
                | Slot::Amber
                | Slot::Lime
                | Slot::Emitter(_)
        )
    }

    /// The name of a fixed-meaning slot (`None` for `Emitter` and `Fixed`, whose names
    /// carry data: see [`Profile::channel_names`]).
    fn fixed_name(self) -> Option<&'static str> {
        NAMED.iter().find(|(_, s)| *s == self).map(|(n, _)| *n)
    }
}

/// One additive emitter: its colour at full, the data a colour solver mixes with.
#[derive(Debug, Clone, PartialEq)]
pub struct Emitter {
    /// `red`, `green`, ... for the named slots; the `NAME` of `emitter:NAME` otherwise.
    pub name: String,
    /// CIE 1931 xy chromaticity.
    pub xy: [f64; 2],
    /// Output at full relative to the fixture's other emitters (the Y of CIE xyY).
    pub flux: f64,
}

impl Emitter {
    /// CIE XYZ at full: `Y = flux`, `X = x / y * Y`, `Z = (1 - x - y) / y * Y`.
    pub fn xyz(&self) -> [f64; 3] {
        crate::emitter::colour::xyy_to_xyz(self.xy[0], self.xy[1], self.flux)
    }
}

/// Emitters whose colour is known without being told (docs/scene.md): the six named
/// slots, and a few common LED colours an importer meets (OFL `Cyan`, `Indigo`, ...).
/// Red, green and blue are the sRGB primaries with the luminances of the sRGB matrix the
/// colour conversions use (`emitter::colour::SRGB_TO_XYZ`), and white is its D65, so RGB
/// at full is exactly the white the basis images were captured in; amber
/// and lime sit on the spectral locus at about 590 nm and 565 nm with the luminance of linear
/// RGB (1, 0.45, 0) and (0.5, 1, 0). The others are rough: give a real
/// fixture's values in `[[profile.emitter]]` where known.
pub const DEFAULT_EMITTERS: &[(&str, [f64; 2], f64)] = &[
    ("red", [0.64, 0.33], 0.212_672_9),
    ("green", [0.30, 0.60], 0.715_152_2),
    ("blue", [0.15, 0.06], 0.072_175),
    ("white", [0.312_726_6, 0.329_023_1], 1.0),
    ("amber", [0.5752, 0.4242], 0.5344),
    ("lime", [0.4087, 0.5896], 0.8215),
    // ~495 nm.
    ("cyan", [0.0235, 0.4127], 0.4),
    // ~450 nm.
    ("indigo", [0.1566, 0.0177], 0.03),
    // ~660 nm.
    ("deep-red", [0.7300, 0.2700], 0.05),
    // The sRGB secondaries, for fixtures with such emitters.
    ("magenta", [0.3209, 0.1542], 0.2848),
    ("yellow", [0.4193, 0.5053], 0.9278),
    // 3000 K and 6500 K.
    ("warm-white", [0.4369, 0.4041], 1.0),
    ("cold-white", [0.3135, 0.3236], 1.0),
];

/// An emitter's colour given in a `[[profile.emitter]]` table (both keys optional).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EmitterFile {
    /// `red` for the `red` slot, `NAME` for `emitter:NAME`.
    pub name: String,
    /// CIE 1931 x, y.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub xy: Option<[f64; 2]>,
    /// Relative output at full.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flux: Option<f64>,
}

/// A `[[profile]]` table as scene.toml spells it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileFile {
    /// The name lights refer to.
    pub name: String,
    /// Slot names in DMX order.
    pub channels: Vec<String>,
    /// Full pan travel in degrees (default [`DEFAULT_PAN_RANGE`]), for `pan`/`pan16`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pan_range: Option<f64>,
    /// Full tilt travel in degrees (default [`DEFAULT_TILT_RANGE`]), for `tilt`/`tilt16`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tilt_range: Option<f64>,
    /// Emitter colours, where they differ from the defaults.
    #[serde(default, rename = "emitter", skip_serializing_if = "Vec::is_empty")]
    pub emitters: Vec<EmitterFile>,
}

/// A fixture type: a name, its slots in DMX order, and its additive emitters.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// The name scene.toml uses.
    pub name: String,
    /// Slots in channel order.
    pub slots: Vec<Slot>,
    /// One per additive slot, in slot order; `Slot::Emitter(k)` is `emitters[k]`.
    pub emitters: Vec<Emitter>,
    /// Full pan travel in degrees: DMX 0 is `-pan_range / 2`, full is `+pan_range / 2`.
    pub pan_range: f64,
    /// Full tilt travel in degrees, likewise.
    pub tilt_range: f64,
}

/// The profiles every scene knows without defining them (docs/scene.md), in the slot
/// names a `[[profile]]` uses, with the default emitters.
const BUILT_IN: &[(&str, &[&str])] = &[
    ("dimmer", &["intensity"]),
    ("dimmer16", &["intensity16"]),
    ("rgb", &["red", "green", "blue"]),
    ("irgb", &["intensity", "red", "green", "blue"]),
    ("rgbw", &["red", "green", "blue", "white"]),
    ("irgbw", &["intensity", "red", "green", "blue", "white"]),
    ("rgba", &["red", "green", "blue", "amber"]),
];

impl Profile {
    /// The names of the emitters the colour model mixes (at most
    /// [`crate::emitter::MAX_EMITTERS`]), in slot order: what per-emitter images and
    /// measurements are kept for.
    pub fn mixed_emitters(&self) -> Vec<&str> {
        self.emitters
            .iter()
            .take(crate::emitter::MAX_EMITTERS)
            .map(|e| e.name.as_str())
            .collect()
    }

    /// A built-in profile by name.
    pub fn built_in(name: &str) -> Option<Profile> {
        let (n, channels) = BUILT_IN.iter().find(|(n, _)| *n == name)?;
        let file = ProfileFile {
            name: (*n).to_string(),
            channels: channels.iter().map(|c| (*c).to_string()).collect(),
            emitters: Vec::new(),
            pan_range: None,
            tilt_range: None,
        };
        Profile::from_file(&file).ok()
    }

    /// The names of the built-in profiles, for error messages.
    pub fn built_in_names() -> impl Iterator<Item = &'static str> {
        BUILT_IN.iter().map(|(n, _)| *n)
    }

    /// A profile from its `[[profile]]` table: slot names, then the emitter colours
    /// (defaults where not given). Errors name the profile and the slot or emitter.
    pub fn from_file(file: &ProfileFile) -> Result<Profile, String> {
        let name = &file.name;
        if file.channels.is_empty() {
            return Err(format!("profile `{name}` has no channels"));
        }
        let mut slots = Vec::with_capacity(file.channels.len());
        let mut emitters: Vec<Emitter> = Vec::new();
        for c in &file.channels {
            let bad = |e: String| format!("profile `{name}`: {e}");
            let (slot, emitter) = parse_slot(c, emitters.len()).map_err(bad)?;
            if let Some(e) = emitter {
                if emitters.iter().any(|o| o.name == e) {
                    return Err(bad(format!("emitter `{e}` is used by two slots")));
                }
                emitters.push(default_emitter(&e));
            }
            slots.push(slot);
        }
        for given in &file.emitters {
            let e = emitters
                .iter_mut()
                .find(|e| e.name == given.name)
                .ok_or_else(|| {
                    format!(
                        "profile `{name}`: [[profile.emitter]] `{}` is not one of its slots",
                        given.name
                    )
                })?;
            if let Some(xy) = given.xy {
                e.xy = xy;
            }
            if let Some(flux) = given.flux {
                e.flux = flux;
            }
        }
        for e in &emitters {
            let [x, y] = e.xy;
            if !(x.is_finite() && y.is_finite() && x >= 0.0 && y > 0.0 && x + y <= 1.0) {
                return Err(format!(
                    "profile `{name}`: emitter `{}` needs a CIE xy with x >= 0, y > 0 and x + y <= 1 (`xy = [x, y]` in its [[profile.emitter]]){}",
                    e.name,
                    if x.is_nan() {
                        ": there is no default for this name"
                    } else {
                        ""
                    }
                ));
            }
            if !(e.flux.is_finite() && e.flux >= 0.0) {
                return Err(format!(
                    "profile `{name}`: emitter `{}` flux {} must be 0 or more",
                    e.name, e.flux
                ));
            }
        }
        let range = |given: Option<f64>, default: f64, key: &str| match given {
            None => Ok(default),
            Some(r) if r.is_finite() && r > 0.0 && r <= 3600.0 => Ok(r),
            Some(r) => Err(format!(
                "profile `{name}`: {key} {r} must be the full travel in degrees, above 0 and at most 3600"
            )),
        };
        Ok(Profile {
            name: name.clone(),
            slots,
            emitters,
            pan_range: range(file.pan_range, DEFAULT_PAN_RANGE, "pan_range")?,
            tilt_range: range(file.tilt_range, DEFAULT_TILT_RANGE, "tilt_range")?,
        })
    }

    /// The `[[profile]]` table that reads back as this profile: every emitter's colour is
    /// written where it differs from its default.
    pub fn to_file(&self) -> ProfileFile {
        let emitters = self
            .emitters
            .iter()
            .filter(|e| **e != default_emitter(&e.name))
            .map(|e| EmitterFile {
                name: e.name.clone(),
                xy: Some(e.xy),
                flux: Some(e.flux),
            })
            .collect();
        ProfileFile {
            name: self.name.clone(),
            channels: self.channel_names(),
            emitters,
            pan_range: (self.pan_range != DEFAULT_PAN_RANGE).then_some(self.pan_range),
            tilt_range: (self.tilt_range != DEFAULT_TILT_RANGE).then_some(self.tilt_range),
        }
    }

    /// The slot names in DMX order, as scene.toml writes them.
    pub fn channel_names(&self) -> Vec<String> {
        self.slots
            .iter()
            .map(|s| match *s {
                Slot::Emitter(k) => format!(
                    "emitter:{}",
                    self.emitters.get(k).map_or("?", |e| e.name.as_str())
                ),
                Slot::Fixed(n) => format!("fixed:{n}"),
                other => other.fixed_name().unwrap_or("?").to_string(),
            })
            .collect()
    }

    /// DMX slots the fixture occupies.
    pub fn footprint(&self) -> usize {
        self.slots.iter().map(|s| s.width()).sum()
    }

    /// Whether the fixture can change colour; dimmers stay white and are never coloured.
    pub fn has_colour(&self) -> bool {
        self.slots.iter().any(|s| s.is_colour())
    }

    /// Whether the fixture has a dimmer; without one, intensity is folded into the emitters.
    pub fn has_intensity(&self) -> bool {
        self.slots
            .iter()
            .any(|s| matches!(s, Slot::Intensity | Slot::Intensity16))
    }

    /// Whether the fixture can be aimed: it has a pan slot and a tilt slot, so it can take
    /// a light's positions (`[[light.position]]`).
    pub fn is_moving(&self) -> bool {
        let has = |a: Slot, b: Slot| self.slots.iter().any(|&s| s == a || s == b);
        has(Slot::Pan, Slot::Pan16) && has(Slot::Tilt, Slot::Tilt16)
    }

    /// The DMX level (0..1) of `degrees` from the centre of a travel of `range` degrees.
    pub fn position_level(degrees: f64, range: f64) -> f32 {
        (0.5 + degrees / range).clamp(0.0, 1.0) as f32
    }

    /// The degrees from centre of DMX `level` (0..1) through a travel of `range` degrees:
    /// the inverse of [`Profile::position_level`].
    pub fn position_degrees(level: f32, range: f64) -> f64 {
        (f64::from(level) - 0.5) * range
    }

    /// Every additive emitter's CIE XYZ at full, in slot order (the order of
    /// [`Profile::emitters`]): the basis a colour solver mixes a requested colour from.
    pub fn emitters_xyz(&self) -> Vec<[f64; 3]> {
        self.emitters.iter().map(Emitter::xyz).collect()
    }
}

/// One slot name; for an additive emitter also its emitter's name (`next` is the index
/// the new emitter will get, for `Slot::Emitter`).
fn parse_slot(name: &str, next: usize) -> Result<(Slot, Option<String>), String> {
    if let Some((n, slot)) = NAMED.iter().find(|(n, _)| *n == name) {
        return Ok((*slot, slot.is_emitter().then(|| (*n).to_string())));
    }
    if let Some(n) = name.strip_prefix("fixed:") {
        let v = n.trim().parse::<u8>().map_err(|_| {
            format!("`{name}`: a fixed slot takes a value 0..=255, as in `fixed:255`")
        })?;
        return Ok((Slot::Fixed(v), None));
    }
    if let Some(e) = name.strip_prefix("emitter:") {
        let ok = !e.is_empty()
            && e.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-');
        if !ok {
            return Err(format!(
                "`{name}`: an emitter name is lowercase letters, digits and `-`, as in `emitter:deep-red`"
            ));
        }
        if NAMED.iter().any(|(n, s)| *n == e && s.is_emitter()) {
            return Err(format!("`{name}`: write the named slot `{e}` instead"));
        }
        return Ok((Slot::Emitter(next), Some(e.to_string())));
    }
    Err(format!(
        "unknown slot `{name}` (known: {}, emitter:NAME, fixed:N)",
        NAMED.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
    ))
}

/// The default emitter called `name`, or one with no chromaticity (NaN, refused by
/// [`Profile::from_file`] unless the scene gives it) when the name has no default.
fn default_emitter(name: &str) -> Emitter {
    let (xy, flux) = DEFAULT_EMITTERS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map_or(([f64::NAN; 2], 1.0), |(_, xy, f)| (*xy, *f));
    Emitter {
        name: name.to_string(),
        xy,
        flux,
    }
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(channels: &[&str], emitters: Vec<EmitterFile>) -> ProfileFile {
        ProfileFile {
            name: "p".into(),
            channels: channels.iter().map(|c| c.to_string()).collect(),
            emitters,
            pan_range: None,
            tilt_range: None,
        }
    }

    #[test]
    fn rgb_at_full_adds_up_to_d65_white() {
        let p = Profile::built_in("rgb").expect("built in");
        let xyz = p.emitters_xyz();
        let sum: Vec<f64> = (0..3).map(|i| xyz.iter().map(|e| e[i]).sum()).collect();
        // D65 at Y = 1 as IEC 61966-2-1's matrix (Lindbloom's table) has it.
        assert!((sum[0] - 0.95047).abs() < 1e-6, "{sum:?}");
        assert!((sum[1] - 1.0).abs() < 1e-6, "{sum:?}");
        assert!((sum[2] - 1.08883).abs() < 1e-6, "{sum:?}");
    }

    #[test]
    fn custom_emitters_take_their_colour_and_keep_slot_order() {
        let p = Profile::from_file(&file(
            &[
                "intensity16",
                "red",
                "emitter:indigo",
                "fixed:7",
                "emitter:teal",
            ],
            vec![
                EmitterFile {
                    name: "teal".into(),
                    xy: Some([0.1, 0.5]),
                    flux: Some(0.25),
                },
                EmitterFile {
                    name: "red".into(),
                    xy: None,
                    flux: Some(0.3),
                },
            ],
        ))
        .expect("parses");
        assert_eq!(
            p.slots,
            [
                Slot::Intensity16,
                Slot::Red,
                Slot::Emitter(1),
                Slot::Fixed(7),
                Slot::Emitter(2)
            ]
        );
        assert_eq!(p.footprint(), 6);
        let names: Vec<&str> = p.emitters.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["red", "indigo", "teal"]);
        assert_eq!(p.emitters[0].xy, [0.64, 0.33]);
        assert_eq!(p.emitters[0].flux, 0.3);
        let teal = p.emitters_xyz()[2];
        assert!((teal[0] - 0.05).abs() < 1e-12 && (teal[1] - 0.25).abs() < 1e-12);
        assert!((teal[2] - 0.2).abs() < 1e-12);
        // Written back and read again, it is the same profile.
        assert_eq!(Profile::from_file(&p.to_file()), Ok(p));
    }

    #[test]
    fn bad_profiles_are_refused_with_the_reason() {
        let err = |c: &[&str], e: Vec<EmitterFile>| Profile::from_file(&file(c, e)).unwrap_err();
        assert!(err(&["emitter:teal"], vec![]).contains("no default"));
        assert!(err(&["emitter:red"], vec![]).contains("write the named slot `red`"));
        assert!(err(&["emitter:Deep Red"], vec![]).contains("lowercase"));
        assert!(err(&["emitter:cyan", "emitter:cyan"], vec![]).contains("two slots"));
        assert!(err(&["fixed:256"], vec![]).contains("0..=255"));
        assert!(err(&["dimmer"], vec![]).contains("unknown slot `dimmer`"));
        let flux = EmitterFile {
            name: "red".into(),
            xy: None,
            flux: Some(-1.0),
        };
        assert!(err(&["red"], vec![flux]).contains("flux"));
        let stray = EmitterFile {
            name: "blue".into(),
            ..EmitterFile::default()
        };
        assert!(err(&["red"], vec![stray]).contains("not one of its slots"));
    }
}
