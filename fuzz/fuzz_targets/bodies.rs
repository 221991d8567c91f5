//! What each fuzz target checks, shared by the libFuzzer targets beside this file and by
//! `tests/cli/fuzz_corpus.rs`, which replays the committed corpus and every crash found so
//! far under `cargo test`.

use visobjd::osc::framing::{Decoder, HEAD, StreamFrame, encode};
use visobjd_method::objective::{Region, analyze, decode_reference_bytes};

/// One UDP datagram (or stream frame) through the daemon's parsing: packet decoding with
/// its nesting limit, bundles, malformed messages, the argument rules and every command's
/// parse. Must never panic; every refusal is a sentence.
pub fn osc_packet(data: &[u8]) {
    if let Ok(items) = visobjd::cmd::parse(data) {
        for item in items {
            if let Err(sentence) = item {
                assert!(!sentence.is_empty());
            }
        }
    }
}

/// A small frame limit for [`osc_stream`], so the oversize path is reached often.
const MAX: usize = 512;

/// A TCP byte stream through the framing decoder (SLIP or length prefix, picked by the
/// first byte of the stream) in chunks whose size the input's first byte picks, then each
/// frame through the parser. Frames never exceed the limit; every whole packet re-frames to
/// itself.
pub fn osc_stream(data: &[u8]) {
    let Some((&chunk, stream)) = data.split_first() else {
        return;
    };
    let mut d = Decoder::new(MAX);
    let mut frames = Vec::new();
    for piece in stream.chunks(usize::from(chunk).max(1)) {
        d.feed(piece, &mut frames);
    }
    for frame in frames {
        match frame {
            StreamFrame::Packet(p) => {
                assert!(!p.is_empty() && p.len() <= MAX);
                let framing = d.framing().expect("a frame implies a framing");
                let mut again = Decoder::new(MAX);
                let mut back = Vec::new();
                again.feed(&encode(framing, &p), &mut back);
                assert_eq!(back, [StreamFrame::Packet(p.clone())]);
                osc_packet(&p);
            }
            StreamFrame::Oversize { len, head } => {
                assert!(len > MAX && head.len() <= HEAD.min(MAX));
                let _ = visobjd::osc::packet::first_address(&head);
            }
        }
    }
}

/// config/visobjd.toml text through the config parser and its checks (unknown keys, the
/// allow-list, ranges). Must never panic.
pub fn config_toml(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(config) =
            visobjd::config::Config::parse(std::path::Path::new("/fuzz/visobjd.toml"), text)
    {
        let _ = config.allow_list();
    }
}

/// scene.toml text through the scene parser and its validation (lights, groups, profiles,
/// the patch). No basis image is read. Must never panic.
pub fn scene_toml(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = visobjd_scene::Scene::parse(std::path::Path::new("/fuzz/scene"), text);
    }
}

/// A reference image file's bytes through the decoder with its limits, then the analysis an
/// objective runs on it. Must never panic. Images over 4 megapixels are left out here only
/// to keep each run fast (the 64-megapixel limit itself is checked from the header).
pub fn reference_image(data: &[u8]) {
    let dims = image::ImageReader::new(std::io::Cursor::new(data))
        .with_guessed_format()
        .ok()
        .and_then(|r| r.into_dimensions().ok());
    if dims.is_some_and(|(w, h)| u64::from(w) * u64::from(h) > 4_000_000) {
        return;
    }
    if let Ok(img) = decode_reference_bytes(data) {
        let a = analyze(&img, Region::FULL, 5);
        assert!(a.stats.mean_l.is_finite());
    }
}
