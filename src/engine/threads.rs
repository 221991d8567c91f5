//! The OS threads the engine starts for commands (generates, explore, Eos exports), kept so
//! shutdown can let the work in flight finish before the output stops.

use std::sync::Mutex;
use std::thread::JoinHandle;

/// The threads started for commands; finished ones are let go as new ones start.
#[derive(Debug, Default)]
pub(super) struct Threads(Mutex<Vec<JoinHandle<()>>>);

impl Threads {
    /// Starts `work` on a thread called `name` and keeps its handle.
    pub(super) fn spawn(
        &self,
        name: &str,
        work: impl FnOnce() + Send + 'static,
    ) -> std::io::Result<()> {
        let handle = std::thread::Builder::new().name(name.into()).spawn(work)?;
        let mut running = self.0.lock().unwrap_or_else(|p| p.into_inner());
        running.retain(|h| !h.is_finished());
        running.push(handle);
        Ok(())
    }

    /// Waits for every thread still running.
    pub(super) fn join(&self) {
        let running = std::mem::take(&mut *self.0.lock().unwrap_or_else(|p| p.into_inner()));
        for handle in running {
            let name = handle.thread().name().unwrap_or("?").to_string();
            if handle.join().is_err() {
                tracing::error!("the {name} thread panicked before shutdown");
            }
        }
    }
}
