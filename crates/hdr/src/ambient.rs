//! The ambient (room light, work lights off or not) is merged like a light and subtracted;
//! two ambient merges (start and end of a capture) show whether it drifted; and a light
//! whose merge does not rise above the ambient by more than noise "shows no light".

use crate::{HdrError, Radiance};

fn same_size(a: &Radiance, b: &Radiance) -> Result<(), HdrError> {
    if (a.width, a.height) != (b.width, b.height) || a.pixels.len() != b.pixels.len() {
        return Err(HdrError::ImageMismatch {
            a_w: a.width,
            a_h: a.height,
            b_w: b.width,
            b_h: b.height,
        });
    }
    Ok(())
}

/// `light - ambient` per sample, clamped at 0: the light's own contribution, which is what
/// a basis image holds.
pub fn subtract_ambient(light: &Radiance, ambient: &Radiance) -> Result<Radiance, HdrError> {
    same_size(light, ambient)?;
    let pixels = light
        .pixels
        .iter()
        .zip(&ambient.pixels)
        .map(|(l, a)| [0, 1, 2].map(|c| (l[c] - a[c]).max(0.0)))
        .collect();
    Ok(Radiance {
        width: light.width,
        height: light.height,
        pixels,
    })
}

/// How much the ambient changed between two merges of it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AmbientDrift {
    /// `sum |end - start| / sum (start + end) / 2` over all samples: 0 when identical,
    /// includes noise (about 1% for a well-exposed merge at 480 px). Warn above ~5%.
    pub relative: f64,
    /// `(mean(end) - mean(start)) / mean(start)`: signed overall brightening or dimming.
    pub mean_change: f64,
}

/// Compares the ambient merged at the start and at the end of a capture.
pub fn ambient_drift(start: &Radiance, end: &Radiance) -> Result<AmbientDrift, HdrError> {
    same_size(start, end)?;
    let (mut diff, mut sum, mut s0, mut s1) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (a, b) in start.pixels.iter().flatten().zip(end.pixels.iter().flatten()) {
        let (a, b) = (f64::from(*a), f64::from(*b));
        diff += (b - a).abs();
        sum += (a + b) / 2.0;
        s0 += a;
        s1 += b;
    }
    let ratio = |n: f64, d: f64| if d > 0.0 { n / d } else { 0.0 };
    Ok(AmbientDrift {
        relative: ratio(diff, sum),
        mean_change: ratio(s1 - s0, s0),
    })
}

/// Whether a light adds anything over the ambient.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LightTest {
    /// False: the light's merge is indistinguishable from the ambient's (a dead lamp, a
    /// wrong patch, a light pointing off stage); capture reports "light N shows no light".
    pub shows_light: bool,
    /// Pixels where `light - ambient` exceeds [`LIT_SIGMAS`] noise standard deviations.
    pub lit_pixels: usize,
    /// How many lit pixels `shows_light` requires.
    pub min_lit_pixels: usize,
    /// The largest `(light - ambient) / noise` over the image.
    pub peak_snr: f64,
}

/// A pixel is lit when `light - ambient` exceeds this many noise standard deviations: for
/// Gaussian noise one sample in 3.5 million passes by chance, so a 480x270 merge (3 x 130k
/// samples) has about 0.1 false lit pixels.
pub const LIT_SIGMAS: f64 = 5.0;
/// A light shows light when at least this fraction of the pixels (and at least
/// [`MIN_LIT_PIXELS`]) are lit: 0.05% is 65 pixels at 480x270, a spot a few pixels across,
/// hundreds of times the chance count.
pub const MIN_LIT_FRACTION: f64 = 0.0005;
/// See [`MIN_LIT_FRACTION`].
pub const MIN_LIT_PIXELS: usize = 10;
/// Brightness classes for the noise estimate (noise grows with signal).
const CLASSES: usize = 16;

/// Tests whether `light` (merged with the light at full, ambient included) shows light
/// over `ambient` (merged with the light off, same settings).
///
/// The noise of `light - ambient` is measured from the data: horizontal neighbour
/// differences of it, whose spread is sqrt(2) x the per-pixel noise while a smooth light
/// field cancels, robustly (1.4826 x median absolute value) and separately for 16
/// brightness classes, since shot noise grows with brightness. A pixel is lit when any
/// channel exceeds [`LIT_SIGMAS`] of its class's noise; the light shows light when the lit
/// pixels reach [`MIN_LIT_FRACTION`] of the image.
pub fn light_test(light: &Radiance, ambient: &Radiance) -> Result<LightTest, HdrError> {
    same_size(light, ambient)?;
    let (w, n) = (light.width, light.pixels.len());
    let min_lit_pixels = ((n as f64 * MIN_LIT_FRACTION).ceil() as usize).max(MIN_LIT_PIXELS);
    let diff: Vec<[f32; 3]> = light
        .pixels
        .iter()
        .zip(&ambient.pixels)
        .map(|(l, a)| [0, 1, 2].map(|c| l[c] - a[c]))
        .collect();
    let bright: Vec<[f32; 3]> = light
        .pixels
        .iter()
        .zip(&ambient.pixels)
        .map(|(l, a)| [0, 1, 2].map(|c| (l[c] + a[c]) / 2.0))
        .collect();
    // Class edges: brightness quantiles.
    let mut all: Vec<f32> = bright.iter().flatten().copied().collect();
    all.sort_by(f32::total_cmp);
    let edges: Vec<f32> = (1..CLASSES).map(|k| all[k * all.len() / CLASSES]).collect();
    let class = |b: f32| edges.partition_point(|&e| e <= b);
    let mean = all.iter().map(|&v| f64::from(v)).sum::<f64>() / all.len().max(1) as f64;
    // Noise per class from neighbour differences.
    let mut d: Vec<Vec<f32>> = vec![Vec::new(); CLASSES];
    for (i, p) in diff.iter().enumerate() {
        if (i + 1) % w == 0 || i + 1 >= n {
            continue;
        }
        for c in 0..3 {
            d[class(bright[i][c])].push((p[c] - diff[i + 1][c]).abs());
        }
    }
    // A floor so an all-black class (exact zeros) does not call every speck lit.
    let floor = (1e-4 * mean).max(f64::MIN_POSITIVE);
    let sigma: Vec<f64> = d
        .iter_mut()
        .map(|v| {
            if v.is_empty() {
                return floor;
            }
            let mid = v.len() / 2;
            let m = f64::from(*v.select_nth_unstable_by(mid, f32::total_cmp).1);
            (1.4826 * m / std::f64::consts::SQRT_2).max(floor)
        })
        .collect();
    let (mut lit, mut peak) = (0usize, 0.0f64);
    for (p, b) in diff.iter().zip(&bright) {
        let snr = (0..3)
            .map(|c| f64::from(p[c]) / sigma[class(b[c])])
            .fold(f64::MIN, f64::max);
        peak = peak.max(snr);
        if snr > LIT_SIGMAS {
            lit += 1;
        }
    }
    Ok(LightTest {
        shows_light: lit >= min_lit_pixels,
        lit_pixels: lit,
        min_lit_pixels,
        peak_snr: peak,
    })
}
