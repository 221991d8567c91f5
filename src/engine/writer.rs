//! The background writer of `live.json` and `session.json`: it always writes the latest
//! [`Snapshot`] it was handed and drops older ones, so a flood of fader moves costs one
//! write per moment; a discrete change waits for its snapshot and hears of a failed write.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::Duration;

use super::persist::{Files, Snapshot};
use visobjd_files::save_json;

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
