//! `visobjd import`: a scene from the rig as the lighting world describes it (an MVR plot
//! with its GDTF fixture types; an Eos patch, from a CSV export or live from the console,
//! with `--fixtures` resolving the types it names), or a fixture type's modes as profiles
//! (a GDTF file, an Open Fixture Library JSON file). The source's kind is told by its
//! content; the parsing is the rig crate's. A re-import into an existing scene keeps what
//! a person or a capture added (docs/import.md, "What a re-import keeps").

mod eos;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use visobjd_rig::eos::EosPalette;
use visobjd_rig::{FixtureType, Kind, Library, Rig};
use visobjd_scene::profile::{Profile, ProfileFile};
use visobjd_scene::{GroupFile, LightFile, Scene, SceneFile};

/// Arguments of `import`.
#[derive(clap::Args)]
pub struct Args {
    /// An MVR plot (`.mvr`), a GDTF fixture type (`.gdtf`), an Open Fixture Library
    /// fixture (`.json`), an Eos CSV export (told apart by content), or an Eos console:
    /// `eos://HOST[:PORT]` (OSC 1.0, port 3032) or `eos+slip://HOST[:PORT]` (3037).
    source: String,
    /// The scene folder to write, or to update when it has a scene.toml (required for an
    /// MVR or an Eos patch; for a fixture type, its profiles are added to that existing
    /// scene).
    #[arg(long)]
    out: Option<PathBuf>,
    /// A folder of GDTF or OFL files (searched with its subfolders) resolving the fixture
    /// types an Eos patch names.
    #[arg(long)]
    fixtures: Option<PathBuf>,
    /// Seconds an Eos console may stay silent (connecting, or between replies) before the
    /// import gives up.
    #[arg(long, default_value_t = 5.0)]
    timeout: f64,
    /// Drop the scene's lights that the source does not have (default: keep them).
    #[arg(long)]
    prune: bool,
}

/// Runs `import`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.timeout.is_finite() && (0.1..=600.0).contains(&args.timeout)) {
        bail!("--timeout must be 0.1..=600 seconds, got {}", args.timeout);
    }
    if let Some(eos) = eos::target(&args.source) {
        let (addr, framing) = eos?;
        let Some(out) = &args.out else {
            bail!(
                "{}: an Eos patch becomes a scene: give --out SCENE_DIR",
                args.source
            );
        };
        let library = library(args.fixtures.as_deref())?;
        let quiet = Duration::from_secs_f64(args.timeout);
        let console = eos::read(&args.source, &addr, framing, quiet)?;
        let rig = console.patch.to_rig(&library);
        rig.check(&args.source)?;
        let host = addr.rsplit_once(':').map_or(addr.as_str(), |(h, _)| h);
        let palettes = match console.palettes {
            Ok(p) => p,
            Err(why) => {
                println!("focus palettes not read: {why} (the patch is imported without them)");
                Vec::new()
            }
        };
        return import_rig(
            &args.source,
            &format!("eos {host}"),
            &rig,
            &palettes,
            out,
            args.prune,
        );
    }
    let path = PathBuf::from(&args.source);
    let bytes =
        std::fs::read(&path).with_context(|| format!("{}: cannot read it", path.display()))?;
    let file = path.display().to_string();
    let kind = visobjd_rig::kind(&file, &bytes)?;
    if let (Some(dir), false) = (&args.fixtures, kind == Kind::EosCsv) {
        bail!(
            "--fixtures {}: a fixture library is for sources that only name fixture types (an Eos CSV export, eos://); {file} carries or is its fixture types",
            dir.display()
        );
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    match kind {
        Kind::Mvr => {
            let rig = visobjd_rig::mvr::parse(&file, &bytes)?;
            let Some(out) = &args.out else {
                bail!("{file}: an MVR becomes a scene: give --out SCENE_DIR");
            };
            import_rig(&file, &stem, &rig, &[], out, args.prune)
        }
        Kind::EosCsv => {
            let Some(out) = &args.out else {
                bail!("{file}: an Eos patch becomes a scene: give --out SCENE_DIR");
            };
            let patch = visobjd_rig::eos::parse_csv(&file, &bytes)?;
            let rig = patch.to_rig(&library(args.fixtures.as_deref())?);
            rig.check(&file)?;
            import_rig(&file, &stem, &rig, &[], out, args.prune)
        }
        Kind::Gdtf => {
            let ty = visobjd_rig::gdtf::GdtfType::parse(&file, &bytes)?;
            import_types(&file, &ty.fixture_types(), args.out.as_deref())
        }
        Kind::Ofl => {
            let ty = visobjd_rig::ofl::OflType::parse(&file, &bytes)?;
            import_types(&file, &ty.fixture_types(), args.out.as_deref())
        }
    }
}

/// How deep `--fixtures` is searched: a library nests a few levels
/// (`fixtures/<manufacturer>/`).
const MAX_FOLDER_DEPTH: usize = 32;

/// The GDTF (`.gdtf`) and OFL (`.json`) files under `dir`, by their path relative to it
/// (an OFL file's manufacturer is in its path); none without `--fixtures`. Links are
/// followed, but each folder and file is taken once, however many ways lead to it (a
/// link back up is no loop), and at most [`MAX_FOLDER_DEPTH`] folders down. A file there
/// that does not parse is an error naming it.
fn library(dir: Option<&Path>) -> anyhow::Result<Library> {
    let mut library = Library::default();
    let Some(dir) = dir else {
        return Ok(library);
    };
    let mut todo = vec![(dir.to_path_buf(), 0)];
    let mut files = Vec::new();
    // Folders and files by their real path: a link back up (a loop) is not walked again.
    let mut seen = BTreeSet::new();
    let real = |p: &Path| p.canonicalize().unwrap_or_else(|_| p.to_path_buf());
    while let Some((d, depth)) = todo.pop() {
        if !seen.insert(real(&d)) {
            continue;
        }
        if depth > MAX_FOLDER_DEPTH {
            bail!(
                "--fixtures {}: {} is more than {MAX_FOLDER_DEPTH} folders deep; give a library that nests less",
                dir.display(),
                d.display()
            );
        }
        let entries = std::fs::read_dir(&d)
            .with_context(|| format!("--fixtures {}: cannot read it", d.display()))?;
        for e in entries {
            let path = e
                .with_context(|| format!("--fixtures {}: cannot read it", d.display()))?
                .path();
            if path.is_dir() {
                todo.push((path, depth + 1));
            } else if seen.insert(real(&path)) {
                files.push(path);
            }
        }
    }
    files.sort();
    for path in files {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if ext != "gdtf" && ext != "json" {
            continue;
        }
        let bytes =
            std::fs::read(&path).with_context(|| format!("{}: cannot read it", path.display()))?;
        let shown = path.display().to_string();
        let relative = path
            .strip_prefix(dir)
            .unwrap_or(&path)
            .to_string_lossy()
            .into_owned();
        match visobjd_rig::kind(&shown, &bytes)? {
            Kind::Gdtf => library.add_gdtf(&shown, &bytes)?,
            Kind::Ofl => library
                .add_ofl(&relative, &bytes)
                .map_err(|e| anyhow::anyhow!("{}: {}", dir.display(), e))?,
            _ => bail!("{shown}: in --fixtures but not a GDTF or an Open Fixture Library file"),
        }
    }
    Ok(library)
}

/// The scene folder's scene.toml as written, if there is one.
fn existing(out: &Path) -> anyhow::Result<Option<SceneFile>> {
    let path = out.join("scene.toml");
    match std::fs::read_to_string(&path) {
        Ok(text) => Ok(Some(SceneFile::parse(&path, &text)?)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(anyhow::anyhow!("{}: cannot read it: {e}", path.display())),
    }
}

/// Validates `file` as a scene of `out` and writes it atomically.
fn write(out: &Path, file: &SceneFile) -> anyhow::Result<PathBuf> {
    let text = file.to_toml().map_err(anyhow::Error::msg)?;
    Scene::parse(out, &text)?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create it", out.display()))?;
    let path = out.join("scene.toml");
    visobjd_files::write_atomic(&path, text.as_bytes())
        .with_context(|| format!("{}: cannot write it", path.display()))?;
    Ok(path)
}

/// Whether per-emitter images captured for a light still fit its (re-imported) profile:
/// one image for each of its emitters, by name. A changed colour system drops them (the
/// light is previewed from its white image until it is captured per emitter again).
fn same_emitters(images: &std::collections::BTreeMap<String, String>, profile: &Profile) -> bool {
    let names = profile.mixed_emitters();
    images.len() == names.len() && names.iter().all(|n| images.contains_key(*n))
}

/// Where a new light's basis image goes: `basis/NNN.exr` by channel.
fn basis_path(channel: u32) -> String {
    format!("basis/{channel:03}.exr")
}

/// Builds or updates the scene in `out` from `rig` (`name`: the name a new scene gets),
/// its positions named after the console's focus palettes (`palettes`, from `eos://`).
fn import_rig(
    file: &str,
    name: &str,
    rig: &Rig,
    palettes: &[EosPalette],
    out: &Path,
    prune: bool,
) -> anyhow::Result<()> {
    let old = existing(out)?;
    let mut scene = merge(rig, name, old.as_ref(), prune);
    let named = name_positions(&mut scene.file, palettes);
    let lights = scene.file.light.len();
    if lights == 0 {
        let mut why = rig.needs_profiles();
        why.extend(rig.skipped.iter().cloned());
        bail!(
            "{file}: no fixture became a light ({})",
            if why.is_empty() {
                "the plot has no fixtures".to_string()
            } else {
                why.join("; ")
            }
        );
    }
    let path = write(out, &scene.file).map_err(|e| {
        if scene.kept.is_empty() {
            e
        } else {
            anyhow::anyhow!(
                "{e:#} (the scene's lights the source does not have are kept: {}; --prune drops them)",
                visobjd_rig::channel_list(&scene.kept)
            )
        }
    })?;
    println!(
        "import: {} lights from {file} ({} new), {} profiles -> {}",
        scene.imported,
        scene.new.len(),
        scene.file.profile.len(),
        path.display()
    );
    if !scene.new.is_empty() {
        println!(
            "basis images to capture: {}",
            visobjd_rig::channel_list(&scene.new)
        );
    }
    if !scene.kept.is_empty() {
        println!(
            "kept, not in the source: {} (--prune drops them)",
            visobjd_rig::channel_list(&scene.kept)
        );
    }
    if !scene.dropped.is_empty() {
        println!(
            "dropped, not in the source: {}",
            visobjd_rig::channel_list(&scene.dropped)
        );
    }
    for p in palettes {
        println!(
            "focus palette {}{}: {}{}",
            p.number,
            Some(&p.label)
                .filter(|l| !l.is_empty())
                .map_or(String::new(), |l| format!(" \"{l}\"")),
            visobjd_rig::channel_list(&p.channels),
            if p.whole().is_none() {
                " (not a whole number: a scene position cannot take it)"
            } else {
                ""
            }
        );
    }
    if !named.is_empty() {
        println!(
            "positions named after the console's palettes: {}",
            visobjd_rig::channel_list(&named)
        );
    }
    for s in &rig.skipped {
        println!("not a light: {s}");
    }
    for n in rig.needs_profiles() {
        println!("{n}");
    }
    Ok(())
}

/// Names every light's position `n` after the console's focus palette `n` (its label;
/// pan, tilt and basis stay), so learned and imported palettes share the console's
/// names; returns the channels whose positions were named.
fn name_positions(file: &mut SceneFile, palettes: &[EosPalette]) -> Vec<u32> {
    let labels: BTreeMap<u32, &str> = palettes
        .iter()
        .filter(|p| !p.label.is_empty())
        .filter_map(|p| Some((p.whole()?, p.label.as_str())))
        .collect();
    let mut named: Vec<u32> = labels
        .iter()
        .flat_map(|(&n, label)| file.name_palette(n, label))
        .collect();
    named.sort_unstable();
    named.dedup();
    named
}

/// A merged scene and what the merge did.
struct Merged {
    file: SceneFile,
    /// Lights that came from the source.
    imported: usize,
    /// Channels new to the scene (their basis images are still to be captured).
    new: Vec<u32>,
    /// Channels of the scene the source does not have, kept.
    kept: Vec<u32>,
    /// The same, dropped (`--prune`).
    dropped: Vec<u32>,
}

/// The scene `rig` makes, merged into `old`: the source decides each light's name, patch,
/// profile and (where it has one) group; the scene keeps its name, exposure, every basis
/// path, the groups given in visobjd to lights whose source has none, and (unless
/// `prune`) the lights the source does not make (absent, or of a type that needs a
/// profile).
fn merge(rig: &Rig, name: &str, old: Option<&SceneFile>, prune: bool) -> Merged {
    let empty = SceneFile::default();
    let old = old.unwrap_or(&empty);
    let stem = Some(name.to_string()).filter(|n| !n.is_empty());
    let mut lights: Vec<LightFile> = Vec::new();
    let mut profiles: Vec<ProfileFile> = Vec::new();
    let mut new = Vec::new();
    for f in &rig.fixtures {
        let FixtureType {
            profile: Ok(profile),
            ..
        } = &rig.types[f.fixture_type]
        else {
            continue;
        };
        // A built-in profile (an Eos dimmer) is known to every scene without a table.
        let built_in = Profile::built_in(&profile.name).is_some_and(|b| &b == profile);
        if !built_in && !profiles.iter().any(|p| p.name == profile.name) {
            profiles.push(profile.to_file());
        }
        let before = old.light.iter().find(|l| l.channel == f.channel);
        if before.is_none() {
            new.push(f.channel);
        }
        // What capture made of the light's emitters holds while they are still the same.
        let kept = before.filter(|l| same_emitters(&l.emitter_basis, profile));
        // A mover's positions hold while its fixture type can still be aimed; else its
        // first position's image is its one basis.
        let (basis, positions) = match before {
            Some(l) if !l.positions.is_empty() && profile.is_moving() => {
                (None, l.positions.clone())
            }
            Some(l) => (
                l.basis
                    .clone()
                    .or_else(|| l.positions.first().map(|p| p.basis.clone())),
                Vec::new(),
            ),
            None => (Some(basis_path(f.channel)), Vec::new()),
        };
        lights.push(LightFile {
            channel: f.channel,
            name: Some(f.name.clone()).filter(|n| !n.is_empty()),
            group: f
                .group
                .clone()
                .filter(|g| !g.is_empty())
                .or_else(|| before.and_then(|l| l.group.clone())),
            basis,
            profile: profile.name.clone(),
            universe: f.universe,
            address: f.address,
            emitter_basis: kept.map(|l| l.emitter_basis.clone()).unwrap_or_default(),
            emitter_measured: kept.map(|l| l.emitter_measured.clone()).unwrap_or_default(),
            ma3_id: before.and_then(|l| l.ma3_id),
            positions,
        });
    }
    let imported = lights.len();
    // A light whose fixture type needs a profile stays as the scene has it.
    let from_source: BTreeSet<u32> = lights.iter().map(|l| l.channel).collect();
    let (mut kept, mut dropped) = (Vec::new(), Vec::new());
    for l in old
        .light
        .iter()
        .filter(|l| !from_source.contains(&l.channel))
    {
        if prune {
            dropped.push(l.channel);
        } else {
            kept.push(l.channel);
            lights.push(l.clone());
        }
    }
    lights.sort_by_key(|l| l.channel);
    // The scene's own profiles stay where a kept light uses them and the source does not
    // redefine them.
    for p in &old.profile {
        let used = lights.iter().any(|l| l.profile == p.name);
        if used && !profiles.iter().any(|q| q.name == p.name) {
            profiles.push(p.clone());
        }
    }
    let used: BTreeSet<&str> = lights.iter().filter_map(|l| l.group.as_deref()).collect();
    let mut groups: Vec<GroupFile> = old
        .group
        .iter()
        .filter(|g| used.contains(g.name.as_str()))
        .cloned()
        .collect();
    for l in &lights {
        if let Some(g) = &l.group
            && !groups.iter().any(|x| &x.name == g)
        {
            groups.push(GroupFile { name: g.clone() });
        }
    }
    Merged {
        file: SceneFile {
            name: old.name.clone().or(stem),
            exposure: old.exposure,
            group: groups,
            light: lights,
            profile: profiles,
        },
        imported,
        new,
        kept,
        dropped,
    }
}

/// A fixture type's modes: printed as profiles, and added to the scene in `out` if given.
fn import_types(file: &str, types: &[FixtureType], out: Option<&Path>) -> anyhow::Result<()> {
    for t in types {
        match &t.profile {
            Ok(p) => println!(
                "profile \"{}\": {} slot{}: {}{}",
                t.name,
                p.footprint(),
                if p.footprint() == 1 { "" } else { "s" },
                p.channel_names().join(", "),
                if p.is_moving() {
                    format!(
                        "; pan {} and tilt {} degrees of travel",
                        p.pan_range, p.tilt_range
                    )
                } else {
                    String::new()
                }
            ),
            Err(why) => println!(
                "needs a profile: {}{}: {why}",
                t.name,
                t.footprint
                    .map_or(String::new(), |n| format!(" ({n} channels)"))
            ),
        }
    }
    let Some(out) = out else {
        return Ok(());
    };
    let Some(mut scene) = existing(out)? else {
        bail!(
            "{}: there is no scene.toml to add {file}'s profiles to (a fixture type has no lights: import an MVR, or write the [[light]]s first)",
            out.display()
        );
    };
    let mut added = 0;
    for t in types {
        if let Ok(p) = &t.profile {
            scene.profile.retain(|q| q.name != p.name);
            scene.profile.push(p.to_file());
            added += 1;
        }
    }
    let path = write(out, &scene)?;
    println!("import: {added} profiles from {file} -> {}", path.display());
    Ok(())
}
