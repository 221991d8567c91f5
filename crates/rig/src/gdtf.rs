//! GDTF fixture types (DIN SPEC 15800, GDTF 1.2; 1.0 and 1.1 files read the same way): a
//! zip with `description.xml`. Read: `FixtureType` names, `DMXModes` > `DMXMode` >
//! `DMXChannels` > `DMXChannel` (`DMXBreak`, `Offset` = the channel's addresses from most
//! to least significant, empty or `None` for a virtual channel) > `LogicalChannel`
//! (`Attribute`) > `ChannelFunction` (`Attribute`, `Default`, `DMXFrom`, `Emitter`,
//! `PhysicalFrom`/`PhysicalTo` for `Pan` and `Tilt`, `ChannelSet`s), and
//! `PhysicalDescriptions` > `Emitters` > `Emitter` (`Color` = CIE xyY). The tables are in
//! mvrdevelopment/spec `gdtf-spec.md` (Tables 16, 58, 59, 60 and the DMXValue type: `v/n`
//! is `v` in `n` bytes, mirrored to the channel's resolution; `v/ns` is shifted; a
//! `ChannelFunction`'s `PhysicalFrom` and `PhysicalTo` default to 0 and 1).

use visobjd_scene::profile::{DEFAULT_EMITTERS, EmitterFile, Profile, ProfileFile};

use crate::{FixtureType, RigError};

/// One `Emitter` of the physical description.
#[derive(Debug, Clone, PartialEq)]
pub struct GdtfEmitter {
    /// Its `Name` (what `ChannelFunction Emitter=` links to).
    pub name: String,
    /// CIE 1931 x, y and Y from `Color` (absent for UV and other invisible emitters).
    pub color: Option<[f64; 3]>,
}

/// One DMX channel of a mode (virtual channels, without an offset, are left out).
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// `DMXBreak` (1 for `Overwrite`).
    pub dmx_break: u32,
    /// 1-based offsets from the most to the least significant byte.
    pub offsets: Vec<usize>,
    /// The first logical channel's attribute (`Dimmer`, `ColorAdd_R`, `Shutter1`...).
    pub attribute: String,
    /// The initial channel function's `Default`, at the channel's resolution.
    pub default: u64,
    /// For `Shutter1`: the DMX value where the shutter is open.
    pub open: Option<u64>,
    /// The emitter a channel function links to (`Emitter=`).
    pub emitter: Option<String>,
    /// For `Pan` and `Tilt`: `PhysicalFrom` and `PhysicalTo` (degrees) of the channel's
    /// first function of that attribute, where the file gives either (the spec's defaults,
    /// 0 and 1, fill the other); `None` leaves the profile's default travel.
    pub physical: Option<(f64, f64)>,
}

/// One `DMXMode`.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// Its `Name` (what MVR `GDTFMode` names).
    pub name: String,
    /// Its channels in file order.
    pub channels: Vec<Channel>,
}

impl Mode {
    /// DMX slots the mode takes: its highest offset.
    pub fn footprint(&self) -> usize {
        self.channels
            .iter()
            .flat_map(|c| c.offsets.iter().copied())
            .max()
            .unwrap_or(0)
    }
}

/// A parsed GDTF fixture type.
#[derive(Debug, Clone, PartialEq)]
pub struct GdtfType {
    /// The file it came from (for errors).
    pub file: String,
    /// `Manufacturer`.
    pub manufacturer: String,
    /// `Name`.
    pub name: String,
    /// `LongName`.
    pub long_name: String,
    /// DMX modes in file order.
    pub modes: Vec<Mode>,
    /// Emitters of the physical description.
    pub emitters: Vec<GdtfEmitter>,
}

impl GdtfType {
    /// Reads a `.gdtf` file (a zip with `description.xml`).
    pub fn parse(file: &str, bytes: &[u8]) -> Result<GdtfType, RigError> {
        let mut archive = crate::open_zip(file, bytes)?;
        let xml = crate::zip_entry(file, &mut archive, "description.xml")?;
        GdtfType::parse_description(file, &xml)
    }

    /// Reads `description.xml` itself.
    pub fn parse_description(file: &str, bytes: &[u8]) -> Result<GdtfType, RigError> {
        let text = crate::utf8(file, bytes)?;
        let doc = crate::xml(file, text)?;
        let err = |m: String| RigError::new(file, None, m);
        let ft = doc
            .descendants()
            .find(|n| n.has_tag_name("FixtureType"))
            .ok_or_else(|| err("description.xml has no <FixtureType>".into()))?;
        let attr = |n: roxmltree::Node, a: &str| n.attribute(a).unwrap_or("").trim().to_string();
        let emitters = ft
            .descendants()
            .filter(|n| {
                n.has_tag_name("Emitter") && n.parent().is_some_and(|p| p.has_tag_name("Emitters"))
            })
            .map(|e| GdtfEmitter {
                name: attr(e, "Name"),
                color: e.attribute("Color").and_then(parse_xyy),
            })
            .collect();
        let mut modes = Vec::new();
        for m in ft.descendants().filter(|n| n.has_tag_name("DMXMode")) {
            // As written: MVR's GDTFMode names it exactly.
            let name = m.attribute("Name").unwrap_or("").to_string();
            let mut channels = Vec::new();
            for c in m.descendants().filter(|n| n.has_tag_name("DMXChannel")) {
                let bad = |what: String| RigError::new(file, Some(format!("mode `{name}`")), what);
                let offsets = match c.attribute("Offset").map(str::trim) {
                    None | Some("") | Some("None") => continue,
                    Some(o) => o
                        .split(',')
                        .map(|v| {
                            v.trim()
                                .parse::<usize>()
                                .ok()
                                .filter(|v| (1..=512).contains(v))
                        })
                        .collect::<Option<Vec<_>>>()
                        .filter(|v| !v.is_empty() && v.len() <= 4)
                        .ok_or_else(|| {
                            bad(format!(
                                "DMXChannel Offset `{o}` is not 1 to 4 offsets in 1..=512"
                            ))
                        })?,
                };
                let dmx_break = match c.attribute("DMXBreak").map(str::trim) {
                    None | Some("Overwrite") => 1,
                    Some(b) => b
                        .parse::<u32>()
                        .map_err(|_| bad(format!("DMXBreak `{b}` is not a number")))?,
                };
                let logical: Vec<_> = c
                    .children()
                    .filter(|n| n.has_tag_name("LogicalChannel"))
                    .collect();
                let functions: Vec<_> = logical
                    .iter()
                    .flat_map(|l| l.children().filter(|n| n.has_tag_name("ChannelFunction")))
                    .collect();
                let attribute = logical
                    .first()
                    .map(|l| attr(*l, "Attribute"))
                    .unwrap_or_default();
                let bytes = offsets.len() as u32;
                // InitialFunction is a node link `Channel.Logical.Function`.
                let initial = c
                    .attribute("InitialFunction")
                    .and_then(|link| link.splitn(3, '.').nth(2))
                    .and_then(|f| functions.iter().find(|n| n.attribute("Name") == Some(f)))
                    .or(functions.first());
                let default = initial
                    .and_then(|f| f.attribute("Default"))
                    .or(c.attribute("Default"))
                    .map(|v| {
                        dmx_value(v, bytes).ok_or_else(|| {
                            bad(format!(
                                "channel `{attribute}`: Default `{v}` is not a DMX value like 255/1"
                            ))
                        })
                    })
                    .transpose()?
                    .unwrap_or(0);
                let open = (attribute == "Shutter1")
                    .then(|| shutter_open(&functions, bytes))
                    .flatten();
                let emitter = initial
                    .and_then(|f| f.attribute("Emitter"))
                    .or_else(|| functions.iter().find_map(|f| f.attribute("Emitter")))
                    .map(str::to_string);
                let physical = if matches!(attribute.as_str(), "Pan" | "Tilt") {
                    functions
                        .iter()
                        .find(|f| f.attribute("Attribute") == Some(attribute.as_str()))
                        .map(|f| physical_range(*f))
                        .transpose()
                        .map_err(|e| bad(format!("channel `{attribute}`: {e}")))?
                        .flatten()
                } else {
                    None
                };
                channels.push(Channel {
                    dmx_break,
                    offsets,
                    attribute,
                    default,
                    open,
                    emitter,
                    physical,
                });
            }
            modes.push(Mode { name, channels });
        }
        if modes.is_empty() {
            return Err(err("the fixture type has no DMXMode".into()));
        }
        Ok(GdtfType {
            file: file.to_string(),
            manufacturer: attr(ft, "Manufacturer"),
            name: attr(ft, "Name"),
            long_name: attr(ft, "LongName"),
            modes,
            emitters,
        })
    }

    /// The mode called `mode` as a fixture type, or an error naming the modes there are.
    pub fn fixture_type(&self, mode: &str) -> Result<FixtureType, RigError> {
        let m = (self.modes.iter().find(|m| m.name == mode))
            .or_else(|| self.modes.iter().find(|m| m.name.trim() == mode.trim()))
            .ok_or_else(|| {
                RigError::new(
                    &self.file,
                    Some(format!("{} {}", self.manufacturer, self.name)),
                    format!(
                        "has no DMX mode `{mode}` (modes: {})",
                        self.modes
                            .iter()
                            .map(|m| format!("`{}`", m.name))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
        let name = format!("{} {} ({})", self.manufacturer, self.name, m.name)
            .trim()
            .to_string();
        Ok(FixtureType {
            footprint: Some(m.footprint()),
            profile: self.profile(&name, m),
            name,
        })
    }

    /// Every mode as a fixture type, in file order.
    pub fn fixture_types(&self) -> Vec<FixtureType> {
        self.modes
            .iter()
            .filter_map(|m| self.fixture_type(&m.name).ok())
            .collect()
    }

    /// `mode` as a profile called `name`, or why it cannot be one.
    fn profile(&self, name: &str, mode: &Mode) -> Result<Profile, String> {
        let mut breaks: Vec<u32> = mode.channels.iter().map(|c| c.dmx_break).collect();
        breaks.sort_unstable();
        breaks.dedup();
        if breaks.len() > 1 {
            return Err(format!(
                "it uses {} DMX breaks (one start address per light is modelled)",
                breaks.len()
            ));
        }
        let footprint = mode.footprint();
        if footprint == 0 {
            return Err("the mode has no DMX channels".into());
        }
        let dimmers = mode
            .channels
            .iter()
            .filter(|c| c.attribute == "Dimmer")
            .count();
        if dimmers > 1 {
            return Err(format!(
                "{dimmers} Dimmer channels (a multi-cell fixture: cells are not modelled)"
            ));
        }
        // Per slot: its name, or "" for the fine byte an intensity16 takes.
        let mut slots: Vec<Option<String>> = vec![None; footprint];
        let mut emitters: Vec<EmitterFile> = Vec::new();
        let mut additive: Vec<&str> = Vec::new();
        let (mut pan_range, mut tilt_range) = (None, None);
        for c in &mode.channels {
            let slot = attribute_slot(&c.attribute);
            let wide = slot
                .and_then(crate::wide_slot)
                .filter(|_| c.offsets.len() >= 2 && c.offsets[1] == c.offsets[0] + 1);
            let mut names: Vec<String> = match (slot, wide) {
                (_, Some(wide)) => vec![wide.into(), String::new()],
                (Some(slot), None) => vec![slot.to_string()],
                (None, None) => {
                    let value = c.open.unwrap_or(c.default);
                    let n = c.offsets.len();
                    (0..n)
                        .map(|i| format!("fixed:{}", (value >> (8 * (n - 1 - i))) & 0xff))
                        .collect()
                }
            };
            // The fine bytes of a 16-bit colour channel stay 0: its coarse byte carries
            // the level at 8 bits (so do a pan's or tilt's whose fine byte is not next).
            names.resize(c.offsets.len(), "fixed:0".into());
            for (&o, n) in c.offsets.iter().zip(names) {
                if slots[o - 1].is_some() {
                    return Err(format!("two channels use offset {o}"));
                }
                slots[o - 1] = Some(n);
            }
            if let Some((from, to)) = c.physical {
                let travel = crate::travel(from, to).map_err(|e| {
                    format!(
                        "channel `{}`: PhysicalFrom {from} to PhysicalTo {to}: {e}",
                        c.attribute
                    )
                })?;
                match c.attribute.as_str() {
                    "Pan" => pan_range = Some(travel),
                    _ => tilt_range = Some(travel),
                }
            }
            if let Some(slot) = slot.filter(|s| is_emitter(s)) {
                additive.push(slot.trim_start_matches("emitter:"));
                let gdtf = c
                    .emitter
                    .as_deref()
                    .and_then(|e| self.emitters.iter().find(|x| x.name == e))
                    .or_else(|| {
                        let want = slot.trim_start_matches("emitter:").replace('-', " ");
                        self.emitters
                            .iter()
                            .find(|x| x.name.trim().eq_ignore_ascii_case(&want))
                    });
                if let Some([x, y, big_y]) = gdtf.and_then(|e| e.color) {
                    emitters.retain(|e| e.name != slot.trim_start_matches("emitter:"));
                    emitters.push(EmitterFile {
                        name: slot.trim_start_matches("emitter:").to_string(),
                        xy: Some([x, y]),
                        flux: Some(big_y),
                    });
                }
            }
        }
        scale_defaults(&additive, &mut emitters);
        let channels: Vec<String> = slots
            .into_iter()
            .filter(|s| s.as_deref() != Some(""))
            .map(|s| s.unwrap_or_else(|| "fixed:0".into()))
            .collect();
        let profile = Profile::from_file(&ProfileFile {
            name: name.to_string(),
            channels,
            emitters,
            pan_range,
            tilt_range,
        })
        .map_err(|e| e.replace(&format!("profile `{name}`: "), ""))?;
        if !profile.has_intensity() && !profile.has_colour() {
            return Err(
                "no Dimmer and no colour channel, so visobjd cannot make it give light".into(),
            );
        }
        Ok(profile)
    }
}

/// The slot an attribute maps to, for the attributes visobjd drives (GDTF Annex A):
/// `Dimmer`, `Pan` and `Tilt`, the additive emitters `ColorAdd_*`, calibrated RGB
/// `ColorRGB_*`, and the subtractive flags `ColorSub_*`. Anything else is held at a fixed
/// value.
fn attribute_slot(attribute: &str) -> Option<&'static str> {
    Some(match attribute {
        "Dimmer" => "intensity",
        "Pan" => "pan",
        "Tilt" => "tilt",
        "ColorAdd_R" | "ColorRGB_Red" => "red",
        "ColorAdd_G" | "ColorRGB_Green" => "green",
        "ColorAdd_B" | "ColorRGB_Blue" => "blue",
        "ColorAdd_W" => "white",
        "ColorAdd_RY" => "amber",
        "ColorAdd_GY" => "lime",
        "ColorAdd_UV" => "uv",
        "ColorAdd_C" => "emitter:cyan",
        "ColorAdd_M" => "emitter:magenta",
        "ColorAdd_Y" => "emitter:yellow",
        "ColorAdd_WW" => "emitter:warm-white",
        "ColorAdd_CW" => "emitter:cold-white",
        "ColorAdd_GC" => "emitter:green-cyan",
        "ColorAdd_BC" => "emitter:light-blue",
        "ColorAdd_BM" => "emitter:purple",
        "ColorAdd_RM" => "emitter:pink",
        "ColorSub_C" => "cyan",
        "ColorSub_M" => "magenta",
        "ColorSub_Y" => "yellow",
        _ => return None,
    })
}

/// A `Pan` or `Tilt` function's `PhysicalFrom` and `PhysicalTo` in degrees, `None` when
/// it gives neither (then the spec's 0 to 1 would be a travel of one degree, so the
/// profile keeps visobjd's default); an error names a value that is not a number.
fn physical_range(function: roxmltree::Node) -> Result<Option<(f64, f64)>, String> {
    let value = |key: &str, default: f64| match function.attribute(key).map(str::trim) {
        None => Ok(default),
        Some(v) => v
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{key} `{v}` is not a number of degrees")),
    };
    if function.attribute("PhysicalFrom").is_none() && function.attribute("PhysicalTo").is_none() {
        return Ok(None);
    }
    Ok(Some((
        value("PhysicalFrom", 0.0)?,
        value("PhysicalTo", 1.0)?,
    )))
}

/// Puts the default emitters of a mode on the scale of the GDTF's Y values where the
/// GDTF describes some of its emitters and not others: the defaults' flux is multiplied by
/// (sum of the described emitters' Y) / (sum of their default fluxes), so every flux stays
/// relative to the same whole.
fn scale_defaults(additive: &[&str], given: &mut Vec<EmitterFile>) {
    let default = |name: &str| {
        DEFAULT_EMITTERS
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|(_, _, f)| *f)
    };
    let (mut sum_given, mut sum_default) = (0.0, 0.0);
    for e in given.iter() {
        if let (Some(f), Some(d)) = (e.flux, default(&e.name)) {
            sum_given += f;
            sum_default += d;
        }
    }
    if sum_default <= 0.0 {
        return;
    }
    let k = sum_given / sum_default;
    for name in additive {
        if !given.iter().any(|e| e.name == *name)
            && let Some(d) = default(name)
        {
            given.push(EmitterFile {
                name: (*name).to_string(),
                xy: None,
                flux: Some(d * k),
            });
        }
    }
}

/// Whether a slot name is an additive emitter (and so may take a GDTF emitter's colour).
fn is_emitter(slot: &str) -> bool {
    matches!(slot, "red" | "green" | "blue" | "white" | "amber" | "lime")
        || slot.starts_with("emitter:")
}

/// The open value of a `Shutter1` channel: the first `ChannelSet` (of a `Shutter1`
/// function) whose name says open and not close, else such a function's `DMXFrom`.
fn shutter_open(functions: &[roxmltree::Node], bytes: u32) -> Option<u64> {
    let says_open = |n: Option<&str>| {
        let n = n.unwrap_or("").to_ascii_lowercase();
        n.contains("open") && !n.contains("close")
    };
    let shutter: Vec<_> = functions
        .iter()
        .filter(|f| f.attribute("Attribute") == Some("Shutter1"))
        .collect();
    shutter
        .iter()
        .flat_map(|f| f.children().filter(|n| n.has_tag_name("ChannelSet")))
        .find(|s| says_open(s.attribute("Name")))
        .and_then(|s| s.attribute("DMXFrom"))
        .or_else(|| {
            shutter
                .iter()
                .find(|f| says_open(f.attribute("Name")))
                .map(|f| f.attribute("DMXFrom").unwrap_or("0/1"))
        })
        .and_then(|v| dmx_value(v, bytes))
}

/// A GDTF DMXValue (`255/1`, `32768/2`, `255/1s`) at a resolution of `bytes` bytes.
pub fn dmx_value(text: &str, bytes: u32) -> Option<u64> {
    let (v, n) = text.trim().split_once('/')?;
    let (n, shift) = match n.strip_suffix('s') {
        Some(n) => (n, true),
        None => (n, false),
    };
    let v: u64 = v.trim().parse().ok()?;
    let n: u32 = n.trim().parse().ok().filter(|n| (1..=4).contains(n))?;
    let bytes = bytes.clamp(1, 4);
    let max = |b: u32| (1u64 << (8 * b)) - 1;
    if v > max(n) {
        return None;
    }
    Some(if n == bytes {
        v
    } else if shift {
        if bytes > n {
            v << (8 * (bytes - n))
        } else {
            v >> (8 * (n - bytes))
        }
    } else {
        (v * max(bytes) + max(n) / 2) / max(n)
    })
}

/// `x,y,Y` (a ColorCIE) as numbers.
fn parse_xyy(text: &str) -> Option<[f64; 3]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>().ok())
        .collect::<Option<_>>()?;
    match v[..] {
        [x, y, big_y] if x.is_finite() && y.is_finite() && big_y.is_finite() => Some([x, y, big_y]),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undescribed_emitters_take_the_scale_of_the_described_ones() {
        // Red and green described at 10x their default flux: blue follows at 10x (the
        // defaults are the sRGB matrix's luminances, 0.2126729, 0.7151522, 0.072175).
        let mut given = vec![
            EmitterFile {
                name: "red".into(),
                xy: Some([0.7, 0.3]),
                flux: Some(2.126_729),
            },
            EmitterFile {
                name: "green".into(),
                xy: Some([0.2, 0.7]),
                flux: Some(7.151_522),
            },
        ];
        scale_defaults(&["red", "green", "blue", "teal"], &mut given);
        assert_eq!(given.len(), 3, "teal has no default to scale");
        assert_eq!(given[2].name, "blue");
        assert!((given[2].flux.expect("flux") - 0.721_75).abs() < 1e-9);
        assert_eq!(given[2].xy, None);
        // Nothing described: the defaults stay as they are.
        let mut none = Vec::new();
        scale_defaults(&["red"], &mut none);
        assert!(none.is_empty());
    }

    /// A GDTF description of one mode with these `DMXChannel`s.
    fn mover(channels: &str) -> String {
        format!(
            r#"<GDTF DataVersion="1.2"><FixtureType Manufacturer="Test" Name="Mover">
            <DMXModes><DMXMode Name="Std"><DMXChannels>{channels}</DMXChannels></DMXMode>
            </DMXModes></FixtureType></GDTF>"#
        )
    }

    fn channel(offset: &str, attribute: &str, physical: &str) -> String {
        format!(
            r#"<DMXChannel Offset="{offset}"><LogicalChannel Attribute="{attribute}">
            <ChannelFunction Attribute="{attribute}" Default="0/1" {physical}/>
            </LogicalChannel></DMXChannel>"#
        )
    }

    fn profile(xml: &str) -> Result<Profile, String> {
        let ty = GdtfType::parse_description("m.gdtf", xml.as_bytes()).expect("parses");
        ty.fixture_type("Std").expect("mode").profile
    }

    #[test]
    fn pan_and_tilt_become_position_slots_with_their_travel() {
        let xml = mover(
            &[
                channel("1,2", "Pan", r#"PhysicalFrom="-270" PhysicalTo="270""#),
                channel("3", "Tilt", r#"PhysicalFrom="110" PhysicalTo="-110""#),
                channel("4", "Dimmer", ""),
            ]
            .concat(),
        );
        let p = profile(&xml).expect("a profile");
        assert_eq!(p.channel_names(), ["pan16", "tilt", "intensity"]);
        assert!(p.is_moving());
        assert_eq!((p.pan_range, p.tilt_range), (540.0, 220.0));
        // No PhysicalFrom/To: the default travel, not the spec's 0 to 1 (one degree). A
        // fine byte that is not next to its coarse one is held at 0, as for a dimmer.
        let xml = mover(
            &[
                channel("1,3", "Pan", ""),
                channel("2", "Tilt", ""),
                channel("4", "Dimmer", ""),
            ]
            .concat(),
        );
        let p = profile(&xml).expect("a profile");
        assert_eq!(p.channel_names(), ["pan", "tilt", "fixed:0", "intensity"]);
        assert_eq!(
            (p.pan_range, p.tilt_range),
            (
                visobjd_scene::profile::DEFAULT_PAN_RANGE,
                visobjd_scene::profile::DEFAULT_TILT_RANGE
            )
        );
    }

    #[test]
    fn a_bad_physical_range_is_named_not_guessed() {
        let xml = mover(
            &[
                channel("1", "Pan", r#"PhysicalFrom="90" PhysicalTo="90""#),
                channel("2", "Dimmer", ""),
            ]
            .concat(),
        );
        assert_eq!(
            profile(&xml).expect_err("no travel"),
            "channel `Pan`: PhysicalFrom 90 to PhysicalTo 90: a travel of 0 degrees, not above 0 and at most 3600"
        );
        let xml = mover(&channel(
            "1",
            "Tilt",
            r#"PhysicalFrom="-1e9" PhysicalTo="0""#,
        ));
        assert!(
            profile(&xml)
                .expect_err("too far")
                .contains("travel of 1000000000 degrees")
        );
        let xml = mover(&channel("1", "Tilt", r#"PhysicalFrom="up""#));
        let e = GdtfType::parse_description("m.gdtf", xml.as_bytes())
            .expect_err("not a number")
            .to_string();
        assert_eq!(
            e,
            "m.gdtf: mode `Std`: channel `Tilt`: PhysicalFrom `up` is not a number of degrees"
        );
    }

    #[test]
    fn dmx_values_convert_as_the_spec_says() {
        // "255/1 in a 16 bit channel will result in 65535 ... 255/1s ... 65280".
        assert_eq!(dmx_value("255/1", 2), Some(65535));
        assert_eq!(dmx_value("255/1s", 2), Some(65280));
        assert_eq!(dmx_value("32768/2", 2), Some(32768));
        assert_eq!(dmx_value("32768/2", 1), Some(128));
        assert_eq!(dmx_value("0/1", 1), Some(0));
        assert_eq!(dmx_value("300/1", 1), None);
        assert_eq!(dmx_value("x/1", 1), None);
    }
}
