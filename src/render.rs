//! The CPU compositor: a look relights the basis images (paper 5.1).
//!
//! A render is `out[pixel] = gain * sum over lights of multiplier[light] * basis[light][pixel]`
//! per channel. Candidates are rendered together, tile by tile, so each basis tile is
//! read from memory once and reused from cache for every candidate.

use rayon::prelude::*;

use crate::basis::BasisImages;
use crate::color::encode_srgb8;
use crate::look::Look;

/// Pixels per tile: a tile of every light's three planes stays in L2 for a few hundred lights.
const TILE: usize = 256;

/// Linear gain of an exposure in stops.
pub fn exposure_gain(stops: f32) -> f32 {
    stops.exp2()
}

/// Per-light linear RGB multipliers of each look, times `gain`: `weights[c][l]`.
pub fn weights(looks: &[&Look], gain: f32) -> Vec<Vec<[f32; 3]>> {
    looks
        .iter()
        .map(|look| {
            look.levels
                .iter()
                .map(|lv| lv.multiplier().map(|m| m * gain))
                .collect()
        })
        .collect()
}

/// Renders every look of `weights` into its output (interleaved RGB, `pixels * 3` long),
/// converting each linear value with `encode` (sRGB bytes for thumbnails, clamped floats
/// for the gallery's proxy).
pub fn composite<O: Send>(
    basis: &BasisImages,
    weights: &[Vec<[f32; 3]>],
    outputs: &mut [Vec<O>],
    encode: impl Fn(f32) -> O + Sync,
) {
    let pixels = basis.pixels();
    let lights = basis.lights;
    let ntiles = pixels.div_ceil(TILE);
    let mut tiles: Vec<Vec<&mut [O]>> = (0..ntiles).map(|_| Vec::new()).collect();
    for out in outputs.iter_mut() {
        debug_assert_eq!(out.len(), pixels * 3);
        for (t, chunk) in out.chunks_mut(TILE * 3).enumerate() {
            tiles[t].push(chunk);
        }
    }
    tiles.into_par_iter().enumerate().for_each(|(t, outs)| {
        let start = t * TILE;
        let len = (pixels - start).min(TILE);
        let mut acc = [[0.0f32; TILE]; 3];
        for (w, out) in weights.iter().zip(outs) {
            for (ch, acc) in acc.iter_mut().enumerate() {
                let acc = &mut acc[..len];
                acc.fill(0.0);
                for (l, wl) in w.iter().enumerate().take(lights) {
                    let k = wl[ch];
                    if k == 0.0 {
                        continue;
                    }
                    let b = &basis.plane(ch, l)[start..start + len];
                    for (a, &v) in acc.iter_mut().zip(b) {
                        *a += k * v;
                    }
                }
            }
            for (i, px) in out.chunks_exact_mut(3).enumerate() {
                px[0] = encode(acc[0][i]);
                px[1] = encode(acc[1][i]);
                px[2] = encode(acc[2][i]);
            }
        }
    });
}

/// Renders looks to 8-bit sRGB images.
pub fn render_srgb8(basis: &BasisImages, looks: &[&Look], gain: f32) -> Vec<image::RgbImage> {
    let w = weights(looks, gain);
    let mut outs: Vec<Vec<u8>> = looks.iter().map(|_| vec![0; basis.pixels() * 3]).collect();
    composite(basis, &w, &mut outs, encode_srgb8);
    outs.into_iter()
        .map(|buf| {
            image::RgbImage::from_raw(basis.width as u32, basis.height as u32, buf)
                .expect("buffer sized width * height * 3 above")
        })
        .collect()
}

/// The scalar reference: one look, one pixel at a time, in the obvious order. Fast paths
/// are tested against it.
pub fn render_reference(basis: &BasisImages, look: &Look, gain: f32) -> Vec<f32> {
    let mut out = vec![0.0f32; basis.pixels() * 3];
    for (l, lv) in look.levels.iter().enumerate() {
        let m = lv.multiplier();
        for ch in 0..3 {
            for (p, &v) in basis.plane(ch, l).iter().enumerate() {
                out[p * 3 + ch] += gain * m[ch] * v;
            }
        }
    }
    out
}
