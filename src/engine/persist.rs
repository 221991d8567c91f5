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
use std::thread::JoinHandle;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::rules::RulesFile;
use super::session::{Change, Entry, Gallery, Session};
use visobjd_files::{Loaded, load_json, save_json};
use visobjd_method::gallery::Generation;
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

    fn live(&self) -> PathBuf {
        self.dir.join("live.json")
    }

    fn looks(&self) -> PathBuf {
        self.dir.join("looks.json")
    }

    fn session(&self) -> PathBuf {
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
fn apply_session(scene: &Scene, f: &SessionFile, s: &mut Session) -> Vec<String> {
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

/// `/vo/backup/state`'s fourth part: what the session holds that the state files do not
/// keep (a restarted main starts without it), so a backup that subscribes at any moment
/// picks, steps, undoes, follows and uses the console selection exactly as its main.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WorkingFile {
    gallery: Option<GalleryFile>,
    /// The live entry and member (1-based).
    entry: Option<(usize, usize)>,
    /// Base looks for undo, oldest first, and for redo.
    undo: Vec<LookFile>,
    redo: Vec<LookFile>,
    last_change: Option<Change>,
    /// The lights the console last reported selected, by channel.
    console_selection: Vec<u32>,
    following: bool,
}

/// A gallery as a main hands it to its backups, in the state and when a generate installs
/// it (`/vo/backup/gallery`): the looks themselves, not a seed to redraw them with, so the
/// backup's gallery is the main's whatever its processor and lands at the same point of
/// the command order as on the main.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GalleryFile {
    seed: u64,
    /// Candidates in acceptance order.
    candidates: Vec<LookFile>,
    /// Candidate indices per entry, representative first.
    entries: Vec<Vec<usize>>,
    threshold: f32,
    draws: usize,
    exhausted: bool,
}

impl GalleryFile {
    fn of(scene: &Scene, generation: &Generation, seed: u64) -> GalleryFile {
        GalleryFile {
            seed,
            candidates: generation
                .candidates
                .iter()
                .map(|look| LookFile::from_look(scene, look, ""))
                .collect(),
            entries: generation.entries.clone(),
            threshold: generation.threshold,
            draws: generation.draws,
            exhausted: generation.exhausted,
        }
    }

    /// The gallery, its thumbnails not rendered yet and serial 0 (see
    /// `Engine::received_gallery`); Err names what does not fit this scene.
    fn to_gallery(&self, scene: &Scene) -> Result<Gallery, String> {
        let candidates = self
            .candidates
            .iter()
            .enumerate()
            .map(|(i, look)| {
                look.to_look(scene)
                    .map_err(|e| format!("candidate {} does not fit this scene: {e}", i + 1))
            })
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(k) = self.entries.iter().position(|members| {
            members.is_empty() || members.iter().any(|&c| c >= candidates.len())
        }) {
            return Err(format!(
                "entry {} names no candidate, or one past the {} there are",
                k + 1,
                candidates.len()
            ));
        }
        let generation = Generation {
            candidates,
            entries: self.entries.clone(),
            threshold: self.threshold,
            draws: self.draws,
            exhausted: self.exhausted,
            thumbnails: std::sync::Arc::new([]),
        };
        Ok(Gallery {
            generation,
            seed: self.seed,
            serial: 0,
        })
    }
}

/// JSON text of what a main sends its backups; Err is a sentence.
fn json(value: &impl Serialize) -> Result<String, String> {
    serde_json::to_string(value).map_err(|e| format!("cannot encode the state: {e}"))
}

/// `/vo/backup/gallery`'s argument: the gallery a generate just installed, as JSON.
pub fn gallery_json(scene: &Scene, generation: &Generation, seed: u64) -> Result<String, String> {
    json(&GalleryFile::of(scene, generation, seed))
}

/// The gallery of a main's [`gallery_json`] (as [`GalleryFile::to_gallery`] gives it);
/// Err, when it does not read or fit this scene, is a sentence.
pub fn gallery_from_json(scene: &Scene, text: &str) -> Result<Gallery, String> {
    let file: GalleryFile =
        serde_json::from_str(text).map_err(|e| format!("the main's gallery does not read: {e}"))?;
    file.to_gallery(scene)
        .map_err(|e| format!("the main's gallery: {e}"))
}

/// The state a main sends a backup that subscribes (`/vo/backup/state`): what the state
/// files would hold now, as the JSON of `session.json`, `live.json` and `looks.json`, and
/// the [`WorkingFile`] of what they do not keep.
pub fn state_json(scene: &Scene, s: &Session) -> Result<[String; 4], String> {
    let snap = Snapshot::of(scene, s);
    let looks = |stack: &[visobjd_scene::look::Look]| -> Vec<LookFile> {
        stack
            .iter()
            .map(|look| LookFile::from_look(scene, look, ""))
            .collect()
    };
    let (undo, redo, last_change) = s.history();
    let working = WorkingFile {
        gallery: s
            .gallery
            .as_ref()
            .map(|g| GalleryFile::of(scene, &g.generation, g.seed)),
        entry: s.entry,
        undo: looks(undo),
        redo: looks(redo),
        last_change,
        console_selection: s
            .console_selection
            .iter()
            .map(|&l| scene.lights[l].channel)
            .collect(),
        following: s.following,
    };
    Ok([
        json(&snap.session)?,
        json(&snap.live)?,
        json(&LooksFile {
            looks: s.looks.clone(),
        })?,
        json(&working)?,
    ])
}

/// The session a backup takes from its main's [`state_json`]: a fresh session holding
/// what the main's session holds (its gallery as [`GalleryFile::to_gallery`] gives it),
/// with what could not be taken, item by item. Err, when a part does not read or the
/// live look does not fit this scene, changes nothing.
pub fn from_state(
    scene: &Scene,
    parts: &[String; 4],
    fresh: Session,
) -> Result<(Session, Vec<String>), String> {
    let read = |what: &str, e: serde_json::Error| format!("the main's {what} does not read: {e}");
    let file: SessionFile = serde_json::from_str(&parts[0]).map_err(|e| read("session", e))?;
    let live: LiveFile = serde_json::from_str(&parts[1]).map_err(|e| read("live look", e))?;
    let looks: LooksFile = serde_json::from_str(&parts[2]).map_err(|e| read("looks", e))?;
    let working: WorkingFile =
        serde_json::from_str(&parts[3]).map_err(|e| read("working state", e))?;
    let fit = |e: String| format!("the main's live look does not fit this scene: {e}");
    let mut s = fresh;
    s.live = live.live.to_look(scene).map_err(fit)?;
    s.base = live.base.to_look(scene).map_err(fit)?;
    s.master = live.master.clamp(0.0, 1.0);
    s.blackout = live.blackout;
    s.looks = looks.looks;
    let mut lost = apply_session(scene, &file, &mut s);
    s.gallery = working
        .gallery
        .map(|g| g.to_gallery(scene))
        .transpose()
        .unwrap_or_else(|e| {
            lost.push(format!("the gallery: {e}"));
            None
        });
    s.entry = working.entry.filter(|&(k, m)| {
        let fits = s
            .gallery
            .as_ref()
            .is_some_and(|g| g.candidate(k, m).is_some());
        if !fits {
            lost.push(format!("the live entry {k}.{m}: not in the gallery"));
        }
        fits
    });
    let stack = |files: &[LookFile]| -> Result<Vec<visobjd_scene::look::Look>, String> {
        files.iter().map(|f| f.to_look(scene)).collect()
    };
    match (stack(&working.undo), stack(&working.redo)) {
        (Ok(undo), Ok(redo)) => s.set_history(undo, redo, working.last_change),
        (Err(e), _) | (_, Err(e)) => lost.push(format!("the undo history: {e}")),
    }
    s.console_selection = Vec::new();
    for ch in working.console_selection {
        match scene.light_index(ch) {
            Some(l) => s.console_selection.push(l),
            None => lost.push(format!(
                "light {ch} of the console selection: the scene has no such light"
            )),
        }
    }
    s.following = working.following;
    Ok((s, lost))
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
                rules: s.rules.record(scene),
            },
        }
    }
}

/// A thread that writes the latest [`Snapshot`] it was handed, dropping older ones.
/// Discrete changes (pick, recall, ...) wait until their snapshot is on disk before they
/// are answered, and hear of a failed write; fader moves do not wait.
pub struct Writer {
    tx: Mutex<Option<mpsc::Sender<(u64, Snapshot)>>>,
    next: AtomicU64,
    written: Arc<(Mutex<Written>, Condvar)>,
    thread: Mutex<Option<JoinHandle<()>>>,
    /// Test hook: milliseconds each write waits first, standing in for a slow disk.
    slow_ms: Arc<AtomicU64>,
}

/// The newest write the thread finished.
#[derive(Debug, Default)]
struct Written {
    /// Its ticket: every snapshot up to it is on disk, or failed with `error`.
    ticket: u64,
    /// Why it failed (snapshots are whole, so a later success covers earlier tickets).
    error: Option<String>,
}

/// How long a caller waits for its snapshot before answering anyway (a stalled disk must
/// not stall the OSC side for long; the write still happens).
const FLUSH_WAIT: Duration = Duration::from_secs(2);

impl Writer {
    /// Starts the writer for `files`.
    pub fn start(files: Files) -> std::io::Result<Writer> {
        let (tx, rx) = mpsc::channel::<(u64, Snapshot)>();
        let written = Arc::new((Mutex::new(Written::default()), Condvar::new()));
        let done = Arc::clone(&written);
        let slow_ms = Arc::new(AtomicU64::new(0));
        let slow = Arc::clone(&slow_ms);
        let thread = std::thread::Builder::new()
            .name("state-writer".into())
            .spawn(move || {
                while let Ok(mut latest) = rx.recv() {
                    // Only the newest snapshot matters.
                    while let Ok(newer) = rx.try_recv() {
                        latest = newer;
                    }
                    let (ticket, snap) = latest;
                    std::thread::sleep(Duration::from_millis(slow.load(Ordering::Relaxed)));
                    let mut error = None;
                    for (path, result) in [
                        (files.live(), save_json(&files.live(), &snap.live)),
                        (files.session(), save_json(&files.session(), &snap.session)),
                    ] {
                        if let Err(e) = result {
                            tracing::error!("{}: cannot save: {e}", path.display());
                            error.get_or_insert(e.to_string());
                        }
                    }
                    let (lock, cvar) = &*done;
                    let mut w = lock.lock().unwrap_or_else(|p| p.into_inner());
                    *w = Written { ticket, error };
                    drop(w);
                    cvar.notify_all();
                }
            })?;
        Ok(Writer {
            tx: Mutex::new(Some(tx)),
            next: AtomicU64::new(1),
            written,
            thread: Mutex::new(Some(thread)),
            slow_ms,
        })
    }

    /// Queues a snapshot and returns at once with its ticket. Call it under the session
    /// lock, so tickets follow the order of the changes.
    pub fn save(&self, snap: Snapshot) -> u64 {
        let ticket = self.next.fetch_add(1, Ordering::SeqCst);
        let tx = self.tx.lock().unwrap_or_else(|p| p.into_inner());
        if tx
            .as_ref()
            .is_none_or(|tx| tx.send((ticket, snap)).is_err())
        {
            tracing::warn!("a change after the state writer stopped was not saved");
        }
        ticket
    }

    /// Waits (bounded) until the snapshot of `ticket`, or a newer one, is on disk; the
    /// error of that write if it failed. Call it after releasing the session lock.
    pub fn wait(&self, ticket: u64) -> Result<(), String> {
        let (lock, cvar) = &*self.written;
        let guard = lock.lock().unwrap_or_else(|p| p.into_inner());
        let (w, timeout) = cvar
            .wait_timeout_while(guard, FLUSH_WAIT, |w| w.ticket < ticket)
            .unwrap_or_else(|p| p.into_inner());
        if timeout.timed_out() {
            tracing::warn!(
                "the state folder has not taken a change within {} s; it is written when the disk answers",
                FLUSH_WAIT.as_secs()
            );
        }
        w.error.clone().map_or(Ok(()), Err)
    }

    /// Test hook: every later write first waits `ms` milliseconds (a slow disk).
    pub fn slow_down(&self, ms: u64) {
        self.slow_ms.store(ms, Ordering::Relaxed);
    }

    /// Writes what is still queued and stops the thread (at shutdown: the last fader move
    /// survives a clean stop). Later saves are logged and dropped.
    pub fn finish(&self) {
        drop(self.tx.lock().unwrap_or_else(|p| p.into_inner()).take());
        let thread = self.thread.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(t) = thread
            && t.join().is_err()
        {
            tracing::error!("the state writer panicked; the last change may not be saved");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use visobjd_scene::look::{Level, Look};

    fn scene() -> Scene {
        let toml = "[[light]]\nchannel = 1\nbasis = \"a.exr\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = 1\n\
                    [[light]]\nchannel = 7\nbasis = \"b.exr\"\nprofile = \"rgb\"\nuniverse = 1\naddress = 2\n";
        Scene::parse(Path::new("."), toml).unwrap()
    }

    fn look(v: f32) -> Look {
        Look {
            levels: vec![
                Level {
                    intensity: v,
                    color: [1.0; 3],
                },
                Level {
                    intensity: 1.0 - v,
                    color: [v, 0.25, 1.0 / 3.0],
                },
            ],
        }
    }

    /// A session with all a backup needs beyond the files: a gallery, a live entry,
    /// history, a console selection, following.
    fn busy(scene: &Scene) -> Session {
        let mut s = Session::new(scene, 100, 12, 2.0);
        s.gallery = Some(Gallery {
            generation: Generation {
                candidates: (1..=5).map(|i| look(i as f32 / 7.0)).collect(),
                entries: vec![vec![0, 3], vec![1], vec![2, 4]],
                threshold: 9.5,
                draws: 11,
                exhausted: false,
                thumbnails: std::sync::Arc::new([]),
            },
            seed: 77,
            serial: 4,
        });
        s.set_base(look(0.1), Change::Step);
        s.set_base(look(0.2), Change::Fader);
        s.undo(1).expect("a step to undo");
        s.entry = Some((3, 2));
        s.console_selection = vec![1];
        s.following = true;
        s
    }

    #[test]
    fn a_backup_takes_the_gallery_history_and_selection_with_the_state() {
        let scene = scene();
        let main = busy(&scene);
        let parts = state_json(&scene, &main).unwrap();
        let (mut s, lost) = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap();
        assert_eq!(lost, Vec::<String>::new());
        let (g, want) = (s.gallery.as_ref().unwrap(), main.gallery.as_ref().unwrap());
        assert_eq!(g.generation.candidates, want.generation.candidates);
        assert_eq!(g.generation.entries, want.generation.entries);
        assert_eq!(g.seed, 77);
        assert_eq!(s.entry, Some((3, 2)));
        assert_eq!(s.history(), main.history());
        assert_eq!(s.console_selection, [1]);
        assert!(s.following);
        assert_eq!(
            (s.live.clone(), s.base.clone()),
            (main.live.clone(), main.base.clone())
        );
        // The history goes on as on the main.
        assert_eq!(s.redo(1), Ok(0));
        assert_eq!(s.base, look(0.2));
    }

    #[test]
    fn what_does_not_fit_is_left_out_and_named() {
        let scene = scene();
        let mut main = busy(&scene);
        main.entry = Some((3, 3));
        let mut parts = state_json(&scene, &main).unwrap();
        parts[3] = parts[3].replace("\"entries\":[[0,3],[1],[2,4]]", "\"entries\":[[0,3],[9]]");
        parts[3] = parts[3].replace("\"console_selection\":[7]", "\"console_selection\":[7,8]");
        let (s, lost) = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap();
        assert!(s.gallery.is_none() && s.entry.is_none(), "{lost:?}");
        assert_eq!(s.console_selection, [1]);
        assert_eq!(lost.len(), 3, "{lost:?}");
        assert!(lost[0].contains("entry 2 names no candidate"), "{lost:?}");
        assert!(lost[1].contains("live entry 3.3"), "{lost:?}");
        assert!(lost[2].contains("light 8"), "{lost:?}");
        parts[3] = "{".into();
        let e = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap_err();
        assert!(e.contains("working state does not read"), "{e}");
    }
}
