//! visobjd: turns a lighting designer's reference images into stage lighting looks.

pub mod color;
pub mod dmx;
pub mod look;
pub mod output;
pub mod scene;
