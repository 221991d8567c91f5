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
    /// `(sum |end - start| - sum |again - start|) / max(sum (start + end) / 2, sum |again -
    /// start|)` over all samples, at least 0: the change beyond what two merges of the same
    /// ambient differ by (noise), relative to the ambient or, on a dark stage, the noise.
    /// A dark stage's ambient is mostly noise, so without taking the noise out its
    /// "change" would be near 100% every time. Warn above ~5%.
    pub relative: f64,
    /// `(mean(end) - mean(start)) / mean(start)`: signed overall brightening or dimming.
    pub mean_change: f64,
}

/// Compares the ambient merged at the start (`start`, and `again`: a second merge of the
/// same ambient right after it, the measure of noise) with the one merged at the end.
pub fn ambient_drift(
    start: &Radiance,
    again: &Radiance,
    end: &Radiance,
) -> Result<AmbientDrift, HdrError> {
    same_size(start, end)?;
    same_size(start, again)?;
    let (mut diff, mut null, mut sum, mut s0, mut s1) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for ((a, b), n) in start
        .pixels
        .iter()
        .flatten()
        .zip(end.pixels.iter().flatten())
        .zip(again.pixels.iter().flatten())
    {
        let (a, b, n) = (f64::from(*a), f64::from(*b), f64::from(*n));
        diff += (b - a).abs();
        null += (n - a).abs();
        sum += (a + b) / 2.0;
        s0 += a;
        s1 += b;
    }
    let ratio = |n: f64, d: f64| if d > 0.0 { n / d } else { 0.0 };
    Ok(AmbientDrift {
        // Over the noise too: a dark stage's ambient sums to about nothing.
        relative: ratio((diff - null).max(0.0), sum.max(null)),
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
/// Half-width in pixels of the window the noise is measured over (15x15).
const WINDOW: usize = 7;

/// Tests whether `light` (merged with the light at full, ambient included) shows light
/// over `ambient` (merged with the light off, same settings).
///
/// The noise of `light - ambient` is measured from the data, robustly: the median absolute
/// deviation of the differences (times 1.4826, a Gaussian's sigma) in a 15x15 window
/// (every other pixel), and no less than the same measure over the whole image, so that
/// noise which is flat within a window but offset from block to block (JPEG near black)
/// counts as noise; a light's own gradient only raises the estimate (fewer lit pixels,
/// never more). A pixel is lit when any channel
/// exceeds [`LIT_SIGMAS`] of its local noise; the light shows light when the lit pixels
/// reach [`MIN_LIT_FRACTION`] of the image.
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
    let h = light.height;
    let mean = light
        .pixels
        .iter()
        .chain(&ambient.pixels)
        .flatten()
        .map(|&v| f64::from(v))
        .sum::<f64>()
        / (2 * 3 * n).max(1) as f64;
    // A floor so an all-black area (exact zeros) does not call every speck lit, and the
    // whole image's spread, so noise that is flat inside a window but differs from block
    // to block (JPEG) is not taken for light.
    let floor = (1e-4 * mean).max(f64::MIN_POSITIVE);
    let global: [f64; 3] = std::array::from_fn(|c| {
        let mut all: Vec<f32> = diff.iter().step_by(7).map(|p| p[c]).collect();
        spread(&mut all)
    });
    let (mut lit, mut peak) = (0usize, 0.0f64);
    let mut window = Vec::with_capacity((WINDOW + 1) * (WINDOW + 1));
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(WINDOW), (y + WINDOW + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(WINDOW), (x + WINDOW + 1).min(w));
            let p = diff[y * w + x];
            let mut snr = f64::MIN;
            for c in 0..3 {
                window.clear();
                window.extend(
                    (y0..y1)
                        .step_by(2)
                        .flat_map(|yy| (x0..x1).step_by(2).map(move |xx| yy * w + xx))
                        .map(|i| diff[i][c]),
                );
                let sigma = spread(&mut window).max(global[c]).max(floor);
                snr = snr.max(f64::from(p[c]) / sigma);
            }
            peak = peak.max(snr);
            if snr > LIT_SIGMAS {
                lit += 1;
            }
        }
    }
    Ok(LightTest {
        shows_light: lit >= min_lit_pixels,
        lit_pixels: lit,
        min_lit_pixels,
        peak_snr: peak,
    })
}

/// The robust spread (1.4826 x the median absolute deviation: a Gaussian's sigma) of
/// `values`, reordered in place.
fn spread(values: &mut [f32]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    let median = *values.select_nth_unstable_by(mid, f32::total_cmp).1;
    for v in values.iter_mut() {
        *v = (*v - median).abs();
    }
    f64::from(*values.select_nth_unstable_by(mid, f32::total_cmp).1) * 1.4826
}
