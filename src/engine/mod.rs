//! The engine: the daemon's session (objectives, gallery, looks) behind the OSC handler,
//! wired to the compositor, the DMX output and the state files.
//!
//! The session sits behind a mutex held only for the few microseconds a command takes;
//! a generate copies what it needs, runs on its own thread with no lock held, and installs
//! its gallery when done. The DMX clock never waits on any of it: it is handed the latest
//! look through the output's watch channel.

mod explore;
mod outcome;
pub mod persist;
pub mod rules;
pub mod session;

pub use outcome::Outcome;
use outcome::{Persist, Push, Show};

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use rand::SeedableRng;
use rosc::{OscMessage, OscType};

use crate::cmd;
use crate::config::Config;
use crate::osc::args::Request;
use crate::osc::{Handler, Peer, Sender};
use crate::shutdown::Threads;
use persist::{Files, Snapshot, Writer};
use session::{Gallery, Session};
use visobjd_dmx::input::SourceInfo;
use visobjd_dmx::{Input, Output, OutputStats, Patch};
use visobjd_method::gallery::Generation;
use visobjd_method::objective::{Objective, decode_reference};
use visobjd_method::sampler::Spread;
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_scene::look::Look;
use visobjd_scene::look::LookFile;

/// How long a subscription lasts without a message from its subscriber (docs/osc.md).
const SUBSCRIPTION: Duration = Duration::from_secs(600);

/// Change batches kept for a slow web page before it is told it fell behind.
const CHANGES_KEPT: usize = 256;

/// Largest name of an uploaded reference image.
const MAX_REFERENCE_NAME: usize = 100;

/// A client that asked for state changes.
#[derive(Debug, Clone)]
struct Subscriber {
    /// Who subscribed (its messages renew the subscription).
    from: std::net::IpAddr,
    /// Where pushes go.
    to: SocketAddr,
    last_seen: Instant,
}

/// The daemon's state and everything it drives.
pub struct Engine {
    /// The loaded scene.
    pub stage: Arc<Stage>,
    references: PathBuf,
    palette_size: usize,
    spread: Spread,
    output: Mutex<Option<Output>>,
    /// The console's sACN, if `[input.sacn]` is configured.
    input: Mutex<Option<Input>>,
    /// The scene's patch, to read the console's DMX back as a look.
    patch: Patch,
    session: Mutex<Session>,
    generating: AtomicBool,
    /// `/vo/explore`: the region slot and the worker that streams galleries.
    explore: explore::Explore,
    /// Held while a reference is decoded: one at a time, so many senders adding 64-megapixel
    /// images at once cannot multiply the ~200 MB each decode takes.
    reading: Mutex<()>,
    /// Generates started in this run (the gallery serial of the next one, minus one).
    generates: AtomicU64,
    /// How many `/vo/entry/<k>/lit` were last pushed, so a smaller gallery turns the
    /// buttons past its end off.
    lit_span: AtomicUsize,
    files: Files,
    writer: Writer,
    /// Held across a write of `looks.json`, so saves and deletes reach the disk in the
    /// order they change the looks, without holding the session during the fsync.
    looks_io: Mutex<()>,
    /// Threads started for commands, joined at shutdown.
    threads: Threads,
    subscribers: Mutex<Vec<Subscriber>>,
    push: OnceLock<Sender>,
    /// Every batch pushed to subscribers, for the web page's event stream (src/http.rs);
    /// an empty batch is a change tablets are not told of (a saved look).
    changes: tokio::sync::broadcast::Sender<Arc<[OscMessage]>>,
    eos: crate::eos::EosConfig,
    /// `VISOBJD_TEST_HOOKS` was set: `/vo/test/...` may inject faults.
    test_hooks: bool,
    /// Test hook: the next generate panics.
    panic_generate: AtomicBool,
    /// `[backup] main`: this daemon is a backup of that main (src/backup.rs).
    main: Option<String>,
    /// The backups following this main: their connections, in subscription order.
    backups: Mutex<Vec<Peer>>,
    /// Generate count, clusters and fade of a fresh session (a backup's re-sync).
    defaults: (u32, u32, f32),
}

/// Set in the environment, enables the `/vo/test/...` fault hooks (never in production).
pub const TEST_HOOKS: &str = "VISOBJD_TEST_HOOKS";

impl Engine {
    /// An engine over a loaded stage, restored from `state_dir`, driving `output` and
    /// reading the console through `input`.
    pub fn new(
        config: &Config,
        stage: Arc<Stage>,
        output: Output,
        input: Option<Input>,
        mut session: Session,
    ) -> std::io::Result<Engine> {
        let files = Files::new(&config.state_dir);
        files.restore(&stage.scene, &mut session);
        output.set_master(session.master);
        output.set_blackout(session.blackout);
        output.set_look(session.live.clone(), 0.0);
        Ok(Engine {
            references: config.references.clone(),
            palette_size: config.generate.palette as usize,
            spread: Spread {
                key: config.generate.sigma_key,
                fill: config.generate.sigma_fill,
            },
            output: Mutex::new(Some(output)),
            input: Mutex::new(input),
            patch: Patch::new(&stage.scene),
            session: Mutex::new(session),
            generating: AtomicBool::new(false),
            explore: explore::Explore::default(),
            reading: Mutex::new(()),
            generates: AtomicU64::new(0),
            lit_span: AtomicUsize::new(0),
            writer: Writer::start(files.clone())?,
            files,
            looks_io: Mutex::new(()),
            threads: Threads::default(),
            subscribers: Mutex::new(Vec::new()),
            push: OnceLock::new(),
            changes: tokio::sync::broadcast::channel(CHANGES_KEPT).0,
            eos: config.eos.clone(),
            test_hooks: std::env::var_os(TEST_HOOKS).is_some(),
            panic_generate: AtomicBool::new(false),
            main: config.backup.as_ref().map(|b| b.main.trim().to_string()),
            backups: Mutex::new(Vec::new()),
            defaults: (
                config.generate.count,
                config.generate.clusters,
                config.output.fade_s,
            ),
            stage,
        })
    }

    /// Gives the engine the OSC server's sender, for subscription pushes.
    pub fn set_push(&self, sender: Sender) {
        let _ = self.push.set(sender);
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

    /// The one path of every change to the session: locks it, lets `change` mutate it
    /// (an `Err` must leave it as it was, and is answered as one `/vo/error`), then does
    /// what the [`Outcome`] asks in this order: the output shows it, the state is queued
    /// for the disk, the lock is released, subscribers are told, the write is waited for.
    /// A failed write is an `Err` too, but the change stays live (the stage is never taken
    /// back for a full disk): it would only not survive a restart.
    pub fn commit(
        &self,
        change: impl FnOnce(&mut Session) -> Result<Outcome, String>,
    ) -> Result<Vec<OscMessage>, String> {
        let mut s = self.session();
        let outcome = change(&mut s)?;
        // Whatever the outcome shows or saves: a change that does neither (the console
        // selection) reaches the backups in the order the session took it too.
        self.forward_pending();
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
            .then(|| self.writer.save(Snapshot::of(&self.stage.scene, &s)));
        self.publish(s, &pushes);
        if let Some(ticket) = ticket.filter(|_| outcome.persist == Persist::Now) {
            self.writer.wait(ticket).map_err(|e| {
                format!(
                    "state not saved: {e}; the change is live, but a restart would not bring it back"
                )
            })?;
        }
        Ok(outcome.replies)
    }

    /// Changes the saved looks durably: `change` edits a copy (seeing the session), the
    /// copy is written with the session unlocked, and only a written copy replaces the
    /// session's. A failed write changes nothing; the error is a sentence for `/vo/error`.
    pub fn change_looks<T>(
        &self,
        change: impl FnOnce(&Session, &mut BTreeMap<u32, LookFile>) -> Result<T, String>,
    ) -> Result<T, String> {
        let _in_order = self.looks_io.lock().unwrap_or_else(|p| p.into_inner());
        let (out, looks) = {
            let s = self.session();
            let mut looks = s.looks.clone();
            (change(&s, &mut looks)?, looks)
        };
        self.files
            .save_looks(&looks)
            .map_err(|e| format!("cannot write the saved looks in the state folder: {e}"))?;
        let mut s = self.session();
        s.looks = looks;
        self.forward_pending();
        self.publish(s, &[]);
        Ok(out)
    }

    /// The main this daemon is a backup of (`[backup] main`), if it is one.
    pub fn main(&self) -> Option<&str> {
        self.main.as_deref()
    }

    /// Sends an accepted command to every backup, in the order called; a backup whose
    /// connection closed or fell behind (its queue overflowed) is dropped: it re-syncs
    /// from the state when it subscribes again.
    pub fn forward(&self, m: &OscMessage) {
        self.forward_with(|| Ok(m.clone()));
    }

    /// As [`Engine::forward`], building the message only if a backup follows (a gallery
    /// costs its encoding); a message that cannot be built is logged and not sent. An
    /// explore gallery the backups lack goes first: the command may build on it.
    fn forward_with(&self, build: impl FnOnce() -> Result<OscMessage, String>) {
        let mut backups = self.backups.lock().unwrap_or_else(|p| p.into_inner());
        let mut msgs = self.explored_messages(!backups.is_empty());
        if backups.is_empty() {
            return;
        }
        match build() {
            Ok(m) => msgs.push(m),
            Err(e) => {
                tracing::error!("{e}; the backups may differ from this main until they re-sync")
            }
        }
        send_backups(&mut backups, &msgs);
    }

    /// Whether any backup follows this main (what is only for backups is then prepared).
    fn has_backups(&self) -> bool {
        !self
            .backups
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .is_empty()
    }

    /// Sends backups the latest explore gallery, if they lack it (call with the session
    /// locked, as [`Engine::forward`]).
    fn flush_explored(&self) {
        let mut backups = self.backups.lock().unwrap_or_else(|p| p.into_inner());
        let msgs = self.explored_messages(!backups.is_empty());
        send_backups(&mut backups, &msgs);
    }

    /// Forwards the command this thread applies, if it was not yet (call with the session
    /// locked, so backups get changes in the order the session took them).
    fn forward_pending(&self) {
        if let Some(m) = crate::backup::Pending::take() {
            self.forward(&m);
        }
    }

    /// `/vo/backup/subscribe` from `peer`: sends it the state and, from then on, every
    /// accepted command. The session stays locked meanwhile, so no change falls between
    /// the state and the first forwarded command.
    pub fn attach_backup(&self, peer: &Peer) -> Result<(), String> {
        if let Some(main) = &self.main {
            return Err(format!(
                "this daemon is itself a backup of {main}; a backup has no backups"
            ));
        }
        if peer.transport() == crate::osc::Transport::Udp {
            return Err(
                "a backup subscribes over TCP (osc.tcp): it needs every command, in order".into(),
            );
        }
        let s = self.session();
        let state = persist::state_json(&self.stage.scene, &s)?;
        let state = msg("/vo/backup/state", state.map(OscType::String).into());
        if !peer.reply(&[state]) {
            return Err("the state could not be sent: the connection is gone".into());
        }
        let mut backups = self.backups.lock().unwrap_or_else(|p| p.into_inner());
        backups.push(peer.clone());
        tracing::info!("backup {} subscribed: {} now", peer.addr(), backups.len());
        Ok(())
    }

    /// A backup takes its main's state (`/vo/backup/state`): the session is replaced (its
    /// gallery, history and console selection too), the stage shows the main's live look
    /// at once, and the state files are written.
    pub fn install_state(&self, parts: &[String; 4]) -> Result<(), String> {
        let _in_order = self.looks_io.lock().unwrap_or_else(|p| p.into_inner());
        let (count, clusters, fade_s) = self.defaults;
        let scene = &self.stage.scene;
        let fresh = Session::new(scene, count, clusters, fade_s);
        let (mut taken, lost) = persist::from_state(scene, parts, fresh)?;
        for what in lost {
            tracing::error!("backup: the main's state: not taken: {what}");
        }
        taken.gallery = taken.gallery.map(|g| self.received_gallery(g));
        self.commit(|s| {
            *s = taken;
            Ok(Outcome::replies(Vec::new()).show_look(0.0).saved().pushed())
        })?;
        self.commit(|_| Ok(Outcome::replies(Vec::new()).show_master()))?;
        let looks = self.session().looks.clone();
        self.files
            .save_looks(&looks)
            .map_err(|e| format!("cannot write the saved looks in the state folder: {e}"))
    }

    /// A backup takes the gallery its main's generate installed (`/vo/backup/gallery`),
    /// at the same point of the command order as the main installed it.
    pub fn install_gallery(&self, text: &str) -> Result<(), String> {
        let gallery = self.received_gallery(persist::gallery_from_json(&self.stage.scene, text)?);
        self.commit(|s| {
            s.gallery = Some(gallery);
            s.entry = None;
            Ok(Outcome::replies(Vec::new()).pushed())
        })
        .map(drop)
    }

    /// A gallery from the main made this daemon's: the representatives' thumbnails (the
    /// web gallery's) rendered here, with the session unlocked, and a serial of this run.
    fn received_gallery(&self, mut g: Gallery) -> Gallery {
        let reps: Vec<&Look> = g
            .generation
            .entries
            .iter()
            .filter_map(|members| g.generation.candidates.get(*members.first()?))
            .collect();
        g.generation.thumbnails = self.stage.thumbnails(&reps).into();
        g.serial = self.generates.fetch_add(1, Ordering::SeqCst) + 1;
        g
    }

    /// Runs `f` on the console input, if one is configured and still running.
    fn with_input<T>(&self, f: impl FnOnce(&Input) -> T) -> Option<T> {
        let guard = self.input.lock().unwrap_or_else(|p| p.into_inner());
        guard.as_ref().map(f)
    }

    /// Changes of the console's merged output (`None` without `[input.sacn]`).
    pub fn console_changes(&self) -> Option<tokio::sync::watch::Receiver<u64>> {
        self.with_input(Input::changes)
    }

    /// The console sources seen now (`None` without `[input.sacn]`).
    pub fn console_sources(&self) -> Option<Vec<SourceInfo>> {
        self.with_input(Input::sources)
    }

    /// The merged console output read back through the patch as a look, with how many
    /// sources made it; a sentence when there is no input or no source counts yet.
    pub fn console_look(&self) -> Result<(Look, usize), String> {
        let read = self.with_input(|input| {
            let console = input.console(self.patch.universes());
            if console.sources == 0 {
                return Err(format!(
                    "no console source is being received on universes {:?} at {} (a new source counts once it has been seen for {:.1} s)",
                    input.universes(),
                    input.bind(),
                    visobjd_dmx::input::SAMPLE.as_secs_f32()
                ));
            }
            Ok((self.patch.look(&console.dmx), console.sources))
        });
        read.unwrap_or_else(|| {
            Err("no console input is configured: add [input.sacn] with bind and universes to the config (docs/config.md)".into())
        })
    }

    /// Waits for the generates and exports still running, stops the output (three
    /// Stream_Terminated packets per sACN universe) and writes the state still queued
    /// (called by [`crate::shutdown::finish`]).
    pub fn shutdown(&self) {
        // A drag still on would keep its worker waiting for updates.
        if let Err(e) = self.explore_stop() {
            tracing::warn!("{e}");
        }
        self.threads.join();
        let input = self.input.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(input) = input {
            input.shutdown();
        }
        let out = self.output.lock().unwrap_or_else(|p| p.into_inner()).take();
        if let Some(out) = out {
            out.shutdown();
        }
        self.writer.finish();
    }

    /// The output's counters (`None` once it stopped).
    pub fn output_stats(&self) -> Option<OutputStats> {
        let mut stats = None;
        self.with_output(|o| stats = Some(o.stats()));
        stats
    }

    /// Fault injection for tests; refused unless [`TEST_HOOKS`] is set.
    pub fn test_hook(&self, hook: TestHook) -> Result<(), String> {
        if !self.test_hooks {
            return Err(format!("test hooks are off ({TEST_HOOKS} is not set)"));
        }
        match hook {
            TestHook::StallDmx(on) => self.with_output(|o| o.stall(on)),
            TestHook::PanicDmx => self.with_output(Output::panic_clock),
            TestHook::PanicGenerate => self.panic_generate.store(true, Ordering::SeqCst),
            TestHook::SlowDisk(ms) => self.writer.slow_down(ms),
        }
        Ok(())
    }

    /// The references folder (objective images are read from it, and only from it).
    pub fn references(&self) -> &Path {
        &self.references
    }

    /// The image files (PNG, JPEG by their extension) in the references folder, sorted.
    pub fn reference_names(&self) -> Result<Vec<String>, String> {
        let dir = std::fs::read_dir(&self.references).map_err(|e| {
            format!(
                "the references folder {} is not readable: {e}",
                self.references.display()
            )
        })?;
        let mut names: Vec<String> = dir
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| reference_format(n).is_some() && !n.starts_with('.'))
            .collect();
        names.sort();
        Ok(names)
    }

    /// Stores an uploaded reference image as `name` in the references folder, atomically,
    /// after the checks every reference passes (a plain file name with a PNG or JPEG
    /// extension, content of that type, within the size limit, decodable). Never replaces a
    /// file. The error says why, with `true` when the name is taken.
    pub fn store_reference(&self, name: &str, bytes: &[u8]) -> Result<String, (bool, String)> {
        let refused = |why: String| (false, format!("upload `{name}`: {why}"));
        let plain = !name.is_empty()
            && name.len() <= MAX_REFERENCE_NAME
            && !name.starts_with('.')
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._- ".contains(&b));
        if !plain {
            return Err(refused(format!(
                "a reference's name is a plain file name of at most {MAX_REFERENCE_NAME} letters, digits, spaces, '.', '_' or '-' (no folders), not starting with '.'"
            )));
        }
        let Some(format) = reference_format(name) else {
            return Err(refused("a reference is a .png, .jpg or .jpeg file".into()));
        };
        if image::guess_format(bytes).ok() != Some(format) {
            return Err(refused(format!(
                "the content is not a {} image",
                format
                    .extensions_str()
                    .first()
                    .copied()
                    .unwrap_or("")
                    .to_uppercase()
            )));
        }
        {
            let _one_at_a_time = self.reading.lock().unwrap_or_else(|p| p.into_inner());
            visobjd_method::objective::decode_reference_bytes(bytes).map_err(&refused)?;
        }
        let path = self.references.join(name);
        visobjd_files::write_new_atomic(&path, bytes).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => (
                true,
                format!("upload `{name}`: a reference of that name exists; choose another name"),
            ),
            _ => refused(format!(
                "cannot write it in the references folder {}: {e}",
                self.references.display()
            )),
        })?;
        tracing::info!("reference {name} stored ({} bytes)", bytes.len());
        Ok(name.to_string())
    }

    /// Reads and analyses a reference image from the references folder for a new
    /// objective, refusing paths that lead outside it (absolute paths, `..`, links). One at
    /// a time, and slow for a big image: it runs on the sender's own handling thread with
    /// the session unlocked, so a slow decode holds up only that sender, whose later
    /// messages then see the objective.
    pub fn read_objective(
        &self,
        name: &str,
        aspects: visobjd_method::objective::Aspects,
    ) -> Result<Objective, String> {
        let path = resolve_reference(&self.references, name)?;
        let img = self
            .decode_reference(&path)
            .map_err(|e| format!("{name} {e}"))?;
        Ok(Objective {
            image: name.to_string(),
            aspects,
            region: visobjd_method::objective::Region::FULL,
            analysis: visobjd_method::objective::analyze(
                &img,
                visobjd_method::objective::Region::FULL,
                self.palette_size,
            ),
        })
    }

    /// Decodes the reference image at `path` (resolved in the references folder), one at a
    /// time: a big image takes hundreds of MB while it decodes, and a page asks for every
    /// reference's picture at once.
    pub fn decode_reference(&self, path: &Path) -> Result<image::RgbImage, String> {
        let _one_at_a_time = self.reading.lock().unwrap_or_else(|p| p.into_inner());
        decode_reference(path)
    }

    /// Starts a generate on its own thread, with `seed` or the session's seed setting; the
    /// reply (`/vo/generated`) goes to `peer` when it is done. Refused while another runs
    /// and while exploring (the gallery then follows the regions).
    /// Backups are sent the gallery itself (`/vo/backup/gallery`) when it is installed.
    pub fn generate(self: &Arc<Self>, peer: &Peer, seed: Option<u64>) -> Result<(), String> {
        if self.exploring() {
            return Err(
                "exploring: the gallery follows the regions; send /vo/explore 0 to generate".into(),
            );
        }
        if self.generating.swap(true, Ordering::SeqCst) {
            return Err("a generate is already running; wait for /vo/generated".into());
        }
        let s = self.session();
        if s.objectives.is_empty() {
            self.generating.store(false, Ordering::SeqCst);
            return Err(NO_OBJECTIVES.into());
        }
        let inputs = Inputs::of(&self.stage, &s);
        // Seeds travel as OSC int32: a random one stays in 1..=i32::MAX so it can be replayed.
        let seed = seed.unwrap_or_else(|| s.next_seed());
        let serial = self.generates.fetch_add(1, Ordering::SeqCst) + 1;
        let mut started = vec![progress(0.0)];
        started.extend(self.feedback(&s));
        // In the session's order, as every change: a change made before the drawing
        // starts pushes after this, not before it.
        self.publish(s, &started);
        let engine = Arc::clone(self);
        let peer = peer.clone();
        let spawned = self.threads.spawn("generate", move || {
            // Whatever happens below, the next generate is allowed.
            let running = Running(&engine.generating);
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
                let e = error("/vo/generate", &why);
                // Free before the answer: the requester may generate again at once.
                drop(running);
                engine.generate_ended();
                engine.poke_explorer();
                peer.reply(std::slice::from_ref(&e));
                return;
            };
            let reply = generated(&generation, ms, seed);
            let mut s = engine.session();
            // Under the lock: the backups install it between the same two commands.
            engine.forward_with(|| {
                let text = persist::gallery_json(&engine.stage.scene, &generation, seed)?;
                Ok(msg("/vo/backup/gallery", vec![OscType::String(text)]))
            });
            s.gallery = Some(Gallery {
                generation,
                seed,
                serial,
            });
            s.entry = None;
            engine.generating.store(false, Ordering::SeqCst);
            let mut pushes = vec![progress(1.0), reply.clone()];
            pushes.extend(engine.feedback(&s));
            // Subscribers first: whoever acts on the reply (a pick) has its pushes come
            // after this gallery's, never before them.
            engine.publish(s, &pushes);
            peer.reply(std::slice::from_ref(&reply));
            engine.poke_explorer();
        });
        if let Err(e) = spawned {
            self.generating.store(false, Ordering::SeqCst);
            self.generate_ended();
            return Err(format!("cannot start the generate: {e}"));
        }
        Ok(())
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
    fn draw(
        &self,
        inputs: &Inputs,
        seed: u64,
        serial: u64,
        progress: impl FnMut(f32) + Send,
    ) -> Option<(Generation, f32)> {
        let started = Instant::now();
        let drawn = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            if self.panic_generate.swap(false, Ordering::SeqCst) {
                panic!("test hook: the generate panics");
            }
            // `scope` runs its body on a pool thread: the sampling and clustering between
            // the parallel parts are niced too, not run on this thread.
            rayon::scope(|_| {
                self.stage.generate_with_progress(
                    &GenerateRequest {
                        objectives: &inputs.objectives,
                        constraints: &inputs.constraints,
                        base: &inputs.base,
                        spread: self.spread,
                        count: inputs.count,
                        clusters: inputs.clusters,
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

    /// Pushes the live look to the configured Eos console and records it as preset `n`,
    /// on its own thread (a console may be slow to connect); `/vo/eos/preset n lights` goes
    /// to `peer` when it is sent, or `/vo/error` if it could not be.
    pub fn eos_preset(&self, n: u32, peer: &Peer) -> Result<(), String> {
        let to = self.eos.console()?.ok_or(
            "no Eos console is configured: set [eos] address (and protocol) in the config",
        )?;
        let commands = crate::eos::preset_commands(&self.stage.scene, &self.session().live, n);
        let lights = self.stage.scene.lights.len();
        let (config, peer) = (self.eos.clone(), peer.clone());
        self.threads
            .spawn("eos", move || {
                let reply = match crate::eos::push(&config, to, &commands) {
                    Ok(()) => msg(
                        "/vo/eos/preset",
                        vec![OscType::Int(n as i32), OscType::Int(lights as i32)],
                    ),
                    Err(e) => {
                        tracing::warn!("/vo/eos/preset {n}: {e}");
                        error("/vo/eos/preset", &e)
                    }
                };
                peer.reply(&[reply]);
            })
            .map(drop)
            .map_err(|e| format!("cannot start the Eos export: {e}"))
    }

    /// Whether a generate is running.
    pub fn is_generating(&self) -> bool {
        self.generating.load(Ordering::SeqCst)
    }

    /// `/vo/status` for `s`: the session, then the output's health (frames per second,
    /// late frames, failed sends, then a label and failed sends per destination).
    pub fn status(&self, s: &Session) -> OscMessage {
        let (candidates, clusters) = s
            .gallery
            .as_ref()
            .map_or((0, 0), |g| (g.generation.candidates.len(), g.len()));
        let health = self.output_stats();
        let mut args = vec![
            OscType::String(self.stage.scene.name.clone()),
            OscType::Int(self.stage.scene.lights.len() as i32),
            OscType::Int(s.objectives.len() as i32),
            OscType::Int(candidates as i32),
            OscType::Int(clusters as i32),
            OscType::Int(s.entry.map_or(0, |(k, _)| k as i32)),
            OscType::Float(s.fade_s),
            OscType::Int(i32::from(s.blackout)),
            OscType::Float(s.master),
        ];
        if let Some(h) = health {
            args.extend([
                OscType::Float(h.tick_rate),
                OscType::Int(h.late_ticks.min(i32::MAX as u64) as i32),
                OscType::Int(h.send_errors.min(i32::MAX as u64) as i32),
            ]);
            for (name, errors) in h.destinations {
                args.push(OscType::String(name));
                args.push(OscType::Int(errors.min(i32::MAX as u64) as i32));
            }
        }
        if let Some(sources) = self.console_sources() {
            args.push(OscType::String("console".into()));
            args.push(OscType::Int(sources.len() as i32));
            for src in sources {
                args.extend([
                    OscType::String(src.name),
                    OscType::Int(i32::from(src.priority)),
                    OscType::String(universe_list(&src.universes)),
                    OscType::Float(src.age.as_secs_f32()),
                ]);
            }
        }
        msg("/vo/status", args)
    }

    /// What a tablet shows of `s`, pushed to subscribers on every change so buttons and
    /// labels follow without scripts: `/vo/status`, the one-line `/vo/status/text`, the
    /// gallery sizes, and `/vo/entry/<k>/lit 0|1` for every entry (and for entries of a
    /// larger earlier gallery, turned off).
    pub fn feedback(&self, s: &Session) -> Vec<OscMessage> {
        let entries = s.gallery.as_ref().map_or(0, Gallery::len);
        let span = entries.max(self.lit_span.swap(entries, Ordering::SeqCst));
        let live = s.entry.map_or(0, |(k, _)| k);
        let mut out = vec![
            self.status(s),
            msg(
                "/vo/status/text",
                vec![OscType::String(self.status_text(s))],
            ),
            crate::cmd::gallery_sizes(s),
        ];
        out.extend((1..=span).map(|k| {
            msg(
                &format!("/vo/entry/{k}/lit"),
                vec![OscType::Int(i32::from(k == live))],
            )
        }));
        out
    }

    /// One line a person reads on a tablet or the web page: what is live, how big the
    /// gallery is, what is running.
    pub fn status_text(&self, s: &Session) -> String {
        let mut parts = Vec::new();
        if s.blackout {
            parts.push("BLACKOUT".to_string());
        }
        if self.exploring() {
            parts.push("exploring...".to_string());
        } else if self.is_generating() {
            parts.push("generating...".to_string());
        }
        parts.push(match (&s.gallery, s.entry) {
            (None, _) => "no gallery yet".to_string(),
            (Some(g), Some((k, 1))) => format!("entry {k} of {} live", g.len()),
            (Some(g), Some((k, m))) => format!("entry {k}.{m} of {} live", g.len()),
            (Some(g), None) => format!("{} entries", g.len()),
        });
        let n = s.objectives.len();
        parts.push(format!("{n} objective{}", if n == 1 { "" } else { "s" }));
        parts.push(format!("fade {} s", s.fade_s));
        if s.master < 1.0 {
            parts.push(format!("master {:.0}%", s.master * 100.0));
        }
        if let Some(h) = self.output_stats() {
            parts.push(h.summary());
        }
        if let Some(sources) = self.console_sources() {
            parts.push(console_summary(&sources, s.following));
        }
        parts.join(", ")
    }

    /// Adds or renews a subscription from `peer`, pushing to its address at `port`.
    pub fn subscribe(&self, peer: &Peer, port: Option<u16>) -> SocketAddr {
        let to = SocketAddr::new(peer.addr().ip(), port.unwrap_or(peer.reply_addr().port()));
        let mut subs = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
        subs.retain(|s| s.to != to);
        subs.push(Subscriber {
            from: peer.addr().ip(),
            to,
            last_seen: Instant::now(),
        });
        to
    }

    /// Ends `peer`'s subscriptions.
    pub fn unsubscribe(&self, peer: &Peer) {
        let mut subs = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
        subs.retain(|s| s.from != peer.addr().ip());
    }

    /// Sends messages to `to` from the OSC port (pushes, not replies).
    pub fn push_to(&self, to: SocketAddr, msgs: &[OscMessage]) -> Result<(), String> {
        let push = self
            .push
            .get()
            .ok_or("subscriptions need OSC over UDP (osc.udp is off)")?;
        msgs.iter().try_for_each(|m| push.send(to, m))
    }

    /// Every change from now on, as the batches [`Engine::notify`] pushes (the web page's
    /// event stream).
    pub fn changes(&self) -> tokio::sync::broadcast::Receiver<Arc<[OscMessage]>> {
        self.changes.subscribe()
    }

    /// Pushes messages to every live subscriber (expired or unreachable ones are dropped)
    /// and to the web pages' event streams.
    pub fn notify(&self, msgs: &[OscMessage]) {
        let subs = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
        self.push_all(subs, msgs);
    }

    /// Releases the session, then pushes `msgs` as [`Engine::notify`] does, in the order the
    /// session changed: the pushes' lock is taken before the session's is let go, so two
    /// changes' pushes never cross (a tablet would be left showing the older state).
    fn publish(&self, s: MutexGuard<'_, Session>, msgs: &[OscMessage]) {
        let subs = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
        drop(s);
        self.push_all(subs, msgs);
    }

    fn push_all(&self, mut subs: MutexGuard<'_, Vec<Subscriber>>, msgs: &[OscMessage]) {
        // No page listening is no error (and then no copy of the batch is made).
        if self.changes.receiver_count() > 0 {
            let _ = self.changes.send(msgs.into());
        }
        subs.retain(|s| {
            s.last_seen.elapsed() < SUBSCRIPTION
                && match self.push_to(s.to, msgs) {
                    Ok(()) => true,
                    Err(e) => {
                        tracing::info!("dropped the subscription of {}: {e}", s.to);
                        false
                    }
                }
        });
    }

    fn renew(&self, peer: &Peer) {
        let mut subs = self.subscribers.lock().unwrap_or_else(|p| p.into_inner());
        for s in subs.iter_mut().filter(|s| s.from == peer.addr().ip()) {
            s.last_seen = Instant::now();
        }
    }
}

/// Sends messages to every backup, in order; a backup whose connection closed or fell
/// behind (its queue overflowed) is dropped: it re-syncs from the state when it
/// subscribes again.
fn send_backups(backups: &mut Vec<Peer>, msgs: &[OscMessage]) {
    if msgs.is_empty() {
        return;
    }
    backups.retain(|b| {
        let sent = b.reply(msgs);
        if !sent {
            tracing::warn!(
                "backup {} dropped: its connection closed or fell behind; it re-syncs when it subscribes again",
                b.addr()
            );
        }
        sent
    });
}

/// The image format a reference's file name promises, by its extension.
fn reference_format(name: &str) -> Option<image::ImageFormat> {
    let (_, ext) = name.rsplit_once('.')?;
    match ext.to_ascii_lowercase().as_str() {
        "png" => Some(image::ImageFormat::Png),
        "jpg" | "jpeg" => Some(image::ImageFormat::Jpeg),
        _ => None,
    }
}

/// Universes as status lists them: `1 2 5`.
fn universe_list(universes: &[u16]) -> String {
    universes
        .iter()
        .map(u16::to_string)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The status line's console part: `console: Eos (100, u1 2, 0.1 s ago)`, `sampling` for a
/// source not counted yet, `following` while the base follows it.
fn console_summary(sources: &[SourceInfo], following: bool) -> String {
    let list = if sources.is_empty() {
        "no source".to_string()
    } else {
        sources
            .iter()
            .map(|s| {
                format!(
                    "{} ({}, u{}, {:.1} s ago{})",
                    s.name,
                    s.priority,
                    universe_list(&s.universes),
                    s.age.as_secs_f32(),
                    if s.active { "" } else { ", sampling" }
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    let follow = if following { ", following" } else { "" };
    format!("console{follow}: {list}")
}

/// A fault a test injects (see [`Engine::test_hook`]).
#[derive(Debug, Clone, Copy)]
pub enum TestHook {
    /// Holds the DMX clock still (on) or lets it go (off).
    StallDmx(bool),
    /// Makes the DMX clock thread panic.
    PanicDmx,
    /// Makes the next generate panic.
    PanicGenerate,
    /// Makes every state write wait this many milliseconds first.
    SlowDisk(u64),
}

/// What a generate draws from, copied out of the session so it runs with the session
/// unlocked.
struct Inputs {
    objectives: Vec<Objective>,
    constraints: visobjd_method::sampler::Constraints,
    base: Look,
    count: usize,
    clusters: usize,
}

impl Inputs {
    fn of(stage: &Stage, s: &Session) -> Inputs {
        Inputs {
            objectives: s.objectives.iter().map(|e| e.objective.clone()).collect(),
            constraints: s.constraints(&stage.scene, false),
            base: s.base.clone(),
            count: s.count as usize,
            clusters: s.clusters as usize,
        }
    }
}

/// `/vo/generated candidates clusters ms seed`, the reply to a generate and the push of
/// every gallery.
fn generated(generation: &Generation, ms: f32, seed: u64) -> OscMessage {
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

/// Why a generate (or an explore) cannot start without objectives.
const NO_OBJECTIVES: &str = "there are no objectives: add one with /vo/objective/add first";

/// Clears the "generating" flag when dropped, so a generate that panics never blocks the
/// next one.
struct Running<'a>(&'a AtomicBool);

impl Drop for Running<'_> {
    fn drop(&mut self) {
        self.0.store(false, Ordering::SeqCst);
    }
}

/// Handles OSC for an engine behind an `Arc` (generates need to outlive the message).
pub struct EngineHandler(pub Arc<Engine>);

impl Handler for EngineHandler {
    fn handle(&self, req: Request, peer: &Peer) -> Vec<OscMessage> {
        self.0.renew(peer);
        match cmd::run(&self.0, &req, peer) {
            Ok(replies) => replies,
            Err(e) => {
                tracing::info!("{} from {}: {e}", req.addr, peer.addr());
                vec![error(&req.addr, &e)]
            }
        }
    }
}

/// An OSC message.
pub fn msg(addr: &str, args: Vec<OscType>) -> OscMessage {
    OscMessage {
        addr: addr.to_string(),
        args,
    }
}

/// `/vo/error <address> <message>`.
pub fn error(addr: &str, message: &str) -> OscMessage {
    msg(
        "/vo/error",
        vec![
            OscType::String(addr.to_string()),
            OscType::String(message.to_string()),
        ],
    )
}

/// The file `name` inside `references`, refusing anything that leads outside it.
pub fn resolve_reference(references: &Path, name: &str) -> Result<PathBuf, String> {
    let relative = visobjd_scene::safe_relative(name).ok_or_else(|| {
        format!("image `{name}` must be a file name inside the references folder (no absolute paths, no ..)")
    })?;
    let root = references.canonicalize().map_err(|e| {
        format!(
            "the references folder {} is not readable: {e}",
            references.display()
        )
    })?;
    let path = root
        .join(relative)
        .canonicalize()
        .map_err(|_| format!("image `{name}` is not in the references folder"))?;
    if !path.starts_with(&root) {
        return Err(format!(
            "image `{name}` leads outside the references folder"
        ));
    }
    if !path.is_file() {
        return Err(format!("image `{name}` is not a file"));
    }
    Ok(path)
}

/// The look of entry `k`, member `m` of the gallery, or a sentence saying why not.
pub fn gallery_look(s: &Session, k: usize, m: usize) -> Result<Look, String> {
    let g = s
        .gallery
        .as_ref()
        .ok_or("there is no gallery yet: send /vo/generate first")?;
    if k == 0 || k > g.len() {
        return Err(format!(
            "entry {k} is not in the gallery (entries 1-{})",
            g.len()
        ));
    }
    g.candidate(k, m).cloned().ok_or_else(|| {
        format!(
            "entry {k} has no member {m} (members 1-{})",
            g.generation.entries[k - 1].len()
        )
    })
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
