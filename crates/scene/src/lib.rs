//! A scene folder's description (`scene.toml`): lights, groups, DMX patch and profiles.
//!
//! Parsing and validation live here so that `check`, the offline commands and the daemon
//! all refuse the same broken scenes with the same messages. Basis images are loaded
//! separately (by the compositor crate's `basis`) because the daemon restores the stage before it reads them.

pub mod emitter;
pub mod look;
pub mod profile;
pub mod srgb;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::emitter::ColourModel;
use crate::profile::{Profile, ProfileFile};

/// Why a scene did not load; each message names the file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: cannot read it: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// TOML syntax or schema problem (the message carries line and key).
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What is wrong, with line and column.
        message: String,
    },
    /// A semantic problem in scene.toml (duplicate channel, patch overlap, ...).
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A basis image is missing, unreadable or of the wrong size.
    #[error("{path}: {message}")]
    Basis {
        /// The basis image.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// scene.toml as written: what `Scene::parse` validates and what an importer writes, so
/// a re-import can keep every key a person or a capture set.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// The scene's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Preview exposure in stops.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub exposure: f32,
    /// `[[group]]` tables.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub group: Vec<GroupFile>,
    /// `[[light]]` tables.
    #[serde(default)]
    pub light: Vec<LightFile>,
    /// `[[profile]]` tables.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub profile: Vec<ProfileFile>,
}

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

/// A `[[group]]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupFile {
    /// The group's name.
    pub name: String,
}

/// A `[[light]]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightFile {
    /// Console channel.
    pub channel: u32,
    /// Display name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// A declared group.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// Basis image path, relative to the scene folder; a moving light gives one per
    /// position in `[[light.position]]` instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub basis: Option<String>,
    /// Built-in or `[[profile]]` name.
    pub profile: String,
    /// sACN universe.
    pub universe: u16,
    /// DMX start address.
    pub address: u16,
    /// Per-emitter basis images (`visobjd capture --emitters`), by emitter name: the stage
    /// lit by that emitter alone at full, so the preview mixes what the camera saw.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub emitter_basis: BTreeMap<String, String>,
    /// Each emitter's colour as the camera saw it in its `emitter_basis` image (capture
    /// measures it), by emitter name: the colour solve aims with these instead of the
    /// profile's, so the light reaches the colour asked of it.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub emitter_measured: BTreeMap<String, MeasuredEmitter>,
    /// The light's fixture ID on a grandMA3, when it is not its channel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ma3_id: Option<u32>,
    /// A moving light's positions (`[[light.position]]`), each a focus palette with its
    /// pan, tilt and basis image.
    #[serde(default, rename = "position", skip_serializing_if = "Vec::is_empty")]
    pub positions: Vec<PositionFile>,
}

/// A `[[light.position]]` table: one focus palette of a moving light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionFile {
    /// The focus palette's number, shared by the lights that have it (Eos `FP n`,
    /// grandMA3 `Preset 2.n`).
    pub palette: u32,
    /// Its label, the same on every light that names it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Degrees from the centre of the profile's pan range.
    pub pan: f64,
    /// Degrees from the centre of the profile's tilt range.
    pub tilt: f64,
    /// The stage lit by this light alone, at full, in this position.
    pub basis: String,
}

/// Most positions one light may hold: bounds what a hostile scene makes the daemon load.
pub const MAX_POSITIONS: usize = 100;
/// Highest focus palette number (Eos and grandMA3 both number from 1).
pub const MAX_PALETTE: u32 = 9999;

/// One emitter's colour measured from its image: CIE 1931 xy and its output relative to
/// the light's other emitters (the Y of CIE xyY).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeasuredEmitter {
    /// CIE 1931 x, y.
    pub xy: [f64; 2],
    /// Output at full relative to the light's other emitters.
    pub flux: f64,
}

impl MeasuredEmitter {
    /// Why it is not a measurement of a real emitter (`None` when it is): an xy of a real
    /// colour (0 < x, 0 < y, x + y < 1) and a finite positive flux. Capture records only
    /// measurements that pass, and loading refuses the others.
    pub fn fault(&self) -> Option<String> {
        let [x, y] = self.xy;
        let xy_ok = x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0 && x + y < 1.0;
        if !xy_ok {
            return Some(format!(
                "xy [{x}, {y}] is not a colour (need 0 < x, 0 < y, x + y < 1)"
            ));
        }
        (!(self.flux.is_finite() && self.flux > 0.0))
            .then(|| format!("flux {} must be a positive number", self.flux))
    }

    /// CIE XYZ at full.
    pub fn xyz(&self) -> [f64; 3] {
        crate::emitter::colour::xyy_to_xyz(self.xy[0], self.xy[1], self.flux)
    }
}

impl SceneFile {
    /// Parses scene.toml text without validating it (`path` names the file in errors).
    pub fn parse(path: &Path, text: &str) -> Result<SceneFile, SceneError> {
        toml::from_str(text).map_err(|e| SceneError::Parse {
            path: path.to_path_buf(),
            message: describe_toml_error(text, &e),
        })
    }

    /// Names focus palette `palette` `name` on every light that has it (a palette has one
    /// name across the lights), keeping pan, tilt and basis; returns the channels renamed.
    pub fn name_palette(&mut self, palette: u32, name: &str) -> Vec<u32> {
        let mut named = Vec::new();
        for l in &mut self.light {
            let mut any = false;
            for p in l.positions.iter_mut().filter(|p| p.palette == palette) {
                p.name = Some(name.to_string());
                any = true;
            }
            if any {
                named.push(l.channel);
            }
        }
        named
    }

    /// The TOML text of this file.
    pub fn to_toml(&self) -> Result<String, String> {
        toml::to_string(self).map_err(|e| e.to_string())
    }
}

/// One light of the rig.
#[derive(Debug, Clone)]
pub struct Light {
    /// Console channel number, unique; what OSC addresses use.
    pub channel: u32,
    /// Display name (defaults to "Ch N").
    pub name: String,
    /// Index into [`Scene::groups`]; every light belongs to exactly one group.
    pub group: usize,
    /// The basis image, resolved against the scene folder.
    pub basis: PathBuf,
    /// Index into [`Scene::profiles`].
    pub profile: usize,
    /// sACN universe 1..=63999.
    pub universe: u16,
    /// DMX start address 1..=512.
    pub address: u16,
    /// One basis image per additive emitter of its profile, in slot order (each emitter
    /// alone at full), resolved against the scene folder; empty for a light captured at
    /// white only, whose colours are previewed from its white image and colour model.
    pub emitter_basis: Vec<PathBuf>,
    /// Each emitter's CIE XYZ at full as measured from its image (`emitter_measured`), in
    /// slot order; empty: the profile's emitters.
    pub emitter_measured: Vec<[f64; 3]>,
    /// Its fixture ID on a grandMA3 (`ma3_id`, by default the channel), unique.
    pub ma3_id: u32,
    /// A moving light's positions in scene.toml order (empty for a fixed light); its
    /// `basis` is the first one's image, the position it takes in a look that names none.
    pub positions: Vec<Position>,
}

impl Light {
    /// Whether the light has positions to choose from.
    pub fn is_moving(&self) -> bool {
        !self.positions.is_empty()
    }

    /// The index in [`Light::positions`] of focus palette `palette`.
    pub fn position_index(&self, palette: u32) -> Option<usize> {
        self.positions.iter().position(|p| p.palette == palette)
    }

    /// The position `level` puts this light in: its palette if the light has it, else
    /// its first (`None` for a fixed light).
    pub fn position_of(&self, level: &look::Level) -> Option<&Position> {
        level.position_in(&self.positions, |p| p.palette)
    }

    /// Its palette numbers, in its order, for "it has 1, 3, 5" messages.
    pub fn palette_list(&self) -> String {
        let n: Vec<String> = self
            .positions
            .iter()
            .map(|p| p.palette.to_string())
            .collect();
        n.join(", ")
    }
}

/// One position of a moving light.
#[derive(Debug, Clone, PartialEq)]
pub struct Position {
    /// The focus palette's number.
    pub palette: u32,
    /// Degrees from the centre of the pan range.
    pub pan: f64,
    /// Degrees from the centre of the tilt range.
    pub tilt: f64,
    /// The basis image, resolved against the scene folder.
    pub basis: PathBuf,
}

/// A focus palette: a number and a label shared by every light that has it.
#[derive(Debug, Clone, PartialEq)]
pub struct Palette {
    /// 1..=[`MAX_PALETTE`].
    pub number: u32,
    /// Its label, if any light names it.
    pub name: Option<String>,
    /// The lights that have it (indices into [`Scene::lights`]), ascending.
    pub lights: Vec<usize>,
}

impl Palette {
    /// `3 "DS centre"`, or `3` without a label.
    pub fn describe(&self) -> String {
        match &self.name {
            Some(n) => format!("{} \"{n}\"", self.number),
            None => self.number.to_string(),
        }
    }
}

/// A light group ("system"): sampling assigns one value per group by default.
#[derive(Debug, Clone)]
pub struct Group {
    /// Name as the CLI and OSC arguments use it (addresses use [`Group::address`]).
    pub name: String,
    /// Indices into [`Scene::lights`], ascending.
    pub lights: Vec<usize>,
}

impl Group {
    /// The name as an OSC address segment: OSC 1.0 forbids spaces and `#*,/?[]{}` in an
    /// address (and `/` splits it), so each is written `_`: group `front warm` is
    /// `/vo/group/front_warm/level`. Matching is case-insensitive, as for names.
    pub fn address(&self) -> String {
        address_segment(&self.name)
    }
}

/// `name` with OSC 1.0's forbidden address characters written `_` (see [`Group::address`]),
/// for whoever writes addresses from names alone (the TouchOSC layout).
pub fn address_segment(name: &str) -> String {
    name.chars()
        .map(|c| match c {
            ' ' | '#' | '*' | ',' | '/' | '?' | '[' | ']' | '{' | '}' => '_',
            c if c.is_ascii_control() => '_',
            c => c,
        })
        .collect()
}

/// A validated scene description.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene folder.
    pub dir: PathBuf,
    /// Human-readable name.
    pub name: String,
    /// Exposure of the preview in stops (optional `exposure` key, default 0).
    pub exposure: f32,
    /// Lights in ascending channel order; looks index them the same way.
    pub lights: Vec<Light>,
    /// Groups: declared groups first, then one implicit group per ungrouped light.
    pub groups: Vec<Group>,
    /// Profiles in use (built-in and custom).
    pub profiles: Vec<Profile>,
    /// The focus palettes the moving lights hold, by number.
    pub palettes: Vec<Palette>,
    /// Each group's index by its address form, lower case ([`Scene::group_index`]), as
    /// parsed.
    by_address: HashMap<String, usize>,
}

impl Scene {
    /// Reads and validates `DIR/scene.toml` (images are not read).
    pub fn load(dir: &Path) -> Result<Scene, SceneError> {
        let path = dir.join("scene.toml");
        let text = std::fs::read_to_string(&path).map_err(|error| SceneError::Io {
            path: path.clone(),
            error,
        })?;
        Scene::parse(dir, &text)
    }

    /// Validates scene.toml text; `dir` resolves basis paths and names the file in errors.
    pub fn parse(dir: &Path, text: &str) -> Result<Scene, SceneError> {
        let path = dir.join("scene.toml");
        let invalid = |message: String| SceneError::Invalid {
            path: path.clone(),
            message,
        };
        let file = SceneFile::parse(&path, text)?;
        if file.light.is_empty() {
            return Err(invalid("the scene has no [[light]]".into()));
        }
        if !file.exposure.is_finite() || file.exposure.abs() > 20.0 {
            return Err(invalid(format!(
                "exposure {} is out of range (-20..=20 stops)",
                file.exposure
            )));
        }

        let mut profiles: Vec<Profile> = Vec::new();
        let mut custom: HashMap<String, Profile> = HashMap::new();
        for p in &file.profile {
            if Profile::built_in(&p.name).is_some() || custom.contains_key(&p.name) {
                return Err(invalid(format!("profile `{}` is defined twice", p.name)));
            }
            let profile = Profile::from_file(p).map_err(invalid)?;
            if profile.footprint() > 512 {
                return Err(invalid(format!(
                    "profile `{}` is wider than a universe",
                    p.name
                )));
            }
            custom.insert(p.name.clone(), profile);
        }

        let mut groups: Vec<Group> = Vec::new();
        let mut group_index: HashMap<String, usize> = HashMap::new();
        for g in &file.group {
            if g.name.trim().is_empty() {
                return Err(invalid("a [[group]] has an empty name".into()));
            }
            if group_index.insert(g.name.clone(), groups.len()).is_some() {
                return Err(invalid(format!("group `{}` is declared twice", g.name)));
            }
            groups.push(Group {
                name: g.name.clone(),
                lights: Vec::new(),
            });
        }

        let mut raw = file.light;
        raw.sort_by_key(|l| l.channel);
        let mut lights = Vec::with_capacity(raw.len());
        // Each lookup per light is a hash map's, so parsing stays linear in the lights
        // (16,000 lights, each its own group, took seconds when these were scans).
        let mut profile_index: HashMap<&str, usize> = HashMap::new();
        let mut slots: BTreeMap<(u16, u16), u32> = BTreeMap::new();
        let mut palettes: BTreeMap<u32, (Palette, u32)> = BTreeMap::new();
        for (i, l) in raw.iter().enumerate() {
            if l.channel == 0 {
                return Err(invalid("light channel 0: channels start at 1".into()));
            }
            if i > 0 && raw[i - 1].channel == l.channel {
                return Err(invalid(format!(
                    "channel {} is used by two lights",
                    l.channel
                )));
            }
            let profile = match profile_index.get(l.profile.as_str()) {
                Some(&p) => p,
                None => {
                    let p = custom
                        .get(&l.profile)
                        .cloned()
                        .or_else(|| Profile::built_in(&l.profile))
                        .ok_or_else(|| {
                            invalid(format!(
                                "light {}: unknown profile `{}` (built in: {}; or define it in a [[profile]])",
                                l.channel,
                                l.profile,
                                Profile::built_in_names().collect::<Vec<_>>().join(", ")
                            ))
                        })?;
                    profiles.push(p);
                    profile_index.insert(&l.profile, profiles.len() - 1);
                    profiles.len() - 1
                }
            };
            if !(1..=63999).contains(&l.universe) {
                return Err(invalid(format!(
                    "light {}: universe {} is out of range (1-63999)",
                    l.channel, l.universe
                )));
            }
            let width = profiles[profile].footprint() as u32;
            let last = u32::from(l.address) + width - 1;
            if l.address == 0 || last > 512 {
                return Err(invalid(format!(
                    "light {}: address {} with a {}-slot `{}` footprint does not fit in slots 1-512",
                    l.channel, l.address, width, l.profile
                )));
            }
            for slot in u32::from(l.address)..=last {
                if let Some(other) = slots.insert((l.universe, slot as u16), l.channel) {
                    return Err(invalid(format!(
                        "lights {} and {} both use universe {} slot {}",
                        other, l.channel, l.universe, slot
                    )));
                }
            }
            let group = match &l.group {
                Some(name) => *group_index.get(name).ok_or_else(|| {
                    invalid(format!(
                        "light {}: group `{}` is not declared with [[group]]",
                        l.channel, name
                    ))
                })?,
                None => {
                    let name = format!("ch{}", l.channel);
                    if group_index.contains_key(&name) {
                        return Err(invalid(format!(
                            "light {} has no group and its implicit group name `{name}` is taken",
                            l.channel
                        )));
                    }
                    group_index.insert(name.clone(), groups.len());
                    groups.push(Group {
                        name,
                        lights: Vec::new(),
                    });
                    groups.len() - 1
                }
            };
            let basis_path = |b: &str| {
                safe_relative(b).map(|p| dir.join(p)).ok_or_else(|| {
                    invalid(format!(
                        "light {}: basis `{b}` must be a relative path inside the scene folder",
                        l.channel
                    ))
                })
            };
            let positions = positions(l, &profiles[profile], &mut palettes)
                .map_err(invalid)?
                .iter()
                .map(|p| {
                    Ok(Position {
                        palette: p.palette,
                        pan: p.pan,
                        tilt: p.tilt,
                        basis: basis_path(&p.basis)?,
                    })
                })
                .collect::<Result<Vec<Position>, SceneError>>()?;
            let basis = match (&l.basis, positions.first()) {
                (Some(b), None) => basis_path(b)?,
                (None, Some(first)) => first.basis.clone(),
                (Some(_), Some(_)) => {
                    return Err(invalid(format!(
                        "light {}: a moving light gives one basis image per [[light.position]], \
                         not `basis`",
                        l.channel
                    )));
                }
                (None, None) => {
                    return Err(invalid(format!(
                        "light {}: no basis image: give `basis`, or [[light.position]] tables \
                         for a moving light",
                        l.channel
                    )));
                }
            };
            if !positions.is_empty() && !l.emitter_basis.is_empty() {
                return Err(invalid(format!(
                    "light {}: a moving light is previewed from one image per position; \
                     emitter_basis is for fixed lights",
                    l.channel
                )));
            }
            for p in &positions {
                if let Some((palette, _)) = palettes.get_mut(&p.palette) {
                    palette.lights.push(i);
                }
            }
            let emitter_basis = emitter_basis(l, &profiles[profile]).map_err(invalid)?;
            let emitter_measured = emitter_measured(l, &profiles[profile]).map_err(invalid)?;
            groups[group].lights.push(i);
            lights.push(Light {
                channel: l.channel,
                name: l
                    .name
                    .clone()
                    .unwrap_or_else(|| format!("Ch {}", l.channel)),
                group,
                basis,
                profile,
                universe: l.universe,
                address: l.address,
                emitter_basis: emitter_basis.into_iter().map(|p| dir.join(p)).collect(),
                emitter_measured,
                ma3_id: l.ma3_id.unwrap_or(l.channel),
                positions,
            });
        }
        let mut ma3_ids: HashMap<u32, u32> = HashMap::with_capacity(lights.len());
        for l in &lights {
            if l.ma3_id == 0 {
                return Err(invalid(format!(
                    "light {}: ma3_id must be a grandMA3 fixture ID, 1 or more",
                    l.channel
                )));
            }
            if let Some(other) = ma3_ids.insert(l.ma3_id, l.channel) {
                return Err(invalid(format!(
                    "lights {other} and {} both have grandMA3 fixture ID {} (ma3_id, by \
                     default the channel): give one its own ma3_id",
                    l.channel, l.ma3_id
                )));
            }
        }
        // A declared group no light uses would be an empty sampling unit: drop it.
        groups.retain(|g| !g.lights.is_empty());
        let mut by_address: HashMap<String, usize> = HashMap::with_capacity(groups.len());
        for (i, g) in groups.iter().enumerate() {
            let address = g.address();
            if let Some(&other) = by_address.get(&address.to_ascii_lowercase()) {
                return Err(invalid(format!(
                    "groups `{}` and `{}` are both `{address}` in OSC addresses (spaces and \
                     #*,/?[]{{}} are written _, case does not count): rename one",
                    groups[other].name, g.name
                )));
            }
            by_address.insert(address.to_ascii_lowercase(), i);
        }
        let mut remap = vec![usize::MAX; group_index.len()];
        for (new, g) in groups.iter().enumerate() {
            remap[lights[g.lights[0]].group] = new;
        }
        for l in &mut lights {
            l.group = remap[l.group];
        }

        Ok(Scene {
            dir: dir.to_path_buf(),
            name: file.name.unwrap_or_else(|| dir.display().to_string()),
            exposure: file.exposure,
            lights,
            groups,
            profiles,
            palettes: palettes.into_values().map(|(p, _)| p).collect(),
            by_address,
        })
    }

    /// Focus palette `number`.
    pub fn palette(&self, number: u32) -> Option<&Palette> {
        self.palettes
            .binary_search_by_key(&number, |p| p.number)
            .ok()
            .map(|i| &self.palettes[i])
    }

    /// The focus palettes every moving light among `lights` has, by number (none when no
    /// light there moves): what one control for all of them can offer (a group's palette
    /// buttons on a tablet or the page), since `/vo/group/<name>/position n` moves only the
    /// lights that have palette n.
    pub fn shared_palettes(&self, lights: &[usize]) -> Vec<&Palette> {
        let movers: Vec<usize> = lights
            .iter()
            .copied()
            .filter(|&l| self.lights[l].is_moving())
            .collect();
        if movers.is_empty() {
            return Vec::new();
        }
        self.palettes
            .iter()
            .filter(|p| movers.iter().all(|l| p.lights.binary_search(l).is_ok()))
            .collect()
    }

    /// The light with console channel `channel`.
    pub fn light_index(&self, channel: u32) -> Option<usize> {
        self.lights
            .binary_search_by_key(&channel, |l| l.channel)
            .ok()
    }

    /// The group called `name`, case-insensitively, as written or in its address form
    /// (`/vo/group/front_warm/...` finds `front warm`): loading refuses two groups that
    /// share an address form, so at most one matches.
    pub fn group_index(&self, name: &str) -> Option<usize> {
        let key = address_segment(name).to_ascii_lowercase();
        self.by_address.get(&key).copied()
    }

    /// The profile of light `i`.
    pub fn profile(&self, light: usize) -> &Profile {
        &self.profiles[self.lights[light].profile]
    }

    /// Light `i`'s colour model: from its measured emitters where capture measured them,
    /// else from its profile's. The DMX output, the preview and the Eos export all take it
    /// from here, so they mix the same light.
    pub fn colour_model(&self, light: usize) -> ColourModel {
        let measured = &self.lights[light].emitter_measured;
        if measured.is_empty() {
            ColourModel::new(self.profile(light))
        } else {
            ColourModel::from_emitters(measured.clone())
        }
    }

    /// A short description of the channel range, for "light 99 is not in the scene" errors.
    pub fn channel_range(&self) -> String {
        match (self.lights.first(), self.lights.last()) {
            (Some(a), Some(b)) => format!("channels {}-{}", a.channel, b.channel),
            _ => "no channels".into(),
        }
    }
}

/// Light `l`'s positions, checked against its profile and against the palettes earlier
/// lights named (`palettes`, which gains the new numbers and labels).
fn positions<'a>(
    l: &'a LightFile,
    profile: &Profile,
    palettes: &mut BTreeMap<u32, (Palette, u32)>,
) -> Result<&'a [PositionFile], String> {
    let ch = l.channel;
    if l.positions.is_empty() {
        return Ok(&l.positions);
    }
    if !profile.is_moving() {
        return Err(format!(
            "light {ch}: it has [[light.position]] tables but profile `{}` has no pan and \
             tilt slots (pan or pan16, and tilt or tilt16)",
            profile.name
        ));
    }
    if l.positions.len() > MAX_POSITIONS {
        return Err(format!(
            "light {ch}: {} positions; a light holds at most {MAX_POSITIONS}",
            l.positions.len()
        ));
    }
    for (k, p) in l.positions.iter().enumerate() {
        if !(1..=MAX_PALETTE).contains(&p.palette) {
            return Err(format!(
                "light {ch}: palette {} is not a focus palette number (1-{MAX_PALETTE})",
                p.palette
            ));
        }
        if l.positions[..k].iter().any(|o| o.palette == p.palette) {
            return Err(format!("light {ch}: palette {} is listed twice", p.palette));
        }
        for (axis, v, range) in [
            ("pan", p.pan, profile.pan_range),
            ("tilt", p.tilt, profile.tilt_range),
        ] {
            if !(v.is_finite() && v.abs() <= range / 2.0) {
                return Err(format!(
                    "light {ch}: palette {} {axis} {v} is outside profile `{}`'s range \
                     (-{h}..={h} degrees: {axis}_range {range})",
                    p.palette,
                    profile.name,
                    h = range / 2.0
                ));
            }
        }
        let name = p.name.as_deref().map(str::trim).filter(|n| !n.is_empty());
        let (palette, named_by) = palettes.entry(p.palette).or_insert_with(|| {
            let palette = Palette {
                number: p.palette,
                name: None,
                lights: Vec::new(),
            };
            (palette, 0)
        });
        match (&palette.name, name) {
            (Some(had), Some(new)) if had != new => {
                return Err(format!(
                    "light {ch}: palette {} is `{new}` here but `{had}` on light {named_by}: \
                     a palette has one name",
                    p.palette
                ));
            }
            (None, Some(new)) => {
                palette.name = Some(new.to_string());
                *named_by = ch;
            }
            _ => {}
        }
    }
    Ok(&l.positions)
}

/// Light `l`'s table `field` (`map`) in its profile's emitter order: none, or an entry for
/// every emitter the colour model mixes and for no other (a partial set could not mix).
fn per_emitter<'a, V>(
    l: &LightFile,
    profile: &Profile,
    field: &str,
    map: &'a BTreeMap<String, V>,
) -> Result<Vec<(&'a str, &'a V)>, String> {
    if map.is_empty() {
        return Ok(Vec::new());
    }
    let names = profile.mixed_emitters();
    if let Some(extra) = map.keys().find(|k| !names.contains(&k.as_str())) {
        return Err(format!(
            "light {}: {field} `{extra}` is not an emitter of profile `{}` ({})",
            l.channel,
            profile.name,
            if names.is_empty() {
                "it has none".to_string()
            } else {
                names.join(", ")
            }
        ));
    }
    names
        .iter()
        .map(|n| {
            map.get_key_value(*n)
                .map(|(k, v)| (k.as_str(), v))
                .ok_or_else(|| {
                    format!(
                        "light {}: {field} has no `{n}` (give every emitter, or none)",
                        l.channel
                    )
                })
        })
        .collect()
}

/// A light's `emitter_basis` in its profile's emitter order ([`per_emitter`]), each a
/// safe relative path.
fn emitter_basis<'a>(l: &'a LightFile, profile: &Profile) -> Result<Vec<&'a Path>, String> {
    per_emitter(l, profile, "emitter_basis", &l.emitter_basis)?
        .into_iter()
        .map(|(_, p)| {
            safe_relative(p).ok_or_else(|| {
                format!(
                    "light {}: emitter_basis `{p}` must be a relative path inside the scene folder",
                    l.channel
                )
            })
        })
        .collect()
}

/// A light's `emitter_measured` as CIE XYZ in its profile's emitter order ([`per_emitter`]),
/// each with a finite positive flux and an xy of a real colour (0 < x, 0 < y, x + y < 1).
fn emitter_measured(l: &LightFile, profile: &Profile) -> Result<Vec<[f64; 3]>, String> {
    per_emitter(l, profile, "emitter_measured", &l.emitter_measured)?
        .into_iter()
        .map(|(n, m)| match m.fault() {
            Some(fault) => Err(format!(
                "light {}: emitter_measured `{n}` {fault}",
                l.channel
            )),
            None => Ok(m.xyz()),
        })
        .collect()
}

/// `p` as a path that cannot leave its folder (no root, no `..`), or None.
pub fn safe_relative(p: &str) -> Option<&Path> {
    use std::path::Component;
    let path = Path::new(p);
    let ok = !p.is_empty()
        && path
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    ok.then_some(path)
}

/// A TOML error on one line ("line 3, column 7: unknown field `colr`, expected ..."),
/// so config and scene errors point a person at the spot to fix.
pub fn describe_toml_error(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let before = &text[..span.start.min(text.len())];
            let line = before.matches('\n').count() + 1;
            let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
            format!("line {line}, column {column}: {msg}")
        }
        None => msg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIGHT: &str =
        "[[light]]\nchannel = 1\nbasis = \"b.exr\"\nprofile = \"p\"\nuniverse = 1\naddress = 1\n";

    #[test]
    fn profile_emitters_parse_and_bad_ones_name_the_file() {
        let text = format!(
            "{LIGHT}[[profile]]\nname = \"p\"\nchannels = [\"intensity\", \"red\", \"emitter:teal\"]\n[[profile.emitter]]\nname = \"teal\"\nxy = [0.1, 0.5]\nflux = 0.2\n"
        );
        let scene = Scene::parse(Path::new("/s"), &text).expect("parses");
        let p = scene.profile(0);
        assert_eq!(p.emitters.len(), 2);
        assert_eq!((p.emitters[1].xy, p.emitters[1].flux), ([0.1, 0.5], 0.2));
        // Written back, it reads the same.
        let file = SceneFile::parse(Path::new("/s/scene.toml"), &text).expect("file");
        let again = file.to_toml().expect("toml");
        let scene2 = Scene::parse(Path::new("/s"), &again).expect("parses again");
        assert_eq!(scene2.profile(0), p);

        let missing = format!("{LIGHT}[[profile]]\nname = \"p\"\nchannels = [\"emitter:teal\"]\n");
        let e = Scene::parse(Path::new("/s"), &missing)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("/s/scene.toml: profile `p`: emitter `teal` needs a CIE xy"),
            "{e}"
        );
        let unknown_key = format!(
            "{LIGHT}[[profile]]\nname = \"p\"\nchannels = [\"red\"]\n[[profile.emitter]]\nname = \"red\"\ncolour = 1\n"
        );
        let e = Scene::parse(Path::new("/s"), &unknown_key)
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field `colour`"), "{e}");
    }

    #[test]
    fn groups_are_found_by_their_address_form_and_must_not_share_one() {
        let light = |ch: u32, group: &str| {
            format!(
                "[[group]]\nname = \"{group}\"\n[[light]]\nchannel = {ch}\nbasis = \"b.exr\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = {ch}\ngroup = \"{group}\"\n"
            )
        };
        let text = [
            light(1, "Front warm"),
            light(2, "cyc/top #2"),
            light(3, "front"),
        ]
        .concat();
        let scene = Scene::parse(Path::new("/s"), &text).expect("parses");
        let addresses: Vec<String> = scene.groups.iter().map(Group::address).collect();
        assert_eq!(addresses, ["Front_warm", "cyc_top__2", "front"]);
        for (name, want) in [
            ("Front warm", Some(0)),
            ("front WARM", Some(0)),
            ("front_warm", Some(0)),
            ("CYC_TOP__2", Some(1)),
            ("cyc/top #2", Some(1)),
            ("front", Some(2)),
            ("front_", None),
            ("frontwarm", None),
        ] {
            assert_eq!(scene.group_index(name), want, "{name}");
        }
        let clash = [light(1, "front warm"), light(2, "Front_Warm")].concat();
        let e = Scene::parse(Path::new("/s"), &clash)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "/s/scene.toml: groups `front warm` and `Front_Warm` are both `Front_Warm` in OSC \
             addresses (spaces and #*,/?[]{} are written _, case does not count): rename one"
        );
    }

    #[test]
    fn emitter_basis_names_every_emitter_or_none() {
        let light = "[[light]]\nchannel = 4\nbasis = \"b.exr\"\nprofile = \"irgb\"\nuniverse = 1\naddress = 1\n";
        let full = format!(
            "{light}[light.emitter_basis]\nred = \"b-red.exr\"\ngreen = \"b-green.exr\"\nblue = \"b-blue.exr\"\n"
        );
        let scene = Scene::parse(Path::new("/s"), &full).expect("parses");
        let want: Vec<PathBuf> = ["red", "green", "blue"]
            .map(|n| PathBuf::from(format!("/s/b-{n}.exr")))
            .to_vec();
        assert_eq!(scene.lights[0].emitter_basis, want, "in slot order");
        let file = SceneFile::parse(Path::new("/s/scene.toml"), &full).expect("file");
        let again = Scene::parse(Path::new("/s"), &file.to_toml().expect("toml")).expect("again");
        assert_eq!(
            again.lights[0].emitter_basis, want,
            "written back, it reads the same"
        );
        for (text, says) in [
            (
                format!("{light}[light.emitter_basis]\nred = \"r.exr\"\n"),
                "light 4: emitter_basis has no `green` (give every emitter, or none)",
            ),
            (
                format!(
                    "{light}[light.emitter_basis]\nred = \"r.exr\"\ngreen = \"g.exr\"\nblue = \"b.exr\"\nwhite = \"w.exr\"\n"
                ),
                "light 4: emitter_basis `white` is not an emitter of profile `irgb` (red, green, blue)",
            ),
            (
                format!(
                    "{light}[light.emitter_basis]\nred = \"../r.exr\"\ngreen = \"g.exr\"\nblue = \"b.exr\"\n"
                ),
                "light 4: emitter_basis `../r.exr` must be a relative path inside the scene folder",
            ),
        ] {
            let e = Scene::parse(Path::new("/s"), &text)
                .unwrap_err()
                .to_string();
            assert_eq!(e, format!("/s/scene.toml: {says}"));
        }
    }

    #[test]
    fn emitter_measured_builds_the_colour_model_and_is_checked() {
        let light = "[[light]]\nchannel = 4\nbasis = \"b.exr\"\nprofile = \"rgb\"\nuniverse = 1\naddress = 1\n";
        let table = |red: &str| {
            format!(
                "{light}[light.emitter_measured]\nred = {red}\ngreen = {{ xy = [0.33, 0.52], flux = 0.6 }}\nblue = {{ xy = [0.16, 0.11], flux = 0.1 }}\n"
            )
        };
        let text = table("{ xy = [0.6, 0.35], flux = 0.25 }");
        let measured = Scene::parse(Path::new("/s"), &text).expect("parses");
        let plain = Scene::parse(Path::new("/s"), light).expect("parses");
        let xyz = |x, y, flux| {
            crate::profile::Emitter {
                name: String::new(),
                xy: [x, y],
                flux,
            }
            .xyz()
        };
        let want = ColourModel::from_emitters(vec![
            xyz(0.6, 0.35, 0.25),
            xyz(0.33, 0.52, 0.6),
            xyz(0.16, 0.11, 0.1),
        ]);
        assert_eq!(measured.colour_model(0), want, "the measured emitters");
        assert_eq!(plain.colour_model(0), ColourModel::new(plain.profile(0)));
        assert_ne!(measured.colour_model(0), plain.colour_model(0));
        let file = SceneFile::parse(Path::new("/s/scene.toml"), &text).expect("file");
        let again = Scene::parse(Path::new("/s"), &file.to_toml().expect("toml")).expect("again");
        assert_eq!(
            again.colour_model(0),
            want,
            "written back, it reads the same"
        );
        for (text, says) in [
            (
                format!("{light}[light.emitter_measured]\nred = {{ xy = [0.6, 0.35], flux = 1.0 }}\n"),
                "light 4: emitter_measured has no `green` (give every emitter, or none)".to_string(),
            ),
            (
                table("{ xy = [0.6, 0.35], flux = 0.0 }"),
                "light 4: emitter_measured `red` flux 0 must be a positive number".into(),
            ),
            (
                table("{ xy = [0.6, 0.45], flux = 0.2 }"),
                "light 4: emitter_measured `red` xy [0.6, 0.45] is not a colour (need 0 < x, 0 < y, x + y < 1)".into(),
            ),
            (
                table("{ xy = [0.6, nan], flux = 0.2 }"),
                "light 4: emitter_measured `red` xy [0.6, NaN] is not a colour (need 0 < x, 0 < y, x + y < 1)".into(),
            ),
            (
                format!("{}white = {{ xy = [0.3, 0.3], flux = 1.0 }}\n", table("{ xy = [0.6, 0.35], flux = 0.2 }")),
                "light 4: emitter_measured `white` is not an emitter of profile `rgb` (red, green, blue)".into(),
            ),
        ] {
            let e = Scene::parse(Path::new("/s"), &text)
                .unwrap_err()
                .to_string();
            assert_eq!(e, format!("/s/scene.toml: {says}"));
        }
    }

    /// A moving head (16-bit pan and tilt) at `address`, its positions' tables after it.
    fn mover(ch: u32, positions: &[(u32, &str, f64, f64)]) -> String {
        let mut t = format!(
            "[[light]]\nchannel = {ch}\nprofile = \"spot\"\nuniverse = 1\naddress = {}\n",
            ch * 10
        );
        for (n, name, pan, tilt) in positions {
            t += &format!(
                "[[light.position]]\npalette = {n}\nname = \"{name}\"\npan = {pan}\ntilt = {tilt}\nbasis = \"b/{ch}-{n}.exr\"\n"
            );
        }
        t
    }

    const SPOT: &str = "[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\npan_range = 540\ntilt_range = 270\n";

    #[test]
    fn movers_list_their_positions_and_share_palettes() {
        let text = [
            mover(1, &[(3, "DS centre", -12.5, 41.0), (1, "home", 0.0, 0.0)]),
            mover(2, &[(3, "DS centre", 10.0, 40.0)]),
            SPOT.to_string(),
            LIGHT
                .replace("channel = 1", "channel = 9")
                .replace("address = 1", "address = 90")
                .replace("\"p\"", "\"dimmer\""),
        ]
        .concat();
        let scene = Scene::parse(Path::new("/s"), &text).expect("parses");
        let l = &scene.lights[0];
        assert!(l.is_moving() && !scene.lights[2].is_moving());
        assert_eq!(
            l.basis,
            PathBuf::from("/s/b/1-3.exr"),
            "its first position's image"
        );
        assert_eq!(l.positions[1].palette, 1);
        assert_eq!(scene.profile(0).footprint(), 5);
        let numbers: Vec<(u32, Option<&str>, Vec<usize>)> = scene
            .palettes
            .iter()
            .map(|p| (p.number, p.name.as_deref(), p.lights.clone()))
            .collect();
        assert_eq!(
            numbers,
            [
                (1, Some("home"), vec![0]),
                (3, Some("DS centre"), vec![0, 1])
            ]
        );
        let level = |position| look::Level {
            position,
            ..look::Level::OFF
        };
        assert_eq!(l.position_of(&level(Some(1))).map(|p| p.pan), Some(0.0));
        assert_eq!(l.position_of(&level(None)).map(|p| p.palette), Some(3));
        assert_eq!(l.position_of(&level(Some(7))).map(|p| p.palette), Some(3));
        assert_eq!(scene.lights[2].position_of(&level(Some(1))), None);
        // What one control for several lights offers: the palettes all their movers have.
        let shared = |lights: &[usize]| -> Vec<u32> {
            scene
                .shared_palettes(lights)
                .iter()
                .map(|p| p.number)
                .collect()
        };
        assert_eq!(shared(&[0, 1, 2]), [3]);
        assert_eq!(shared(&[0, 2]), [1, 3]);
        assert!(shared(&[2]).is_empty(), "a fixed light alone offers none");
        // Written back, it reads the same.
        let file = SceneFile::parse(Path::new("/s/scene.toml"), &text).expect("file");
        let again = Scene::parse(Path::new("/s"), &file.to_toml().expect("toml")).expect("again");
        assert_eq!(again.lights[0].positions, l.positions);
        assert_eq!(again.palettes, scene.palettes);
    }

    #[test]
    fn broken_movers_are_refused_with_the_reason() {
        let bad = |text: String| {
            Scene::parse(Path::new("/s"), &format!("{text}{SPOT}"))
                .unwrap_err()
                .to_string()
                .trim_start_matches("/s/scene.toml: ")
                .to_string()
        };
        assert_eq!(
            bad([
                mover(1, &[(3, "DS centre", 0.0, 0.0)]),
                mover(2, &[(3, "DS left", 0.0, 0.0)])
            ]
            .concat()),
            "light 2: palette 3 is `DS left` here but `DS centre` on light 1: a palette has one name"
        );
        assert_eq!(
            bad(mover(1, &[(3, "a", 271.0, 0.0)])),
            "light 1: palette 3 pan 271 is outside profile `spot`'s range (-270..=270 degrees: pan_range 540)"
        );
        assert_eq!(
            bad(mover(1, &[(3, "a", 0.0, -136.0)])),
            "light 1: palette 3 tilt -136 is outside profile `spot`'s range (-135..=135 degrees: tilt_range 270)"
        );
        assert_eq!(
            bad(mover(1, &[(3, "a", 0.0, 0.0), (3, "a", 1.0, 0.0)])),
            "light 1: palette 3 is listed twice"
        );
        assert_eq!(
            bad(mover(1, &[(0, "a", 0.0, 0.0)])),
            "light 1: palette 0 is not a focus palette number (1-9999)"
        );
        assert_eq!(
            bad(mover(1, &[(1, "a", 0.0, 0.0)]).replace("\"spot\"\nuniverse", "\"irgb\"\nuniverse")),
            "light 1: it has [[light.position]] tables but profile `irgb` has no pan and tilt slots (pan or pan16, and tilt or tilt16)"
        );
        assert_eq!(
            bad(mover(1, &[(1, "a", 0.0, 0.0)]).replace("universe", "basis = \"x.exr\"\nuniverse")),
            "light 1: a moving light gives one basis image per [[light.position]], not `basis`"
        );
        assert_eq!(
            bad(mover(1, &[])),
            "light 1: no basis image: give `basis`, or [[light.position]] tables for a moving light"
        );
        assert_eq!(
            bad(mover(1, &[(1, "a", 0.0, 0.0)]).replace("b/1-1.exr", "../x.exr")),
            "light 1: basis `../x.exr` must be a relative path inside the scene folder"
        );
        let p = |range: &str| {
            Scene::parse(
                Path::new("/s"),
                &format!(
                    "{}{}",
                    mover(1, &[(1, "a", 0.0, 0.0)]),
                    SPOT.replace("pan_range = 540", range)
                ),
            )
            .map(|_| ())
            .map_err(|e| e.to_string())
        };
        assert!(
            p("pan_range = 0")
                .unwrap_err()
                .contains("pan_range 0 must be the full travel")
        );
        assert!(
            p("pan_range = nan")
                .unwrap_err()
                .contains("pan_range NaN must be")
        );
        assert!(p("pan_range = 630").is_ok());
    }
}
