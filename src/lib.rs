//! visobjd: turns a lighting designer's reference images into stage lighting looks.

pub mod basis;
pub mod cli;
pub mod cmd;
pub mod color;
pub mod config;
pub mod dmx;
pub mod engine;
pub mod eos;
pub mod gallery;
pub mod http;
pub mod look;
pub mod objective;
pub mod osc;
pub mod output;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod sheet;
pub mod stage;
pub mod state;
pub mod synth;
pub mod targeting;
pub mod touchosc;
