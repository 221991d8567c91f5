//! visobjd: turns a lighting designer's reference images into stage lighting looks.
//!
//! This crate is the daemon and its command line: OSC in ([`osc`]), commands parsed once
//! ([`cmd`]), the session they change ([`engine`]), the web page ([`http`]), the Eos
//! export ([`eos`]). The method, the compositor, DMX, the scene model, durable files and the
//! virtual stage are crates of their own (`crates/`; see `docs/architecture.md`).

pub mod backup;
pub mod cli;
pub mod cmd;
pub mod config;
pub mod engine;
pub mod eos;
pub mod http;
pub mod osc;
pub mod shutdown;
pub mod touchosc;
