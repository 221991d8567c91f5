//! The long runs of docs/reliability.md: floods with TCP clients ([`daemon_load`]) and a
//! simulated hour ([`daemon_soak`]). Each measures DMX gaps and memory of a daemon under
//! its own load, so each holds [`alone`] for its whole run: nothing else in this binary
//! runs beside it, and the binary holds only such tests.

#[path = "../common/mod.rs"]
mod common;

mod daemon_load;
mod daemon_soak;

use std::sync::{Mutex, MutexGuard, PoisonError};

/// The machine to one long run at a time (libtest would run two side by side).
fn alone() -> MutexGuard<'static, ()> {
    static MACHINE: Mutex<()> = Mutex::new(());
    MACHINE.lock().unwrap_or_else(PoisonError::into_inner)
}
