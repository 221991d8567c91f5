//! The running config and scene, replaced whole by a reload (`SIGHUP`, `systemctl reload`,
//! `/vo/reload`), and what stands in for a scene that did not load.
//!
//! A reload reads everything first (the config, the scene, its images, the new output
//! sockets) with the session unlocked, and changes nothing unless all of it worked; then,
//! under the session's lock, the output is rewired (the DMX clock swaps its destinations
//! between two ticks, never stopping), the stage, the config and, when the rig changed, the
//! session carried onto the new lights are swapped in. The transports follow the config
//! through [`Engine::config_changes`].
//!
//! A daemon whose scene cannot be loaded keeps running on a stand-in ([`Loaded::standing_in`]:
//! the patch last loaded, kept in the state folder, with black images): the saved look
//! stays on the wire, queries are answered and every change is refused with "scene not
//! loaded: <file>: <why>". It loads the scene when its files change
//! ([`Engine::retry_scene`]) or on a reload.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::SystemTime;

use super::persist::{Snapshot, apply_session};
use super::session::Session;
use super::{Engine, Later, Refusal};
use crate::config::Config;
use rosc::OscMessage;
use visobjd_dmx::Patch;
use visobjd_method::stage::{Stage, THUMB_WIDTH};
use visobjd_scene::Scene;
use visobjd_scene::look::{Level, Look};

/// The copy of the last scene description that loaded, in the state folder: the patch a
/// daemon keeps sending the saved look through when `scene.toml` itself is broken.
const LAST_SCENE: &str = "last-scene.toml";

/// The scene the engine runs.
pub struct Loaded {
    /// The stage: the configured scene, or a stand-in for it.
    pub stage: Arc<Stage>,
    /// Why the configured scene is not running ("scene not loaded: <file>: <why>").
    pub problem: Option<String>,
    /// The scene's files as they were when it was (or failed to be) loaded.
    files: Fingerprint,
}

impl Loaded {
    /// The configured scene with its images (a light whose image is bad is left out and
    /// logged); a scene none of whose images can be read stands in, black.
    pub fn from_scene(scene: Scene) -> Loaded {
        let files = Fingerprint::of(&scene);
        match Stage::from_scene(scene.clone(), THUMB_WIDTH) {
            Ok(stage) => {
                for u in &stage.unseen {
                    tracing::error!(
                        "light {} is left out of generation: {}",
                        stage.scene.lights[u.light].channel,
                        u.error
                    );
                }
                for u in &stage.unseen_positions {
                    tracing::warn!(
                        "light {} palette {} is left out of generation until its image is captured: {}",
                        stage.scene.lights[u.light].channel,
                        u.palette,
                        u.error
                    );
                }
                Loaded {
                    stage: Arc::new(stage),
                    problem: None,
                    files,
                }
            }
            Err(e) => Loaded::standing_in(scene, &e.to_string(), files),
        }
    }

    /// A stage loaded elsewhere (the benchmark's), running as the configured scene.
    pub fn running(stage: Arc<Stage>) -> Loaded {
        Loaded {
            files: Fingerprint::of(&stage.scene),
            stage,
            problem: None,
        }
    }

    /// `scene`'s patch with black images, standing in for a scene that failed with `why`.
    fn standing_in(scene: Scene, why: &str, files: Fingerprint) -> Loaded {
        let problem = format!("scene not loaded: {why}");
        tracing::error!("{problem}; the saved look stays on the wire, changes are refused");
        Loaded {
            stage: Arc::new(Stage::blank(scene)),
            problem: Some(problem),
            files,
        }
    }

    /// What runs when `dir/scene.toml` failed to load with `why`: the scene last loaded
    /// (its copy in `state_dir`) with black images, or `None` when there is none.
    pub fn last_scene(dir: &Path, state_dir: &Path, why: &str) -> Option<Loaded> {
        let text = std::fs::read_to_string(state_dir.join(LAST_SCENE)).ok()?;
        let scene = Scene::parse(dir, &text)
            .inspect_err(|e| tracing::error!("{}: {e}", state_dir.join(LAST_SCENE).display()))
            .ok()?;
        tracing::error!(
            "{why}: running the patch last loaded ({} lights) until the scene is fixed",
            scene.lights.len()
        );
        let files = Fingerprint::of(&scene);
        Some(Loaded::standing_in(scene, why, files))
    }
}

/// A scene's files as seen on disk (size and modification time of its `scene.toml` and of
/// every image it names): a change is worth another load.
#[derive(Debug, Clone, PartialEq)]
struct Fingerprint(Vec<Option<(u64, SystemTime)>>);

impl Fingerprint {
    fn of(scene: &Scene) -> Fingerprint {
        let stat = |p: &Path| {
            std::fs::metadata(p)
                .ok()
                .map(|m| (m.len(), m.modified().unwrap_or(SystemTime::UNIX_EPOCH)))
        };
        let mut files: Vec<&Path> = vec![];
        let toml = scene.dir.join("scene.toml");
        files.push(&toml);
        for l in &scene.lights {
            files.push(&l.basis);
            files.extend(l.emitter_basis.iter().map(PathBuf::as_path));
            files.extend(l.positions.iter().skip(1).map(|p| p.basis.as_path()));
        }
        Fingerprint(files.into_iter().map(stat).collect())
    }
}

impl Engine {
    /// The running stage. Read it with the session locked when what it says must match the
    /// session (a reload swaps both under that lock).
    pub fn stage(&self) -> Arc<Stage> {
        let loaded = self.loaded.read().unwrap_or_else(|p| p.into_inner());
        Arc::clone(&loaded.stage)
    }

    /// The running config.
    pub fn config(&self) -> Arc<Config> {
        Arc::clone(&self.config.borrow())
    }

    /// The config as each reload replaces it: the transports follow it (the OSC
    /// allow-list and peers; the web page reads it on every request).
    pub fn config_changes(&self) -> tokio::sync::watch::Receiver<Arc<Config>> {
        self.config.subscribe()
    }

    /// Why the configured scene is not running, if it is not.
    pub fn scene_problem(&self) -> Option<String> {
        let loaded = self.loaded.read().unwrap_or_else(|p| p.into_inner());
        loaded.problem.clone()
    }

    /// Refuses a change while the scene is not loaded.
    pub fn scene_loaded(&self) -> Result<(), Refusal> {
        match self.scene_problem() {
            Some(p) => Err(Refusal::conflict(p)),
            None => Ok(()),
        }
    }

    /// Reloads if the scene is not loaded (or leaves lights out) and its files changed
    /// since: a fixed file loads without anyone asking. Called every few seconds.
    pub fn retry_scene(&self) {
        let changed = {
            let loaded = self.loaded.read().unwrap_or_else(|p| p.into_inner());
            let incomplete = loaded.problem.is_some() || !loaded.stage.unseen.is_empty();
            incomplete && loaded.files != Fingerprint::of(&loaded.stage.scene)
        };
        if changed {
            tracing::info!("the scene's files changed: loading it again");
            // reload() logs its outcome.
            let _ = self.reload();
        }
    }

    /// [`Engine::reload`] on a thread of its own (it reads every image), answered through
    /// `answer`: `reply(what runs now)` (`/vo/reloaded`'s, or that of a command that
    /// changed the scene's files and is answered once they run), or why nothing changed.
    pub fn reload_then(
        self: &Arc<Self>,
        answer: Later,
        reply: impl FnOnce(String) -> Vec<OscMessage> + Send + 'static,
    ) -> Result<(), Refusal> {
        let engine = Arc::clone(self);
        self.threads
            .spawn("reload", move || {
                answer(engine.reload().map(reply));
            })
            .map_err(|e| Refusal::internal(format!("cannot start the reload: {e}")))
    }

    /// Re-reads the config and the scene and applies both, without a gap in the DMX
    /// output; a config or scene that fails to load keeps everything as it was and says
    /// why. The answer names what runs now and the settings that take a restart.
    pub fn reload(&self) -> Result<String, Refusal> {
        let _one = self.reloading.lock().unwrap_or_else(|p| p.into_inner());
        // systemd wants MONOTONIC_USEC= with RELOADING=1; without a clock, RELOADING alone.
        let mut reloading = vec![sd_notify::NotifyState::Reloading];
        reloading.extend(sd_notify::NotifyState::monotonic_usec_now().ok());
        let _ = sd_notify::notify(&reloading);
        let result = self.reload_now();
        let status = match &result {
            Ok(done) => done.clone(),
            Err(e) => format!("{e}"),
        };
        let problem = self.scene_problem();
        let status = problem.map_or(status.clone(), |p| format!("{p}; {status}"));
        let _ = sd_notify::notify(&[
            sd_notify::NotifyState::Ready,
            sd_notify::NotifyState::Status(&status),
        ]);
        match &result {
            Ok(done) => tracing::info!("{done}"),
            Err(e) => tracing::error!("{e}"),
        }
        result
    }

    fn reload_now(&self) -> Result<String, Refusal> {
        let old = self.config();
        let kept = "; everything stays as it was";
        // Config::load checks the whole file, the allow-list and peers included.
        let config = Config::load(&old.path)
            .map_err(|e| Refusal::input(format!("config not reloaded: {e}{kept}")))?;
        let scene = Scene::load(&config.scene).map_err(|e| {
            self.note_failure(&format!("scene not loaded: {e}"));
            Refusal::input(format!("scene not reloaded: {e}{kept}"))
        })?;
        let loaded = Loaded::from_scene(scene);
        if let Some(p) = &loaded.problem {
            self.note_failure(p);
            return Err(Refusal::input(format!("{p}{kept}")));
        }
        let restart = needs_restart(&old, &config);
        let stage = Arc::clone(&loaded.stage);

        let mut s = self.session();
        let running = self.stage();
        let carried = (!same_rig(&running.scene, &stage.scene))
            .then(|| carry(&running.scene, &stage.scene, &s));
        let live = carried.as_ref().map_or(&s.live, |c| &c.live).clone();
        let mut rewired = Ok(());
        self.with_output(|o| {
            rewired = o.rewire(&config.output, Patch::new(&stage.scene), live);
        });
        rewired.map_err(|e| Refusal::input(format!("output not reloaded: {e}{kept}")))?;
        if let Some(c) = carried {
            *s = c;
        }
        *self.loaded.write().unwrap_or_else(|p| p.into_inner()) = loaded;
        self.config.send_replace(Arc::new(config));
        keep_scene(&self.config());
        let ticket = self.writer.save(Snapshot::of(&stage.scene, &s));
        let pushes = self.feedback(&s);
        self.publish(s, &pushes);
        if let Err(e) = self.writer.wait(ticket) {
            tracing::error!("after the reload, the state was not saved: {e}");
        }
        let config = self.config();
        let mut done = format!(
            "reloaded {}: scene `{}` ({} lights{}), {} sACN and {} Art-Net destinations",
            config.path.display(),
            stage.scene.name,
            stage.scene.lights.len(),
            if stage.unseen.is_empty() {
                String::new()
            } else {
                format!(", {} left out: {}", stage.unseen.len(), unseen_list(&stage))
            },
            config.output.sacn.len(),
            config.output.artnet.len()
        );
        if !restart.is_empty() {
            done += &format!(
                "; {} changed and take effect at the next restart",
                restart.join(", ")
            );
        }
        Ok(done)
    }

    /// Records a failed load of the scene files as they are now, so the retry waits for
    /// the next change rather than loading the same broken files every few seconds.
    fn note_failure(&self, why: &str) {
        let mut loaded = self.loaded.write().unwrap_or_else(|p| p.into_inner());
        loaded.files = Fingerprint::of(&loaded.stage.scene);
        if loaded.problem.is_some() {
            loaded.problem = Some(why.to_string());
        }
    }
}

/// The lights a stage leaves out, for a sentence: `7 (front 3), 12`.
pub(super) fn unseen_list(stage: &Stage) -> String {
    stage
        .unseen
        .iter()
        .map(|u| {
            let light = &stage.scene.lights[u.light];
            if light.name.is_empty() {
                light.channel.to_string()
            } else {
                format!("{} ({})", light.channel, light.name)
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Keeps a copy of the scene description that just loaded in the state folder (for
/// [`Loaded::last_scene`]); a failure only costs that fallback, so it is logged.
pub fn keep_scene(config: &Config) {
    let from = config.scene.join("scene.toml");
    let to = config.state_dir.join(LAST_SCENE);
    let copied = std::fs::read(&from).and_then(|bytes| {
        if std::fs::read(&to).is_ok_and(|old| old == bytes) {
            return Ok(());
        }
        visobjd_files::write_atomic(&to, &bytes)
    });
    if let Err(e) = copied {
        tracing::warn!(
            "cannot keep a copy of {} in {}: {e}",
            from.display(),
            to.display()
        );
    }
}

/// Whether two scenes have the same lights in the same order and the same groups: the
/// session (indexed by light and group) then stays as it is.
fn same_rig(a: &Scene, b: &Scene) -> bool {
    a.lights.len() == b.lights.len()
        && a.lights
            .iter()
            .zip(&b.lights)
            .all(|(x, y)| x.channel == y.channel)
        && a.groups.len() == b.groups.len()
        && a.groups
            .iter()
            .zip(&b.groups)
            .all(|(x, y)| x.name == y.name)
}

/// `s` carried from the scene `old` onto the rig `new`: what the state files would bring
/// back after a restart (objectives, locks and rules by group name, settings, saved looks),
/// the live and base looks light by light (by channel; a new light is off), the gallery
/// and the undo history dropped (they are the old rig's).
fn carry(old: &Scene, new: &Scene, s: &Session) -> Session {
    let mut c = Session::new(new, s.count, s.clusters, s.fade_s);
    let snapshot = Snapshot::of(old, s);
    for lost in apply_session(new, &snapshot.session, &mut c) {
        tracing::warn!("reload: not carried onto the new rig: {lost}");
    }
    c.live = remap(old, new, &s.live);
    c.base = remap(old, new, &s.base);
    c.master = s.master;
    c.blackout = s.blackout;
    c.looks = s.looks.clone();
    c
}

/// `look` of `old`'s lights as a look of `new`'s, by channel.
fn remap(old: &Scene, new: &Scene, look: &Look) -> Look {
    Look {
        levels: new
            .lights
            .iter()
            .map(|l| {
                old.light_index(l.channel)
                    .and_then(|i| look.levels.get(i).copied())
                    .unwrap_or(Level::OFF)
            })
            .collect(),
    }
}

/// The config keys a reload cannot apply (sockets bound at start, the state folder, the
/// backup's role), named when they changed.
fn needs_restart(old: &Config, new: &Config) -> Vec<&'static str> {
    [
        ("state_dir", old.state_dir != new.state_dir),
        ("osc.udp", old.osc.udp != new.osc.udp),
        ("osc.tcp", old.osc.tcp != new.osc.tcp),
        ("osc.reply_port", old.osc.reply_port != new.osc.reply_port),
        ("http.listen", old.http.listen != new.http.listen),
        ("[input]", old.input != new.input),
        ("[backup]", old.backup != new.backup),
    ]
    .into_iter()
    .filter(|(_, changed)| *changed)
    .map(|(key, _)| key)
    .collect()
}
