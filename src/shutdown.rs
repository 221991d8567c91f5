//! Stopping, in one place and one order. On SIGTERM or SIGINT the daemon stops taking
//! messages (OSC, the web page) and stops pinging the watchdog, lets the work already
//! started finish (generates, Eos exports), then stops the output (three sACN
//! Stream_Terminated packets per universe, so receivers release at once) and writes the
//! state still queued (the last fader move survives a clean stop). The engine joins the OS
//! threads it started for commands ([`Engine::shutdown`]); the runtime's tasks are aborted
//! and awaited.

use anyhow::Context;

use crate::engine::Engine;
use crate::http::Http;
use crate::osc::Server;

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
