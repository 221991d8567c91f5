//! DMX: fixture profiles, and how a look becomes slot values in universes.

pub mod profile;
