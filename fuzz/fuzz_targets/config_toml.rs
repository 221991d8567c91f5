//! libFuzzer target: see `bodies::config_toml`.
#![no_main]

#[allow(dead_code)]
#[path = "bodies.rs"]
mod bodies;

libfuzzer_sys::fuzz_target!(|data: &[u8]| bodies::config_toml(data));
