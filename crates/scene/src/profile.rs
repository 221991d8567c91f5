//! Fixture profiles: which DMX slots a light has and what each one means (docs/scene.md).

use std::fmt;

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
    /// White emitter, extracted from the colour's common part.
    White,
    /// Amber emitter.
    Amber,
    /// Lime emitter.
    Lime,
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
}

impl Slot {
    /// Parses one slot name as written in a custom `[[profile]]`.
    pub fn parse(name: &str) -> Result<Slot, String> {
        Ok(match name {
            "intensity" => Slot::Intensity,
            "intensity16" => Slot::Intensity16,
            "red" => Slot::Red,
            "green" => Slot::Green,
            "blue" => Slot::Blue,
            "white" => Slot::White,
            "amber" => Slot::Amber,
            "lime" => Slot::Lime,
            "uv" => Slot::Uv,
            "cyan" => Slot::Cyan,
            "magenta" => Slot::Magenta,
            "yellow" => Slot::Yellow,
            other => match other.strip_prefix("fixed:") {
                Some(n) => Slot::Fixed(n.trim().parse::<u8>().map_err(|_| {
                    format!("`{other}`: a fixed slot takes a value 0..=255, as in `fixed:255`")
                })?),
                None => {
                    return Err(format!(
                        "unknown slot `{other}` (known: intensity, intensity16, red, green, blue, white, amber, lime, uv, cyan, magenta, yellow, fixed:N)"
                    ));
                }
            },
        })
    }

    /// How many DMX slots this takes.
    pub fn width(self) -> usize {
        if self == Slot::Intensity16 { 2 } else { 1 }
    }

    /// Whether this slot changes the light's colour (so the sampler may colour it).
    pub fn is_colour(self) -> bool {
        matches!(
            self,
            Slot::Red
                | Slot::Green
                | Slot::Blue
                | Slot::White
                | Slot::Amber
                | Slot::Lime
                | Slot::Cyan
                | Slot::Magenta
                | Slot::Yellow
        )
    }
}

/// A fixture type: a name and its slots in DMX order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Profile {
    /// The name scene.toml uses.
    pub name: String,
    /// Slots in channel order.
    pub slots: Vec<Slot>,
}

/// The profiles every scene knows without defining them (docs/scene.md).
const BUILT_IN: &[(&str, &[Slot])] = &[
    ("dimmer", &[Slot::Intensity]),
    ("dimmer16", &[Slot::Intensity16]),
    ("rgb", &[Slot::Red, Slot::Green, Slot::Blue]),
    (
        "irgb",
        &[Slot::Intensity, Slot::Red, Slot::Green, Slot::Blue],
    ),
    ("rgbw", &[Slot::Red, Slot::Green, Slot::Blue, Slot::White]),
    (
        "irgbw",
        &[
            Slot::Intensity,
            Slot::Red,
            Slot::Green,
            Slot::Blue,
            Slot::White,
        ],
    ),
    ("rgba", &[Slot::Red, Slot::Green, Slot::Blue, Slot::Amber]),
];

impl Profile {
    /// A built-in profile by name.
    pub fn built_in(name: &str) -> Option<Profile> {
        BUILT_IN
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(n, slots)| Profile {
                name: (*n).to_string(),
                slots: slots.to_vec(),
            })
    }

    /// The names of the built-in profiles, for error messages.
    pub fn built_in_names() -> impl Iterator<Item = &'static str> {
        BUILT_IN.iter().map(|(n, _)| *n)
    }

    /// A custom profile from its slot names.
    pub fn custom(name: &str, channels: &[String]) -> Result<Profile, String> {
        if channels.is_empty() {
            return Err(format!("profile `{name}` has no channels"));
        }
        let slots = channels
            .iter()
            .map(|c| Slot::parse(c).map_err(|e| format!("profile `{name}`: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Profile {
            name: name.to_string(),
            slots,
        })
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
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}
