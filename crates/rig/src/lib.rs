//! The rig as the lighting world describes it: an MVR plot, GDTF fixture types and Open
//! Fixture Library fixtures, read into one model (fixtures with channel, name, group,
//! universe, address and a fixture type that is, or is not, a visobjd profile).
//!
//! Pure parsing: every function takes the file's bytes and its name (for the errors), no
//! I/O and no network. The model is independent of the source, so a console patch (Eos
//! CSV, Eos over OSC) can fill it the same way through [`Rig::add`] and a [`Library`].
//! A fixture type that cannot become a profile is kept with the reason and listed
//! ("needs a profile: ..."), never guessed.

pub mod eos;
pub mod gdtf;
pub mod mvr;
pub mod ofl;

use std::collections::BTreeMap;
use std::fmt;
use std::io::Read;

use visobjd_scene::profile::Profile;

/// A wrong input: one line naming the file, the fixture (where there is one) and the
/// problem.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RigError {
    /// The file the problem is in (for an embedded GDTF: `plot.mvr: Acme.gdtf`).
    pub file: String,
    /// The fixture, as `channel 12 "FOH L1"`, or the fixture type.
    pub fixture: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl RigError {
    fn new(file: &str, fixture: Option<String>, message: impl Into<String>) -> RigError {
        RigError {
            file: file.to_string(),
            fixture,
            message: message.into().replace('\n', " "),
        }
    }
}

impl fmt::Display for RigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.fixture {
            Some(x) => write!(f, "{}: {}: {}", self.file, x, self.message),
            None => write!(f, "{}: {}", self.file, self.message),
        }
    }
}

impl std::error::Error for RigError {}

/// One fixture type in one mode, as the rig uses it.
#[derive(Debug, Clone, PartialEq)]
pub struct FixtureType {
    /// `Manufacturer Name (Mode)`: the profile name scene.toml gets.
    pub name: String,
    /// DMX slots the mode takes, where the source says.
    pub footprint: Option<usize>,
    /// The profile, or why the type cannot be one (a multi-cell fixture, no dimmer...).
    pub profile: Result<Profile, String>,
}

/// One fixture of the plot.
#[derive(Debug, Clone, PartialEq)]
pub struct Fixture {
    /// Console channel (MVR: `FixtureIDNumeric`, else `FixtureID`).
    pub channel: u32,
    /// The fixture's name in the source.
    pub name: String,
    /// Its group in the source (MVR `GroupObject`), if any.
    pub group: Option<String>,
    /// Universe 1..=63999.
    pub universe: u16,
    /// Start address 1..=512.
    pub address: u16,
    /// Index into [`Rig::types`].
    pub fixture_type: usize,
}

/// A plot: fixtures, their types, and the fixtures that cannot become lights.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rig {
    /// Fixtures in source order.
    pub fixtures: Vec<Fixture>,
    /// Fixture types (one per type and mode) the fixtures use.
    pub types: Vec<FixtureType>,
    /// Fixtures that are not lights and why (not patched, no numeric id, ...).
    pub skipped: Vec<String>,
}

impl Rig {
    /// Adds a fixture of type `fixture_type` (the same type, by name, is stored once).
    pub fn add(&mut self, mut fixture: Fixture, fixture_type: FixtureType) {
        fixture.fixture_type = match self.types.iter().position(|t| t.name == fixture_type.name) {
            Some(i) => i,
            None => {
                self.types.push(fixture_type);
                self.types.len() - 1
            }
        };
        self.fixtures.push(fixture);
    }

    /// Refuses two fixtures on one channel and two fixtures on one DMX slot (for types of
    /// known footprint); `file` names the source in the error.
    pub fn check(&self, file: &str) -> Result<(), RigError> {
        let mut channels: BTreeMap<u32, &Fixture> = BTreeMap::new();
        for f in &self.fixtures {
            if let Some(other) = channels.insert(f.channel, f) {
                return Err(RigError::new(
                    file,
                    Some(describe(f)),
                    format!("channel {} is also \"{}\"", f.channel, other.name),
                ));
            }
        }
        let mut slots: BTreeMap<(u16, usize), &Fixture> = BTreeMap::new();
        for f in &self.fixtures {
            let ty = &self.types[f.fixture_type];
            let width = ty
                .profile
                .as_ref()
                .map(|p| p.footprint())
                .ok()
                .or(ty.footprint)
                .unwrap_or(1);
            let first = usize::from(f.address);
            if first == 0 || first + width - 1 > 512 {
                return Err(RigError::new(
                    file,
                    Some(describe(f)),
                    format!(
                        "address {} with a {width}-slot footprint does not fit in slots 1-512",
                        f.address
                    ),
                ));
            }
            for slot in first..first + width {
                if let Some(other) = slots.insert((f.universe, slot), f) {
                    return Err(RigError::new(
                        file,
                        Some(describe(f)),
                        format!(
                            "universe {} slot {slot} is also used by {}",
                            f.universe,
                            describe(other)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// One line per fixture type that is not a profile: "needs a profile: Acme Wash 7
    /// (12 channels), channels 101-108: why".
    pub fn needs_profiles(&self) -> Vec<String> {
        self.types
            .iter()
            .enumerate()
            .filter_map(|(i, t)| {
                let why = t.profile.as_ref().err()?;
                let channels: Vec<u32> = self
                    .fixtures
                    .iter()
                    .filter(|f| f.fixture_type == i)
                    .map(|f| f.channel)
                    .collect();
                let size = t.footprint.map_or(String::new(), |n| {
                    format!(" ({n} channel{})", if n == 1 { "" } else { "s" })
                });
                Some(format!(
                    "needs a profile: {}{size}, {}: {why}",
                    t.name,
                    channel_list(&channels)
                ))
            })
            .collect()
    }
}

/// `channel 12 "FOH L1"`, how errors name a fixture.
fn describe(f: &Fixture) -> String {
    format!("channel {} \"{}\"", f.channel, f.name)
}

/// The channels as runs of consecutive numbers `(first, last)`, ascending, each channel
/// once: what every channel list (here, the Eos selection) is written from.
pub fn channel_runs(channels: &[u32]) -> Vec<(u32, u32)> {
    let mut sorted = channels.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    let mut runs: Vec<(u32, u32)> = Vec::new();
    for c in sorted {
        match runs.last_mut() {
            Some((_, b)) if *b + 1 == c => *b = c,
            _ => runs.push((c, c)),
        }
    }
    runs
}

/// Channels written as `1-100, 200` (commas, ranges), the way an Eos group's channel list
/// and `visobjd capture --lights` spell them; `Err` names the part that is not a channel
/// or a range (a range spans at most 100,000).
pub fn parse_channels(spec: &str) -> Result<Vec<u32>, &str> {
    let mut out = Vec::new();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        match (a.trim().parse::<u32>(), b.trim().parse::<u32>()) {
            (Ok(a), Ok(b)) if a <= b && b - a <= 100_000 => out.extend(a..=b),
            _ => return Err(part),
        }
    }
    Ok(out)
}

/// `channels 101-108, 110` (sorted, runs joined).
pub fn channel_list(channels: &[u32]) -> String {
    let parts: Vec<String> = channel_runs(channels)
        .iter()
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}-{b}")
            }
        })
        .collect();
    let word = if channels.len() == 1 {
        "channel"
    } else {
        "channels"
    };
    format!("{word} {}", parts.join(", "))
}

/// Fixture types by name, from GDTF and OFL files: what sources that only name a type
/// (an Eos patch, an MVR) resolve against.
#[derive(Debug, Clone, Default)]
pub struct Library {
    gdtf: Vec<(String, gdtf::GdtfType)>,
    ofl: Vec<(String, ofl::OflType)>,
}

impl Library {
    /// Adds a GDTF file (`file` is its name, which MVR `GDTFSpec` refers to).
    pub fn add_gdtf(&mut self, file: &str, bytes: &[u8]) -> Result<(), RigError> {
        let ty = gdtf::GdtfType::parse(file, bytes)?;
        self.gdtf.push((file.to_string(), ty));
        Ok(())
    }

    /// Adds an Open Fixture Library JSON file.
    pub fn add_ofl(&mut self, file: &str, bytes: &[u8]) -> Result<(), RigError> {
        let ty = ofl::OflType::parse(file, bytes)?;
        self.ofl.push((file.to_string(), ty));
        Ok(())
    }

    /// A fixture type by name (GDTF `Manufacturer Name`, `Name` or `LongName`, or OFL
    /// `name`, case-insensitive) in the mode called `mode`: what a console patch names.
    /// `None` when no file has the type (the fixture needs a profile); an error when the
    /// type is there without that mode.
    pub fn find(&self, type_name: &str, mode: &str) -> Option<Result<FixtureType, RigError>> {
        let eq = |a: &str| a.trim().eq_ignore_ascii_case(type_name.trim());
        if let Some((_, t)) = self.gdtf.iter().find(|(_, t)| {
            eq(&t.name) || eq(&t.long_name) || eq(&format!("{} {}", t.manufacturer, t.name))
        }) {
            return Some(t.fixture_type(mode));
        }
        let (_, t) = self.ofl.iter().find(|(_, t)| eq(&t.name))?;
        Some(t.fixture_type(mode))
    }

    /// A fixture type by an Eos name: `manufacturer` and `model` with the mode in it, as
    /// Eos names its types (`JB_Lighting`, `P18_Profile_Mk2_HP_M1`). Names are compared by
    /// their letters and digits only, case-insensitive ([`eos::compact`]). A GDTF file
    /// matches when its `Manufacturer` is the manufacturer; an OFL file (which keeps its
    /// manufacturer in its path, `fixtures/<manufacturer>/<name>.json`) when its path
    /// relative to the library starts with it (`cameo-root-par-6.json`,
    /// `cameo/root-par-6.json`). The model must then be the fixture's name (GDTF `Name` or
    /// `LongName`, OFL `name`) followed by a mode's name (OFL: or `shortName`), or the name
    /// alone for a type with one mode. `None` when nothing matches; an error (the type
    /// needs a profile, nothing is guessed) when several modes do.
    pub fn find_eos(&self, manufacturer: &str, model: &str) -> Option<Result<FixtureType, String>> {
        let maker = eos::compact(manufacturer);
        let model = eos::compact(model);
        if maker.is_empty() || model.is_empty() {
            return None;
        }
        let fits = |names: &[&str], modes: &[Vec<&str>], i: usize| {
            names.iter().any(|n| {
                let n = eos::compact(n);
                !n.is_empty()
                    && (modes[i]
                        .iter()
                        .any(|m| model == format!("{n}{}", eos::compact(m)))
                        || (modes.len() == 1 && model == n))
            })
        };
        let mut found: Vec<Result<FixtureType, RigError>> = Vec::new();
        for (_, t) in &self.gdtf {
            if eos::compact(&t.manufacturer) != maker {
                continue;
            }
            let modes: Vec<Vec<&str>> = t.modes.iter().map(|m| vec![m.name.as_str()]).collect();
            for (i, m) in t.modes.iter().enumerate() {
                if fits(&[&t.name, &t.long_name], &modes, i) {
                    found.push(t.fixture_type(&m.name));
                }
            }
        }
        for (file, t) in &self.ofl {
            if !eos::compact(file).starts_with(&maker) {
                continue;
            }
            let modes: Vec<Vec<&str>> = t
                .modes
                .iter()
                .map(|m| {
                    std::iter::once(m.name.as_str())
                        .chain(m.short_name.as_deref())
                        .collect()
                })
                .collect();
            for (i, m) in t.modes.iter().enumerate() {
                if fits(&[&t.name], &modes, i) {
                    found.push(t.fixture_type(&m.name));
                }
            }
        }
        match found.len() {
            0 => None,
            1 => Some(found.remove(0).map_err(|e| e.to_string())),
            _ => Some(Err(format!(
                "several fixture types match it: {}",
                found
                    .iter()
                    .map(|t| match t {
                        Ok(t) => t.name.clone(),
                        Err(e) => e.to_string(),
                    })
                    .collect::<Vec<_>>()
                    .join("; ")
            ))),
        }
    }
}

/// The 16-bit (coarse, fine) slot of a slot that has one: what a GDTF channel with two
/// adjacent offsets, or an OFL channel followed by its fine alias, becomes. Colours have
/// none (their coarse byte carries them at 8 bits).
fn wide_slot(slot: &str) -> Option<&'static str> {
    Some(match slot {
        "intensity" => "intensity16",
        "pan" => "pan16",
        "tilt" => "tilt16",
        _ => return None,
    })
}

/// The full travel in degrees between a pan's or tilt's two end angles (either way
/// round: the profile keeps the travel, DMX centre being 0), or why it is not one a
/// profile takes (`pan_range` and `tilt_range` are above 0 and at most 3600).
fn travel(from: f64, to: f64) -> Result<f64, String> {
    let travel = (to - from).abs();
    if travel.is_finite() && travel > 0.0 && travel <= 3600.0 {
        Ok(travel)
    } else {
        Err(format!(
            "a travel of {travel} degrees, not above 0 and at most 3600"
        ))
    }
}

/// What a source file is, told by its content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A zip with `GeneralSceneDescription.xml`.
    Mvr,
    /// A zip with `description.xml`.
    Gdtf,
    /// JSON (an Open Fixture Library fixture).
    Ofl,
    /// Text starting with a `START_...` block (an Eos CSV export).
    EosCsv,
}

/// The kind of `bytes`, or a sentence saying why it is none of them.
pub fn kind(file: &str, bytes: &[u8]) -> Result<Kind, RigError> {
    if bytes.starts_with(b"PK") {
        let archive = open_zip(file, bytes)?;
        if archive
            .index_for_name("GeneralSceneDescription.xml")
            .is_some()
        {
            return Ok(Kind::Mvr);
        }
        if archive.index_for_name("description.xml").is_some() {
            return Ok(Kind::Gdtf);
        }
        return Err(RigError::new(
            file,
            None,
            "a zip with neither GeneralSceneDescription.xml (MVR) nor description.xml (GDTF)",
        ));
    }
    let text = bytes.trim_ascii_start();
    if text.starts_with(b"{") {
        return Ok(Kind::Ofl);
    }
    let text = text.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(text);
    if text.starts_with(b"START_") {
        return Ok(Kind::EosCsv);
    }
    Err(RigError::new(
        file,
        None,
        "not an MVR, a GDTF, an Open Fixture Library JSON file or an Eos CSV export",
    ))
}

type Archive<'a> = zip::ZipArchive<std::io::Cursor<&'a [u8]>>;

fn open_zip<'a>(file: &str, bytes: &'a [u8]) -> Result<Archive<'a>, RigError> {
    zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| RigError::new(file, None, format!("not a readable zip: {e}")))
}

/// The bytes of `name` inside the zip, at most 64 MB (a plot's XML is a few MB).
fn zip_entry(file: &str, archive: &mut Archive, name: &str) -> Result<Vec<u8>, RigError> {
    const LIMIT: u64 = 64 << 20;
    let entry = archive
        .by_name(name)
        .map_err(|e| RigError::new(file, None, format!("cannot read {name} in the zip: {e}")))?;
    let mut out = Vec::new();
    entry
        .take(LIMIT + 1)
        .read_to_end(&mut out)
        .map_err(|e| RigError::new(file, None, format!("cannot read {name} in the zip: {e}")))?;
    if out.len() as u64 > LIMIT {
        return Err(RigError::new(file, None, format!("{name} is over 64 MB")));
    }
    Ok(out)
}

/// The deepest nesting of elements an MVR or GDTF document may have: real plots and
/// fixture types nest a few levels (layers, groups, geometries), and the walks over them
/// recurse once per level, so a deeper file is refused before it can overflow the stack.
pub const MAX_XML_DEPTH: usize = 64;

/// `bytes` as an XML document, its elements nested at most [`MAX_XML_DEPTH`] deep.
fn xml<'a>(file: &str, text: &'a str) -> Result<roxmltree::Document<'a>, RigError> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| RigError::new(file, None, format!("not well-formed XML: {e}")))?;
    // Counted without recursion, in document order: a node's parent comes before it.
    let mut depths: Vec<usize> = Vec::new();
    for node in doc.descendants() {
        let at = |n: roxmltree::Node| n.id().get() as usize;
        let depth = node
            .parent()
            .and_then(|p| depths.get(at(p)).copied())
            .unwrap_or(0)
            + usize::from(node.is_element());
        if depth > MAX_XML_DEPTH {
            return Err(RigError::new(
                file,
                None,
                format!(
                    "elements nested more than {MAX_XML_DEPTH} deep: not a plot or fixture type this import reads"
                ),
            ));
        }
        if depths.len() <= at(node) {
            depths.resize(at(node) + 1, 0);
        }
        depths[at(node)] = depth;
    }
    Ok(doc)
}

/// `bytes` as UTF-8 text (a BOM is dropped).
fn utf8<'a>(file: &str, bytes: &'a [u8]) -> Result<&'a str, RigError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    std::str::from_utf8(bytes).map_err(|e| RigError::new(file, None, format!("not UTF-8: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(channel: u32, universe: u16, address: u16) -> Fixture {
        Fixture {
            channel,
            name: format!("F{channel}"),
            group: None,
            universe,
            address,
            fixture_type: 0,
        }
    }

    fn four_slots() -> FixtureType {
        FixtureType {
            name: "irgb".into(),
            footprint: Some(4),
            profile: Profile::built_in("irgb").ok_or_else(String::new),
        }
    }

    #[test]
    fn channel_lists_join_runs() {
        assert_eq!(
            channel_list(&[108, 101, 102, 103, 110]),
            "channels 101-103, 108, 110"
        );
        assert_eq!(channel_list(&[7]), "channel 7");
    }

    #[test]
    fn channel_specs_parse_and_name_the_bad_part() {
        assert_eq!(parse_channels("1-3, 7,9 - 10"), Ok(vec![1, 2, 3, 7, 9, 10]));
        assert_eq!(parse_channels(""), Ok(vec![]));
        assert_eq!(parse_channels("1-3,x"), Err("x"));
        assert_eq!(parse_channels("5-2"), Err("5-2"));
        assert_eq!(parse_channels("1-200000"), Err("1-200000"));
        assert_eq!(channel_runs(&[3, 1, 2, 2, 9]), vec![(1, 3), (9, 9)]);
    }

    #[test]
    fn overlaps_and_duplicate_channels_are_refused() {
        let mut rig = Rig::default();
        rig.add(fixture(1, 1, 1), four_slots());
        rig.add(fixture(2, 1, 5), four_slots());
        rig.add(fixture(3, 2, 4), four_slots());
        assert_eq!(rig.types.len(), 1);
        assert_eq!(rig.check("plot.mvr"), Ok(()));
        let mut overlap = rig.clone();
        overlap.add(fixture(4, 1, 8), four_slots());
        let e = overlap.check("plot.mvr").unwrap_err().to_string();
        assert_eq!(
            e,
            "plot.mvr: channel 4 \"F4\": universe 1 slot 8 is also used by channel 2 \"F2\""
        );
        let mut twice = rig.clone();
        twice.add(fixture(2, 3, 1), four_slots());
        let e = twice.check("plot.mvr").unwrap_err().to_string();
        assert_eq!(e, "plot.mvr: channel 2 \"F2\": channel 2 is also \"F2\"");
        let mut off_end = rig;
        off_end.add(fixture(9, 4, 510), four_slots());
        assert!(
            off_end
                .check("x")
                .unwrap_err()
                .to_string()
                .contains("does not fit")
        );
    }

    #[test]
    fn kinds_are_told_by_content() {
        assert_eq!(kind("a.json", b"  {\"name\": 1}"), Ok(Kind::Ofl));
        let e = kind("a.mvr", b"PK\x03\x04 broken").unwrap_err().to_string();
        assert!(e.starts_with("a.mvr: not a readable zip"), "{e}");
        assert_eq!(kind("a.csv", b"START_TARGETS"), Ok(Kind::EosCsv));
        assert!(kind("a.txt", b"CHANNEL,LABEL").is_err());
    }
}
