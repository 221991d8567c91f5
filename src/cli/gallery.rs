//! `visobjd gallery`: one generate, offline, written as a contact sheet and JSON.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::ArgMatches;
use rand::SeedableRng;
use serde::Serialize;

use visobjd_method::gallery::{Generation, MAX_SEED};
use visobjd_method::objective::{
    Aspects, Objective, ObjectiveRecord, Region, analyze, decode_reference,
};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::sheet::contact_sheet;
use visobjd_method::stage::{GenerateRequest, Stage, THUMB_WIDTH};
use visobjd_scene::look::{LightEntry, LookFile, entries};

/// Arguments of `gallery`. `--aspects`, `--region` and `--crop` apply to the `--ref`
/// before them (or, given before any `--ref`, to the first).
#[derive(clap::Args)]
pub struct Args {
    /// The scene folder.
    #[arg(long)]
    scene: PathBuf,
    /// A reference image; repeat for several objectives.
    #[arg(long = "ref", required = true)]
    refs: Vec<PathBuf>,
    /// intensity, color or both (default both), for the preceding --ref.
    #[arg(long)]
    aspects: Vec<String>,
    /// Stage region X0,Y0,X1,Y1 (0..1, y down) the preceding --ref aims at.
    #[arg(long)]
    region: Vec<String>,
    /// Part of the preceding reference image to analyse, X0,Y0,X1,Y1 (default all).
    #[arg(long)]
    crop: Vec<String>,
    /// Candidates to accept (N).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=1000))]
    count: u32,
    /// Gallery entries at most (c).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u32).range(1..=64))]
    clusters: u32,
    /// Random seed (0..=2147483647, the daemon's range: `/vo/generate/seeded` replays it
    /// live); the same inputs and seed give the same gallery. Default: a new one.
    #[arg(long)]
    seed: Option<u64>,
    /// Colours per palette.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=16))]
    palette: u32,
    /// A look file to start from (default: all off).
    #[arg(long)]
    base: Option<PathBuf>,
    /// A designer-chosen key group (repeatable).
    #[arg(long)]
    key: Vec<String>,
    /// A group that keeps its base values (repeatable).
    #[arg(long)]
    lock: Vec<String>,
    /// Sample each light on its own instead of per group.
    #[arg(long)]
    per_light: bool,
    /// The contact sheet to write (PNG).
    #[arg(long)]
    out: PathBuf,
    /// Also write every candidate's levels as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// For each occurrence of per-reference option `id`, the reference it belongs to.
fn per_ref(matches: &ArgMatches, id: &str) -> Vec<usize> {
    let refs: Vec<usize> = matches
        .indices_of("refs")
        .map(Iterator::collect)
        .unwrap_or_default();
    matches
        .indices_of(id)
        .map(|idx| {
            idx.map(|i| refs.iter().rposition(|&r| r < i).unwrap_or(0))
                .collect()
        })
        .unwrap_or_default()
}

/// Runs `gallery`.
pub fn run(args: Args, matches: &ArgMatches) -> anyhow::Result<()> {
    let n = args.refs.len();
    let mut aspects = vec![Aspects::Both; n];
    let mut regions = vec![Region::FULL; n];
    let mut crops = vec![Region::FULL; n];
    for (v, r) in args.aspects.iter().zip(per_ref(matches, "aspects")) {
        aspects[r] = Aspects::parse(v).map_err(anyhow::Error::msg)?;
    }
    for (v, r) in args.region.iter().zip(per_ref(matches, "region")) {
        regions[r] = Region::parse(v).map_err(anyhow::Error::msg)?;
    }
    for (v, r) in args.crop.iter().zip(per_ref(matches, "crop")) {
        crops[r] = Region::parse(v).map_err(anyhow::Error::msg)?;
    }

    let stage = Stage::load(&args.scene, THUMB_WIDTH)?;
    let mut objectives = Vec::with_capacity(n);
    for (i, path) in args.refs.iter().enumerate() {
        let img = decode_reference(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        objectives.push(Objective {
            image: file_name(path),
            aspects: aspects[i],
            region: regions[i],
            analysis: analyze(&img, crops[i], args.palette as usize),
        });
    }

    let base = match &args.base {
        Some(path) => read_look(path, &stage)?,
        None => visobjd_scene::look::Look::off(stage.scene.lights.len()),
    };
    let mut constraints = Constraints::none(&stage.rig);
    constraints.per_light = args.per_light;
    for name in &args.key {
        constraints.keys[group(&stage, name)?] = true;
    }
    for name in &args.lock {
        for &l in &stage.scene.groups[group(&stage, name)?].lights {
            constraints.locked[l] = true;
        }
    }
    if !args.lock.is_empty() && args.base.is_none() {
        tracing::warn!(
            "--lock {} without --base: locked groups keep the base look's level, and without \
             --base every light starts off, so they stay at 0 in every entry (give the look \
             to keep them at with --base FILE)",
            args.lock.join(", ")
        );
    }

    if let Some(seed) = args.seed.filter(|&s| s > MAX_SEED) {
        bail!(
            "--seed {seed}: seeds are 0..={MAX_SEED}, the daemon's range, so that \
             /vo/generate/seeded can replay the gallery live"
        );
    }
    let seed = args
        .seed
        .unwrap_or_else(|| rand::random_range(1..=MAX_SEED));
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
    let started = std::time::Instant::now();
    let generation = stage.generate(
        &GenerateRequest {
            objectives: &objectives,
            constraints: &constraints,
            base: &base,
            spread: Spread::default(),
            count: args.count as usize,
            clusters: args.clusters as usize,
            steer: None,
        },
        &mut rng,
    );
    let ms = started.elapsed().as_secs_f64() * 1000.0;
    contact_sheet(&generation.thumbnails)
        .save_with_format(&args.out, image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot write the contact sheet", args.out.display()))?;
    if let Some(json) = &args.json {
        let text = serde_json::to_string_pretty(&report(&stage, &objectives, &generation, seed))?;
        std::fs::write(json, text).with_context(|| format!("{}: cannot write", json.display()))?;
    }
    println!(
        "gallery: {} entries from {} candidates ({} draws, threshold {:.1}{}) in {ms:.0} ms, seed {seed} -> {}",
        generation.entries.len(),
        generation.candidates.len(),
        generation.draws,
        generation.threshold,
        if generation.exhausted {
            ", draw limit reached"
        } else {
            ""
        },
        args.out.display()
    );
    for note in generation.notes(&objectives) {
        eprintln!("gallery: {note}");
    }
    Ok(())
}

/// Reads a look file for `stage`'s scene.
/// A look file, or with `FILE#N` saved look N of the daemon's `looks.json` (its state
/// folder's), on `stage`.
pub fn read_look(path: &Path, stage: &Stage) -> anyhow::Result<visobjd_scene::look::Look> {
    let spelled = path.to_string_lossy();
    let saved = spelled
        .rsplit_once('#')
        .and_then(|(file, n)| Some((Path::new(file), n.parse::<u32>().ok()?)));
    let (path, file) = match saved {
        Some((path, n)) => {
            let saved = read_saved_looks(path)?;
            let numbers: Vec<String> = saved.looks.keys().map(u32::to_string).collect();
            let Some(file) = saved.looks.get(&n).cloned() else {
                bail!(
                    "{}: no saved look {n} (saved: {})",
                    path.display(),
                    if numbers.is_empty() {
                        "none".into()
                    } else {
                        numbers.join(", ")
                    }
                );
            };
            (path, file)
        }
        None => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("{}: cannot read", path.display()))?;
            let file: LookFile = serde_json::from_str(&text)
                .map_err(|e| anyhow::anyhow!("{}: not a look file: {e}", path.display()))?;
            (path, file)
        }
    };
    file.to_look(&stage.scene)
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// The daemon's saved looks in `path` (a state folder's `looks.json`).
pub fn read_saved_looks(path: &Path) -> anyhow::Result<crate::engine::persist::LooksFile> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: not the daemon's looks.json: {e}", path.display()))
}

fn group(stage: &Stage, name: &str) -> anyhow::Result<usize> {
    match stage.scene.group_index(name) {
        Some(g) => Ok(g),
        None => bail!(
            "group `{name}` is not in the scene (groups: {})",
            stage
                .scene
                .groups
                .iter()
                .map(|g| g.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

#[derive(Serialize)]
struct Report {
    scene: String,
    seed: u64,
    threshold: f32,
    draws: usize,
    objectives: Vec<ObjectiveRecord>,
    entries: Vec<EntryReport>,
    candidates: Vec<CandidateReport>,
}

#[derive(Serialize)]
struct EntryReport {
    entry: usize,
    members: Vec<usize>,
}

#[derive(Serialize)]
struct CandidateReport {
    index: usize,
    entry: usize,
    member: usize,
    lights: Vec<LightEntry>,
}

fn report(stage: &Stage, objectives: &[Objective], g: &Generation, seed: u64) -> Report {
    let mut place = vec![(0, 0); g.candidates.len()];
    for (e, members) in g.entries.iter().enumerate() {
        for (m, &c) in members.iter().enumerate() {
            place[c] = (e + 1, m + 1);
        }
    }
    Report {
        scene: stage.scene.name.clone(),
        seed,
        threshold: g.threshold,
        draws: g.draws,
        objectives: objectives.iter().map(ObjectiveRecord::from).collect(),
        entries: g
            .entries
            .iter()
            .enumerate()
            .map(|(e, members)| EntryReport {
                entry: e + 1,
                members: members.clone(),
            })
            .collect(),
        candidates: g
            .candidates
            .iter()
            .enumerate()
            .map(|(i, look)| CandidateReport {
                index: i,
                entry: place[i].0,
                member: place[i].1,
                lights: entries(&stage.scene, look),
            })
            .collect(),
    }
}
