//! Replays the fuzz targets' committed seed corpus and every crash the fuzzers found
//! (`fuzz/regressions/<target>/`) through the same checks, under `cargo test`: a crash,
//! once fixed, stays fixed without nightly or libFuzzer.

#[path = "../../fuzz/fuzz_targets/bodies.rs"]
mod bodies;

use std::path::Path;

fn replay(target: &str, check: fn(&[u8])) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut n = 0;
    for dir in ["corpus", "regressions"] {
        let Ok(entries) = std::fs::read_dir(root.join(dir).join(target)) else {
            continue;
        };
        for e in entries {
            let path = e.expect("a corpus entry").path();
            let data = std::fs::read(&path).expect("read a corpus file");
            let outcome = std::panic::catch_unwind(|| check(&data));
            assert!(outcome.is_ok(), "{target}: {} fails", path.display());
            n += 1;
        }
    }
    assert!(n > 0, "{target}: no seed corpus in fuzz/corpus/{target}");
}

#[test]
fn osc_packet() {
    replay("osc_packet", bodies::osc_packet);
}

#[test]
fn osc_stream() {
    replay("osc_stream", bodies::osc_stream);
}

#[test]
fn config_toml() {
    replay("config_toml", bodies::config_toml);
}

#[test]
fn scene_toml() {
    replay("scene_toml", bodies::scene_toml);
}

#[test]
fn reference_image() {
    replay("reference_image", bodies::reference_image);
}
