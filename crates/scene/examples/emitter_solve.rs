//! Times `emitter::solve` per call for fixtures of 3, 4, 5 and 7 emitters, on in-gamut
//! targets (random mixes of the emitters) and on targets anywhere (random chromaticities,
//! many outside the gamut), and for a fixture whose solutions tie (the least-drive path).
//! Run with
//! `cargo run --release -p visobjd-scene --example emitter_solve`.

use std::hint::black_box;
use std::time::Instant;

use visobjd_scene::emitter::colour::{linear_srgb_to_xyz, xyy_to_xyz};
use visobjd_scene::emitter::solve;

fn main() {
    // x, y, Y: red, green, blue, amber, white as the GDTF documentation's example gives
    // them, a phosphor lime, and cyan and indigo near the spectral locus.
    let gdtf = |p: [f64; 3]| xyy_to_xyz(p[0], p[1], p[2]);
    let [r, g, b, a, w, lime, cyan, indigo] = [
        [0.6951, 0.3044, 100.0],
        [0.3002, 0.5998, 71.55],
        [0.1503, 0.0602, 7.246],
        [0.473, 0.4623, 58.526],
        [0.3104, 0.3242, 96.1],
        [0.405, 0.545, 90.0],
        [0.0387, 0.5175, 40.0],
        [0.1722, 0.0488, 3.0],
    ]
    .map(gdtf);
    let srgb = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(linear_srgb_to_xyz);
    // Amber as today's patch models it, on the red-green line: most targets tie.
    let collinear = linear_srgb_to_xyz([1.0, 0.45, 0.0]);
    let fixtures: [(&str, Vec<[f64; 3]>); 5] = [
        ("3 (sRGB)", srgb.to_vec()),
        ("4 (RGBW)", vec![r, g, b, w]),
        ("4 (ties)", vec![srgb[0], srgb[1], srgb[2], collinear]),
        ("5 (RGBAW)", vec![r, g, b, a, w]),
        ("7 (RGBALCI)", vec![r, g, b, a, lime, cyan, indigo]),
    ];
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    println!("emitters      in gamut ns/solve   anywhere ns/solve");
    for (name, e) in &fixtures {
        let mixes: Vec<[f64; 3]> = (0..4096)
            .map(|_| {
                let mut s = [0.0; 3];
                for em in e {
                    let l = next();
                    for k in 0..3 {
                        s[k] += l * em[k];
                    }
                }
                s
            })
            .collect();
        let anywhere: Vec<[f64; 3]> = (0..4096)
            .map(|_| xyy_to_xyz(0.05 + 0.65 * next(), 0.02 + 0.8 * next(), 1.0))
            .collect();
        let time = |targets: &[[f64; 3]]| {
            // The best of 7 rounds of every target, so another process's burst is ignored.
            (0..7)
                .map(|_| {
                    let start = Instant::now();
                    for t in targets {
                        black_box(solve(black_box(e), black_box(*t)));
                    }
                    start.elapsed().as_nanos() as f64 / targets.len() as f64
                })
                .fold(f64::INFINITY, f64::min)
        };
        println!(
            "{name:<13} {:>17.0} {:>19.0}",
            time(&mixes),
            time(&anywhere)
        );
    }
}
