//! An ETC Eos patch: from the console's CSV export or from its OSC replies, into the same
//! [`EosPatch`], then into a [`Rig`] with fixture types resolved through a [`Library`].
//!
//! Pure: bytes or OSC arguments in, data out; the socket work is the CLI's. Eos names a
//! fixture type by manufacturer and model, the mode being part of the model (one Eos type
//! per DMX mode), spelled with `_` for spaces (`JB_Lighting`, `P18_Profile_Mk2_HP_M1`);
//! [`Library::find_eos`] says how such a name is matched to a GDTF or OFL file.
//!
//! The CSV follows a real export (Eos "File > Export > CSV", patch included): a
//! `START_CHANNELS` block whose first row names the columns (`CHANNEL`, `FIXTURE_TYPE`,
//! `MANUFACTURER`, ..., `ADDRESS`, `LABEL`, ...), one row per channel part (a channel's
//! parts are its rows in order), addresses as `U/A` or `U/A<E` (E: the last address), and
//! other blocks (`START_FIXTURES`, ...) that are not the patch.
//!
//! The OSC replies follow ETC's "Eos Integration via OSC" (Eos 2.6, shipped with ETCLabs'
//! EosSyncLib, "Detailed Information Packet Contents"):
//! `/eos/out/get/patch/<channel>/<part>/list/<list index>/<list count>` =
//! index, OSC UID, label, fixture manufacturer, fixture model, address, address of the
//! intensity parameter, current level, OSC gel, text 1-10, part count, end address;
//! `/eos/out/get/group/<group>/list/<i>/<n>` = index, UID, label and
//! `/eos/out/get/group/<group>/channels/list/<i>/<n>` = index, UID, then the channel list as
//! numbers or strings (`1-100`). The OSC list convention (same document): `<list index>` is
//! the offset of the message's first argument in the whole list and `<list count>` the
//! whole list's length; Bitfocus Companion's Eos module reads the label at list position 2
//! the same way (`get_list_param`).
//!
//! Focus palettes (the Eos manual's "Integrating Your App with Eos", `fp`): after
//! `/eos/get/fp/count` (answered by `/eos/out/get/fp/count <n>`), `/eos/get/fp/index/<i>`
//! is answered by three lists: `/eos/out/get/fp/<fp>/list/<i>/<n>` = index, UID, label,
//! absolute, locked; `/eos/out/get/fp/<fp>/channels/list/<i>/<n>` = index, UID, then the
//! member channels as for a group; and `.../byType/list/...` (the by-type channels, which
//! the import does not use). No reply carries pan or tilt values.

use std::collections::BTreeMap;

use visobjd_scene::profile::Profile;

use crate::{Fixture, FixtureType, Library, Rig, RigError};

/// One OSC argument as the console sent it (what the replies carry).
#[derive(Debug, Clone, PartialEq)]
pub enum Arg {
    /// int32 (Eos sends its uint32 fields as OSC ints).
    Int(i64),
    /// float32.
    Float(f64),
    /// string.
    Str(String),
}

impl Arg {
    fn text(&self) -> String {
        match self {
            Arg::Int(i) => i.to_string(),
            Arg::Float(f) => f.to_string(),
            Arg::Str(s) => s.clone(),
        }
    }

    fn int(&self) -> Option<i64> {
        match self {
            Arg::Int(i) => Some(*i),
            Arg::Float(f) if f.fract() == 0.0 => Some(*f as i64),
            Arg::Float(_) => None,
            Arg::Str(s) => s.trim().parse().ok(),
        }
    }
}

/// One channel part of the patch.
#[derive(Debug, Clone, PartialEq)]
pub struct EosChannel {
    /// Channel number.
    pub channel: u32,
    /// Part number (1 for the first).
    pub part: u32,
    /// The channel's label.
    pub label: String,
    /// Manufacturer as Eos names it (`JB_Lighting`).
    pub manufacturer: String,
    /// Model as Eos names it, mode included (`P18_Profile_Mk2_HP_M1`).
    pub model: String,
    /// Universe and start address; `None` when not patched.
    pub address: Option<(u16, u16)>,
    /// Addresses the part takes, where the source says (its end address).
    pub footprint: Option<usize>,
}

/// A group of the show file.
#[derive(Debug, Clone, PartialEq)]
pub struct EosGroup {
    /// Group number as Eos spells it (`1`, `1.2`).
    pub number: String,
    /// Its label (may be empty).
    pub label: String,
    /// Its channels in order.
    pub channels: Vec<u32>,
}

/// A focus palette of the show file: the number a moving light's position takes
/// (`[[light.position]] palette`), its label and its channels.
#[derive(Debug, Clone, PartialEq)]
pub struct EosPalette {
    /// Palette number as Eos spells it (`3`, `3.5`).
    pub number: String,
    /// Its label (may be empty).
    pub label: String,
    /// The channels it holds data for, in order.
    pub channels: Vec<u32>,
}

impl EosPalette {
    /// The number as a scene's palette number (a whole 1..=9999), None for a decimal one
    /// (Eos allows `3.5`; a scene does not).
    pub fn whole(&self) -> Option<u32> {
        self.number
            .parse()
            .ok()
            .filter(|n| (1..=visobjd_scene::MAX_PALETTE).contains(n))
    }
}

/// A console's patch and groups, however they were read.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EosPatch {
    /// Channel parts in source order.
    pub channels: Vec<EosChannel>,
    /// Groups in source order.
    pub groups: Vec<EosGroup>,
}

/// Fields of a patch reply, by list position (see the module header for the source).
mod field {
    pub const LABEL: usize = 2;
    pub const MANUFACTURER: usize = 3;
    pub const MODEL: usize = 4;
    pub const ADDRESS: usize = 5;
    /// Eos 2.3.2 and later.
    pub const END_ADDRESS: usize = 20;
    /// Group and group-channel replies: label, or the first channel entry.
    pub const GROUP_LABEL: usize = 2;
}

/// Universe and address of an absolute Eos address (`(U - 1) * 512 + A`); `None` for 0
/// (not patched); an error past universe 63999.
fn split_absolute(abs: u64) -> Result<Option<(u16, u16)>, String> {
    if abs == 0 {
        return Ok(None);
    }
    let universe = (abs - 1) / 512 + 1;
    let address = (abs - 1) % 512 + 1;
    match u16::try_from(universe) {
        Ok(u) if u <= 63999 => Ok(Some((u, address as u16))),
        _ => Err(format!("address {abs} is past universe 63999")),
    }
}

/// Universe and start address (`None`: not patched), and the addresses taken if known.
type Patched = (Option<(u16, u16)>, Option<usize>);

/// `U/A`, `U/A<E` or `U/A<U/E` (E the last address), or an absolute address (`276`,
/// `276<280`); empty is not patched. Returns the patch and the addresses it takes.
fn csv_address(text: &str) -> Result<Patched, String> {
    let text = text.trim();
    if text.is_empty() {
        return Ok((None, None));
    }
    let bad = || format!("ADDRESS `{text}` is not U/A (or U/A<E for a range)");
    let (start, end) = match text.split_once('<') {
        Some((s, e)) => (s.trim(), Some(e.trim())),
        None => (text, None),
    };
    let absolute = |s: &str| -> Result<u64, String> {
        match s.split_once('/') {
            Some((u, a)) => {
                let u: u64 = u.trim().parse().map_err(|_| bad())?;
                let a: u64 = a.trim().parse().map_err(|_| bad())?;
                if u == 0 || !(1..=512).contains(&a) {
                    return Err(bad());
                }
                Ok((u - 1) * 512 + a)
            }
            None => s.parse().map_err(|_| bad()),
        }
    };
    let first = absolute(start)?;
    let patch = split_absolute(first)?;
    // Eos writes a single address without an end.
    let footprint = match (patch, end) {
        (Some(_), None) => Some(1),
        (Some((u, _)), Some(e)) => {
            // A bare end is an address in the start's universe.
            let last = if e.contains('/') {
                absolute(e)?
            } else {
                let a: u64 = e.parse().map_err(|_| bad())?;
                (u64::from(u) - 1) * 512 + a
            };
            if last < first {
                return Err(format!("ADDRESS `{text}` ends before it starts"));
            }
            Some((last - first + 1) as usize)
        }
        _ => None,
    };
    Ok((patch, footprint))
}

/// Text as UTF-8 (a BOM dropped), else as Latin-1 (a console on Windows may write it).
fn text_of(bytes: &[u8]) -> String {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    match std::str::from_utf8(bytes) {
        Ok(s) => s.to_string(),
        Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
    }
}

/// CSV records (RFC 4180 quoting: `"a,b"`, `""` for a quote, line breaks inside quotes),
/// one at a time with the line each starts on, so only the rows kept take memory; `Err`
/// names the line of an unterminated quote (and ends the records).
struct Records<'a> {
    chars: std::iter::Peekable<std::str::Chars<'a>>,
    line: usize,
}

fn records(text: &str) -> Records<'_> {
    Records {
        chars: text.chars().peekable(),
        line: 1,
    }
}

impl Iterator for Records<'_> {
    type Item = Result<(usize, Vec<String>), usize>;

    fn next(&mut self) -> Option<Self::Item> {
        let start = self.line;
        let mut fields = Vec::new();
        let mut field = String::new();
        let mut quoted = false;
        while let Some(c) = self.chars.next() {
            if quoted {
                match c {
                    '"' if self.chars.peek() == Some(&'"') => {
                        self.chars.next();
                        field.push('"');
                    }
                    '"' => quoted = false,
                    '\n' => {
                        self.line += 1;
                        field.push('\n');
                    }
                    other => field.push(other),
                }
                continue;
            }
            match c {
                '"' => quoted = true,
                ',' => fields.push(std::mem::take(&mut field)),
                '\r' => {}
                '\n' => {
                    fields.push(field);
                    self.line += 1;
                    return Some(Ok((start, fields)));
                }
                other => field.push(other),
            }
        }
        if quoted {
            return Some(Err(start));
        }
        if !field.is_empty() || !fields.is_empty() {
            fields.push(field);
            return Some(Ok((start, fields)));
        }
        None
    }
}

/// The most channel parts a patch may have (a CSV export's channel rows, or a console's
/// patch count), and the most groups a console may report: far past any show (Eos
/// numbers channels up to 99999), and what bounds an import's memory and time.
pub const MAX_ENTRIES: usize = 100_000;

/// The largest CSV export read (a show's export is a few MB).
pub const MAX_CSV_BYTES: usize = 64 << 20;

/// Reads an Eos CSV export's patch (its `START_CHANNELS` block), row by row: at most
/// [`MAX_CSV_BYTES`] and [`MAX_ENTRIES`] channel parts. Errors name the file and the line.
pub fn parse_csv(file: &str, bytes: &[u8]) -> Result<EosPatch, RigError> {
    if bytes.len() > MAX_CSV_BYTES {
        return Err(RigError::new(
            file,
            None,
            format!(
                "is {} MB; an Eos CSV export read is at most {} MB",
                bytes.len() >> 20,
                MAX_CSV_BYTES >> 20
            ),
        ));
    }
    let text = text_of(bytes);
    let at = |line: usize, m: String| RigError::new(file, Some(format!("line {line}")), m);
    let unclosed = |line: usize| at(line, "a quoted field is never closed".into());
    let first = |r: &[String]| r.first().map(|s| s.trim().to_string()).unwrap_or_default();
    let mut rows = records(&text);
    let begin_line = loop {
        match rows.next() {
            None => {
                return Err(RigError::new(
                    file,
                    None,
                    "no START_CHANNELS block: not an Eos patch export (export the show as CSV with the patch)",
                ));
            }
            Some(Err(line)) => return Err(unclosed(line)),
            Some(Ok((line, r))) if first(&r) == "START_CHANNELS" => break line,
            Some(Ok(_)) => {}
        }
    };
    let (header_line, header) = match rows.next() {
        None => return Err(at(begin_line, "START_CHANNELS has no column row".into())),
        Some(Err(line)) => return Err(unclosed(line)),
        Some(Ok(row)) => row,
    };
    let column = |name: &str| -> Result<usize, RigError> {
        header
            .iter()
            .position(|h| h.trim() == name)
            .ok_or_else(|| at(header_line, format!("the column row has no {name}")))
    };
    let (c_channel, c_type, c_maker, c_address, c_label) = (
        column("CHANNEL")?,
        column("FIXTURE_TYPE")?,
        column("MANUFACTURER")?,
        column("ADDRESS")?,
        column("LABEL")?,
    );
    let mut patch = EosPatch::default();
    let mut parts: BTreeMap<u32, u32> = BTreeMap::new();
    let mut ended = false;
    for row in rows {
        let (line, row) = row.map_err(unclosed)?;
        if first(&row) == "END_CHANNELS" {
            ended = true;
            break;
        }
        if row.iter().all(|f| f.trim().is_empty()) {
            continue;
        }
        if patch.channels.len() == MAX_ENTRIES {
            return Err(at(
                line,
                format!("more than {MAX_ENTRIES} channel parts: not a patch this import reads"),
            ));
        }
        let get = |i: usize| row.get(i).map(|s| s.trim()).unwrap_or("");
        if row.len() < header.len() {
            return Err(at(
                line,
                format!(
                    "{} fields where the column row has {}",
                    row.len(),
                    header.len()
                ),
            ));
        }
        let channel: u32 = get(c_channel)
            .parse()
            .ok()
            .filter(|&c| c > 0)
            .ok_or_else(|| {
                at(
                    line,
                    format!("CHANNEL `{}` is not a channel number", get(c_channel)),
                )
            })?;
        let (address, footprint) =
            csv_address(get(c_address)).map_err(|e| at(line, format!("channel {channel}: {e}")))?;
        let part = parts.entry(channel).or_insert(0);
        *part += 1;
        patch.channels.push(EosChannel {
            channel,
            part: *part,
            label: get(c_label).to_string(),
            manufacturer: get(c_maker).to_string(),
            model: get(c_type).to_string(),
            address,
            footprint,
        });
    }
    if !ended {
        return Err(at(begin_line, "START_CHANNELS has no END_CHANNELS".into()));
    }
    Ok(patch)
}

/// A reply the import reads, told by its OSC address; everything else Eos sends (pings,
/// the active channel, the command line, notes, augment3d) is [`Reply::Other`].
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// `/eos/out/get/patch/count`.
    PatchCount,
    /// `/eos/out/get/group/count`.
    GroupCount,
    /// `/eos/out/get/fp/count`.
    PaletteCount,
    /// A piece of a focus palette's list, of its channel list, or of its by-type list.
    Palette {
        /// The palette number as sent.
        number: String,
        /// Which of its three lists.
        list: PaletteList,
        /// The piece's place in the whole list.
        piece: Piece,
    },
    /// A piece of a patch list: `/eos/out/get/patch/<channel>/<part>/list/<offset>/<total>`.
    Patch {
        /// Channel.
        channel: u32,
        /// Part.
        part: u32,
        /// The piece's place in the whole list.
        piece: Piece,
    },
    /// A piece of a group's list, or (`channels`) of its channel list.
    Group {
        /// The group number as sent.
        number: String,
        /// `/channels/list/...` rather than `/list/...`.
        channels: bool,
        /// The piece's place in the whole list.
        piece: Piece,
    },
    /// Anything else.
    Other,
}

/// Which of a focus palette's three replies a message is part of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaletteList {
    /// `/list/...`: index, UID, label, absolute, locked.
    Main,
    /// `/channels/list/...`: index, UID, the member channels.
    Channels,
    /// `/byType/list/...`: index, UID, the by-type channels.
    ByType,
}

/// Where a message's arguments sit in a list split over several messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Piece {
    /// Offset of the message's first argument in the whole list.
    pub offset: usize,
    /// Length of the whole list.
    pub total: usize,
}

/// What the reply at `address` is.
pub fn reply(address: &str) -> Reply {
    let parts: Vec<&str> = address.trim_start_matches('/').split('/').collect();
    let piece = |o: &str, t: &str| -> Option<Piece> {
        Some(Piece {
            offset: o.parse().ok()?,
            total: t.parse().ok()?,
        })
    };
    match parts.as_slice() {
        ["eos", "out", "get", "patch", "count"] => Reply::PatchCount,
        ["eos", "out", "get", "group", "count"] => Reply::GroupCount,
        ["eos", "out", "get", "patch", ch, part, "list", o, t] => {
            match (ch.parse(), part.parse(), piece(o, t)) {
                (Ok(channel), Ok(part), Some(piece)) => Reply::Patch {
                    channel,
                    part,
                    piece,
                },
                _ => Reply::Other,
            }
        }
        ["eos", "out", "get", "group", n, "list", o, t] => match piece(o, t) {
            Some(piece) => Reply::Group {
                number: (*n).to_string(),
                channels: false,
                piece,
            },
            None => Reply::Other,
        },
        ["eos", "out", "get", "group", n, "channels", "list", o, t] => match piece(o, t) {
            Some(piece) => Reply::Group {
                number: (*n).to_string(),
                channels: true,
                piece,
            },
            None => Reply::Other,
        },
        ["eos", "out", "get", "fp", "count"] => Reply::PaletteCount,
        ["eos", "out", "get", "fp", n, rest @ ..] => {
            let (list, o, t) = match rest {
                ["list", o, t] => (PaletteList::Main, o, t),
                ["channels", "list", o, t] => (PaletteList::Channels, o, t),
                ["byType", "list", o, t] => (PaletteList::ByType, o, t),
                _ => return Reply::Other,
            };
            match piece(o, t) {
                Some(piece) => Reply::Palette {
                    number: (*n).to_string(),
                    list,
                    piece,
                },
                None => Reply::Other,
            }
        }
        _ => Reply::Other,
    }
}

/// Lists split over several messages, put back together by key (the list's address
/// without `/list/...`).
#[derive(Debug, Default)]
pub struct Lists {
    open: BTreeMap<String, Vec<Option<Arg>>>,
}

/// The longest list accepted (a patch reply has 21 fields; a group's channel list one per
/// range).
const MAX_LIST: usize = MAX_ENTRIES;

impl Lists {
    /// Adds a message's arguments at `piece`; returns the whole list once every position
    /// has arrived. An error when the piece does not fit its list.
    pub fn add(
        &mut self,
        key: &str,
        piece: Piece,
        args: Vec<Arg>,
    ) -> Result<Option<Vec<Arg>>, String> {
        if piece.total > MAX_LIST || piece.offset + args.len() > piece.total {
            return Err(format!(
                "{key}: {} arguments at offset {} of a {}-long list",
                args.len(),
                piece.offset,
                piece.total
            ));
        }
        let list = self
            .open
            .entry(key.to_string())
            .or_insert_with(|| vec![None; piece.total]);
        if list.len() != piece.total {
            // A new reply for the same target: start over.
            *list = vec![None; piece.total];
        }
        for (slot, a) in list[piece.offset..].iter_mut().zip(args) {
            *slot = Some(a);
        }
        if list.iter().all(Option::is_some) {
            let done = self.open.remove(key).unwrap_or_default();
            return Ok(Some(done.into_iter().flatten().collect()));
        }
        Ok(None)
    }
}

/// The first argument of a list as a count or an index (a count reply's only argument, a
/// list's index), None when it is not a non-negative whole number.
pub fn first_number(list: &[Arg]) -> Option<usize> {
    list.first()
        .and_then(Arg::int)
        .and_then(|i| usize::try_from(i).ok())
}

/// A whole patch list as a channel part (fields as in the module header).
pub fn patch_entry(channel: u32, part: u32, list: &[Arg]) -> Result<EosChannel, String> {
    let text = |i: usize| list.get(i).map(Arg::text).unwrap_or_default();
    let what = format!("channel {channel} part {part}");
    if list.len() <= field::ADDRESS {
        return Err(format!(
            "{what}: the reply has {} fields, the patch list has at least {}",
            list.len(),
            field::ADDRESS + 1
        ));
    }
    let abs = list[field::ADDRESS]
        .int()
        .and_then(|a| u64::try_from(a).ok())
        .ok_or_else(|| format!("{what}: address `{}` is not a number", text(field::ADDRESS)))?;
    let address = split_absolute(abs).map_err(|e| format!("{what}: {e}"))?;
    let end = list
        .get(field::END_ADDRESS)
        .and_then(Arg::int)
        .and_then(|e| u64::try_from(e).ok());
    let footprint = match (address, end) {
        (Some(_), Some(e)) if e >= abs => Some((e - abs + 1) as usize),
        _ => None,
    };
    Ok(EosChannel {
        channel,
        part,
        label: text(field::LABEL).trim().to_string(),
        manufacturer: text(field::MANUFACTURER).trim().to_string(),
        model: text(field::MODEL).trim().to_string(),
        address,
        footprint,
    })
}

/// A group from its list (label) and its channel list (`1-100`, `200`, or numbers).
pub fn group_entry(number: &str, list: &[Arg], channels: &[Arg]) -> Result<EosGroup, String> {
    let (label, channels) = label_and_channels(&format!("group {number}"), list, channels)?;
    Ok(EosGroup {
        number: number.to_string(),
        label,
        channels,
    })
}

/// A focus palette from its list (label) and its channel list, read as a group's.
pub fn palette_entry(number: &str, list: &[Arg], channels: &[Arg]) -> Result<EosPalette, String> {
    let (label, channels) = label_and_channels(&format!("focus palette {number}"), list, channels)?;
    Ok(EosPalette {
        number: number.to_string(),
        label,
        channels,
    })
}

/// The label of a target's list and the channels of its channel list (`what` names it in
/// errors): groups and palettes answer alike.
fn label_and_channels(
    what: &str,
    list: &[Arg],
    channels: &[Arg],
) -> Result<(String, Vec<u32>), String> {
    let mut out = Vec::new();
    for a in channels.iter().skip(field::GROUP_LABEL) {
        let parsed = crate::parse_channels(&a.text())
            .map_err(|item| format!("{what}: `{item}` is not a channel or a range"))?;
        out.extend(parsed);
    }
    let label = list
        .get(field::GROUP_LABEL)
        .map(Arg::text)
        .unwrap_or_default()
        .trim()
        .to_string();
    Ok((label, out))
}

impl EosPatch {
    /// The rig this patch makes: part 1 of every patched channel becomes a fixture whose
    /// type is resolved through `library` ([`Library::find_eos`]; Eos's `Generic Dimmer`
    /// is the built-in `dimmer`); its group is the first group (in source order) holding
    /// it, by label, else `Group N`. Other parts and unpatched channels are listed as
    /// skipped; types no file matches need a profile.
    pub fn to_rig(&self, library: &Library) -> Rig {
        let mut rig = Rig::default();
        for c in &self.channels {
            let ty = format!("{} {}", c.manufacturer, c.model).trim().to_string();
            let who = format!("channel {} \"{}\" ({ty})", c.channel, c.label);
            if c.part != 1 {
                rig.skipped.push(format!(
                    "{who}: part {} (only a channel's first part becomes a light)",
                    c.part
                ));
                continue;
            }
            let Some((universe, address)) = c.address else {
                rig.skipped.push(format!("{who}: not patched"));
                continue;
            };
            let group = self
                .groups
                .iter()
                .find(|g| g.channels.contains(&c.channel))
                .map(|g| {
                    if g.label.is_empty() {
                        format!("Group {}", g.number)
                    } else {
                        g.label.clone()
                    }
                });
            let fixture_type = resolve(library, c, &ty);
            rig.add(
                Fixture {
                    channel: c.channel,
                    name: c.label.clone(),
                    group,
                    universe,
                    address,
                    fixture_type: 0,
                },
                fixture_type,
            );
        }
        rig
    }
}

/// Eos's own dimmer type: one 8-bit intensity slot.
fn is_generic_dimmer(c: &EosChannel) -> bool {
    compact(&c.manufacturer) == "generic" && compact(&c.model) == "dimmer"
}

fn resolve(library: &Library, c: &EosChannel, ty: &str) -> FixtureType {
    if is_generic_dimmer(c)
        && let Some(p) = Profile::built_in("dimmer")
    {
        return FixtureType {
            name: p.name.clone(),
            footprint: Some(1),
            profile: Ok(p),
        };
    }
    match library.find_eos(&c.manufacturer, &c.model) {
        // A patch of another width than the type's is another mode: not this one.
        Some(Ok(t)) => match (t.footprint, c.footprint) {
            (Some(lib), Some(eos)) if lib != eos => FixtureType {
                name: ty.to_string(),
                footprint: c.footprint,
                profile: Err(format!(
                    "{} matches its name but takes {lib} addresses where the patch gives {eos}",
                    t.name
                )),
            },
            _ => t,
        },
        Some(Err(why)) => FixtureType {
            name: ty.to_string(),
            footprint: c.footprint,
            profile: Err(why),
        },
        None => FixtureType {
            name: ty.to_string(),
            footprint: c.footprint,
            profile: Err(
                "no GDTF or OFL file in --fixtures matches its manufacturer and model".into(),
            ),
        },
    }
}

/// A name reduced to its lowercase letters and digits, how Eos names and library names are
/// compared (`JB_Lighting` = `JB-Lighting` = `jb lighting`).
pub fn compact(s: &str) -> String {
    s.chars()
        .filter(|c| c.is_alphanumeric())
        .flat_map(char::to_lowercase)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_read_as_eos_writes_them() {
        assert_eq!(csv_address(" 1/276"), Ok((Some((1, 276)), Some(1))));
        assert_eq!(csv_address(" 4/249<290"), Ok((Some((4, 249)), Some(42))));
        assert_eq!(csv_address("3/151<3/153"), Ok((Some((3, 151)), Some(3))));
        assert_eq!(csv_address("513"), Ok((Some((2, 1)), Some(1))));
        assert_eq!(csv_address(""), Ok((None, None)));
        assert!(csv_address("1/513").is_err());
        assert!(csv_address("1/20<10").is_err());
        assert_eq!(split_absolute(1024), Ok(Some((2, 512))));
    }

    #[test]
    fn csv_records_keep_quoted_commas_and_lines() {
        let r: Vec<_> = records("a,\"b,c\",\"d\"\"e\"\r\n\"x\ny\",z\nlast").collect();
        assert_eq!(
            r,
            vec![
                Ok((1, vec!["a".into(), "b,c".into(), "d\"e".into()])),
                Ok((2, vec!["x\ny".into(), "z".into()])),
                Ok((4, vec!["last".into()])),
            ]
        );
        assert_eq!(records("a,\"b\nc").collect::<Vec<_>>(), [Err(1)]);
    }

    #[test]
    fn csv_parts_follow_row_order_and_errors_name_the_line() {
        let csv = "START_CHANNELS\nCHANNEL,FIXTURE_TYPE,MANUFACTURER,ADDRESS,LABEL\n\
                   7,Dimmer,Generic, 1/7,A\n7,Scroller,Custom, 1/8<9,\n8,Dimmer,Generic,,B\nEND_CHANNELS\n";
        let p = parse_csv("x.csv", csv.as_bytes()).unwrap_or_default();
        let got: Vec<String> = p
            .channels
            .iter()
            .map(|c| format!("{}.{} {:?} {:?}", c.channel, c.part, c.address, c.footprint))
            .collect();
        assert_eq!(
            got,
            [
                "7.1 Some((1, 7)) Some(1)",
                "7.2 Some((1, 8)) Some(2)",
                "8.1 None None"
            ]
        );
        let bad = csv.replace("8,Dimmer", "8x,Dimmer");
        let e = parse_csv("x.csv", bad.as_bytes()).unwrap_err().to_string();
        assert_eq!(e, "x.csv: line 5: CHANNEL `8x` is not a channel number");
        let bad = csv.replace("1/8<9", "1/800");
        let e = parse_csv("x.csv", bad.as_bytes()).unwrap_err().to_string();
        assert!(
            e.starts_with("x.csv: line 4: channel 7: ADDRESS `1/800`"),
            "{e}"
        );
    }

    #[test]
    fn replies_are_told_by_address() {
        assert_eq!(
            reply("/eos/out/get/patch/12/1/list/0/21"),
            Reply::Patch {
                channel: 12,
                part: 1,
                piece: Piece {
                    offset: 0,
                    total: 21
                }
            }
        );
        assert!(matches!(
            reply("/eos/out/get/group/1.2/channels/list/2/5"),
            Reply::Group { channels: true, .. }
        ));
        assert_eq!(reply("/eos/out/get/fp/count"), Reply::PaletteCount);
        assert_eq!(
            reply("/eos/out/get/fp/3/byType/list/0/2"),
            Reply::Palette {
                number: "3".into(),
                list: PaletteList::ByType,
                piece: Piece {
                    offset: 0,
                    total: 2
                }
            }
        );
        assert!(matches!(
            reply("/eos/out/get/fp/3.5/channels/list/2/4"),
            Reply::Palette {
                list: PaletteList::Channels,
                ..
            }
        ));
        assert_eq!(reply("/eos/out/get/fp/3/notes"), Reply::Other);
        for other in [
            "/eos/out/ping",
            "/eos/out/active/chan",
            "/eos/out/get/patch/12/1/notes",
            "/eos/out/get/patch/12/1/augment3d/position",
        ] {
            assert_eq!(reply(other), Reply::Other, "{other}");
        }
    }

    #[test]
    fn split_lists_are_put_back_together() {
        let mut lists = Lists::default();
        let key = "/eos/out/get/curve/901";
        let got = lists.add(
            key,
            Piece {
                offset: 0,
                total: 3,
            },
            vec![Arg::Int(0), Arg::Str("u".into())],
        );
        assert_eq!(got, Ok(None));
        let got = lists.add(
            key,
            Piece {
                offset: 2,
                total: 3,
            },
            vec![Arg::Str("IES".into())],
        );
        assert_eq!(
            got,
            Ok(Some(vec![
                Arg::Int(0),
                Arg::Str("u".into()),
                Arg::Str("IES".into())
            ]))
        );
        assert!(
            lists
                .add(
                    key,
                    Piece {
                        offset: 2,
                        total: 3
                    },
                    vec![Arg::Int(1), Arg::Int(2)]
                )
                .is_err()
        );
    }

    #[test]
    fn patch_and_group_lists_read_by_position() {
        // ETC's own example reply for channel 1 part 1, with a real address and end.
        let mut list = vec![
            Arg::Int(0),
            Arg::Str("UID".into()),
            Arg::Str("Channel Label".into()),
            Arg::Str("ETC_Fixtures".into()),
            Arg::Str("Releve_Spot_Direct".into()),
            Arg::Int(513),
            Arg::Int(513),
            Arg::Int(100),
            Arg::Str(String::new()),
        ];
        list.extend((1..=10).map(|i| Arg::Str(format!("Text{i}"))));
        list.extend([Arg::Int(1), Arg::Int(537)]);
        let c = patch_entry(1, 1, &list).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.address, Some((2, 1)));
        assert_eq!(c.footprint, Some(25));
        assert_eq!(
            (c.manufacturer.as_str(), c.model.as_str()),
            ("ETC_Fixtures", "Releve_Spot_Direct")
        );
        let g = group_entry(
            "1.2",
            &[
                Arg::Int(0),
                Arg::Str("U".into()),
                Arg::Str("My Group".into()),
            ],
            &[
                Arg::Int(0),
                Arg::Str("U".into()),
                Arg::Str("1-3".into()),
                Arg::Int(200),
            ],
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(g.channels, [1, 2, 3, 200]);
        assert_eq!(g.label, "My Group");
        let fp = |number: &str| {
            palette_entry(
                number,
                &[Arg::Int(0), Arg::Str("U".into()), Arg::Str(" DS ".into())],
                &[
                    Arg::Int(0),
                    Arg::Str("U".into()),
                    Arg::Str("101-103".into()),
                ],
            )
            .unwrap_or_else(|e| panic!("{e}"))
        };
        assert_eq!((fp("3").label.as_str(), fp("3").whole()), ("DS", Some(3)));
        assert_eq!(fp("3").channels, [101, 102, 103]);
        assert_eq!(fp("2.5").whole(), None);
        assert_eq!(fp("10000").whole(), None);
    }
}
