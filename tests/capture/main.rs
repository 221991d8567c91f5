//! `visobjd capture` end to end, through the real binary with the simulated camera
//! ([`capture`]) and the fake gphoto2 ([`capture_gphoto2`]), on the stage of
//! `common::capture`.

#[path = "../common/mod.rs"]
mod common;

mod capture;
mod capture_gphoto2;
