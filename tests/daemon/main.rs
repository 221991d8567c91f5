//! The daemon, black box: `visobjd run` on loopback through `common::daemon` (OSC, the DMX
//! wire, backups, faults, the web page, the TouchOSC layout, the booth unit), and its OSC
//! transport and Eos export in process. One module per subject; libtest runs them side by
//! side, each test with its own daemon, folder and ports.

#[path = "../common/mod.rs"]
mod common;

mod booth_unit;
mod daemon_access;
mod daemon_args;
mod daemon_backup;
mod daemon_backup_resync;
mod daemon_booth;
mod daemon_console;
mod daemon_constraints;
mod daemon_dmx;
mod daemon_eos;
mod daemon_eos_in;
mod daemon_explore;
mod daemon_export;
mod daemon_faults;
mod daemon_gallery;
mod daemon_hostile;
mod daemon_live;
mod daemon_looks;
mod daemon_ma3;
mod daemon_movers;
mod daemon_objectives;
mod daemon_peers;
mod daemon_reload;
mod daemon_slots;
mod daemon_start;
mod eos;
mod osc_transport;
mod touchosc;
mod web;
