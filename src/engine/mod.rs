//! The engine: the daemon's session (objectives, gallery, looks) and the one path every
//! change takes ([`Engine::commit`]), wired to the method, the compositor, the DMX output
//! and the state folder.
//!
//! It knows no transport and no command: the commands (src/cmd/) call it, never the other
//! way, as mini-redis's `Db` knows nothing of its `cmd`. What it sends when nobody is
//! waiting for a reply (a generate's late answer, a backup's stream of commands,
//! subscribers' pushes) goes through what the transport hands it: a [`Later`], a
//! [`Follower`], a [`Pusher`].
//!
//! The session sits behind a mutex held only for the few microseconds a change takes; a
//! generate copies what it needs, runs on its own thread with no lock held, and installs its
//! gallery when done. The DMX clock never waits on any of it: it is handed the latest look
//! through the output's watch channel.
//!
//! By concern, one file each: this one (the state, `commit`, `change_looks`, shutdown);
//! `session` and `rules` (the state itself, plain data); `outcome` (what a change asks
//! for); `refusal` (why one was refused); `generate` and `explore` (galleries);
//! `references` (the reference images); `reload` (the running config and scene, swapped
//! whole by a reload); `view` (what tablets are shown); `pushes`
//! (subscribers and the web page's event stream); `backups`, `handover` and `state_size` (a
//! main's replication, and the largest state it hands a backup); `console` (the console's sACN); `export` (to Eos); `persist` and `writer`
//! (the state folder); `threads`; `test_hooks`.

mod backups;
mod console;
mod explore;
mod export;
pub use export::EosRecord;
mod generate;
mod handover;
mod outcome;
pub mod persist;
mod pushes;
mod references;
mod refusal;
mod reload;
pub mod rules;
pub mod session;
pub mod state_size;
mod test_hooks;
mod threads;
mod view;
mod writer;

pub use outcome::Outcome;
pub use pushes::{Pusher, SUBSCRIPTIONS_PER_HOST};
pub use references::{reference_files, resolve_reference, stock_references};
pub use refusal::{Refusal, RefusalKind};
pub use reload::{Loaded, keep_scene};
pub use test_hooks::{TEST_HOOKS, TestHook};
pub use view::gallery_sizes;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, RwLock};

use rosc::{OscMessage, OscType};

use crate::config::Config;
use outcome::{Persist, Push, Show};
use persist::{Files, Snapshot};
use session::Session;
use threads::Threads;
use visobjd_dmx::{Input, Output, OutputStats};
use visobjd_scene::look::LookFile;
use writer::Writer;

/// Where a command's answer goes when it comes after the command returned (a generate's
/// `/vo/generated`, an Eos export's result): the transport renders it to the sender as it
/// renders a reply, so the engine knows no socket.
pub type Later = Box<dyn FnOnce(Result<Vec<OscMessage>, Refusal>) + Send>;

/// A backup following this main: sent the state, then every accepted command. The
/// transport implements it over the backup's connection.
pub trait Follower: Send + Sync + 'static {
    /// Sends `msgs` in order; false when the connection is gone or fell behind (its queue
    /// is full).
    fn send(&self, msgs: &[OscMessage]) -> bool;
    /// Where it is, for the log.
    fn addr(&self) -> SocketAddr;
}

/// The daemon's state and everything it drives.
pub struct Engine {
    /// The running scene (see [`Engine::stage`]).
    loaded: RwLock<Loaded>,
    /// The running config: a reload replaces it, and the transports follow it
    /// ([`Engine::config_changes`]).
    config: tokio::sync::watch::Sender<Arc<Config>>,
    /// Held by a reload, so two never interleave.
    reloading: Mutex<()>,
    session: Mutex<Session>,
    output: Mutex<Option<Output>>,
    files: Files,
    writer: Writer,
    /// Held across a write of `looks.json`, so saves and deletes reach the disk in the
    /// order they change the looks, without holding the session during the fsync.
    looks_io: Mutex<()>,
    /// Threads started for commands, joined at shutdown.
    threads: Threads,
    references: references::References,
    generator: generate::Generator,
    /// `/vo/explore`: the region slot and the worker that streams galleries.
    explore: explore::Explore,
    pushes: pushes::Pushes,
    backups: backups::Backups,
    console: console::ConsoleInput,
    /// The Eos export waiting for Eos's answers, if one runs.
    eos_answers: export::EosAnswers,
    hooks: test_hooks::Hooks,
}

impl Engine {
    /// An engine over `loaded` (the scene, or what stands in for one that did not load),
    /// restored from `state_dir`, driving `output` and reading the console through `input`.
    pub fn new(
        config: Config,
        loaded: Loaded,
        output: Output,
        input: Option<Input>,
        mut session: Session,
    ) -> std::io::Result<Engine> {
        let files = Files::new(&config.state_dir);
        files.restore(&loaded.stage.scene, &mut session);
        output.set_master(session.master);
        output.set_blackout(session.blackout);
        output.set_look(session.live.clone(), 0.0);
        Ok(Engine {
            references: references::References::default(),
            generator: generate::Generator::default(),
            explore: explore::Explore::default(),
            pushes: pushes::Pushes::default(),
            backups: backups::Backups::new(&config),
            console: console::ConsoleInput::new(input),
            eos_answers: export::EosAnswers::default(),
            hooks: test_hooks::Hooks::from_env(),
            output: Mutex::new(Some(output)),
            session: Mutex::new(session),
            writer: Writer::start(files.clone())?,
            files,
            looks_io: Mutex::new(()),
            threads: Threads::default(),
            loaded: RwLock::new(loaded),
            config: tokio::sync::watch::Sender::new(Arc::new(config)),
            reloading: Mutex::new(()),
        })
    }

    /// The session, locked. A panic elsewhere never leaves it unusable.
    pub fn session(&self) -> MutexGuard<'_, Session> {
        self.session.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Runs `f` on the output, if it is still running.
    fn with_output(&self, f: impl FnOnce(&Output)) {
        let guard = self.output.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(out) = guard.as_ref() {
            f(out);
        }
    }

    /// The one path of every change to the session: locks it, lets `change` mutate it (an
    /// `Err` must leave it as it was), then does what the [`Outcome`] asks in this order:
    /// `forward` goes to the backups (the command as received, when it changes the
    /// session), the output shows the change, the state is queued for the disk, the lock is
    /// released, subscribers are told, the write is waited for. A failed write is an `Err`
    /// too, but the change stays live (the stage is never taken back for a full disk): it
    /// would only not survive a restart.
    pub fn commit(
        &self,
        forward: Option<&OscMessage>,
        change: impl FnOnce(&mut Session) -> Result<Outcome, Refusal>,
    ) -> Result<Vec<OscMessage>, Refusal> {
        let mut s = self.session();
        let outcome = change(&mut s)?;
        // Under the lock, whatever the outcome shows or saves (the Eos selection does
        // neither): backups take changes in the order the session took them.
        if let Some(m) = forward {
            self.forward(m);
        }
        match outcome.show {
            Show::Nothing => {}
            Show::Look(fade_s) => self.with_output(|o| o.set_look(s.live.clone(), fade_s)),
            Show::Master => self.with_output(|o| {
                o.set_master(s.master);
                o.set_blackout(s.blackout);
            }),
        }
        let mut pushes = Vec::new();
        if outcome.push == Push::Echo {
            pushes.extend(outcome.replies.iter().cloned());
        }
        if outcome.push != Push::Nobody {
            pushes.extend(self.feedback(&s));
        }
        let ticket = (outcome.persist != Persist::No)
            .then(|| self.writer.save(Snapshot::of(&self.stage().scene, &s)));
        self.publish(s, &pushes);
        if let Some(ticket) = ticket.filter(|_| outcome.persist == Persist::Now) {
            self.writer.wait(ticket).map_err(|e| {
                Refusal::internal(format!(
                    "state not saved: {e}; the change is live, but a restart would not bring it back"
                ))
            })?;
        }
        Ok(outcome.replies)
    }

    /// Changes the saved looks durably: `change` edits a copy (seeing the session), the
    /// copy is written with the session unlocked, and only a written copy replaces the
    /// session's (and only then is `forward` sent to the backups). A failed write changes
    /// nothing.
    pub fn change_looks<T>(
        &self,
        forward: Option<&OscMessage>,
        change: impl FnOnce(&Session, &mut BTreeMap<u32, LookFile>) -> Result<T, Refusal>,
    ) -> Result<T, Refusal> {
        let _in_order = self.looks_io.lock().unwrap_or_else(|p| p.into_inner());
        let (out, looks) = {
            let s = self.session();
            let mut looks = s.looks.clone();
            (change(&s, &mut looks)?, looks)
        };
        self.save_looks(&looks)?;
        let mut s = self.session();
        s.looks = looks;
        if let Some(m) = forward {
            self.forward(m);
        }
        self.publish(s, &[]);
        Ok(out)
    }

    /// Writes `looks.json` now (call with the session unlocked).
    fn save_looks(&self, looks: &BTreeMap<u32, LookFile>) -> Result<(), Refusal> {
        self.files.save_looks(looks).map_err(|e| {
            Refusal::internal(format!(
                "cannot write the saved looks in the state folder: {e}"
            ))
        })
    }

    /// The output's counters (`None` once it stopped).
    pub fn output_stats(&self) -> Option<OutputStats> {
        let mut stats = None;
        self.with_output(|o| stats = Some(o.stats()));
        stats
    }

    /// Waits for the generates and exports still running, stops the output (three
    /// Stream_Terminated packets per sACN universe) and writes the state still queued
    /// (called by `shutdown::finish`, once nothing new comes in).
    pub fn shutdown(&self) {
        // A drag still on would keep its worker waiting for updates.
        if let Err(e) = self.explore_stop() {
            tracing::warn!("{e}");
        }
        self.threads.join();
        self.console.shutdown();
        let out = self.output.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(out) = out {
            out.shutdown();
        }
        self.writer.finish();
    }
}

/// An OSC message.
pub fn msg(addr: &str, args: Vec<OscType>) -> OscMessage {
    OscMessage {
        addr: addr.to_string(),
        args,
    }
}
