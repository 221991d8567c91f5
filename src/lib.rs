//! visobjd: turns a lighting designer's reference images into stage lighting looks.
//!
//! This crate is the daemon and its command line. Calls go one way, down: the transports
//! (OSC in [`osc`], the web page in [`http`], a backup's link to its main in [`backup`]) hand
//! each message to the commands ([`cmd`]: parsed once, one file per address family), which
//! change the session through the [`engine`]; the engine drives the method, the compositor
//! and DMX, which are crates of their own (`crates/`). [`config`] and [`eos`] (the commands an
//! Eos console takes) sit below whoever reads them; [`slots`] shares the OSC and web
//! listeners' connections out by host; [`shutdown`] and [`cli`] wire it all.
//! `docs/architecture.md` draws it.

pub mod backup;
pub mod cli;
pub mod cmd;
pub mod config;
pub mod desk;
pub mod engine;
pub mod eos;
pub mod http;
pub mod ma3;
pub mod osc;
pub mod shutdown;
pub mod slots;
pub mod touchosc;
