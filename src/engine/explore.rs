//! Exploration that follows the hand: `/vo/explore 1`, then `/vo/objective/<id>/region`
//! updates as a finger or a mouse drags, then `/vo/explore 0`. One worker thread
//! regenerates from the latest regions for as long as they change and streams every
//! gallery to the subscribers (`/vo/generated`, then the tablet feedback, through
//! [`Engine::install_gallery`]).
//!
//! A region update only lands in a latest-value slot (per objective) and wakes the worker:
//! it never waits for a generate or the disk, and updates that arrive while a gallery is
//! drawn replace each other, so a flood costs one generate per gallery time, not one per
//! message. The worker takes the slot's regions into the session when it starts a gallery
//! (as a generate copies its inputs when it starts), so the regions the session shows are
//! always those of the gallery being drawn or shown. One seed serves the whole drag: the
//! candidates change with the region, not with fresh randomness.
//!
//! Backups are sent the regions and the latest gallery itself (`/vo/backup/gallery`), not
//! every gallery: before any other command is forwarded (so they see it in the main's
//! order), at most once a [`BACKUP_EVERY`] while the drag goes on, and once it ends.

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use rosc::{OscMessage, OscType};

use super::generate::{Inputs, NO_OBJECTIVES, Running, generated};
use super::session::Gallery;
use super::{Engine, Refusal, handover, msg};
use visobjd_method::gallery::Generation;
use visobjd_method::objective::Region;

/// An explore that hears no region update for this long ends by itself: a tablet that lost
/// the network mid-drag does not hold `/vo/generate` off for ever.
const IDLE: Duration = Duration::from_secs(60);
/// While a drag goes on, backups are brought up to date at most this often.
const BACKUP_EVERY: Duration = Duration::from_secs(1);
/// How long `/vo/explore 0` waits for the last gallery before answering anyway.
const FINISH: Duration = Duration::from_secs(60);

/// The explore slot and the worker's state (one per engine).
#[derive(Default)]
pub(super) struct Explore {
    state: Mutex<State>,
    /// Signalled when the slot changes, explore ends, a generate ends, the worker exits.
    changed: Condvar,
    /// What backups have not been sent yet of the explore galleries.
    unforwarded: Mutex<Option<Unforwarded>>,
}

#[derive(Default)]
struct State {
    on: bool,
    /// The worker thread is running.
    worker: bool,
    /// Regions received and not yet taken into a gallery: the latest per objective id.
    regions: Vec<(u32, Region)>,
    /// A gallery from the latest inputs is wanted.
    dirty: bool,
    seed: u64,
    last_update: Option<Instant>,
    /// Galleries streamed since `/vo/explore 1`.
    galleries: u64,
}

/// What brings a backup to the latest explore gallery: the regions it was drawn from,
/// and the gallery with its seed once one is drawn.
#[derive(Default)]
struct Unforwarded {
    regions: Vec<(u32, Region)>,
    gallery: Option<(Generation, u64)>,
}

impl Explore {
    fn state(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn unforwarded(&self) -> MutexGuard<'_, Option<Unforwarded>> {
        self.unforwarded.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Keeps the latest region of each objective.
fn merge(into: &mut Vec<(u32, Region)>, id: u32, region: Region) {
    match into.iter_mut().find(|(i, _)| *i == id) {
        Some(slot) => slot.1 = region,
        None => into.push((id, region)),
    }
}

impl Engine {
    /// Whether `/vo/explore 1` is on.
    pub fn exploring(&self) -> bool {
        self.explore.state().on
    }

    /// `/vo/explore 1`: starts streaming galleries (the first from the current regions at
    /// once). Returns the seed the drag draws with. Refused without objectives.
    pub fn explore_start(self: &Arc<Self>) -> Result<u64, Refusal> {
        let s = self.session();
        if s.objectives.is_empty() {
            return Err(Refusal::conflict(NO_OBJECTIVES));
        }
        let mut st = self.explore.state();
        if !st.on {
            st.on = true;
            st.seed = s.next_seed();
            st.galleries = 0;
        }
        st.dirty = true;
        st.last_update = Some(Instant::now());
        if !st.worker {
            let engine = Arc::clone(self);
            if let Err(e) = self
                .threads
                .spawn("explore", move || engine.explore_worker())
            {
                st.on = false;
                return Err(Refusal::internal(format!("cannot start exploring: {e}")));
            }
            st.worker = true;
        }
        self.explore.changed.notify_all();
        Ok(st.seed)
    }

    /// `/vo/explore 0`: ends the drag once the gallery of the last region is in (waits for
    /// it). Returns the galleries streamed and the seed (0 0 when not exploring).
    pub fn explore_stop(&self) -> Result<(u64, u64), Refusal> {
        let mut st = self.explore.state();
        if !st.on && !st.worker {
            return Ok((0, 0));
        }
        st.on = false;
        self.explore.changed.notify_all();
        let deadline = Instant::now() + FINISH;
        while st.worker {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(Refusal::internal(format!(
                    "explore stopped, but its last gallery took over {FINISH:?}; the gallery shows the last one done"
                )));
            }
            st = (self.explore.changed)
                .wait_timeout(st, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        Ok((st.galleries, st.seed))
    }

    /// A region update while exploring: kept in the slot for the next gallery (backups get
    /// the regions with the explore galleries, not as commands). False when explore has
    /// ended meanwhile (the caller sets the region as usual).
    pub fn explore_region(&self, id: u32, region: Region) -> bool {
        let mut st = self.explore.state();
        if !st.on {
            return false;
        }
        merge(&mut st.regions, id, region);
        st.dirty = true;
        st.last_update = Some(Instant::now());
        self.explore.changed.notify_all();
        true
    }

    /// Wakes the explore worker if it waits for a generate to end.
    pub(super) fn poke_explorer(&self) {
        self.explore.changed.notify_all();
    }

    /// The explore worker: draws a gallery whenever the inputs changed, until explore ends
    /// and the last gallery is in.
    fn explore_worker(self: Arc<Self>) {
        let mut last_backup = Instant::now();
        loop {
            let Some((regions, seed)) = self.next_job() else {
                return;
            };
            let running = Running(&self.generator.generating);
            let Some((inputs, serial)) = self.take_regions(&regions) else {
                continue;
            };
            // No progress: a gallery a drag draws is over in a few milliseconds, up to 50
            // a second.
            let Some((generation, ms)) = self.draw(&inputs, seed, serial, |_| {}) else {
                drop(running);
                continue;
            };
            let reply = generated(&generation, ms, seed);
            let s = self.session();
            if !inputs.current(&self) {
                tracing::info!("explore: {}", super::generate::RELOADED);
                continue;
            }
            if self.has_backups() {
                self.explore.unforwarded().get_or_insert_default().gallery =
                    Some((generation.clone(), seed));
            }
            drop(running);
            let done = {
                let mut st = self.explore.state();
                st.galleries += 1;
                !st.on && !st.dirty
            };
            if done || last_backup.elapsed() >= BACKUP_EVERY {
                self.flush_explored();
                last_backup = Instant::now();
            }
            let gallery = Gallery {
                generation,
                seed,
                serial,
            };
            self.install_gallery(s, gallery, vec![reply]);
        }
    }

    /// Waits until a gallery is wanted and no generate runs, then claims the generate
    /// flag and takes the slot: its regions and the seed. `None` when the worker is done
    /// (explore ended and the last gallery is in).
    fn next_job(&self) -> Option<(Vec<(u32, Region)>, u64)> {
        let mut st = self.explore.state();
        loop {
            if st.dirty
                && !self
                    .generator
                    .generating
                    .swap(true, std::sync::atomic::Ordering::SeqCst)
            {
                st.dirty = false;
                return Some((std::mem::take(&mut st.regions), st.seed));
            }
            if !st.on && !st.dirty {
                st.worker = false;
                self.explore.changed.notify_all();
                return None;
            }
            let idle = st.last_update.map_or(Duration::ZERO, |t| t.elapsed());
            if st.on && !st.dirty && idle >= IDLE {
                tracing::warn!(
                    "explore: no region update for {IDLE:?}; exploring ended (send /vo/explore 0 at the end of a drag)"
                );
                st.on = false;
                continue;
            }
            // Dirty but a generate runs: its end pokes; otherwise the idle limit.
            let wait = if st.dirty { FINISH } else { IDLE - idle };
            st = (self.explore.changed)
                .wait_timeout(st, wait)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    /// Sets the slot's regions in the session (objectives removed meanwhile are skipped)
    /// and copies the inputs of the gallery; the state is written soon. `None` when no
    /// objective is left.
    fn take_regions(&self, regions: &[(u32, Region)]) -> Option<(Inputs, u64)> {
        let mut s = self.session();
        for &(id, region) in regions {
            match s.objective_index(id) {
                Some(i) => s.objectives[i].objective.region = region,
                None => {
                    tracing::info!("explore: objective {id} was removed; its region is dropped")
                }
            }
        }
        if s.objectives.is_empty() {
            tracing::warn!("explore: every objective was removed; no gallery");
            return None;
        }
        let mut unforwarded = self.explore.unforwarded();
        let u = unforwarded.get_or_insert_default();
        for &(id, region) in regions {
            merge(&mut u.regions, id, region);
        }
        drop(unforwarded);
        if !regions.is_empty() {
            self.writer
                .save(super::Snapshot::of(&self.stage().scene, &s));
        }
        Some((Inputs::of(self.stage(), &s), self.next_serial()))
    }

    /// The messages that bring a backup to the latest explore gallery, once: the regions
    /// it set, then the gallery (`/vo/backup/gallery`); nothing, and nothing kept, when
    /// `backups` is false (a backup that subscribes later takes the state, gallery
    /// included). Call with the session locked, so they reach backups in the order the
    /// session took the changes.
    pub(super) fn explored_messages(&self, backups: bool) -> Vec<OscMessage> {
        let Some(u) = self.explore.unforwarded().take().filter(|_| backups) else {
            return Vec::new();
        };
        let mut out: Vec<OscMessage> = u
            .regions
            .iter()
            .map(|(id, r)| {
                msg(
                    &format!("/vo/objective/{id}/region"),
                    [r.x0, r.y0, r.x1, r.y1].map(OscType::Float).into(),
                )
            })
            .collect();
        if let Some((generation, seed)) = u.gallery {
            match handover::gallery_json(&self.stage().scene, &generation, seed) {
                Ok(text) => out.push(msg("/vo/backup/gallery", vec![OscType::String(text)])),
                Err(e) => tracing::error!(
                    "explore: {e}; the backups may differ from this main until they re-sync"
                ),
            }
        }
        out
    }
}
