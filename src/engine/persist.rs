//! What the session keeps in `state_dir` across restarts and crashes: the live look (so the
//! stage comes back exactly as it was), saved looks, and objectives with settings.
//!
//! `looks.json` is written before `/vo/look/saved` is answered; the live look and session
//! go through a background writer (`writer`) that always writes the latest snapshot, so a
//! flood of fader moves costs one write per moment, never one per message.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::rules::RulesFile;
use super::session::{Entry, Session};
use visobjd_files::{Loaded, load_json, save_json};
use visobjd_method::objective::ObjectiveRecord;
use visobjd_scene::Scene;
use visobjd_scene::look::LookFile;

/// `live.json`: what the stage shows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LiveFile {
    /// The live look.
    pub live: LookFile,
    /// The base look.
    pub base: LookFile,
    /// Grand master.
    pub master: f32,
    /// Blackout.
    pub blackout: bool,
}

/// `looks.json`: saved looks by number.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct LooksFile {
    /// Looks by number.
    pub looks: BTreeMap<u32, LookFile>,
}

/// One objective as stored, with the id OSC addresses use.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObjectiveFile {
    id: u32,
    #[serde(flatten)]
    record: ObjectiveRecord,
}

/// `session.json`: objectives, constraints (by name, so a re-ordered scene keeps them) and
/// generation settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SessionFile {
    objectives: Vec<ObjectiveFile>,
    next_id: u32,
    key_groups: Vec<String>,
    locked_groups: Vec<String>,
    locked_lights: Vec<u32>,
    count: u32,
    clusters: u32,
    seed: u64,
    fade_s: f32,
    /// Ratios, saturation ranges, exclusions and pins.
    #[serde(default)]
    rules: RulesFile,
}

/// Paths of the state files.
#[derive(Debug, Clone)]
pub struct Files {
    dir: PathBuf,
}

impl Files {
    /// The files in `dir`.
    pub fn new(dir: &Path) -> Files {
        Files {
            dir: dir.to_path_buf(),
        }
    }

    pub(super) fn live(&self) -> PathBuf {
        self.dir.join("live.json")
    }

    fn looks(&self) -> PathBuf {
        self.dir.join("looks.json")
    }

    pub(super) fn session(&self) -> PathBuf {
        self.dir.join("session.json")
    }

    /// Writes saved looks now (the caller answers only once they are on disk; call it with
    /// the session unlocked).
    pub fn save_looks(&self, looks: &BTreeMap<u32, LookFile>) -> std::io::Result<()> {
        save_json(
            &self.looks(),
            &LooksFile {
                looks: looks.clone(),
            },
        )
    }

    /// Restores what the files hold into a fresh session; anything unreadable is kept
    /// aside (logged) and the rest still restored. What a readable file holds but this
    /// scene cannot take (a lock on a group it no longer has, an objective that does not
    /// parse) is logged item by item, and the file is copied aside before it is rewritten.
    pub fn restore(&self, scene: &Scene, session: &mut Session) {
        if let Loaded::Ok(live) = load_json::<LiveFile>(&self.live()) {
            match (live.live.to_look(scene), live.base.to_look(scene)) {
                (Ok(l), Ok(b)) => {
                    session.live = l;
                    session.base = b;
                    session.master = live.master.clamp(0.0, 1.0);
                    session.blackout = live.blackout;
                }
                (Err(e), _) | (_, Err(e)) => {
                    partly_restored(&self.live(), &[format!("does not fit the scene: {e}")])
                }
            }
        }
        if let Loaded::Ok(looks) = load_json::<LooksFile>(&self.looks()) {
            session.looks = looks.looks;
        }
        if let Loaded::Ok(file) = load_json::<SessionFile>(&self.session()) {
            partly_restored(&self.session(), &apply_session(scene, &file, session));
        }
    }
}

/// Logs what `path` held that was not restored and keeps a copy of it aside.
fn partly_restored(path: &Path, lost: &[String]) {
    if lost.is_empty() {
        return;
    }
    for what in lost {
        tracing::error!("{}: not restored: {what}", path.display());
    }
    match visobjd_files::keep_copy(path) {
        Ok(aside) => tracing::error!(
            "{}: kept the file as it was in {}",
            path.display(),
            aside.display()
        ),
        Err(e) => tracing::error!("{}: could not keep a copy aside: {e}", path.display()),
    }
}

/// The live look file alone, for restoring the stage before anything else loads.
pub fn restore_live(files: &Files) -> Option<LiveFile> {
    match load_json::<LiveFile>(&files.live()) {
        Loaded::Ok(live) => Some(live),
        _ => None,
    }
}

/// Applies what `f` holds to `s`; returns a sentence for each thing it could not.
pub(super) fn apply_session(scene: &Scene, f: &SessionFile, s: &mut Session) -> Vec<String> {
    let mut lost = Vec::new();
    s.objectives = f
        .objectives
        .iter()
        .filter_map(|o| {
            let objective = o.record.to_objective();
            if objective.is_none() {
                lost.push(format!(
                    "objective {} (`{}`): its aspects or region do not parse",
                    o.id, o.record.image
                ));
            }
            Some(Entry {
                id: o.id,
                objective: objective?,
            })
        })
        .collect();
    s.next_id = f
        .next_id
        .max(s.objectives.iter().map(|e| e.id + 1).max().unwrap_or(1));
    for (names, flags, what) in [
        (&f.key_groups, &mut s.key_groups, "key"),
        (&f.locked_groups, &mut s.locked_groups, "lock"),
    ] {
        for name in names {
            match scene.group_index(name) {
                Some(g) => flags[g] = true,
                None => lost.push(format!(
                    "the {what} on group `{name}`: the scene has no such group"
                )),
            }
        }
    }
    for &ch in &f.locked_lights {
        match scene.light_index(ch) {
            Some(l) => s.locked_lights[l] = true,
            None => lost.push(format!(
                "the lock on light {ch}: the scene has no such light"
            )),
        }
    }
    lost.extend(s.rules.restore(scene, &f.rules));
    s.count = f.count.clamp(1, 1000);
    s.clusters = f.clusters.clamp(1, 64);
    s.seed = f.seed;
    if f.fade_s.is_finite() {
        s.fade_s = f.fade_s.clamp(0.0, 600.0);
    }
    lost
}

/// The snapshot the background writer persists.
pub struct Snapshot {
    pub(super) live: LiveFile,
    pub(super) session: SessionFile,
}

impl Snapshot {
    /// What to write for `s`.
    pub fn of(scene: &Scene, s: &Session) -> Snapshot {
        let names = |flags: &[bool]| -> Vec<String> {
            flags
                .iter()
                .enumerate()
                .filter(|(_, on)| **on)
                .map(|(g, _)| scene.groups[g].name.clone())
                .collect()
        };
        Snapshot {
            live: LiveFile {
                live: LookFile::from_look(scene, &s.live, ""),
                base: LookFile::from_look(scene, &s.base, ""),
                master: s.master,
                blackout: s.blackout,
            },
            session: SessionFile {
                objectives: s
                    .objectives
                    .iter()
                    .map(|e| ObjectiveFile {
                        id: e.id,
                        record: ObjectiveRecord::from(&e.objective),
                    })
                    .collect(),
                next_id: s.next_id,
                key_groups: names(&s.key_groups),
                locked_groups: names(&s.locked_groups),
                locked_lights: s
                    .locked_lights
                    .iter()
                    .enumerate()
                    .filter(|(_, on)| **on)
                    .map(|(l, _)| scene.lights[l].channel)
                    .collect(),
                count: s.count,
                clusters: s.clusters,
                seed: s.seed,
                fade_s: s.fade_s,
                rules: s.rules.record(scene),
            },
        }
    }
}
