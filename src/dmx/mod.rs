//! DMX: fixture profiles, and how a look becomes slot values in universes.

pub mod patch;
pub mod profile;

pub use patch::{Frame, Patch};
