//! Open Fixture Library fixtures: one JSON file per fixture type
//! (OpenLightingProject/open-fixture-library `schemas/fixture.json`). Read: `name`,
//! `availableChannels` (each with one `capability` or a list of `capabilities`, an
//! optional `defaultValue` and `fineChannelAliases`), and `modes[]` with `name`,
//! `shortName` and `channels` (channel keys in DMX order; `null` is an unused slot; an
//! object is a pixel-matrix insert, not modelled). A channel whose only capability is
//! `Intensity` is the dimmer (16-bit when its fine alias follows it); `ColorIntensity`
//! with a `color` is an emitter; a `ShutterStrobe` capability with `shutterEffect: Open`
//! gives the value a shutter is held at; a channel whose only capability is `Pan` or
//! `Tilt` aims the light (16-bit when its fine alias follows it), its travel
//! `angleEnd - angleStart` in degrees (`capability.json`: a `rotationAngle`, `"540deg"`;
//! a percentage says no angle, so the profile keeps visobjd's default); anything else is
//! held at its `defaultValue`. OFL gives no chromaticities: emitters take visobjd's
//! defaults.

use visobjd_scene::profile::{Profile, ProfileFile};

use crate::{FixtureType, RigError};

/// One mode.
#[derive(Debug, Clone, PartialEq)]
pub struct OflMode {
    /// `name`.
    pub name: String,
    /// `shortName`, if given.
    pub short_name: Option<String>,
    /// Channel keys in DMX order; `None` for `null`; `Some("")` for a matrix insert.
    pub channels: Vec<Option<String>>,
}

/// A parsed OFL fixture.
#[derive(Debug, Clone, PartialEq)]
pub struct OflType {
    /// The file it came from (for errors).
    pub file: String,
    /// `name`.
    pub name: String,
    /// `availableChannels`, as given.
    channels: serde_json::Map<String, serde_json::Value>,
    /// `modes`.
    pub modes: Vec<OflMode>,
}

impl OflType {
    /// Reads an OFL fixture JSON file.
    pub fn parse(file: &str, bytes: &[u8]) -> Result<OflType, RigError> {
        let err = |m: String| RigError::new(file, None, m);
        let v: serde_json::Value =
            serde_json::from_slice(bytes).map_err(|e| err(format!("not JSON: {e}")))?;
        let name = v
            .get("name")
            .and_then(|n| n.as_str())
            .ok_or_else(|| err("no `name`: not an Open Fixture Library fixture".into()))?
            .trim()
            .to_string();
        let channels = v
            .get("availableChannels")
            .and_then(|c| c.as_object())
            .cloned()
            .unwrap_or_default();
        let modes = v
            .get("modes")
            .and_then(|m| m.as_array())
            .ok_or_else(|| err(format!("{name}: no `modes`")))?
            .iter()
            .map(|m| {
                let name = m.get("name").and_then(|n| n.as_str())?.to_string();
                let short_name = m
                    .get("shortName")
                    .and_then(|n| n.as_str())
                    .map(str::to_string);
                let channels = m
                    .get("channels")?
                    .as_array()?
                    .iter()
                    .map(|c| match c {
                        serde_json::Value::Null => None,
                        serde_json::Value::String(s) => Some(s.clone()),
                        _ => Some(String::new()),
                    })
                    .collect();
                Some(OflMode {
                    name,
                    short_name,
                    channels,
                })
            })
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| {
                err(format!(
                    "{name}: a mode without a `name` or `channels` list"
                ))
            })?;
        if modes.is_empty() {
            return Err(err(format!("{name}: no modes")));
        }
        Ok(OflType {
            file: file.to_string(),
            name,
            channels,
            modes,
        })
    }

    /// The mode called `mode` (its `name` or `shortName`) as a fixture type.
    pub fn fixture_type(&self, mode: &str) -> Result<FixtureType, RigError> {
        let m = self
            .modes
            .iter()
            .find(|m| m.name == mode || m.short_name.as_deref() == Some(mode))
            .ok_or_else(|| {
                RigError::new(
                    &self.file,
                    Some(self.name.clone()),
                    format!(
                        "has no mode `{mode}` (modes: {})",
                        self.modes
                            .iter()
                            .map(|m| format!("`{}`", m.name))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
        let name = format!("{} ({})", self.name, m.name);
        Ok(FixtureType {
            footprint: Some(m.channels.len()),
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

    /// The coarse channel `key` is a fine alias of, with the byte (1 = the first fine).
    fn fine_of(&self, key: &str) -> Option<(&str, usize)> {
        self.channels.iter().find_map(|(coarse, def)| {
            let aliases = def.get("fineChannelAliases")?.as_array()?;
            let i = aliases.iter().position(|a| a.as_str() == Some(key))?;
            Some((coarse.as_str(), i + 1))
        })
    }

    fn profile(&self, name: &str, mode: &OflMode) -> Result<Profile, String> {
        let mut channels: Vec<String> = Vec::with_capacity(mode.channels.len());
        let mut dimmers = 0;
        let mut skip_next = false;
        let (mut pan_range, mut tilt_range) = (None, None);
        for (i, key) in mode.channels.iter().enumerate() {
            if std::mem::take(&mut skip_next) {
                continue;
            }
            let Some(key) = key else {
                channels.push("fixed:0".into());
                continue;
            };
            if key.is_empty() {
                return Err("a pixel matrix mode (cells are not modelled)".into());
            }
            if let Some(def) = self.channels.get(key) {
                let slot = slot(def);
                match slot {
                    Some("intensity") => dimmers += 1,
                    Some("pan") => {
                        pan_range = travel(def).map_err(|e| format!("channel `{key}`: {e}"))?
                    }
                    Some("tilt") => {
                        tilt_range = travel(def).map_err(|e| format!("channel `{key}`: {e}"))?
                    }
                    _ => {}
                }
                if let Some(wide) = slot.and_then(crate::wide_slot) {
                    let fine = def
                        .get("fineChannelAliases")
                        .and_then(|a| a.get(0))
                        .and_then(|a| a.as_str());
                    if fine.is_some() && mode.channels.get(i + 1).and_then(|c| c.as_deref()) == fine
                    {
                        channels.push(wide.into());
                        skip_next = true;
                        continue;
                    }
                }
                channels.push(
                    slot.map_or_else(|| format!("fixed:{}", held_value(def)), str::to_string),
                );
            } else if self.fine_of(key).is_some() {
                // A fine byte whose coarse byte is 8-bit here (or is not a dimmer).
                channels.push("fixed:0".into());
            } else {
                return Err(format!("channel `{key}` is not in availableChannels"));
            }
        }
        if dimmers > 1 {
            return Err(format!(
                "{dimmers} Intensity channels (a multi-cell fixture: cells are not modelled)"
            ));
        }
        let profile = Profile::from_file(&ProfileFile {
            name: name.to_string(),
            channels,
            emitters: Vec::new(),
            pan_range,
            tilt_range,
        })
        .map_err(|e| e.replace(&format!("profile `{name}`: "), ""))?;
        if !profile.has_intensity() && !profile.has_colour() {
            return Err(
                "no Intensity and no ColorIntensity channel, so visobjd cannot make it give light"
                    .into(),
            );
        }
        Ok(profile)
    }
}

/// The slot of a channel with a single `Intensity`, `ColorIntensity`, `Pan` or `Tilt`
/// capability.
fn slot(def: &serde_json::Value) -> Option<&'static str> {
    let cap = def.get("capability")?;
    match cap.get("type")?.as_str()? {
        "Intensity" => Some("intensity"),
        "Pan" => Some("pan"),
        "Tilt" => Some("tilt"),
        "ColorIntensity" => Some(match cap.get("color")?.as_str()? {
            "Red" => "red",
            "Green" => "green",
            "Blue" => "blue",
            "White" => "white",
            "Amber" => "amber",
            "Lime" => "lime",
            "UV" => "uv",
            "Cyan" => "emitter:cyan",
            "Magenta" => "emitter:magenta",
            "Yellow" => "emitter:yellow",
            "Indigo" => "emitter:indigo",
            "Warm White" => "emitter:warm-white",
            "Cold White" => "emitter:cold-white",
            _ => return None,
        }),
        _ => None,
    }
}

/// A `Pan` or `Tilt` channel's travel in degrees from its capability's `angleStart` and
/// `angleEnd`; `None` (the profile's default) when they are percentages or absent, an
/// error when they are degrees that are not a travel.
fn travel(def: &serde_json::Value) -> Result<Option<f64>, String> {
    let cap = def.get("capability");
    let angle = |key: &str| -> Result<Option<f64>, String> {
        let Some(v) = cap.and_then(|c| c.get(key)) else {
            return Ok(None);
        };
        let text = v.as_str().unwrap_or("").trim();
        if text.ends_with('%') {
            return Ok(None);
        }
        text.strip_suffix("deg")
            .and_then(|d| d.trim().parse::<f64>().ok())
            .filter(|d| d.is_finite())
            .map(Some)
            .ok_or_else(|| format!("{key} {v} is not an angle like \"540deg\""))
    };
    match (angle("angleStart")?, angle("angleEnd")?) {
        (Some(from), Some(to)) => crate::travel(from, to)
            .map(Some)
            .map_err(|e| format!("angleStart {from}deg to angleEnd {to}deg: {e}")),
        _ => Ok(None),
    }
}

/// The value a channel visobjd does not drive is held at: a shutter's open value, else
/// its `defaultValue` (a number, or a percentage of 255), else 0.
fn held_value(def: &serde_json::Value) -> u8 {
    let caps: Vec<&serde_json::Value> = match (def.get("capability"), def.get("capabilities")) {
        (Some(c), _) => vec![c],
        (None, Some(serde_json::Value::Array(list))) => list.iter().collect(),
        _ => Vec::new(),
    };
    let open = caps.iter().find(|c| {
        c.get("type").and_then(|t| t.as_str()) == Some("ShutterStrobe")
            && c.get("shutterEffect").and_then(|t| t.as_str()) == Some("Open")
    });
    if let Some(open) = open {
        return open
            .get("dmxRange")
            .and_then(|r| r.get(0))
            .and_then(|v| v.as_u64())
            .map_or(0, |v| v.min(255) as u8);
    }
    match def.get("defaultValue") {
        Some(serde_json::Value::Number(n)) => n.as_u64().map_or(0, |v| v.min(255) as u8),
        Some(serde_json::Value::String(s)) => s
            .trim()
            .strip_suffix('%')
            .and_then(|p| p.trim().parse::<f64>().ok())
            .map_or(0, |p| (p.clamp(0.0, 100.0) / 100.0 * 255.0).round() as u8),
        _ => 0,
    }
}
