//! Stopping, in one place and one order. On SIGTERM or SIGINT the daemon stops taking
//! messages (OSC, the web page) and stops pinging the watchdog, lets the work already
//! started finish (generates, Eos exports), then stops the output (three sACN
//! Stream_Terminated packets per universe, so receivers release at once) and writes the
//! state still queued (the last fader move survives a clean stop). Every OS thread the
//! daemon starts for a command is registered in [`Threads`] and joined here; the runtime's
//! tasks are aborted and awaited.

use std::sync::Mutex;
use std::thread::JoinHandle;

use anyhow::Context;

use crate::engine::Engine;
use crate::http::Http;
use crate::osc::Server;

/// The OS threads started for commands (generates, Eos exports), so shutdown can join the
/// ones still running; finished ones are let go as new ones start.
#[derive(Debug, Default)]
pub struct Threads(Mutex<Vec<JoinHandle<()>>>);

impl Threads {
    /// Starts `work` on a thread called `name` and keeps its handle.
    pub fn spawn(&self, name: &str, work: impl FnOnce() + Send + 'static) -> std::io::Result<()> {
        let handle = std::thread::Builder::new().name(name.into()).spawn(work)?;
        let mut running = self.0.lock().unwrap_or_else(|p| p.into_inner());
        running.retain(|h| !h.is_finished());
        running.push(handle);
        Ok(())
    }

    /// Waits for every thread still running.
    pub fn join(&self) {
        let running = std::mem::take(&mut *self.0.lock().unwrap_or_else(|p| p.into_inner()));
        for handle in running {
            let name = handle.thread().name().unwrap_or("?").to_string();
            if handle.join().is_err() {
                tracing::error!("the {name} thread panicked before shutdown");
            }
        }
    }
}

/// Waits for SIGTERM or SIGINT.
pub async fn signalled() -> anyhow::Result<()> {
    use tokio::signal::unix::{SignalKind, signal};
    let mut term = signal(SignalKind::terminate()).context("cannot watch SIGTERM")?;
    let mut int = signal(SignalKind::interrupt()).context("cannot watch SIGINT")?;
    tokio::select! {
        _ = term.recv() => tracing::info!("SIGTERM: stopping"),
        _ = int.recv() => tracing::info!("SIGINT: stopping"),
    }
    Ok(())
}

/// Inside the runtime: nothing new comes in. The OSC listeners and the web page stop, and
/// so do the runtime's own tasks (the watchdog pinger), each awaited.
pub async fn stop_intake(
    server: Server,
    http: Option<Http>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
) {
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
    server.stop().await;
    if let Some(http) = http {
        http.stop().await;
    }
    for task in tasks {
        task.abort();
        // A cancelled task's error is the expected outcome.
        let _ = task.await;
    }
}

/// After the runtime: the work in flight finishes, the output stops, the state is written.
pub fn finish(engine: &Engine) {
    engine.shutdown();
    tracing::info!("stopped");
}
