//! What a main hands a backup (docs/reliability.md, "Backup"): the whole session when it
//! subscribes (`/vo/backup/state`: the state files' JSON and what they do not keep) and each
//! gallery a generate installs (`/vo/backup/gallery`), with the backup's reading of both.

use serde::{Deserialize, Serialize};

use super::persist::{LiveFile, LooksFile, SessionFile, Snapshot, apply_session};
use super::session::{Change, Gallery, HISTORY, Session};
use visobjd_method::gallery::Generation;
use visobjd_scene::Scene;
use visobjd_scene::look::LookFile;

/// `/vo/backup/state`'s fourth part: what the session holds that the state files do not
/// keep (a restarted main starts without it), so a backup that subscribes at any moment
/// picks, steps, undoes, follows and uses the Eos selection exactly as its main.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WorkingFile {
    gallery: Option<GalleryFile>,
    /// The live entry and member (1-based).
    entry: Option<(usize, usize)>,
    /// Base looks for undo, oldest first, and for redo.
    undo: Vec<LookFile>,
    redo: Vec<LookFile>,
    last_change: Option<Change>,
    /// The lights Eos last reported selected, by channel.
    eos_selection: Vec<u32>,
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
        if !self.threshold.is_finite() {
            return Err(format!(
                "its threshold {} is not a finite number",
                self.threshold
            ));
        }
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
            // Notes go to the requester of the main's generate, not to a backup.
            lit_for_color: Vec::new(),
            thumbnails: std::sync::Arc::new([]),
            turned_down: 0,
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
        eos_selection: s
            .eos_selection
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
    live.live.to_look(scene).map_err(fit)?;
    live.base.to_look(scene).map_err(fit)?;
    let (restored, mut lost) = live.restore(scene);
    let mut s = fresh;
    s.live = restored.live;
    s.base = restored.base;
    s.master = restored.master;
    s.blackout = restored.blackout;
    let mut looks = looks;
    lost.extend(looks.drop_invalid());
    s.looks = looks.looks;
    lost.extend(apply_session(scene, &file, &mut s));
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
    // A main's history is at most HISTORY steps each way, as this backup's; a longer one
    // (a main of another version) is cut to the newest HISTORY steps, said here: an undo
    // or redo on the main that reaches past them fails here, and the backup subscribes
    // again (src/backup.rs).
    for (what, steps) in [("undo", working.undo.len()), ("redo", working.redo.len())] {
        if steps > HISTORY {
            lost.push(format!(
                "{} of the main's {steps} {what} steps, the farthest from its look: this \
                 backup keeps {HISTORY}",
                steps - HISTORY
            ));
        }
    }
    match (stack(&working.undo), stack(&working.redo)) {
        (Ok(undo), Ok(redo)) => s.set_history(undo, redo, working.last_change),
        (Err(e), _) | (_, Err(e)) => lost.push(format!("the undo history: {e}")),
    }
    s.eos_selection = Vec::new();
    for ch in working.eos_selection {
        match scene.light_index(ch) {
            Some(l) => s.eos_selection.push(l),
            None => lost.push(format!(
                "light {ch} of the Eos selection: the scene has no such light"
            )),
        }
    }
    s.following = working.following;
    Ok((s, lost))
}

#[cfg(test)]
mod tests {
    use super::*;
    use visobjd_scene::look::{Level, Look};

    fn scene() -> Scene {
        let toml = "[[light]]\nchannel = 1\nbasis = \"a.exr\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = 1\n\
                    [[light]]\nchannel = 7\nbasis = \"b.exr\"\nprofile = \"rgb\"\nuniverse = 1\naddress = 2\n";
        Scene::parse(std::path::Path::new("."), toml).unwrap()
    }

    fn look(v: f32) -> Look {
        Look {
            levels: vec![
                Level {
                    intensity: v,
                    color: [1.0; 3],
                    position: None,
                },
                Level {
                    intensity: 1.0 - v,
                    color: [v, 0.25, 1.0 / 3.0],
                    position: None,
                },
            ],
        }
    }

    /// A session with all a backup needs beyond the files: a gallery, a live entry,
    /// history, an Eos selection, following.
    fn busy(scene: &Scene) -> Session {
        let mut s = Session::new(scene, 100, 12, 2.0);
        s.gallery = Some(Gallery {
            generation: Generation {
                candidates: (1..=5).map(|i| look(i as f32 / 7.0)).collect(),
                entries: vec![vec![0, 3], vec![1], vec![2, 4]],
                threshold: 9.5,
                draws: 11,
                exhausted: false,
                lit_for_color: Vec::new(),
                thumbnails: std::sync::Arc::new([]),
                turned_down: 0,
            },
            seed: 77,
            serial: 4,
        });
        s.set_base(look(0.1), Change::Step);
        s.set_base(look(0.2), Change::Fader);
        s.undo(1).expect("a step to undo");
        s.entry = Some((3, 2));
        s.eos_selection = vec![1];
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
        assert_eq!(s.eos_selection, [1]);
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
    fn a_history_longer_than_the_backups_is_cut_to_it_and_said() {
        let scene = scene();
        let main = busy(&scene);
        let mut parts = state_json(&scene, &main).unwrap();
        // A main keeping more undo steps than this backup (another version's HISTORY).
        let mut working: WorkingFile = serde_json::from_str(&parts[3]).unwrap();
        working.undo = (0..HISTORY + 6)
            .map(|i| LookFile::from_look(&scene, &look(i as f32 / 100.0), ""))
            .collect();
        parts[3] = serde_json::to_string(&working).unwrap();
        let (s, lost) = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap();
        assert_eq!(lost.len(), 1, "{lost:?}");
        assert!(
            lost[0].contains(&format!("6 of the main's {} undo steps", HISTORY + 6)),
            "{lost:?}"
        );
        let (undo, _, _) = s.history();
        assert_eq!(undo.len(), HISTORY);
        assert_eq!(undo[0], look(6.0 / 100.0), "the newest are kept");
    }

    #[test]
    fn what_does_not_fit_is_left_out_and_named() {
        let scene = scene();
        let mut main = busy(&scene);
        main.entry = Some((3, 3));
        let mut parts = state_json(&scene, &main).unwrap();
        parts[3] = parts[3].replace("\"entries\":[[0,3],[1],[2,4]]", "\"entries\":[[0,3],[9]]");
        parts[3] = parts[3].replace("\"eos_selection\":[7]", "\"eos_selection\":[7,8]");
        let (s, lost) = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap();
        assert!(s.gallery.is_none() && s.entry.is_none(), "{lost:?}");
        assert_eq!(s.eos_selection, [1]);
        assert_eq!(lost.len(), 3, "{lost:?}");
        assert!(lost[0].contains("entry 2 names no candidate"), "{lost:?}");
        assert!(lost[1].contains("live entry 3.3"), "{lost:?}");
        assert!(lost[2].contains("light 8"), "{lost:?}");
        parts[3] = "{".into();
        let e = from_state(&scene, &parts, Session::new(&scene, 1, 1, 0.0)).unwrap_err();
        assert!(e.contains("working state does not read"), "{e}");
    }
}
