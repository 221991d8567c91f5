//! What the session keeps in `state_dir` across restarts and crashes: the live look (so the
//! stage comes back exactly as it was), saved looks, and objectives with settings.
//!
//! `looks.json` is written before `/vo/look/saved` is answered; the live look and session
//! go through a background writer that always writes the latest snapshot, so a flood of
//! fader moves costs one write per moment, never one per message.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::session::{Entry, Session};
use crate::look::LookFile;
use crate::objective::ObjectiveRecord;
use crate::scene::Scene;
use crate::state::{Loaded, load_json, save_json};

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

    fn live(&self) -> PathBuf {
        self.dir.join("live.json")
    }

    fn looks(&self) -> PathBuf {
        self.dir.join("looks.json")
    }

    fn session(&self) -> PathBuf {
        self.dir.join("session.json")
    }

    /// Writes saved looks now (the caller answers only once they are on disk).
    pub fn save_looks(&self, looks: &BTreeMap<u32, LookFile>) -> std::io::Result<()> {
        save_json(
            &self.looks(),
            &LooksFile {
                looks: looks.clone(),
            },
        )
    }

    /// Restores what the files hold into a fresh session; anything unreadable is kept
    /// aside (logged) and the rest still restored.
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
                    tracing::error!("{}: does not fit the scene: {e}", self.live().display())
                }
            }
        }
        if let Loaded::Ok(looks) = load_json::<LooksFile>(&self.looks()) {
            session.looks = looks.looks;
        }
        if let Loaded::Ok(file) = load_json::<SessionFile>(&self.session()) {
            apply_session(scene, &file, session);
        }
    }
}

/// The live look file alone, for restoring the stage before anything else loads.
pub fn restore_live(files: &Files) -> Option<LiveFile> {
    match load_json::<LiveFile>(&files.live()) {
        Loaded::Ok(live) => Some(live),
        _ => None,
    }
}

fn apply_session(scene: &Scene, f: &SessionFile, s: &mut Session) {
    s.objectives = f
        .objectives
        .iter()
        .filter_map(|o| {
            Some(Entry {
                id: o.id,
                objective: o.record.to_objective()?,
            })
        })
        .collect();
    s.next_id = f
        .next_id
        .max(s.objectives.iter().map(|e| e.id + 1).max().unwrap_or(1));
    for name in &f.key_groups {
        if let Some(g) = scene.group_index(name) {
            s.key_groups[g] = true;
        }
    }
    for name in &f.locked_groups {
        if let Some(g) = scene.group_index(name) {
            s.locked_groups[g] = true;
        }
    }
    for &ch in &f.locked_lights {
        if let Some(l) = scene.light_index(ch) {
            s.locked_lights[l] = true;
        }
    }
    s.count = f.count.clamp(1, 1000);
    s.clusters = f.clusters.clamp(1, 64);
    s.seed = f.seed;
    if f.fade_s.is_finite() {
        s.fade_s = f.fade_s.clamp(0.0, 600.0);
    }
}

/// The snapshot the background writer persists.
pub struct Snapshot {
    live: LiveFile,
    session: SessionFile,
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
            },
        }
    }
}

/// A thread that writes the latest [`Snapshot`] it was handed, dropping older ones.
/// Discrete changes (pick, recall, ...) wait until their snapshot is on disk before they
/// are answered; fader moves do not wait.
pub struct Writer {
    tx: mpsc::Sender<(u64, Snapshot)>,
    next: AtomicU64,
    written: Arc<(Mutex<u64>, Condvar)>,
}

/// How long a caller waits for its snapshot before answering anyway (a stalled disk must
/// not stall the OSC side for long; the write still happens).
const FLUSH_WAIT: Duration = Duration::from_secs(2);

impl Writer {
    /// Starts the writer for `files`.
    pub fn start(files: Files) -> std::io::Result<Writer> {
        let (tx, rx) = mpsc::channel::<(u64, Snapshot)>();
        let written = Arc::new((Mutex::new(0u64), Condvar::new()));
        let done = Arc::clone(&written);
        std::thread::Builder::new()
            .name("state-writer".into())
            .spawn(move || {
                while let Ok(mut latest) = rx.recv() {
                    // Only the newest snapshot matters.
                    while let Ok(newer) = rx.try_recv() {
                        latest = newer;
                    }
                    let (ticket, snap) = latest;
                    for (path, result) in [
                        (files.live(), save_json(&files.live(), &snap.live)),
                        (files.session(), save_json(&files.session(), &snap.session)),
                    ] {
                        if let Err(e) = result {
                            tracing::error!("{}: cannot save: {e}", path.display());
                        }
                    }
                    let (lock, cvar) = &*done;
                    if let Ok(mut w) = lock.lock() {
                        *w = (*w).max(ticket);
                    }
                    cvar.notify_all();
                }
            })?;
        Ok(Writer {
            tx,
            next: AtomicU64::new(1),
            written,
        })
    }

    /// Queues a snapshot and returns at once with its ticket. Call it under the session
    /// lock, so tickets follow the order of the changes.
    pub fn save(&self, snap: Snapshot) -> u64 {
        let ticket = self.next.fetch_add(1, Ordering::SeqCst);
        let _ = self.tx.send((ticket, snap));
        ticket
    }

    /// Waits (bounded) until the snapshot of `ticket`, or a newer one, is on disk. Call it
    /// after releasing the session lock.
    pub fn wait(&self, ticket: u64) {
        let (lock, cvar) = &*self.written;
        if let Ok(guard) = lock.lock() {
            let _ = cvar.wait_timeout_while(guard, FLUSH_WAIT, |w| *w < ticket);
        }
    }
}
