//! `/vo/generate`: a gallery drawn on its own thread from a copy of the session's
//! objectives, constraints and base look, with progress pushed as it goes, and installed
//! when done by [`Engine::install_gallery`], the one way a gallery (a generate's, an
//! explore's, a main's) becomes the session's.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use rand::SeedableRng;
use rosc::{OscMessage, OscType};

use super::session::{Gallery, Session};
use super::{Engine, Later, Refusal, handover, msg};
use visobjd_method::gallery::Generation;
use visobjd_method::objective::Objective;
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_scene::look::Look;

/// Why a generate (or an explore) cannot start without objectives.
pub(super) const NO_OBJECTIVES: &str =
    "there are no objectives: add one with /vo/objective/add first";

/// What generates share: the one-at-a-time flag, the serial counter.
#[derive(Default)]
pub(super) struct Generator {
    /// A generate (or an explore gallery) is being drawn.
    pub(super) generating: AtomicBool,
    /// Galleries made in this run (the serial of the next one, minus one).
    made: AtomicU64,
}

/// What a generate draws from, copied out of the session so it runs with the session
/// unlocked.
pub(super) struct Inputs {
    /// The stage it draws on: a reload meanwhile makes its gallery stale (see
    /// [`Inputs::current`]).
    pub(super) stage: Arc<Stage>,
    objectives: Vec<Objective>,
    constraints: Constraints,
    base: Look,
    count: usize,
    clusters: usize,
}

impl Inputs {
    pub(super) fn of(stage: Arc<Stage>, s: &Session) -> Inputs {
        Inputs {
            constraints: s.constraints(&stage.scene, false),
            stage,
            objectives: s.objectives.iter().map(|e| e.objective.clone()).collect(),
            base: s.base.clone(),
            count: s.count as usize,
            clusters: s.clusters as usize,
        }
    }
}

impl Inputs {
    /// Whether `engine` still runs the stage these inputs were drawn on (no reload since).
    pub(super) fn current(&self, engine: &Engine) -> bool {
        Arc::ptr_eq(&self.stage, &engine.stage())
    }
}

/// Why a gallery drawn before a reload is not installed.
pub(super) const RELOADED: &str =
    "the scene was reloaded while the gallery was drawn; the gallery is unchanged, generate again";

/// Clears the "generating" flag when dropped, so a generate that panics never blocks the
/// next one.
pub(super) struct Running<'a>(pub(super) &'a AtomicBool);

impl Drop for Running<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::SeqCst);
    }
}

impl Engine {
    /// Whether a generate is running.
    pub fn is_generating(&self) -> bool {
        self.generator.generating.load(Ordering::SeqCst)
    }

    /// The serial of a new gallery of this run (1, 2, ...): caches of its renders are
    /// keyed by it.
    pub(super) fn next_serial(&self) -> u64 {
        self.generator.made.fetch_add(1, Ordering::SeqCst) + 1
    }

    /// Starts a generate on its own thread, with `seed` or the session's seed setting; the
    /// answer (`/vo/generated`, or why it failed) goes to `answer` when it is done. Refused
    /// while another runs and while exploring (the gallery then follows the regions).
    /// Backups are sent the gallery itself (`/vo/backup/gallery`) when it is installed.
    pub fn generate(self: &Arc<Self>, seed: Option<u64>, answer: Later) -> Result<(), Refusal> {
        if self.exploring() {
            return Err(Refusal::conflict(
                "exploring: the gallery follows the regions; send /vo/explore 0 to generate",
            ));
        }
        let generating = &self.generator.generating;
        if generating.swap(true, Ordering::SeqCst) {
            return Err(Refusal::conflict(
                "a generate is already running; wait for /vo/generated",
            ));
        }
        let s = self.session();
        if s.objectives.is_empty() {
            generating.store(false, Ordering::SeqCst);
            return Err(Refusal::conflict(NO_OBJECTIVES));
        }
        let inputs = Inputs::of(self.stage(), &s);
        // Seeds travel as OSC int32: a random one stays in 1..=i32::MAX so it can be replayed.
        let seed = seed.unwrap_or_else(|| s.next_seed());
        let serial = self.next_serial();
        let mut started = vec![progress(0.0)];
        started.extend(self.feedback(&s));
        // In the session's order, as every change: a change made before the drawing
        // starts pushes after this, not before it.
        self.publish(s, &started);
        let engine = Arc::clone(self);
        let spawned = self.threads.spawn("generate", move || {
            // Whatever happens below, the next generate is allowed.
            let running = Running(&engine.generator.generating);
            let mut tenths = Tenths::default();
            let drawn = engine.draw(&inputs, seed, serial, |f| {
                if tenths.crossed(f) {
                    engine.notify(&[progress(f)]);
                }
            });
            let Some((generation, ms)) = drawn else {
                let why = format!(
                    "the generate failed (an internal error, logged with seed {seed}); \
                         the gallery is unchanged, generate again"
                );
                // Free before the answer: the requester may generate again at once.
                drop(running);
                engine.generate_ended();
                engine.poke_explorer();
                answer(Err(Refusal::internal(why)));
                return;
            };
            let reply = generated(&generation, ms, seed);
            let notes: Vec<OscMessage> = generation
                .notes(&inputs.objectives)
                .into_iter()
                .map(|note| {
                    tracing::warn!("generate {serial}: {note}");
                    msg("/vo/note", vec![OscType::String(note)])
                })
                .collect();
            let s = engine.session();
            if !inputs.current(&engine) {
                drop((s, running));
                engine.generate_ended();
                answer(Err(Refusal::conflict(RELOADED)));
                return;
            }
            // Under the lock: the backups install it between the same two commands.
            engine.forward_with(|| {
                let text = handover::gallery_json(&inputs.stage.scene, &generation, seed)?;
                Ok(msg("/vo/backup/gallery", vec![OscType::String(text)]))
            });
            drop(running);
            let gallery = Gallery {
                generation,
                seed,
                serial,
            };
            // Subscribers first: whoever acts on the reply (a pick) has its pushes come
            // after this gallery's, never before them.
            let mut first = vec![progress(1.0), reply.clone()];
            first.extend(notes.iter().cloned());
            engine.install_gallery(s, gallery, first);
            answer(Ok(std::iter::once(reply).chain(notes).collect()));
            engine.poke_explorer();
        });
        if let Err(e) = spawned {
            generating.store(false, Ordering::SeqCst);
            self.generate_ended();
            return Err(Refusal::internal(format!("cannot start the generate: {e}")));
        }
        Ok(())
    }

    /// Makes `gallery` the session's, with no entry live, and pushes `first` then the
    /// tablets' feedback, in the session's order (the lock is let go as they go out). The
    /// one way a gallery is installed: a generate's, an explore's, a main's on its backup.
    pub(super) fn install_gallery(
        &self,
        mut s: std::sync::MutexGuard<'_, Session>,
        gallery: Gallery,
        first: Vec<OscMessage>,
    ) {
        s.gallery = Some(gallery);
        s.entry = None;
        let mut pushes = first;
        pushes.extend(self.feedback(&s));
        self.publish(s, &pushes);
    }

    /// Tells subscribers a generate ended without a gallery: the bar at its end, the status
    /// line no longer "generating...".
    fn generate_ended(&self) {
        let s = self.session();
        let mut pushes = vec![progress(1.0)];
        pushes.extend(self.feedback(&s));
        self.publish(s, &pushes);
    }

    /// Draws a gallery from `inputs` with `seed` on the compute pool (whose threads run at
    /// a lower priority, so the DMX clock and the OSC threads get a core the moment they
    /// wake), with the time it took in ms. `None` when it panicked (logged). `progress` is
    /// told the share done as it goes, on the drawing's thread
    /// ([`Stage::generate_with_progress`]): it must not wait on anything.
    pub(super) fn draw(
        &self,
        inputs: &Inputs,
        seed: u64,
        serial: u64,
        progress: impl FnMut(f32) + Send,
    ) -> Option<(Generation, f32)> {
        let started = Instant::now();
        let config = self.config();
        let spread = Spread {
            key: config.generate.sigma_key,
            fill: config.generate.sigma_fill,
        };
        let stage = &inputs.stage;
        let drawn = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            self.hooks.maybe_panic_generate();
            // `scope` runs its body on a pool thread: the sampling and clustering between
            // the parallel parts are niced too, not run on this thread.
            rayon::scope(|_| {
                stage.generate_with_progress(
                    &GenerateRequest {
                        objectives: &inputs.objectives,
                        constraints: &inputs.constraints,
                        base: &inputs.base,
                        spread,
                        count: inputs.count,
                        clusters: inputs.clusters,
                        steer: None,
                    },
                    &mut rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed),
                    progress,
                )
            })
        }));
        let Ok(generation) = drawn else {
            tracing::error!("generate {serial} (seed {seed}) failed: see the panic above");
            return None;
        };
        if generation.exhausted {
            tracing::warn!(
                "generate: only {} of {} candidates after {} draws",
                generation.candidates.len(),
                inputs.count,
                generation.draws
            );
        }
        Some((generation, started.elapsed().as_secs_f32() * 1000.0))
    }
}

/// `/vo/generated candidates clusters ms seed`, the reply to a generate and the push of
/// every gallery.
pub(super) fn generated(generation: &Generation, ms: f32, seed: u64) -> OscMessage {
    msg(
        "/vo/generated",
        vec![
            OscType::Int(generation.candidates.len() as i32),
            OscType::Int(generation.entries.len() as i32),
            OscType::Float(ms),
            OscType::Int(seed as i32),
        ],
    )
}

/// `/vo/progress fraction`: how far the running generate is (docs/osc.md).
fn progress(fraction: f32) -> OscMessage {
    msg("/vo/progress", vec![OscType::Float(fraction)])
}

/// Which of a generate's progress reports are pushed: the first to reach each next tenth,
/// so a generate pushes at most nine values between its 0 and its 1 however many batches
/// it draws (a tablet and the page need no more, and a 1000-candidate generate draws
/// dozens).
#[derive(Debug, Default)]
struct Tenths {
    /// Tenths passed so far.
    passed: u8,
}

impl Tenths {
    /// Whether `fraction` (0..1) reaches a tenth not reached before.
    fn crossed(&mut self, fraction: f32) -> bool {
        let tenth = (fraction * 10.0).clamp(0.0, 9.0) as u8;
        let crossed = tenth > self.passed;
        self.passed = self.passed.max(tenth);
        crossed
    }
}

#[cfg(test)]
mod tests {
    use super::Tenths;

    #[test]
    fn progress_is_pushed_once_a_tenth() {
        let mut tenths = Tenths::default();
        let reports = [0.0, 0.05, 0.12, 0.13, 0.31, 0.35, 0.5, 0.99, 0.995];
        let pushed: Vec<f32> = reports.into_iter().filter(|&f| tenths.crossed(f)).collect();
        assert_eq!(pushed, [0.12, 0.31, 0.5, 0.99]);
        // However many reports, at most nine pushes between 0 and 1.
        let mut tenths = Tenths::default();
        let n = (0..10_000)
            .filter(|&i| tenths.crossed(i as f32 / 10_000.0))
            .count();
        assert_eq!(n, 9);
    }
}
