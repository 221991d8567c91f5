//! The camera's inverse response for JPEG frames, recovered with Robertson et al.'s
//! iteration (2003): alternate "radiance from the curve" and "curve from the radiance"
//! until the curve settles.

use rand::{Rng, RngExt};

use crate::frame::{Pixels, check_bracket};
use crate::{Frame, HdrError};

/// The camera's inverse response `g`: for each channel, JPEG code 0..=255 to linear value,
/// normalised so `g(255) = 1` (full scale). Non-decreasing.
///
/// Recovered once per session and stored in `capture.json` (it is serde), so a resumed
/// capture linearises with the same curve and its basis images stay comparable.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Response {
    /// `curves[channel][code]`, 256 entries each.
    pub curves: [Vec<f32>; 3],
}

/// Pixel positions drawn at random before sorting into bins.
const DRAWS: usize = 60_000;
/// Bins over the sum of a pixel's codes across the bracket (a monotone proxy for radiance).
const BINS: usize = 64;
/// At most this many pixels per bin, so bright and dark pixels are as well represented as
/// the mid-tones that dominate a stage picture.
const PER_BIN: usize = 80;
/// Iterations at most; the curve usually settles well before.
const ITERATIONS: usize = 100;
/// Fewest usable sample pixels (seen mid-range in at least two frames).
const MIN_SAMPLES: usize = 200;

/// Robertson's certainty weight: a hat that is zero at codes 0 and 255, so clipped samples
/// never pull the curve (OpenCV's CalibrateDebevec weights them above zero).
fn weight(z: u8) -> f64 {
    let z = f64::from(z);
    (1.0 - (2.0 * z / 255.0 - 1.0).abs()).max(0.0)
}

impl Response {
    /// A linear camera (`g(z) = z / 255`), for tests and for cameras that write linear JPEG.
    pub fn linear() -> Response {
        let c: Vec<f32> = (0..256).map(|z| z as f32 / 255.0).collect();
        Response {
            curves: [c.clone(), c.clone(), c],
        }
    }

    /// Recovers the response from a bracket of JPEG frames of one still, lit scene (3 or
    /// more frames 1-2 stops apart, spanning dark to bright). Sample pixels are drawn with
    /// `rng` and spread evenly over the range of brightness. Uses the EXIF exposures: an
    /// error of a few percent in them bends the curve only slightly, and [`crate::merge`]
    /// refits the ratios afterwards.
    pub fn recover(frames: &[Frame<'_>], rng: &mut impl Rng) -> Result<Response, HdrError> {
        let rel = check_bracket(frames)?;
        let codes: Vec<&[u8]> = frames
            .iter()
            .map(|f| match f.pixels {
                Pixels::Jpeg(p) => Ok(p),
                Pixels::Raw { .. } => Err(HdrError::ResponseNeedsJpeg),
            })
            .collect::<Result<_, _>>()?;
        if frames.len() < 2 {
            return Err(HdrError::TooFewSamples {
                got: 0,
                need: MIN_SAMPLES,
            });
        }
        let n_px = frames[0].width * frames[0].height;
        let nf = frames.len();
        let top = 255 * 3 * nf + 1;
        let mut bins: Vec<Vec<usize>> = vec![Vec::new(); BINS];
        for _ in 0..DRAWS {
            let p = rng.random_range(0..n_px);
            let s: usize = codes
                .iter()
                .map(|c| {
                    c[p * 3..p * 3 + 3]
                        .iter()
                        .map(|&v| usize::from(v))
                        .sum::<usize>()
                })
                .sum();
            let b = s * BINS / top;
            if bins[b].len() < PER_BIN {
                bins[b].push(p);
            }
        }
        let positions: Vec<usize> = bins.into_iter().flatten().collect();
        let mut curves: [Vec<f32>; 3] = Default::default();
        for (c, curve) in curves.iter_mut().enumerate() {
            let z: Vec<u8> = positions
                .iter()
                .flat_map(|&p| codes.iter().map(move |f| f[p * 3 + c]))
                .collect();
            *curve = robertson(&z, nf, &rel)?;
        }
        Ok(Response { curves })
    }

    /// Checks a stored response (256 finite, non-decreasing entries per channel, full scale
    /// positive) before it is used.
    pub fn validate(&self) -> Result<(), HdrError> {
        for c in &self.curves {
            let ok = c.len() == 256
                && c.iter().all(|v| v.is_finite() && *v >= 0.0)
                && c.windows(2).all(|w| w[1] >= w[0])
                && c[255] > 0.0;
            if !ok {
                return Err(HdrError::BadResponse);
            }
        }
        Ok(())
    }

    /// The linear value of `code` in `channel` (0 = R, 1 = G, 2 = B).
    pub fn linearise(&self, channel: usize, code: u8) -> f32 {
        self.curves[channel][usize::from(code)]
    }
}

/// One channel's curve from `z[i * nf + j]` (sample i, frame j) and the frames' relative
/// exposures.
fn robertson(z: &[u8], nf: usize, t: &[f64]) -> Result<Vec<f32>, HdrError> {
    let n = z.len() / nf;
    let w: Vec<f64> = (0..=255u8).map(weight).collect();
    // Usable samples: seen with non-zero weight in at least two frames.
    let usable: Vec<usize> = (0..n)
        .filter(|&i| {
            z[i * nf..(i + 1) * nf]
                .iter()
                .filter(|&&v| w[usize::from(v)] > 0.0)
                .count()
                >= 2
        })
        .collect();
    if usable.len() < MIN_SAMPLES {
        return Err(HdrError::TooFewSamples {
            got: usable.len(),
            need: MIN_SAMPLES,
        });
    }
    let mut g: Vec<f64> = (0..256).map(|v| (v as f64).max(0.5) / 128.0).collect();
    let mut e = vec![0.0f64; n];
    for _ in 0..ITERATIONS {
        for &i in &usable {
            let (mut num, mut den) = (0.0, 0.0);
            for j in 0..nf {
                let v = usize::from(z[i * nf + j]);
                num += w[v] * t[j] * g[v];
                den += w[v] * t[j] * t[j];
            }
            e[i] = num / den;
        }
        let mut sum = [0.0f64; 256];
        let mut cnt = [0usize; 256];
        for &i in &usable {
            for j in 0..nf {
                let v = usize::from(z[i * nf + j]);
                sum[v] += e[i] * t[j];
                cnt[v] += 1;
            }
        }
        let mut next = fill_gaps(&sum, &cnt);
        let norm = next[128];
        if !(norm.is_finite() && norm > 0.0) {
            return Err(HdrError::TooFewSamples {
                got: usable.len(),
                need: MIN_SAMPLES,
            });
        }
        for v in &mut next {
            *v /= norm;
        }
        let change = g
            .iter()
            .zip(&next)
            .skip(1)
            .take(254)
            .map(|(a, b)| ((a - b) / b.max(1e-9)).abs())
            .fold(0.0, f64::max);
        g = next;
        if change < 1e-7 {
            break;
        }
    }
    // Codes 0 and 255 hold everything below/above the sensor's range: extrapolate them from
    // their neighbours instead, then make the curve non-decreasing and full scale 1.
    g[255] = g[254] + (g[254] - g[253]).max(0.0);
    g[0] = (2.0 * g[1] - g[2]).clamp(0.0, g[1]);
    for v in 1..256 {
        g[v] = g[v].max(g[v - 1]);
    }
    let full = g[255];
    Ok(g.iter().map(|&v| (v / full) as f32).collect())
}

/// The curve from per-code sums and counts; codes no sample hit are interpolated between
/// their neighbours (linearly to 0 below the lowest, extrapolated above the highest).
fn fill_gaps(sum: &[f64; 256], cnt: &[usize; 256]) -> Vec<f64> {
    let known: Vec<(usize, f64)> = (0..256)
        .filter(|&v| cnt[v] > 0)
        .map(|v| (v, sum[v] / cnt[v] as f64))
        .collect();
    let mut g = vec![0.0f64; 256];
    if known.is_empty() {
        return g;
    }
    for (v, out) in g.iter_mut().enumerate() {
        let k = known.partition_point(|&(c, _)| c < v);
        *out = if k < known.len() && known[k].0 == v {
            known[k].1
        } else if k == 0 {
            known[0].1 * v as f64 / known[0].0 as f64
        } else if k == known.len() {
            let (c1, g1) = known[k - 1];
            match known.get(k.wrapping_sub(2)) {
                Some(&(c0, g0)) if k >= 2 => g1 + (g1 - g0) / (c1 - c0) as f64 * (v - c1) as f64,
                _ => g1,
            }
        } else {
            let ((c0, g0), (c1, g1)) = (known[k - 1], known[k]);
            g0 + (g1 - g0) * (v - c0) as f64 / (c1 - c0) as f64
        };
    }
    g
}
