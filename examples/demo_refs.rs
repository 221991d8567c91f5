//! Writes the demo scene's reference images: procedural pictures that differ clearly in mean
//! brightness, contrast and palette, so the gallery has distinct objectives to chase.
//!
//! `cargo run --release --example demo_refs -- scenes/demo/refs`

use std::path::Path;

const W: u32 = 320;
const H: u32 = 200;

type Rgb = [f32; 3];

/// A picture as a function of position (u across, v down, in picture heights).
type Picture = fn(f32, f32) -> Rgb;

fn main() {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: demo_refs OUT_DIR");
        std::process::exit(2);
    };
    let dir = Path::new(&dir);
    if let Err(e) = std::fs::create_dir_all(dir) {
        eprintln!("{}: {e}", dir.display());
        std::process::exit(1);
    }
    let pictures: [(&str, Picture); 8] = [
        ("sunset", sunset),
        ("moonlight", moonlight),
        ("overcast", overcast),
        ("festive", festive),
        ("firelight", firelight),
        ("deepsea", deepsea),
        ("noir", noir),
        ("pastel", pastel),
    ];
    for (name, f) in pictures {
        let img = image::RgbImage::from_fn(W, H, |x, y| {
            // u, v in 0..1 (v down); aspect kept by scaling u.
            let c = f(x as f32 / H as f32, y as f32 / H as f32);
            image::Rgb(c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8))
        });
        let path = dir.join(format!("{name}.png"));
        if let Err(e) = img.save(&path) {
            eprintln!("{}: {e}", path.display());
            std::process::exit(1);
        }
        println!("{}", path.display());
    }
}

/// Horizontal extent of the picture in `u` units (u runs 0..ASPECT, v 0..1).
const ASPECT: f32 = W as f32 / H as f32;

fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    [0, 1, 2].map(|i| a[i] + (b[i] - a[i]) * t)
}

fn smooth(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn add(a: Rgb, b: Rgb, k: f32) -> Rgb {
    [0, 1, 2].map(|i| a[i] + b[i] * k)
}

/// Integer hash to 0..1: the same picture on every machine, no RNG state.
fn hash(x: i32, y: i32, seed: u32) -> f32 {
    let mut h = (x as u32)
        .wrapping_mul(0x8da6_b343)
        .wrapping_add((y as u32).wrapping_mul(0xd816_3841))
        .wrapping_add(seed.wrapping_mul(0xcb1a_b31f));
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0xffff) as f32 / 65535.0
}

/// Smooth value noise at scale `s`.
fn noise(u: f32, v: f32, s: f32, seed: u32) -> f32 {
    let (x, y) = (u * s, v * s);
    let (ix, iy) = (x.floor() as i32, y.floor() as i32);
    let (fx, fy) = (smooth(0.0, 1.0, x.fract()), smooth(0.0, 1.0, y.fract()));
    let a = hash(ix, iy, seed) + (hash(ix + 1, iy, seed) - hash(ix, iy, seed)) * fx;
    let b = hash(ix, iy + 1, seed) + (hash(ix + 1, iy + 1, seed) - hash(ix, iy + 1, seed)) * fx;
    a + (b - a) * fy
}

/// Four octaves of value noise, 0..1.
fn fbm(u: f32, v: f32, s: f32, seed: u32) -> f32 {
    (0..4)
        .map(|o| noise(u, v, s * (1 << o) as f32, seed + o) / (1 << o) as f32)
        .sum::<f32>()
        / 1.875
}

fn dist(u: f32, v: f32, cu: f32, cv: f32) -> f32 {
    ((u - cu).powi(2) + (v - cv).powi(2)).sqrt()
}

/// Soft bokeh dots on a cell grid: colour and coverage of the nearest dot.
fn bokeh(u: f32, v: f32, cell: f32, seed: u32, palette: &[Rgb]) -> (Rgb, f32) {
    let (cx, cy) = ((u / cell).floor() as i32, (v / cell).floor() as i32);
    let mut best = ([0.0; 3], 0.0f32);
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (gx, gy) = (cx + dx, cy + dy);
            if hash(gx, gy, seed + 7) < 0.5 {
                continue;
            }
            let pu = (gx as f32 + hash(gx, gy, seed)) * cell;
            let pv = (gy as f32 + hash(gx, gy, seed + 1)) * cell;
            let r = cell * (0.25 + 0.35 * hash(gx, gy, seed + 2));
            let k = palette.len() as f32 * hash(gx, gy, seed + 3);
            let a = 1.0 - smooth(r * 0.8, r, dist(u, v, pu, pv));
            if a > best.1 {
                best = (palette[(k as usize).min(palette.len() - 1)], a);
            }
        }
    }
    best
}

fn sunset(u: f32, v: f32) -> Rgb {
    let horizon = 0.62;
    let sky = if v < 0.35 {
        mix([0.25, 0.1, 0.35], [0.85, 0.3, 0.3], v / 0.35)
    } else {
        mix(
            [0.85, 0.3, 0.3],
            [1.0, 0.75, 0.35],
            (v - 0.35) / (horizon - 0.35),
        )
    };
    let d = dist(u, v, ASPECT * 0.55, horizon - 0.08);
    let sky = add(sky, [1.0, 0.8, 0.5], 0.6 * (-d * 9.0).exp());
    let sky = mix(sky, [1.0, 0.95, 0.8], 1.0 - smooth(0.075, 0.085, d));
    if v < horizon {
        return sky;
    }
    // Sea: darker, with the sun's glitter path.
    let sea = mix(
        [0.35, 0.12, 0.15],
        [0.08, 0.03, 0.08],
        (v - horizon) / (1.0 - horizon),
    );
    let path = (-((u - ASPECT * 0.55) * 12.0).powi(2)).exp() * (0.5 + noise(u, v, 60.0, 3));
    add(sea, [1.0, 0.7, 0.4], 0.5 * path)
}

fn moonlight(u: f32, v: f32) -> Rgb {
    let mut c = mix([0.02, 0.03, 0.08], [0.08, 0.12, 0.22], v);
    let d = dist(u, v, ASPECT * 0.3, 0.25);
    c = add(c, [0.5, 0.6, 0.8], 0.25 * (-d * 8.0).exp());
    c = mix(c, [0.9, 0.92, 0.85], 1.0 - smooth(0.06, 0.065, d));
    let (sx, sy) = ((u * 90.0) as i32, (v * 90.0) as i32);
    if hash(sx, sy, 11) > 0.985 && v < 0.6 {
        c = add(c, [0.8, 0.8, 0.9], 0.6);
    }
    let hill = 0.72 + 0.08 * (u * 3.0).sin() + 0.05 * fbm(u, 0.0, 4.0, 5);
    if v > hill {
        c = mix(
            [0.01, 0.015, 0.03],
            [0.03, 0.05, 0.08],
            fbm(u, v, 20.0, 6) * 0.6,
        );
    }
    c
}

fn overcast(u: f32, v: f32) -> Rgb {
    let horizon = 0.58;
    if v < horizon {
        let n = fbm(u, v * 2.0, 3.0, 21);
        let g = 0.62 + 0.12 * n + 0.1 * v;
        [g, g, g * 1.03]
    } else {
        let n = fbm(u, v, 12.0, 22);
        mix([0.42, 0.45, 0.38], [0.3, 0.34, 0.28], n)
    }
}

fn festive(u: f32, v: f32) -> Rgb {
    let palette = [
        [0.95, 0.15, 0.15],
        [0.15, 0.8, 0.3],
        [1.0, 0.75, 0.2],
        [0.2, 0.4, 1.0],
        [1.0, 0.4, 0.8],
    ];
    let base = mix([0.05, 0.02, 0.06], [0.12, 0.04, 0.05], v);
    let (c1, a1) = bokeh(u, v, 0.16, 31, &palette);
    let (c2, a2) = bokeh(u + 0.05, v + 0.03, 0.07, 41, &palette);
    add(add(base, c2, 0.35 * a2), c1, 0.9 * a1)
}

fn firelight(u: f32, v: f32) -> Rgb {
    let (cu, cv) = (ASPECT * 0.5, 1.05);
    let d = ((u - cu) * 1.3).hypot(v - cv);
    let glow = (-d * 2.6).exp();
    let mut c = mix([0.02, 0.01, 0.005], [0.9, 0.35, 0.08], glow);
    // Flames: noisy tongues rising from the bottom centre.
    let n = fbm(u * 1.5, v * 0.7 + 0.0, 6.0, 51);
    let flame = smooth(0.55, 0.95, v + 0.35 * n - 0.7 * ((u - cu) * 2.2).abs());
    c = mix(c, [1.0, 0.7, 0.2], flame);
    mix(
        c,
        [1.0, 0.95, 0.7],
        smooth(0.9, 1.0, v + 0.3 * n - ((u - cu) * 3.0).abs()),
    )
}

fn deepsea(u: f32, v: f32) -> Rgb {
    let mut c = mix([0.05, 0.35, 0.45], [0.0, 0.04, 0.1], v.powf(0.7));
    // Shafts of light slanting down from the surface.
    let s = (u * 0.8 - v * 0.25) * 9.0;
    let shaft = (0.5 + 0.5 * (s + 2.0 * noise(s, 0.0, 1.0, 61)).sin()).powi(6);
    c = add(c, [0.3, 0.7, 0.75], 0.35 * shaft * (1.0 - v));
    let (px, py) = ((u * 160.0) as i32, (v * 160.0) as i32);
    if hash(px, py, 62) > 0.997 {
        c = add(c, [0.5, 0.8, 0.8], 0.3);
    }
    c
}

fn noir(u: f32, v: f32) -> Rgb {
    // Venetian blind light across a wall, and a figure's silhouette in a doorway.
    let wall = 0.12 + 0.05 * fbm(u, v, 8.0, 71);
    let blind = smooth(0.45, 0.55, ((v - u * 0.35) * 14.0).sin());
    let patch = 1.0 - smooth(0.3, 0.9, dist(u, v, ASPECT * 0.35, 0.45));
    let mut g = wall + 0.8 * blind * patch;
    let (fx, fy) = (ASPECT * 0.72, 0.2);
    let body = (u - fx).abs() < 0.09 - 0.02 * (v - fy) && v > fy + 0.1;
    let head = dist(u, v, fx, fy) < 0.065;
    if body || head {
        g = 0.02;
    }
    [g, g, g]
}

fn pastel(u: f32, v: f32) -> Rgb {
    let mut c = mix([0.98, 0.86, 0.9], [0.85, 0.95, 0.92], u / ASPECT);
    c = mix(c, [0.88, 0.85, 0.98], smooth(0.3, 1.0, v));
    let blobs = [
        (0.4, 0.3, 0.25, [1.0, 0.78, 0.85]),
        (1.1, 0.6, 0.3, [0.78, 0.95, 0.88]),
        (1.35, 0.2, 0.2, [0.95, 0.95, 0.75]),
    ];
    for (bu, bv, r, col) in blobs {
        c = mix(c, col, 0.8 * (1.0 - smooth(0.0, r, dist(u, v, bu, bv))));
    }
    c
}
