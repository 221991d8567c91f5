//! `visobjd capture` end to end, through the real binary with the simulated camera
//! ([`capture`]) and the fake gphoto2 ([`capture_gphoto2`]), on the stage of
//! `common::capture`; and on a camera built unlike any of those, over a larger stage
//! ([`unseen_camera`]).

#[path = "../common/mod.rs"]
mod common;

mod capture;
mod capture_gphoto2;
mod movers;
mod unseen_camera;
