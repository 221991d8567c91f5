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
    /// JPEG noise model, shot noise: the electrons a sample at full scale holds. The
    /// camera's own figure is unknown; any value in the thousands to tens of thousands
    /// makes shot noise dominate wherever the tone curve is not flat, which is what the
    /// weights need to know (see [`merge`]).
    pub jpeg_electrons: f32,
    /// JPEG noise model, the code's own error in codes (rounding, 0.29, and compression).
    pub jpeg_code_noise: f32,
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
            jpeg_electrons: 10_000.0,
            jpeg_code_noise: 0.5,
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
    /// Relative exposure the merge used: the fitted ratios on the EXIF scale, their
    /// geometric mean that of the EXIF exposures (an EXIF error of one frame is shared out
    /// over the bracket instead of setting the whole light's scale).
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
        /// Per channel `w(z) * t^2` (denominator).
        den: Box<[[f32; 256]; 3]>,
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
/// inverse-variance weights `w = t^2 / var(value)`: raw, shot noise (`var` proportional to
/// the value, so `w` to `t` and the estimate is sum(value) / sum(t)); JPEG, the variance
/// of the linear value a code stands for, `g'(z)^2 s^2 + g(z) / N` (the code's own error
/// through the curve's slope, and shot noise; [`jpeg_variance`]). Shot noise dominates
/// where the curve is steep in codes, so a pixel's frames weigh about as `t` there, as in
/// raw; on a shoulder or a toe, where a code spans a wide range of values (and the
/// recovered curve is least certain), the slope takes the weight away. A channel seen in
/// no frame above the floor takes the longest unclipped frame's value; a pixel clipped in
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
            let lin = Response::linear();
            let g = &response.unwrap_or(&lin).curves;
            let mut num = Box::new([[0.0f32; 256]; 3]);
            let mut den = Box::new([[0.0f32; 256]; 3]);
            let mut gt = Box::new([[0.0f32; 256]; 3]);
            for c in 0..3 {
                let var = jpeg_variance(&g[c], s);
                for z in 0..256 {
                    let w = if var[z] > 0.0 {
                        f64::from(var[z]).recip()
                    } else {
                        0.0
                    };
                    gt[c][z] = g[c][z];
                    den[c][z] = (w * t * t) as f32;
                    num[c][z] = (w * t) as f32 * g[c][z];
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

/// The variance of the linear value (fraction of full scale) each code of curve `g` stands
/// for: `g'(z)^2 s^2 + g(z) / N`, the code's own error (`s` codes: rounding and
/// compression) through the curve's slope, and shot noise (`N` electrons at full scale);
/// 0 (no weight) for the near-black codes and the clipped ones. The slope is the curve's
/// central difference: the recovered curve is smooth.
fn jpeg_variance(g: &[f32], s: &MergeSettings) -> [f32; 256] {
    let (sigma2, electrons) = (s.jpeg_code_noise.powi(2), s.jpeg_electrons.max(1.0));
    std::array::from_fn(|z| {
        if z <= usize::from(s.jpeg_black) || z >= usize::from(s.jpeg_clip) || z >= g.len() {
            return 0.0;
        }
        let (lo, hi) = (z - 1, (z + 1).min(g.len() - 1));
        let slope = (g[hi] - g[lo]) / (hi - lo) as f32;
        (slope * slope * sigma2 + g[z].max(0.0) / electrons).max(f32::MIN_POSITIVE)
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
                        den[c] += dl[c][z];
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
/// exposure order from the samples both see well ([`pair_ratio`]), chained, then put on
/// the EXIF scale with the fitted exposures' geometric mean equal to the EXIF ones': each
/// EXIF time is off by its own few percent, and the mean over the bracket is off by less
/// than any one of them.
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
    samples[order[n / 2]] = 0;
    let log_scale = nominal
        .iter()
        .zip(&chained)
        .map(|(e, c)| (e / c).ln())
        .sum::<f64>()
        / n as f64;
    let scale = log_scale.exp();
    (chained.iter().map(|c| c * scale).collect(), samples)
}

/// A frame as the ratio fit reads it: each sample's linear value and its variance.
struct FitFrame<'a> {
    frame: &'a BracketFrame<'a>,
    response: Option<&'a Response>,
    /// JPEG: per channel, the variance of each code's linear value ([`jpeg_variance`]).
    var: Option<Box<[[f32; 256]; 3]>>,
}

impl<'a> FitFrame<'a> {
    fn new(frame: &'a BracketFrame<'a>, response: Option<&'a Response>, s: &MergeSettings) -> Self {
        let var = match (frame.pixels, response) {
            (Pixels::Jpeg(_), Some(r)) => {
                Some(Box::new([0, 1, 2].map(|c| jpeg_variance(&r.curves[c], s))))
            }
            _ => None,
        };
        FitFrame {
            frame,
            response,
            var,
        }
    }

    /// Pixel `p`'s linear values (fractions of full scale) and their variances (raw: the
    /// value, shot noise up to a factor the pair shares); None when the pixel is clipped.
    fn sample(&self, s: &MergeSettings, p: usize) -> Option<[(f32, f32); 3]> {
        match self.frame.pixels {
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
                Some([0, 1, 2].map(|c| {
                    let x = (f32::from(v[c]) - f32::from(black)) / range;
                    (x, x.max(0.0))
                }))
            }
            Pixels::Jpeg(codes) => {
                let v = &codes[p * 3..p * 3 + 3];
                if v.iter().any(|&x| x >= s.jpeg_clip) {
                    return None;
                }
                let (r, var) = (self.response?, self.var.as_deref()?);
                Some([0, 1, 2].map(|c| (r.linearise(c, v[c]), var[c][usize::from(v[c])])))
            }
        }
    }
}

/// Samples taken per pair for the ratio fit (every k-th pixel), plenty for a 0.1% fit.
const FIT_PIXELS: usize = 300_000;

/// exposure(b) / exposure(a) from pixels both frames see well, and the samples used: the
/// samples inside `fit_window` in both frames (and, for JPEG, on codes the merge weighs),
/// those off the median ratio by more than 20% dropped (movement, flicker), then the
/// ratio `r` minimising `sum (b - r a)^2 / (var b + r^2 var a)` (weighted least squares
/// with each sample's noise, [`FitFrame::sample`]: the codes of a shoulder or a toe,
/// where the curve is least certain, count little; for raw it is the ratio of the sums).
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
    let (fa, fb) = (FitFrame::new(a, response, s), FitFrame::new(b, response, s));
    // (value in a, its variance, value in b, its variance)
    let mut pairs: Vec<[f32; 4]> = Vec::with_capacity(3 * n_px / step + 3);
    for p in (0..n_px).step_by(step) {
        let (Some(va), Some(vb)) = (fa.sample(s, p), fb.sample(s, p)) else {
            continue;
        };
        for c in 0..3 {
            let ok = |(v, var): (f32, f32)| v >= lo && v <= hi && var > 0.0;
            if ok(va[c]) && ok(vb[c]) {
                pairs.push([va[c].0, va[c].1, vb[c].0, vb[c].1]);
            }
        }
    }
    if pairs.is_empty() {
        return None;
    }
    let mut r: Vec<f32> = pairs.iter().map(|p| p[2] / p[0]).collect();
    let mid = r.len() / 2;
    let median = *r.select_nth_unstable_by(mid, f32::total_cmp).1;
    pairs.retain(|p| {
        let q = p[2] / p[0];
        q > median / 1.2 && q < median * 1.2
    });
    if pairs.is_empty() {
        return None;
    }
    // The weights depend on the ratio: two rounds from the median are plenty.
    let mut ratio = f64::from(median);
    for _ in 0..2 {
        let (mut ab, mut aa) = (0.0f64, 0.0f64);
        for &[x, vx, y, vy] in &pairs {
            let (x, y) = (f64::from(x), f64::from(y));
            let w = 1.0 / (f64::from(vy) + ratio * ratio * f64::from(vx));
            ab += w * x * y;
            aa += w * x * x;
        }
        ratio = ab / aa;
    }
    (ratio.is_finite() && ratio > 0.0).then_some((ratio, pairs.len()))
}
