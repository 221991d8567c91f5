//! A simulated camera over a known radiance map, shared by the tests and the benchmark.
#![allow(dead_code)]

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use visobjd_hdr::{BracketFrame, Exposure, Pixels};

pub type Rng = rand::rngs::Xoshiro256PlusPlus;

/// Raw camera: 14-bit, black level 512.
pub const BLACK: u16 = 512;
pub const WHITE: u16 = 16383;
/// Electrons at full scale (shot noise), and read noise in DN.
pub const FULL_WELL: f64 = 30_000.0;
pub const READ_NOISE: f64 = 3.0;
/// EXIF: ISO 100 at f/10, so relative exposure = seconds.
pub fn exif(seconds: f64) -> Exposure {
    Exposure {
        seconds,
        iso: 100.0,
        f_number: 10.0,
    }
}

/// A stage-like radiance map (units: full scale per unit relative exposure): smooth
/// coloured gradients, a dark area 8 stops down, bright spots, and (if `blown`) a tiny
/// spot bright enough to clip even the shortest frame of a 1 ms bracket.
pub fn radiance_map(w: usize, h: usize, blown: bool) -> Vec<[f32; 3]> {
    let mut px = vec![[0.0f32; 3]; w * h];
    px.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let v = y as f64 / h as f64;
        for (x, p) in row.iter_mut().enumerate() {
            let u = x as f64 / w as f64;
            let base = 0.05 + 2.0 * u * (0.3 + 0.7 * v);
            let mut rgb = [base * 1.0, base * 0.8, base * 0.6 + 0.02];
            // Dark area (a masked wing).
            if u < 0.15 && v > 0.5 {
                rgb = rgb.map(|c| c / 256.0);
            }
            // Bright spots: lamps and specular hits.
            for (cx, cy, r, peak, tint) in [
                (0.6, 0.3, 0.06, 300.0, [1.0, 0.9, 0.7]),
                (0.3, 0.7, 0.04, 60.0, [0.6, 0.8, 1.0]),
                (0.8, 0.8, 0.08, 12.0, [1.0, 0.5, 0.4]),
            ] {
                let d2 = ((u - cx).powi(2) + ((v - cy) * h as f64 / w as f64).powi(2)) / (r * r);
                let k = peak * (-d2).exp();
                for c in 0..3 {
                    rgb[c] += k * tint[c];
                }
            }
            if blown && ((u - 0.9).powi(2) + ((v - 0.1) * h as f64 / w as f64).powi(2)) < 0.0004 {
                rgb = [5000.0, 4000.0, 3000.0];
            }
            *p = rgb.map(|c| c as f32);
        }
    });
    px
}

/// Raw frame at relative exposure `t` (true), with shot and read noise and clipping.
pub fn raw_frame(map: &[[f32; 3]], w: usize, t: f64, seed: u64) -> Vec<u16> {
    let range = f64::from(WHITE - BLACK);
    let gain = range / FULL_WELL; // DN per electron
    let mut out = vec![0u16; map.len() * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let mut rng = Rng::seed_from_u64(seed.wrapping_mul(1_000_003).wrapping_add(y as u64));
        for (x, s) in row.chunks_exact_mut(3).enumerate() {
            let p = map[y * w + x];
            for c in 0..3 {
                let e = f64::from(p[c]) * t * FULL_WELL;
                let n: f64 = StandardNormal.sample(&mut rng);
                let r: f64 = StandardNormal.sample(&mut rng);
                let dn = (e + e.sqrt() * n) * gain + READ_NOISE * r + f64::from(BLACK);
                s[c] = dn.round().clamp(0.0, f64::from(WHITE)) as u16;
            }
        }
    });
    out
}

/// The JPEG camera's true tone curve: a filmic shoulder then a gamma, the same on every
/// channel (a camera's JPEG keeps a neutral neutral at every level).
pub const GAMMA: f64 = 2.2;
const SHOULDER: f64 = 0.3;

pub fn tone(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    let s = x * (1.0 + SHOULDER) / (x + SHOULDER);
    s.powf(1.0 / GAMMA)
}

/// The true inverse response (code -> linear, full scale 1).
pub fn true_g(z: u8) -> f64 {
    let y = (f64::from(z) / 255.0).powf(GAMMA);
    SHOULDER * y / (1.0 + SHOULDER - y)
}

/// JPEG frame at relative exposure `t`: small sensor noise, tone curve, 8-bit rounding.
pub fn jpeg_frame(map: &[[f32; 3]], w: usize, t: f64, seed: u64) -> Vec<u8> {
    let mut out = vec![0u8; map.len() * 3];
    // The curve as a table over linear values (fast for 24 MP).
    const N: usize = 1 << 16;
    let lut: Vec<u8> = (0..=N)
        .map(|i| (255.0 * tone(i as f64 / N as f64)).round() as u8)
        .collect();
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let mut rng = Rng::seed_from_u64(seed.wrapping_mul(999_983).wrapping_add(y as u64));
        for (x, s) in row.chunks_exact_mut(3).enumerate() {
            let p = map[y * w + x];
            for (c, out) in s.iter_mut().enumerate() {
                let e = f64::from(p[c]) * t;
                let n: f64 = StandardNormal.sample(&mut rng);
                let v = (e + (e * 2e-5).sqrt() * n).clamp(0.0, 1.0);
                *out = lut[(v * N as f64).round() as usize];
            }
        }
    });
    out
}

/// A bracket: true relative exposures `base * 4^k` (2 stops apart) and the EXIF ones,
/// off by +-3% except the middle (reference) frame.
pub fn bracket_times(n: usize, base: f64) -> (Vec<f64>, Vec<f64>) {
    let truth: Vec<f64> = (0..n).map(|k| base * 4f64.powi(k as i32)).collect();
    let exif: Vec<f64> = truth
        .iter()
        .enumerate()
        .map(|(k, t)| {
            if k == n / 2 {
                *t
            } else if k % 2 == 0 {
                t * 1.03
            } else {
                t * 0.97
            }
        })
        .collect();
    (truth, exif)
}

/// Raw frames (`w` x `h`) of `data` with EXIF times `times`.
pub fn raw_frames_of<'a>(
    data: &'a [Vec<u16>],
    times: &[f64],
    w: usize,
    h: usize,
) -> Vec<BracketFrame<'a>> {
    frames_of(data, times, w, h, |values| Pixels::Raw {
        values,
        black: BLACK,
        white: WHITE,
    })
}

/// JPEG frames (`w` x `h`) of `data` with EXIF times `times`.
pub fn jpeg_frames_of<'a>(
    data: &'a [Vec<u8>],
    times: &[f64],
    w: usize,
    h: usize,
) -> Vec<BracketFrame<'a>> {
    frames_of(data, times, w, h, Pixels::Jpeg)
}

/// Frames (`w` x `h`) of `data`, each made pixels by `pixels`, with EXIF times `times`.
fn frames_of<'a, T>(
    data: &'a [Vec<T>],
    times: &[f64],
    w: usize,
    h: usize,
    pixels: impl Fn(&'a [T]) -> Pixels<'a>,
) -> Vec<BracketFrame<'a>> {
    data.iter()
        .zip(times)
        .map(|(d, &t)| BracketFrame {
            width: w,
            height: h,
            exposure: exif(t),
            pixels: pixels(d),
        })
        .collect()
}
