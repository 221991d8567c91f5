//! visobjd: turns a lighting designer's reference images into stage lighting looks.

pub mod synth;
