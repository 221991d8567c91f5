//! Fault injection for the tests of the watchdog and of recovery (`/vo/test/...`), refused
//! unless the daemon was started with [`TEST_HOOKS`] set (never in production).

use std::sync::atomic::{AtomicBool, Ordering};

use super::{Engine, Refusal};
use visobjd_dmx::Output;

/// Set in the environment, enables the `/vo/test/...` fault hooks (never in production).
pub const TEST_HOOKS: &str = "VISOBJD_TEST_HOOKS";

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

/// Whether the hooks are on, and the faults waiting to happen.
pub(super) struct Hooks {
    /// [`TEST_HOOKS`] was set.
    enabled: bool,
    /// The next generate panics.
    panic_generate: AtomicBool,
}

impl Hooks {
    pub(super) fn from_env() -> Hooks {
        Hooks {
            enabled: std::env::var_os(TEST_HOOKS).is_some(),
            panic_generate: AtomicBool::new(false),
        }
    }

    /// Panics if a test asked the next generate to (called where the drawing starts).
    pub(super) fn maybe_panic_generate(&self) {
        if self.panic_generate.swap(false, Ordering::SeqCst) {
            panic!("test hook: the generate panics");
        }
    }
}

impl Engine {
    /// Fault injection for tests; refused unless [`TEST_HOOKS`] is set.
    pub fn test_hook(&self, hook: TestHook) -> Result<(), Refusal> {
        if !self.hooks.enabled {
            return Err(Refusal::conflict(format!(
                "test hooks are off ({TEST_HOOKS} is not set)"
            )));
        }
        match hook {
            TestHook::StallDmx(on) => self.with_output(|o| o.stall(on)),
            TestHook::PanicDmx => self.with_output(Output::panic_clock),
            TestHook::PanicGenerate => self.hooks.panic_generate.store(true, Ordering::SeqCst),
            TestHook::SlowDisk(ms) => self.writer.slow_down(ms),
        }
        Ok(())
    }
}
