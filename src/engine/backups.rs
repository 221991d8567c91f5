//! A main's side of replication (docs/reliability.md, "Backup"): the backups following it,
//! each sent the whole session when it subscribes and then every command the main
//! accepted, in the order the session took them ([`Engine::commit`] forwards under the
//! session lock); a generate is sent as the gallery it installed, explore galleries as
//! their regions and the latest gallery. And a backup's side of taking its main's state
//! and galleries. The backup's connection to its main is src/backup.rs.

use std::sync::{Arc, Mutex, MutexGuard};

use rosc::{OscMessage, OscType};

use super::handover;
use super::session::{Gallery, Session};
use super::{Engine, Follower, Outcome, Refusal, msg};
use crate::config::Config;
use visobjd_scene::look::Look;

/// The backups following this main, or the main this daemon is a backup of.
pub(super) struct Backups {
    /// `[backup] main`: this daemon is a backup of that main.
    main: Option<String>,
    /// The backups following this main, in subscription order.
    followers: Mutex<Vec<Arc<dyn Follower>>>,
    /// Generate count, clusters and fade of a fresh session (a backup's re-sync).
    defaults: (u32, u32, f32),
    /// A backup's: why it is not following its main, while it is not (`/vo/status`).
    problem: Mutex<Option<String>>,
}

impl Backups {
    pub(super) fn new(config: &Config) -> Backups {
        Backups {
            main: config.backup.as_ref().map(|b| b.main.trim().to_string()),
            followers: Mutex::new(Vec::new()),
            defaults: (
                config.generate.count,
                config.generate.clusters,
                config.output.fade_s,
            ),
            problem: Mutex::new(None),
        }
    }

    fn followers(&self) -> MutexGuard<'_, Vec<Arc<dyn Follower>>> {
        self.followers.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Engine {
    /// The main this daemon is a backup of (`[backup] main`), if it is one.
    pub fn main(&self) -> Option<&str> {
        self.backups.main.as_deref()
    }

    /// A backup's: why it is not following its main now, if it is not (what
    /// `/vo/status` shows beside a scene that did not load).
    pub fn backup_problem(&self) -> Option<String> {
        self.backups
            .problem
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// A backup's: records why it is not following its main (None: it follows again), and
    /// tells subscribers when that changed.
    pub fn set_backup_problem(&self, problem: Option<String>) {
        {
            let mut now = self
                .backups
                .problem
                .lock()
                .unwrap_or_else(|p| p.into_inner());
            if *now == problem {
                return;
            }
            *now = problem;
        }
        let s = self.session();
        let pushes = self.feedback(&s);
        self.publish(s, &pushes);
    }

    /// A backup's: the largest frame it takes from its main, the largest state a main of
    /// this scene can send ([`super::state_size`]), and never less than a client's frame.
    pub fn backup_frame_limit(&self) -> usize {
        super::state_size::max_state_message(&self.stage().scene)
            .max(crate::osc::framing::MAX_FRAME)
    }

    /// Sends an accepted command to every backup (call with the session locked, so they
    /// take changes in the order the session did).
    pub(super) fn forward(&self, m: &OscMessage) {
        self.forward_with(|| Ok(m.clone()));
    }

    /// As [`Engine::forward`], building the message only if a backup follows (a gallery
    /// costs its encoding); a message that cannot be built is logged and not sent. An
    /// explore gallery the backups lack goes first: the command may build on it.
    pub(super) fn forward_with(&self, build: impl FnOnce() -> Result<OscMessage, String>) {
        let mut followers = self.backups.followers();
        let mut msgs = self.explored_messages(!followers.is_empty());
        if followers.is_empty() {
            return;
        }
        match build() {
            Ok(m) => msgs.push(m),
            Err(e) => {
                tracing::error!("{e}; the backups may differ from this main until they re-sync")
            }
        }
        send(&mut followers, &msgs);
    }

    /// Whether any backup follows this main (what is only for backups is then prepared).
    pub(super) fn has_backups(&self) -> bool {
        !self.backups.followers().is_empty()
    }

    /// Sends backups the latest explore gallery, if they lack it (call with the session
    /// locked, as [`Engine::forward`]).
    pub(super) fn flush_explored(&self) {
        let mut followers = self.backups.followers();
        let msgs = self.explored_messages(!followers.is_empty());
        send(&mut followers, &msgs);
    }

    /// `/vo/backup/subscribe`: sends `backup` the state and, from then on, every accepted
    /// command. The session stays locked meanwhile, so no change falls between the state
    /// and the first forwarded command.
    pub fn attach_backup(&self, backup: Arc<dyn Follower>) -> Result<(), Refusal> {
        if let Some(main) = self.main() {
            return Err(Refusal::conflict(format!(
                "this daemon is itself a backup of {main}; a backup has no backups"
            )));
        }
        let s = self.session();
        let scene = &self.stage().scene;
        let state = handover::state_json(scene, &s).map_err(Refusal::internal)?;
        // What the backup will say too, said here where the state is (a backup of this
        // scene takes no larger frame): saved looks of a larger rig, or a state file
        // edited past the session's limits.
        let bytes: usize = state.iter().map(|part| part.len() + 4).sum::<usize>() + 28;
        let limit = super::state_size::max_state_message(scene);
        if bytes > limit {
            tracing::error!(
                "backup {}: this main's state is about {bytes} bytes, over the {limit} a backup of this scene takes: it will not follow (saved looks made on a larger rig? delete them or save them again)",
                backup.addr()
            );
        }
        let state = msg("/vo/backup/state", state.map(OscType::String).into());
        if !backup.send(&[state]) {
            return Err(Refusal::internal(
                "the state could not be sent: the connection is gone",
            ));
        }
        let mut followers = self.backups.followers();
        followers.push(Arc::clone(&backup));
        tracing::info!(
            "backup {} subscribed: {} now",
            backup.addr(),
            followers.len()
        );
        Ok(())
    }

    /// A backup takes its main's state (`/vo/backup/state`): the session is replaced (its
    /// gallery, history and Eos selection too), the stage shows the main's live look at
    /// once, and the state files are written.
    pub fn install_state(&self, parts: &[String; 4]) -> Result<(), Refusal> {
        let _in_order = self.looks_io.lock().unwrap_or_else(|p| p.into_inner());
        let (count, clusters, fade_s) = self.backups.defaults;
        let scene = &self.stage().scene;
        let fresh = Session::new(scene, count, clusters, fade_s);
        let (mut taken, lost) =
            handover::from_state(scene, parts, fresh).map_err(Refusal::input)?;
        for what in lost {
            tracing::error!("backup: the main's state: not taken: {what}");
        }
        taken.gallery = taken.gallery.map(|g| self.received_gallery(g));
        // Once the session is the main's, the backup follows: a state file it cannot write
        // (a full disk) is logged, and does not make it re-subscribe for the same state.
        let written = self.commit(None, |s| {
            *s = taken;
            Ok(Outcome::replies(Vec::new()).show_look(0.0).saved().pushed())
        });
        self.commit(None, |_| Ok(Outcome::replies(Vec::new()).show_master()))?;
        let looks = self.session().looks.clone();
        for e in [written.err(), self.save_looks(&looks).err()]
            .into_iter()
            .flatten()
        {
            tracing::error!("backup: the main's state is taken, but {e}");
        }
        Ok(())
    }

    /// A backup takes the gallery its main's generate installed (`/vo/backup/gallery`),
    /// at the same point of the command order as the main installed it.
    pub fn take_gallery(&self, text: &str) -> Result<(), Refusal> {
        let gallery =
            handover::gallery_from_json(&self.stage().scene, text).map_err(Refusal::input)?;
        let gallery = self.received_gallery(gallery);
        self.install_gallery(self.session(), gallery, Vec::new());
        Ok(())
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
        g.generation.thumbnails = self.stage().thumbnails(&reps).into();
        g.serial = self.next_serial();
        g
    }
}

/// Sends messages to every backup, in order; a backup whose connection closed or fell
/// behind (its queue overflowed) is dropped: it re-syncs from the state when it
/// subscribes again.
fn send(followers: &mut Vec<Arc<dyn Follower>>, msgs: &[OscMessage]) {
    if msgs.is_empty() {
        return;
    }
    followers.retain(|b| {
        let sent = b.send(msgs);
        if !sent {
            tracing::warn!(
                "backup {} dropped: its connection closed or fell behind; it re-syncs when it subscribes again",
                b.addr()
            );
        }
        sent
    });
}
