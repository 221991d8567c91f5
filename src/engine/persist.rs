//! What the session keeps in `state_dir` across restarts and crashes: the live look (so the
//! stage comes back exactly as it was), saved looks, and objectives with settings.
//!
//! `looks.json` is written before `/vo/look/saved` is answered; the live look and session
//! go through a background writer (`writer`) that always writes the latest snapshot, so a
//! flood of fader moves costs one write per moment, never one per message.

use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::rules::RulesFile;
use super::session::{
    CLUSTERS, COUNT, Entry, FADE_S, MAX_IMAGE_NAME, MAX_LABEL, MAX_LOOKS, MAX_OBJECTIVES,
    MAX_PALETTE, SEED, Session,
};
use visobjd_files::{Loaded, load_json, save_json};
use visobjd_method::objective::ObjectiveRecord;
use visobjd_scene::Scene;
use visobjd_scene::look::{Look, LookFile};

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
    /// scene or the session cannot take (a lock on a group it no longer has, an objective
    /// that does not parse, a number that is not finite or out of its range) is left out
    /// and logged item by item, and the file is copied aside before it is rewritten.
    pub fn restore(&self, scene: &Scene, session: &mut Session) {
        let mut partial = [false; 3];
        if let Loaded::Ok(file) = load_json::<LiveFile>(&self.live()) {
            let (live, lost) = file.restore(scene);
            session.live = live.live;
            session.base = live.base;
            session.master = live.master;
            session.blackout = live.blackout;
            partial[0] = partly_restored(&self.live(), &lost);
        }
        if let Loaded::Ok(mut file) = load_json::<LooksFile>(&self.looks()) {
            let lost = file.drop_invalid();
            session.looks = file.looks;
            partial[1] = partly_restored(&self.looks(), &lost);
        }
        if let Loaded::Ok(file) = load_json::<SessionFile>(&self.session()) {
            let lost = apply_session(scene, &file, session);
            partial[2] = partly_restored(&self.session(), &lost);
        }
        // A file restored in part is written again as restored (its copy is aside), so
        // the next start does not lose the same things again.
        let snap = Snapshot::of(scene, session);
        for (path, written) in [
            (
                self.live(),
                partial[0].then(|| save_json(&self.live(), &snap.live)),
            ),
            (
                self.looks(),
                partial[1].then(|| self.save_looks(&session.looks)),
            ),
            (
                self.session(),
                partial[2].then(|| save_json(&self.session(), &snap.session)),
            ),
        ] {
            if let Some(Err(e)) = written {
                tracing::error!("{}: cannot write what was restored: {e}", path.display());
            }
        }
    }
}

/// Logs what `path` held that was not restored and keeps a copy of it aside; whether
/// the file may now be rewritten (something was lost and the copy is aside).
fn partly_restored(path: &Path, lost: &[String]) -> bool {
    if lost.is_empty() {
        return false;
    }
    for what in lost {
        tracing::error!("{}: not restored: {what}", path.display());
    }
    match visobjd_files::keep_copy(path) {
        Ok(aside) => {
            tracing::error!(
                "{}: kept the file as it was in {}",
                path.display(),
                aside.display()
            );
            true
        }
        Err(e) => {
            tracing::error!("{}: could not keep a copy aside: {e}", path.display());
            false
        }
    }
}

/// What `live.json` puts on stage.
#[derive(Debug, Clone)]
pub struct Live {
    /// The live look.
    pub live: Look,
    /// The base look.
    pub base: Look,
    /// Grand master.
    pub master: f32,
    /// Blackout.
    pub blackout: bool,
}

impl LiveFile {
    /// The stage this file holds on `scene`: each light a look cannot take is left out
    /// (off), a master that is not one stays at full; a sentence for each.
    pub fn restore(&self, scene: &Scene) -> (Live, Vec<String>) {
        let (live, live_lost) = self.live.fit(scene);
        let (base, base_lost) = self.base.fit(scene);
        let mut lost: Vec<String> = (live_lost.iter().map(|e| format!("live look: {e}")))
            .chain(base_lost.iter().map(|e| format!("base look: {e}")))
            .collect();
        let master = ranged("master", self.master, &(0.0..=1.0), 1.0, &mut lost);
        let live = Live {
            live,
            base,
            master,
            blackout: self.blackout,
        };
        (live, lost)
    }
}

impl LooksFile {
    /// Leaves out what a session may not hold, with a sentence for each: each saved look's
    /// lights whose numbers are not levels (channels are not checked: a saved look
    /// outlives a patch), a label past [`MAX_LABEL`] characters (cut to it), and looks past
    /// [`MAX_LOOKS`] (the highest numbers).
    pub fn drop_invalid(&mut self) -> Vec<String> {
        let mut lost = Vec::new();
        if self.looks.len() > MAX_LOOKS
            && let Some((&first, _)) = self.looks.iter().nth(MAX_LOOKS)
        {
            let past = self.looks.split_off(&first);
            lost.push(format!(
                "{} saved looks past the {MAX_LOOKS} a session keeps: looks {first} and above \
                 were left out",
                past.len()
            ));
        }
        for (n, look) in &mut self.looks {
            lost.extend(
                look.drop_invalid()
                    .into_iter()
                    .map(|e| format!("look {n}: {e}")),
            );
            let chars = look.label.chars().count();
            if chars > MAX_LABEL {
                look.label = look.label.chars().take(MAX_LABEL).collect();
                lost.push(format!(
                    "look {n}: its label of {chars} characters was cut to {MAX_LABEL}"
                ));
            }
        }
        lost
    }
}

/// The stage `live.json` holds, for putting it on the wire before anything else loads
/// (what it cannot take is left out quietly here: [`Files::restore`] logs it).
pub fn restore_live(files: &Files, scene: &Scene) -> Option<Live> {
    match load_json::<LiveFile>(&files.live()) {
        Loaded::Ok(file) => Some(file.restore(scene).0),
        _ => None,
    }
}

/// A number a state file restores.
trait Number: Copy + PartialOrd + std::fmt::Display {
    fn finite(self) -> bool;
}

impl Number for f32 {
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Number for u32 {
    fn finite(self) -> bool {
        true
    }
}

impl Number for u64 {
    fn finite(self) -> bool {
        true
    }
}

/// `value` when it is a finite number in `range`; else `default`, with a sentence naming
/// `name`, the value and the default in `lost`.
fn ranged<T: Number>(
    name: &str,
    value: T,
    range: &RangeInclusive<T>,
    default: T,
    lost: &mut Vec<String>,
) -> T {
    let why = if !value.finite() {
        "is not a finite number".to_string()
    } else if !range.contains(&value) {
        format!("is outside {}..={}", range.start(), range.end())
    } else {
        return value;
    };
    lost.push(format!(
        "{name} {value} {why}; kept the default ({default})"
    ));
    default
}

/// Applies what `f` holds to `s`; returns a sentence for each thing it could not.
pub(super) fn apply_session(scene: &Scene, f: &SessionFile, s: &mut Session) -> Vec<String> {
    let mut lost = Vec::new();
    s.objectives = f
        .objectives
        .iter()
        .filter_map(|o| {
            let chars = o.record.image.chars().count();
            let objective = if chars > MAX_IMAGE_NAME {
                Err(format!(
                    "its image name has {chars} characters, more than the {MAX_IMAGE_NAME} \
                     an objective's may have"
                ))
            } else if o.record.palette.len() > MAX_PALETTE {
                Err(format!(
                    "its palette has {} colours, more than the {MAX_PALETTE} a palette may have",
                    o.record.palette.len()
                ))
            } else {
                o.record.to_objective()
            };
            match objective {
                Ok(objective) => Some(Entry {
                    id: o.id,
                    objective,
                }),
                Err(e) => {
                    let image: String = o.record.image.chars().take(MAX_IMAGE_NAME).collect();
                    lost.push(format!("objective {} (`{image}`): {e}", o.id));
                    None
                }
            }
        })
        .collect();
    if s.objectives.len() > MAX_OBJECTIVES {
        let past = s.objectives.split_off(MAX_OBJECTIVES);
        lost.push(format!(
            "{} objectives past the {MAX_OBJECTIVES} a session keeps: objectives {} were left out",
            past.len(),
            past.iter()
                .map(|e| e.id.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
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
    s.count = ranged("count", f.count, &COUNT, s.count, &mut lost);
    s.clusters = ranged("clusters", f.clusters, &CLUSTERS, s.clusters, &mut lost);
    s.seed = ranged("seed", f.seed, &SEED, s.seed, &mut lost);
    s.fade_s = ranged("fade_s", f.fade_s, &FADE_S, s.fade_s, &mut lost);
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
