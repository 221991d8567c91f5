//! The console's sACN (`[input.sacn]`): its merged output read back through the patch as a
//! look, for `/vo/console/grab` and for following it ([`Engine::follow_console`]). "The
//! console" in this daemon is always this input; Eos's OSC is `eos`.

use std::sync::{Arc, Mutex};

use super::session::Change;
use super::{Engine, Outcome, Refusal};
use visobjd_dmx::input::{Console, SourceInfo};
use visobjd_dmx::{Input, Patch};
use visobjd_scene::look::Look;
use visobjd_scene::profile::Profile;

/// The input, while it runs (its DMX is read through the running scene's patch).
pub(super) struct ConsoleInput {
    input: Mutex<Option<Input>>,
}

impl ConsoleInput {
    pub(super) fn new(input: Option<Input>) -> ConsoleInput {
        ConsoleInput {
            input: Mutex::new(input),
        }
    }

    /// Runs `f` on the input, if one is configured and still running.
    fn with_input<T>(&self, f: impl FnOnce(&Input) -> T) -> Option<T> {
        let guard = self.input.lock().unwrap_or_else(|p| p.into_inner());
        guard.as_ref().map(f)
    }

    /// Stops the input (at shutdown).
    pub(super) fn shutdown(&self) {
        let input = self.input.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(input) = input {
            input.shutdown();
        }
    }
}

impl Engine {
    /// Changes of the console's merged output (`None` without `[input.sacn]`).
    pub fn console_changes(&self) -> Option<tokio::sync::watch::Receiver<u64>> {
        self.console.with_input(Input::changes)
    }

    /// The console sources seen now (`None` without `[input.sacn]`).
    pub fn console_sources(&self) -> Option<Vec<SourceInfo>> {
        self.console.with_input(Input::sources)
    }

    /// The merged console output read back through the patch as a look, with how many
    /// sources made it; refused when there is no input or no source counts yet.
    pub fn console_look(&self) -> Result<(Look, usize), Refusal> {
        let patch = Patch::new(&self.stage().scene);
        let console = self.console_now(&patch)?;
        Ok((patch.look(&console.dmx), console.sources))
    }

    /// Where the console's merged output aims each light, in degrees from the centre of
    /// its profile's pan and tilt ranges: `None` for a light without pan and tilt slots or
    /// on a universe no console source counts on now (its zeros are not the console's).
    /// Refused as [`Engine::console_look`] is.
    pub fn console_aims(&self) -> Result<Vec<Option<[f64; 2]>>, Refusal> {
        let stage = self.stage();
        let scene = &stage.scene;
        let patch = Patch::new(scene);
        let console = self.console_now(&patch)?;
        Ok(patch
            .aims(&console.dmx)
            .into_iter()
            .enumerate()
            .map(|(l, aim)| {
                let [pan, tilt] = aim.filter(|_| console.received[patch.universe_of(l)])?;
                let profile = scene.profile(l);
                Some([
                    Profile::position_degrees(pan, profile.pan_range),
                    Profile::position_degrees(tilt, profile.tilt_range),
                ])
            })
            .collect())
    }

    /// The merged console output of `patch`'s universes now; refused when there is no
    /// input or no source counts yet.
    fn console_now(&self, patch: &Patch) -> Result<Console, Refusal> {
        let read = self.console.with_input(|input| {
            let console = input.console(patch.universes());
            if console.sources == 0 {
                return Err(Refusal::conflict(format!(
                    "no console source is being received on universes {:?} at {} (a new source counts once it has been seen for {:.1} s)",
                    input.universes(),
                    input.bind(),
                    visobjd_dmx::input::SAMPLE.as_secs_f32()
                )));
            }
            Ok(console)
        });
        read.unwrap_or_else(|| {
            Err(Refusal::conflict(
                "no console input is configured: add [input.sacn] with bind and universes to the config (docs/config.md)",
            ))
        })
    }

    /// Runs for the daemon's life when `[input.sacn]` is configured (`changes` is
    /// [`Engine::console_changes`]): every change of the console's merged output becomes the
    /// base and live look at once while the session follows the console. While no source
    /// counts (the console went away) the base stays.
    pub async fn follow_console(self: Arc<Self>, mut changes: tokio::sync::watch::Receiver<u64>) {
        while changes.changed().await.is_ok() {
            if !self.session().following {
                continue;
            }
            let Ok((look, _)) = self.console_look() else {
                continue;
            };
            let followed = self.commit(None, |s| {
                s.fits(&look)?;
                if !s.following || s.base == look {
                    return Ok(Outcome::replies(Vec::new()));
                }
                s.set_base(look, Change::Follow);
                s.entry = None;
                // Like a fader: at once, written a moment later.
                Ok(Outcome::replies(Vec::new())
                    .show_look(0.0)
                    .saved_later()
                    .pushed())
            });
            if let Err(err) = followed {
                tracing::warn!("following the console: {err}");
            }
        }
    }
}
