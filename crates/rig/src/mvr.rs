//! MVR (DIN SPEC 15801): a zip with `GeneralSceneDescription.xml` and the GDTF files its
//! fixtures name. Every `Fixture`, wherever it sits (layers, `GroupObject`s, child lists
//! of other objects), becomes a fixture of the rig: channel = `FixtureIDNumeric` when not
//! 0, else `FixtureID` read as a number; its `GroupObject` (the nearest) is its group;
//! `GDTFSpec` + `GDTFMode` its type; `Addresses` > `Address` its patch. An `Address` is an
//! integer, the absolute DMX address `(universe - 1) * 512 + address`, or the string
//! `Universe.Address` (mvrdevelopment/spec `mvr-spec.md`, Table 50 and 51); the `break`
//! attribute (default 0) is the GDTF DMX break minus one, and break 0 is the fixture's
//! start address. Address 0 is not patched.

use std::collections::HashMap;

use crate::gdtf::GdtfType;
use crate::{Fixture, FixtureType, Rig, RigError};

/// The scene description's name inside the zip.
const SCENE: &str = "GeneralSceneDescription.xml";

/// Reads an `.mvr` file into a rig (checked: no channel twice, no slot twice).
pub fn parse(file: &str, bytes: &[u8]) -> Result<Rig, RigError> {
    let mut archive = crate::open_zip(file, bytes)?;
    let xml = crate::zip_entry(file, &mut archive, SCENE)?;
    let text = crate::utf8(&format!("{file}: {SCENE}"), &xml)?;
    let doc = crate::xml(&format!("{file}: {SCENE}"), text)?;
    let root = doc.root_element();

    let mut found = Vec::new();
    let mut nameless = 0;
    walk(root, None, &mut nameless, &mut found);

    let mut types: HashMap<String, Result<GdtfType, String>> = HashMap::new();
    let mut rig = Rig::default();
    for f in found {
        if f.multipatch {
            rig.skipped.push(format!(
                "fixture \"{}\": a multipatch copy (its parent's channel drives it)",
                f.name
            ));
            continue;
        }
        let channel = match f.channel() {
            Some(c) => c,
            None => {
                rig.skipped.push(format!(
                    "fixture \"{}\": no numeric FixtureID (`{}`), so no channel",
                    f.name, f.fixture_id
                ));
                continue;
            }
        };
        let who_ch = Some(format!("channel {channel} \"{}\"", f.name));
        let (universe, address) = match f.address.as_deref().map(parse_address) {
            None | Some(Ok(None)) => {
                rig.skipped
                    .push(format!("channel {channel} \"{}\": not patched", f.name));
                continue;
            }
            Some(Ok(Some(ua))) => ua,
            Some(Err(e)) => return Err(RigError::new(file, who_ch, e)),
        };
        let fixture_type = if f.spec.is_empty() {
            FixtureType {
                name: format!("\"{}\" without a GDTF", f.name),
                footprint: None,
                profile: Err("the MVR gives it no GDTFSpec".into()),
            }
        } else {
            let entry = [f.spec.clone(), format!("{}.gdtf", f.spec)]
                .into_iter()
                .find(|n| archive.index_for_name(n).is_some());
            match entry {
                // A type the plot names but does not carry: the rest of the plot imports,
                // and this type is listed once with its channels (`Rig::needs_profiles`).
                None => FixtureType {
                    name: f.spec.clone(),
                    footprint: None,
                    profile: Err(format!(
                        "its GDTFSpec `{}` is not in the MVR: export the plot with its GDTF files, or give the type a profile",
                        f.spec
                    )),
                },
                // A GDTF that does not read, or lacks the plot's mode, is the same: the
                // type is listed once with its channels, and the rest imports.
                Some(entry) => {
                    let ty = types.entry(f.spec.clone()).or_insert_with(|| {
                        crate::zip_entry(file, &mut archive, &entry)
                            .and_then(|gdtf| GdtfType::parse(&entry, &gdtf))
                            .map_err(|e| format!("its GDTF {e}"))
                    });
                    let unusable = |why: String| FixtureType {
                        name: format!("{} ({})", f.spec, f.mode),
                        footprint: None,
                        profile: Err(format!(
                            "{why}: fix or replace the GDTF in the MVR, or give the type a profile"
                        )),
                    };
                    match ty {
                        Ok(ty) => ty.fixture_type(&f.mode).unwrap_or_else(|e| {
                            unusable(format!("its GDTF `{}` {}", f.spec, e.message))
                        }),
                        Err(why) => unusable(why.clone()),
                    }
                }
            }
        };
        rig.add(
            Fixture {
                channel,
                name: f.name,
                group: f.group,
                universe,
                address,
                fixture_type: 0,
            },
            fixture_type,
        );
    }
    rig.check(file)?;
    Ok(rig)
}

/// A `Fixture` node's fields, as found.
struct Found {
    name: String,
    group: Option<String>,
    fixture_id: String,
    numeric: String,
    spec: String,
    mode: String,
    address: Option<String>,
    multipatch: bool,
}

impl Found {
    /// `FixtureIDNumeric` when not 0, else `FixtureID` as a number (not 0).
    fn channel(&self) -> Option<u32> {
        let n = |s: &str| s.trim().parse::<u32>().ok().filter(|&c| c > 0);
        n(&self.numeric).or_else(|| n(&self.fixture_id))
    }
}

/// Collects every `Fixture` under `node` in document order, with its nearest
/// `GroupObject`'s name (a group without a name is `group N`, numbered in document order
/// among the nameless groups that hold fixtures).
fn walk(node: roxmltree::Node, group: Option<&str>, nameless: &mut usize, out: &mut Vec<Found>) {
    for child in node.children().filter(|n| n.is_element()) {
        let text = |tag: &str| {
            child
                .children()
                .find(|n| n.has_tag_name(tag))
                .and_then(|n| n.text())
                .unwrap_or("")
                .trim()
                .to_string()
        };
        match child.tag_name().name() {
            "GroupObject" => {
                let named = child
                    .attribute("name")
                    .map(str::trim)
                    .filter(|n| !n.is_empty());
                let holds = child.descendants().any(|n| n.has_tag_name("Fixture"));
                let name = match named {
                    Some(n) => n.to_string(),
                    None if holds => {
                        *nameless += 1;
                        format!("group {nameless}")
                    }
                    None => String::new(),
                };
                walk(child, Some(&name), nameless, out);
            }
            "Fixture" => {
                let address = child
                    .children()
                    .find(|n| n.has_tag_name("Addresses"))
                    .and_then(|a| {
                        a.children()
                            .filter(|n| n.has_tag_name("Address"))
                            .min_by_key(|n| {
                                n.attribute("break")
                                    .and_then(|b| b.trim().parse::<i64>().ok())
                                    .unwrap_or(0)
                            })
                    })
                    .map(|a| a.text().unwrap_or("").trim().to_string());
                out.push(Found {
                    name: child.attribute("name").unwrap_or("").trim().to_string(),
                    group: group.map(str::to_string),
                    fixture_id: text("FixtureID"),
                    numeric: text("FixtureIDNumeric"),
                    spec: text("GDTFSpec"),
                    mode: text("GDTFMode"),
                    address,
                    multipatch: child
                        .attribute("multipatch")
                        .is_some_and(|m| !m.trim().is_empty()),
                });
                walk(child, group, nameless, out);
            }
            _ => walk(child, group, nameless, out),
        }
    }
}

/// An MVR address (`513` absolute, or `2.1`) as (universe, address); `None` for 0 (not
/// patched).
pub fn parse_address(text: &str) -> Result<Option<(u16, u16)>, String> {
    let bad =
        || format!("Address `{text}` is neither an absolute DMX address nor Universe.Address");
    let (universe, address) = match text.split_once('.') {
        Some((u, a)) => {
            let u: u64 = u.trim().parse().map_err(|_| bad())?;
            let a: u64 = a.trim().parse().map_err(|_| bad())?;
            if u == 0 && a == 0 {
                return Ok(None);
            }
            if u == 0 || !(1..=512).contains(&a) {
                return Err(bad());
            }
            (u, a)
        }
        None => {
            let abs: u64 = text.trim().parse().map_err(|_| bad())?;
            if abs == 0 {
                return Ok(None);
            }
            ((abs - 1) / 512 + 1, (abs - 1) % 512 + 1)
        }
    };
    if universe > 63999 {
        return Err(format!(
            "Address `{text}` is in universe {universe} (1-63999)"
        ));
    }
    Ok(Some((universe as u16, address as u16)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_are_absolute_or_universe_dot_address() {
        assert_eq!(parse_address("1"), Ok(Some((1, 1))));
        assert_eq!(parse_address("512"), Ok(Some((1, 512))));
        assert_eq!(parse_address("513"), Ok(Some((2, 1))));
        assert_eq!(parse_address("2.17"), Ok(Some((2, 17))));
        assert_eq!(parse_address("0"), Ok(None));
        assert!(parse_address("2.513").is_err());
        assert!(parse_address("A").is_err());
        assert!(parse_address("40000000").is_err());
    }
}
