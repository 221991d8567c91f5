//! The camera's inverse response for JPEG frames, recovered by Debevec & Malik's least
//! squares (1997) with a smoothness term, per channel.
//!
//! Why the smoothness term: with a bracket whose steps are all the same ratio `r` (the
//! usual 2-stop bracket), the data alone cannot tell the true curve from one multiplied by
//! any positive function that is periodic in `ln(value)` with period `ln r` — every pixel
//! pair one step apart is fitted equally well. Robertson's iteration (used before) has no
//! preference among those curves and drifted to one 23% off. The smoothness term makes
//! the wiggle cost something, and the true curve (smooth) wins.

use rand::{Rng, RngExt};

use crate::frame::{Pixels, check_bracket};
use crate::{BracketFrame, HdrError};

/// The camera's inverse response `g`: for each channel, JPEG code 0..=255 to linear value,
/// the channels equal at code 128 and the brightest channel's `g(255)` 1 (about full
/// scale). Non-decreasing.
///
/// Recovered once per session and stored in `capture.json` (it is serde), so a resumed
/// capture linearises with the same curve and its basis images stay comparable.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Response {
    /// `curves[channel][code]`, 256 entries each.
    pub curves: [Vec<f32>; 3],
}

/// Pixel positions drawn at random before sorting into bins. The solve eliminates each
/// sample's radiance in closed form, so many samples cost little (about 30 ms in all).
const DRAWS: usize = 240_000;
/// Bins over the sum of a pixel's codes across the bracket (a monotone proxy for radiance).
const BINS: usize = 128;
/// At most this many pixels per bin, so bright and dark pixels are as well represented as
/// the mid-tones that dominate a stage picture.
const PER_BIN: usize = 400;
/// Weight of the smoothness term against the data term (the data term is normalised by
/// its total weight, see [`debevec`]). On the synthetic 7-frame 2-stop bracket, 1-3 give
/// the best curve (worst error 1.7-2.0% over codes 16-240); 0.3 lets noise through
/// (3%), 10 starts to flatten the toe (3%), 1000 is a straight line in log (47%).
const LAMBDA: f64 = 2.0;
/// A very weak pull of each frame's `ln t` to its EXIF value, only so the system stays
/// definite when a frame overlaps no other.
const EXIF_PRIOR: f64 = 1e-6;
/// A firm hold on the mean and the spread of the fitted `ln t` (their least-squares line
/// through the EXIF values): the two things the data cannot fix.
const EXIF_LINE: f64 = 1e3;
/// Fewest usable sample pixels (seen mid-range in at least two frames).
const MIN_SAMPLES: usize = 200;

/// The certainty weight: a hat that is zero at codes 0 and 255, so clipped samples never
/// pull the curve (OpenCV's CalibrateDebevec weights them above zero). It weights both the
/// data and the smoothness term, as in Debevec & Malik.
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
    /// `rng` and spread evenly over the range of brightness. The exposure ratios between
    /// frames are fitted along with the curve (EXIF fixes only their overall scale and
    /// spread), so EXIF errors of a few percent in single frames do not bend it;
    /// [`crate::merge`] refits the ratios of every bracket it merges anyway.
    pub fn recover(frames: &[BracketFrame<'_>], rng: &mut impl Rng) -> Result<Response, HdrError> {
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
        let mut curves: [Vec<f64>; 3] = Default::default();
        for (c, curve) in curves.iter_mut().enumerate() {
            let z: Vec<u8> = positions
                .iter()
                .flat_map(|&p| codes.iter().map(move |f| f[p * 3 + c]))
                .collect();
            *curve = debevec(&z, nf, &rel, LAMBDA)?;
        }
        // The channels are tied where each curve is best known, at code 128 (the solve's
        // own anchor): a camera's JPEG keeps a neutral grey neutral, its white balance
        // and its tone curve the same on every channel. Not at 255, which stands for
        // everything above the top of the range, so no sample pins it and each channel's
        // value there is the smoothness term's extrapolation: tying the channels there
        // tinted a camera with a flat shoulder by a few percent. One factor for all then
        // puts the brightest channel's 255 at 1 (each curve is finite, non-decreasing and 1
        // at 128, so `full` is at least 1).
        let full = curves.iter().map(|c| c[255]).fold(1.0f64, f64::max);
        Ok(Response {
            curves: curves.map(|c| c.iter().map(|&v| (v / full) as f32).collect()),
        })
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

/// One channel's curve from `z[i * nf + j]` (sample i, frame j) and the frames' EXIF
/// relative exposures `t`, by Debevec & Malik's least squares (1997) on `g = ln` of the
/// inverse response, with the frames' `ln t_j` as unknowns too:
///
/// minimise `sum_ij [w(z_ij) (g(z_ij) - ln E_i - ln t_j)]^2 / D
///           + lambda * sum_z [w(z) (g(z-1) - 2 g(z) + g(z+1))]^2 + (EXIF terms)`,
/// with `g(128) = 0`,
///
/// and `D = sum_ij w(z_ij)^2` so `lambda` does not depend on the number of samples. Each
/// `ln E_i` touches only its own sample's terms, so it is eliminated in closed form
/// (`ln E_i` = the weighted mean of `g(z_ij) - ln t_j`), which leaves a dense symmetric
/// positive definite system of 255 + `nf` unknowns, solved by Cholesky.
///
/// Then back to linear: `exp(g)` (1 at code 128), code 0 extrapolated, a running max (the
/// smoothness keeps the solved curve increasing wherever samples are plentiful; the running
/// max only guards the sparse ends).
fn debevec(z: &[u8], nf: usize, t: &[f64], lambda: f64) -> Result<Vec<f64>, HdrError> {
    let n = z.len() / nf;
    let w: Vec<f64> = (0..=255u8).map(weight).collect();
    let lt: Vec<f64> = t.iter().map(|v| v.ln()).collect();
    // Usable samples: seen with non-zero weight in at least two frames (a sample seen in
    // one frame fits any curve exactly and adds nothing after the elimination).
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
    // Normal equations over x = (g(0..=255), ln t_0..ln t_nf): `a x = b`.
    let dim = 256 + nf;
    let mut a = vec![0.0f64; dim * dim];
    let mut b = vec![0.0f64; dim];
    let mut total = 0.0f64;
    let mut v: Vec<(usize, f64)> = Vec::with_capacity(2 * nf);
    for &i in &usable {
        let row = &z[i * nf..(i + 1) * nf];
        let s: f64 = row.iter().map(|&c| w[usize::from(c)].powi(2)).sum();
        total += s;
        // Frame j's residual is u_j . x - (sum_k a_k u_k . x) / s with u_j = e_g(z_j) -
        // e_t(j) and a_j = w(z_j)^2, once ln E_i is eliminated.
        v.clear();
        for (j, &c) in row.iter().enumerate() {
            let (zj, aj, tj) = (usize::from(c), w[usize::from(c)].powi(2), 256 + j);
            if aj == 0.0 {
                continue;
            }
            a[zj * dim + zj] += aj;
            a[tj * dim + tj] += aj;
            a[zj * dim + tj] -= aj;
            a[tj * dim + zj] -= aj;
            v.push((zj, aj));
            v.push((tj, -aj));
        }
        for &(p, cp) in &v {
            for &(q, cq) in &v {
                a[p * dim + q] -= cp * cq / s;
            }
        }
    }
    for x in &mut a {
        *x /= total;
    }
    // The data fix the exposures only up to a common factor and a common power (ln t ->
    // gamma ln t + c, with g -> gamma g: the curve's overall "gamma"). Pin those two from
    // EXIF: the least-squares line through the EXIF ln t (its mean and its spread) is held
    // firmly, so EXIF errors of single frames average out and the smoothness term cannot
    // flatten the curve; the ratios between frames come from the data. A very weak prior
    // on each frame keeps the system definite if a frame overlaps no other.
    let mean_lt = lt.iter().sum::<f64>() / nf as f64;
    let spread: Vec<f64> = lt.iter().map(|l| l - mean_lt).collect();
    let norm = spread.iter().map(|d| d * d).sum::<f64>().sqrt().max(1e-12);
    let ones = vec![1.0 / (nf as f64).sqrt(); nf];
    let unit: Vec<f64> = spread.iter().map(|d| d / norm).collect();
    for u in [&ones, &unit] {
        let target: f64 = u.iter().zip(&lt).map(|(uj, lj)| uj * lj).sum();
        for j in 0..nf {
            for k in 0..nf {
                a[(256 + j) * dim + 256 + k] += EXIF_LINE * u[j] * u[k];
            }
            b[256 + j] += EXIF_LINE * u[j] * target;
        }
    }
    for (j, l) in lt.iter().enumerate() {
        a[(256 + j) * dim + 256 + j] += EXIF_PRIOR;
        b[256 + j] += EXIF_PRIOR * l;
    }
    // Smoothness: w(z)^2 (g(z-1) - 2 g(z) + g(z+1))^2 for z = 1..=254.
    for (zc, &wz) in w.iter().enumerate().take(255).skip(1) {
        let k = lambda * wz * wz;
        let taps = [(zc - 1, 1.0), (zc, -2.0), (zc + 1, 1.0)];
        for &(p, cp) in &taps {
            for &(q, cq) in &taps {
                a[p * dim + q] += k * cp * cq;
            }
        }
    }
    // g(128) = 0: drop code 128's row and column.
    let keep: Vec<usize> = (0..dim).filter(|&v| v != 128).collect();
    let m = keep.len();
    let mut r = vec![0.0f64; m * m];
    let mut y: Vec<f64> = keep.iter().map(|&p| b[p]).collect();
    for (pi, &p) in keep.iter().enumerate() {
        for (qi, &q) in keep.iter().enumerate() {
            r[pi * m + qi] = a[p * dim + q];
        }
    }
    if !cholesky_solve(&mut r, &mut y, m) {
        return Err(HdrError::TooFewSamples {
            got: usable.len(),
            need: MIN_SAMPLES,
        });
    }
    let mut g = vec![0.0f64; 256];
    for (pi, &p) in keep.iter().enumerate().take(255) {
        g[p] = y[pi].exp();
    }
    g[128] = 1.0;
    // Code 0 holds everything below the sensor's range: extrapolate it linearly (in linear
    // units) from its neighbours, towards 0. Then make the curve non-decreasing (a running
    // max; the smoothness term already keeps it so wherever samples are plentiful).
    g[0] = (2.0 * g[1] - g[2]).clamp(0.0, g[1]);
    for v in 1..256 {
        g[v] = g[v].max(g[v - 1]);
    }
    if !g.iter().all(|v| v.is_finite()) {
        return Err(HdrError::TooFewSamples {
            got: usable.len(),
            need: MIN_SAMPLES,
        });
    }
    Ok(g)
}

/// Solves `a x = y` in place for a symmetric positive definite `m x m` matrix `a` (row
/// major; overwritten by its Cholesky factor). False if `a` is not positive definite.
fn cholesky_solve(a: &mut [f64], y: &mut [f64], m: usize) -> bool {
    for j in 0..m {
        let (done, rest) = a.split_at_mut(j * m);
        let row_j = &mut rest[..m];
        for k in 0..j {
            let row_k = &done[k * m..k * m + m];
            let s: f64 = row_j[..k].iter().zip(&row_k[..k]).map(|(x, y)| x * y).sum();
            row_j[k] = (row_j[k] - s) / row_k[k];
        }
        let d = row_j[j] - row_j[..j].iter().map(|x| x * x).sum::<f64>();
        if !(d.is_finite() && d > 0.0) {
            return false;
        }
        row_j[j] = d.sqrt();
    }
    // L z = y, then L^T x = z.
    for i in 0..m {
        let s: f64 = (0..i).map(|k| a[i * m + k] * y[k]).sum();
        y[i] = (y[i] - s) / a[i * m + i];
    }
    for i in (0..m).rev() {
        let s: f64 = (i + 1..m).map(|k| a[k * m + i] * y[k]).sum();
        y[i] = (y[i] - s) / a[i * m + i];
    }
    true
}
