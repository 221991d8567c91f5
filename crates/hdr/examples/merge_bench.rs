//! Times merging seven 24-megapixel frames (6000x4000 RGB), raw and JPEG, to 480 px wide,
//! and recovering the JPEG response from them (once per session).
//! Run: `cargo run --release -p visobjd-hdr --example merge_bench`.

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::Instant;

use common::*;
use visobjd_hdr::*;

const W: usize = 6000;
const H: usize = 4000;
const RUNS: usize = 5;

fn time(label: &str, mut f: impl FnMut() -> Merged) {
    let mut secs: Vec<f64> = (0..RUNS)
        .map(|_| {
            let t = Instant::now();
            let m = f();
            std::hint::black_box(&m);
            t.elapsed().as_secs_f64()
        })
        .collect();
    secs.sort_by(f64::total_cmp);
    println!(
        "{label}: best {:.3} s, median {:.3} s over {RUNS} runs ({} threads)",
        secs[0],
        secs[RUNS / 2],
        rayon::current_num_threads()
    );
}

fn main() {
    println!("generating 7 synthetic {W}x{H} frames (raw and JPEG)...");
    let map = radiance_map(W, H, true);
    let (truth, exif_t) = bracket_times(7, 1e-3);
    let raw: Vec<Vec<u16>> = truth
        .iter()
        .enumerate()
        .map(|(k, &t)| raw_frame(&map, W, t, k as u64))
        .collect();
    let jpeg: Vec<Vec<u8>> = truth
        .iter()
        .enumerate()
        .map(|(k, &t)| jpeg_frame(&map, W, t, 50 + k as u64))
        .collect();
    drop(map);
    let settings = MergeSettings::default();
    let raw_frames = raw_frames_of(&raw, &exif_t, W, H);
    let jpeg_frames = jpeg_frames_of(&jpeg, &exif_t, W, H);
    let t = Instant::now();
    let mut rng = <Rng as rand::SeedableRng>::seed_from_u64(7);
    let recovered = Response::recover(&jpeg_frames, &mut rng).expect("response");
    println!(
        "JPEG response recovery from 7 x 24 MP: {:.3} s (once per session)",
        t.elapsed().as_secs_f64()
    );
    std::hint::black_box(&recovered);
    // A stand-in response (the true one; recovery is not part of the per-light merge).
    let response = Response {
        curves: std::array::from_fn(|_| (0..=255u8).map(|z| true_g(z) as f32).collect()),
    };
    time("raw  7 x 24 MP -> 480 px", || {
        merge(&raw_frames, None, &settings).expect("merge")
    });
    time("JPEG 7 x 24 MP -> 480 px", || {
        merge(&jpeg_frames, Some(&response), &settings).expect("merge")
    });
}
