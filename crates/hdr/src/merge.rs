//! A bracket to one radiance image: exposure ratios fitted from the pixels, then per pixel
//! a noise-weighted average of (linear value / exposure) over the frames that see it well,
//! area-downsampled to the working width on the way (the full-resolution image is never
//! stored).

use rayon::prelude::*;

use crate::frame::{Pixels, check_bracket};
use crate::resample::{add_row, owner, scaled_size, taps};
use crate::{BracketFrame, HdrError, Radiance, Response};

/// How to merge. The defaults are the settled values documented in `docs/capture.md`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MergeSettings {
    /// Output width (height from the aspect); `None` keeps the camera's resolution. The
    /// scene's working width, 480 by default.
    pub width: Option<usize>,
    /// Raw: a sample at most this fraction of full scale above black is near-black (read
    /// noise dominates) and gets no weight. 0.002 is about 8 DN at 12 bits, 32 at 14.
    pub raw_floor: f32,
    /// JPEG: codes at or below this are near-black and get no weight.
    pub jpeg_black: u8,
    /// JPEG: a pixel with any channel at or above this code is clipped in that frame (the
    /// tone curve's shoulder and JPEG ringing make the last codes unreliable).
    pub jpeg_clip: u8,
    /// Refit the frames' exposure ratios from the pixels (EXIF times can be off by a few
    /// percent). Off: the EXIF values are used as they are.
    pub fit_exposures: bool,
    /// The ratio fit uses samples whose linear value is inside this window (fractions of
    /// full scale) in both frames: well above noise, well below the shoulder.
    pub fit_window: [f32; 2],
    /// A pair of frames with fewer usable samples than this keeps its EXIF ratio.
    pub min_fit_samples: usize,
}

impl Default for MergeSettings {
    fn default() -> Self {
        MergeSettings {
            width: Some(480),
            raw_floor: 0.002,
            jpeg_black: 3,
            jpeg_clip: 250,
            fit_exposures: true,
            fit_window: [0.01, 0.85],
            min_fit_samples: 1000,
        }
    }
}

/// A frame's exposure: from EXIF, and as fitted from the pixels.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExposureFit {
    /// Relative exposure from EXIF (`t * ISO / N^2`).
    pub nominal: f64,
    /// Relative exposure the merge used (the reference frame keeps its EXIF value, so
    /// every frame's fitted exposure is on the EXIF scale).
    pub fitted: f64,
    /// `nominal / nominal(reference)`.
    pub nominal_ratio: f64,
    /// `fitted / fitted(reference)`: compare with `nominal_ratio` to see how far EXIF was
    /// off.
    pub fitted_ratio: f64,
    /// Samples the fit of this frame against its neighbour (next shorter; next longer for
    /// the shortest frame) used; 0 for the reference frame and for a ratio kept from EXIF
    /// because too few pixels were seen well in both.
    pub samples: usize,
}

/// A merged bracket.
#[derive(Debug, Clone, PartialEq)]
pub struct Merged {
    /// The radiance image (units: see [`Radiance`]).
    pub radiance: Radiance,
    /// Camera pixels clipped in every frame (at full resolution): they hold the shortest
    /// frame's value, a lower bound. Non-zero means the bracket needs a shorter exposure.
    pub clipped_everywhere: usize,
    /// Per frame, in the order given: EXIF vs fitted exposure.
    pub exposures: Vec<ExposureFit>,
    /// Index of the reference frame (the middle exposure).
    pub reference: usize,
}

/// How one frame turns into linear values, weights and clip tests.
enum Lin<'a> {
    Raw {
        values: &'a [u16],
        black: f32,
        /// 1 / (white - black): values as fractions of full scale.
        scale: f32,
        white: u16,
        /// Near-black threshold above black, in DN.
        floor: f32,
    },
    Jpeg {
        codes: &'a [u8],
        /// Per channel `w(z) * t * g(z)` (numerator) for this frame's fitted `t`.
        num: Box<[[f32; 256]; 3]>,
        /// `w(z) * t^2` (denominator).
        den: Box<[f32; 256]>,
        /// The response, `g[channel][code]`.
        g: Box<[[f32; 256]; 3]>,
        clip: u8,
    },
}

/// Merges a bracket into radiance. `response` is required for JPEG frames and ignored for
/// raw ones.
///
/// Per pixel and channel: radiance = sum(w * value / t) / sum(w) over the frames where the
/// pixel is unclipped in every channel and the channel is above the noise floor, with
/// inverse-variance weights: raw `w = t` (shot noise; the estimate becomes
/// sum(value) / sum(t)); JPEG `w = hat(code) * t^2` (Robertson's). A channel seen in no
/// frame above the floor takes the longest unclipped frame's value; a pixel clipped in
/// every frame takes the shortest frame's value and is counted.
pub fn merge(
    frames: &[BracketFrame<'_>],
    response: Option<&Response>,
    settings: &MergeSettings,
) -> Result<Merged, HdrError> {
    let nominal = check_bracket(frames)?;
    let (w, h) = (frames[0].width, frames[0].height);
    let jpeg = matches!(frames[0].pixels, Pixels::Jpeg(_));
    let response = if jpeg {
        let r = response.ok_or(HdrError::NoResponse)?;
        r.validate()?;
        Some(r)
    } else {
        None
    };
    // Frames in ascending exposure.
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by(|&a, &b| nominal[a].total_cmp(&nominal[b]));
    let reference = order[order.len() / 2];

    let (fitted, samples) = if settings.fit_exposures {
        fit_exposures(frames, response, settings, &nominal, &order)
    } else {
        (nominal.clone(), vec![0; frames.len()])
    };
    let exposures = (0..frames.len())
        .map(|i| ExposureFit {
            nominal: nominal[i],
            fitted: fitted[i],
            nominal_ratio: nominal[i] / nominal[reference],
            fitted_ratio: fitted[i] / fitted[reference],
            samples: samples[i],
        })
        .collect();

    let lins: Vec<(Lin<'_>, f32)> = order
        .iter()
        .map(|&i| {
            let t = fitted[i];
            (lin(&frames[i], response, settings, t), t as f32)
        })
        .collect();

    let (nw, nh) = scaled_size(w, h, settings.width.unwrap_or(0));
    let mut pixels = vec![[0.0f32; 3]; nw * nh];
    let clipped: usize = if (nw, nh) == (w, h) {
        pixels
            .par_chunks_mut(w)
            .enumerate()
            .map(|(y, out)| merge_row(&lins, y, w, out))
            .sum()
    } else {
        let xs = taps(w, nw);
        let ys = taps(h, nh);
        pixels
            .par_chunks_mut(nw)
            .zip(ys.par_iter())
            .enumerate()
            .map(|(oy, (out, rows))| {
                let mut row = vec![[0.0f32; 3]; w];
                let mut clipped = 0;
                for &(y, wy) in rows {
                    let c = merge_row(&lins, y, w, &mut row);
                    if owner(y, h, nh) == oy {
                        clipped += c;
                    }
                    add_row(&row, &xs, wy, out);
                }
                clipped
            })
            .sum()
    };
    Ok(Merged {
        radiance: Radiance {
            width: nw,
            height: nh,
            pixels,
        },
        clipped_everywhere: clipped,
        exposures,
        reference,
    })
}

/// The linearisation of one frame at fitted exposure `t`.
fn lin<'a>(
    frame: &BracketFrame<'a>,
    response: Option<&Response>,
    s: &MergeSettings,
    t: f64,
) -> Lin<'a> {
    match frame.pixels {
        Pixels::Raw {
            values,
            black,
            white,
        } => {
            let range = f32::from(white) - f32::from(black);
            Lin::Raw {
                values,
                black: f32::from(black),
                scale: 1.0 / range,
                white,
                floor: s.raw_floor * range,
            }
        }
        Pixels::Jpeg(codes) => {
            let g = response.map(|r| &r.curves);
            let hat = jpeg_weights(s);
            let mut num = Box::new([[0.0f32; 256]; 3]);
            let mut den = Box::new([0.0f32; 256]);
            let mut gt = Box::new([[0.0f32; 256]; 3]);
            for z in 0..256 {
                den[z] = (hat[z] * t * t) as f32;
                for c in 0..3 {
                    gt[c][z] = g.map_or(z as f32 / 255.0, |g| g[c][z]);
                    num[c][z] = (hat[z] * t) as f32 * gt[c][z];
                }
            }
            Lin::Jpeg {
                codes,
                num,
                den,
                g: gt,
                clip: s.jpeg_clip,
            }
        }
    }
}

/// The JPEG hat: 0 at and below `jpeg_black` and at and above `jpeg_clip`, 1 midway.
fn jpeg_weights(s: &MergeSettings) -> [f64; 256] {
    let (lo, hi) = (f64::from(s.jpeg_black), f64::from(s.jpeg_clip));
    let mid = (lo + hi) / 2.0;
    std::array::from_fn(|z| {
        let z = z as f64;
        if z <= lo || z >= hi {
            0.0
        } else {
            1.0 - (z - mid).abs() / (mid - lo)
        }
    })
}

/// Merges source row `y` into `out` (`w` pixels); returns how many of its pixels were
/// clipped in every frame. `lins` is in ascending exposure.
fn merge_row(lins: &[(Lin<'_>, f32)], y: usize, w: usize, out: &mut [[f32; 3]]) -> usize {
    let mut clipped = 0;
    let start = y * w * 3;
    for (x, o) in out.iter_mut().enumerate() {
        let i = start + x * 3;
        let mut num = [0.0f32; 3];
        let mut den = [0.0f32; 3];
        // (linear value, t) of the longest frame where the pixel is unclipped.
        let mut longest: Option<([f32; 3], f32)> = None;
        for (l, t) in lins {
            match l {
                Lin::Raw {
                    values,
                    black,
                    scale,
                    white,
                    floor,
                } => {
                    let s = &values[i..i + 3];
                    if s[0].max(s[1]).max(s[2]) >= *white {
                        continue;
                    }
                    let v = [
                        f32::from(s[0]) - black,
                        f32::from(s[1]) - black,
                        f32::from(s[2]) - black,
                    ];
                    for c in 0..3 {
                        if v[c] > *floor {
                            num[c] += v[c] * scale;
                            den[c] += t;
                        }
                    }
                    longest = Some((v.map(|v| v * scale), *t));
                }
                Lin::Jpeg {
                    codes,
                    num: nl,
                    den: dl,
                    g,
                    clip,
                } => {
                    let s = &codes[i..i + 3];
                    if s[0].max(s[1]).max(s[2]) >= *clip {
                        continue;
                    }
                    for c in 0..3 {
                        let z = usize::from(s[c]);
                        num[c] += nl[c][z];
                        den[c] += dl[z];
                    }
                    longest = Some(([0, 1, 2].map(|c| g[c][usize::from(s[c])]), *t));
                }
            }
        }
        match longest {
            None => {
                clipped += 1;
                let (l, t) = &lins[0];
                *o = shortest_value(l, i).map(|v| v / t);
            }
            Some((lv, lt)) => {
                for c in 0..3 {
                    o[c] = if den[c] > 0.0 {
                        num[c] / den[c]
                    } else {
                        lv[c] / lt
                    };
                }
            }
        }
    }
    clipped
}

/// Linear values of the (clipped) shortest frame at sample index `i`, as a lower bound.
fn shortest_value(l: &Lin<'_>, i: usize) -> [f32; 3] {
    match l {
        Lin::Raw {
            values,
            black,
            scale,
            ..
        } => [0, 1, 2].map(|c| ((f32::from(values[i + c]) - black) * scale).max(0.0)),
        Lin::Jpeg { codes, g, .. } => [0, 1, 2].map(|c| g[c][usize::from(codes[i + c])]),
    }
}

/// Fits every frame's relative exposure from the pixels: the ratio between neighbours in
/// exposure order from the samples both see well (ratio of sums after a median-based
/// outlier cut), chained outward from the reference frame, which keeps its EXIF value.
fn fit_exposures(
    frames: &[BracketFrame<'_>],
    response: Option<&Response>,
    s: &MergeSettings,
    nominal: &[f64],
    order: &[usize],
) -> (Vec<f64>, Vec<usize>) {
    let n = frames.len();
    let mut samples = vec![0usize; n];
    // ratio[k] = exposure(order[k+1]) / exposure(order[k])
    let ratios: Vec<(f64, usize)> = order
        .par_windows(2)
        .map(|p| {
            let (a, b) = (p[0], p[1]);
            match pair_ratio(&frames[a], &frames[b], response, s) {
                Some((r, k)) if k >= s.min_fit_samples => (r, k),
                _ => (nominal[b] / nominal[a], 0),
            }
        })
        .collect();
    let mut chained = vec![1.0f64; n];
    for (k, &(r, m)) in ratios.iter().enumerate() {
        chained[order[k + 1]] = chained[order[k]] * r;
        samples[order[k + 1]] = m;
    }
    if let Some(&(_, m)) = ratios.first() {
        samples[order[0]] = m;
    }
    let reference = order[n / 2];
    samples[reference] = 0;
    let scale = nominal[reference] / chained[reference];
    (chained.iter().map(|c| c * scale).collect(), samples)
}

/// Linear value (fraction of full scale) of sample `i` of a frame, and whether its pixel
/// is clipped.
fn sample(
    f: &BracketFrame<'_>,
    response: Option<&Response>,
    s: &MergeSettings,
    p: usize,
) -> Option<[f32; 3]> {
    match f.pixels {
        Pixels::Raw {
            values,
            black,
            white,
        } => {
            let v = &values[p * 3..p * 3 + 3];
            if v.iter().any(|&x| x >= white) {
                return None;
            }
            let range = f32::from(white) - f32::from(black);
            Some([0, 1, 2].map(|c| (f32::from(v[c]) - f32::from(black)) / range))
        }
        Pixels::Jpeg(codes) => {
            let v = &codes[p * 3..p * 3 + 3];
            if v.iter().any(|&x| x >= s.jpeg_clip) {
                return None;
            }
            let r = response?;
            Some([0, 1, 2].map(|c| r.linearise(c, v[c])))
        }
    }
}

/// Samples taken per pair for the ratio fit (every k-th pixel), plenty for a 0.1% fit.
const FIT_PIXELS: usize = 300_000;

/// exposure(b) / exposure(a) from pixels both frames see well, and the samples used.
fn pair_ratio(
    a: &BracketFrame<'_>,
    b: &BracketFrame<'_>,
    response: Option<&Response>,
    s: &MergeSettings,
) -> Option<(f64, usize)> {
    let n_px = a.width * a.height;
    // An odd stride so the samples do not line up in columns.
    let step = (n_px / FIT_PIXELS).max(1) | 1;
    let [lo, hi] = s.fit_window;
    let mut pairs: Vec<(f32, f32)> = Vec::with_capacity(3 * n_px / step + 3);
    for p in (0..n_px).step_by(step) {
        let (Some(va), Some(vb)) = (sample(a, response, s, p), sample(b, response, s, p)) else {
            continue;
        };
        for c in 0..3 {
            let ok = |v: f32| v >= lo && v <= hi;
            if ok(va[c]) && ok(vb[c]) {
                pairs.push((va[c], vb[c]));
            }
        }
    }
    if pairs.is_empty() {
        return None;
    }
    let mut r: Vec<f32> = pairs.iter().map(|(x, y)| y / x).collect();
    let mid = r.len() / 2;
    let median = *r.select_nth_unstable_by(mid, f32::total_cmp).1;
    // Drop pixels that changed between frames (movement, flicker): off the median by >20%.
    let (mut sa, mut sb, mut k) = (0.0f64, 0.0f64, 0usize);
    for &(x, y) in &pairs {
        let q = y / x;
        if q > median / 1.2 && q < median * 1.2 {
            sa += f64::from(x);
            sb += f64::from(y);
            k += 1;
        }
    }
    (k > 0).then(|| (sb / sa, k))
}
