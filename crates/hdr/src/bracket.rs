//! Which exposures to shoot, measured from one metering frame instead of a fixed bracket:
//! short enough that the brightest pixel is unclipped, long enough that the light's dim
//! useful pixels rise well above the noise, steps no wider than the merge can bridge.

use crate::frame::{Pixels, check_bracket};
use crate::{BracketFrame, HdrError, Response};

/// How to choose a bracket. Defaults are the settled values in `docs/capture.md`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BracketSettings {
    /// The brightest pixel should reach at most this fraction of full scale in the
    /// shortest frame (margin for the shoulder and for EXIF error).
    pub headroom: f64,
    /// The useful pixels should reach at least this fraction of full scale in the longest
    /// frame: 5% is about 800 DN at 14 bits, signal/noise near 30.
    pub useful_level: f64,
    /// A pixel is lit noticeably when its radiance is at least this fraction of the
    /// brightest.
    pub lit_fraction: f64,
    /// Which percentile of the noticeably lit pixels must reach `useful_level`.
    pub percentile: f64,
    /// Largest step between consecutive exposures, in stops (the ratio fit needs pixels
    /// that both frames see well).
    pub max_step_stops: f64,
    /// Raw: the near-black floor as a fraction of full scale (as in the merge).
    pub raw_floor: f64,
    /// JPEG: codes at or above this are clipped (as in the merge).
    pub jpeg_clip: u8,
    /// JPEG: codes at or below this are near-black (as in the merge).
    pub jpeg_black: u8,
}

impl Default for BracketSettings {
    fn default() -> Self {
        BracketSettings {
            headroom: 0.8,
            useful_level: 0.05,
            lit_fraction: 0.01,
            percentile: 0.05,
            max_step_stops: 2.0,
            raw_floor: 0.002,
            jpeg_clip: 250,
            jpeg_black: 3,
        }
    }
}

/// A proposed bracket.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bracket {
    /// Exposure times in seconds, ascending, from the camera's choices, at the metering
    /// frame's ISO and aperture.
    pub times: Vec<f64>,
    /// The metering frame clipped some pixels, so the brightest radiance is unknown: the
    /// bracket starts at the shortest choice. Meter again with that frame to be sure.
    pub meter_clipped: bool,
    /// The brightest radiance measured (per unit relative exposure).
    pub brightest: f64,
    /// The percentile radiance of the noticeably lit pixels; 0 when none was measurable.
    pub useful: f64,
}

/// Proposes exposure times from a metering frame. `response` is needed for JPEG.
/// `shutter_choices` are the camera's available times in seconds (any order).
pub fn propose_bracket(
    meter: &BracketFrame<'_>,
    response: Option<&Response>,
    shutter_choices: &[f64],
    settings: &BracketSettings,
) -> Result<Bracket, HdrError> {
    let rel = check_bracket(std::slice::from_ref(meter))?[0];
    let mut choices: Vec<f64> = shutter_choices
        .iter()
        .copied()
        .filter(|t| t.is_finite() && *t > 0.0)
        .collect();
    if choices.is_empty() {
        return Err(HdrError::NoShutterChoices);
    }
    choices.sort_by(f64::total_cmp);
    choices.dedup();
    // Relative exposure per second at the meter's ISO and aperture.
    let k = rel / meter.exposure.seconds;

    // Per pixel: brightest channel as a fraction of full scale; None if clipped; and
    // whether it is above the noise floor.
    let n = meter.width * meter.height;
    let mut clipped = false;
    let mut values: Vec<f64> = Vec::with_capacity(n);
    match meter.pixels {
        Pixels::Raw {
            values: v,
            black,
            white,
        } => {
            let range = f64::from(white) - f64::from(black);
            for p in v.chunks_exact(3) {
                let m = p[0].max(p[1]).max(p[2]);
                if m >= white {
                    clipped = true;
                    continue;
                }
                let x = (f64::from(m) - f64::from(black)) / range;
                if x > settings.raw_floor {
                    values.push(x);
                }
            }
        }
        Pixels::Jpeg(codes) => {
            let r = response.ok_or(HdrError::NoResponse)?;
            r.validate()?;
            for p in codes.chunks_exact(3) {
                if p.iter().any(|&z| z >= settings.jpeg_clip) {
                    clipped = true;
                    continue;
                }
                if p.iter().all(|&z| z <= settings.jpeg_black) {
                    continue;
                }
                let x = (0..3)
                    .map(|c| f64::from(r.linearise(c, p[c])))
                    .fold(0.0, f64::max);
                values.push(x);
            }
        }
    }
    let brightest = values.iter().copied().fold(0.0, f64::max) / rel;
    // Shortest: the longest choice that keeps the brightest pixel under the headroom.
    let short = if clipped || brightest <= 0.0 {
        choices[0]
    } else {
        choices
            .iter()
            .copied()
            .rfind(|&t| brightest * t * k <= settings.headroom)
            .unwrap_or(choices[0])
    };
    // Longest: the shortest choice that lifts the useful percentile to the useful level.
    let mut lit: Vec<f64> = values
        .iter()
        .map(|v| v / rel)
        .filter(|&e| e >= settings.lit_fraction * brightest)
        .collect();
    let useful = if lit.is_empty() {
        0.0
    } else {
        let i = ((lit.len() - 1) as f64 * settings.percentile.clamp(0.0, 1.0)) as usize;
        *lit.select_nth_unstable_by(i, f64::total_cmp).1
    };
    let long = if useful > 0.0 {
        choices
            .iter()
            .copied()
            .find(|&t| useful * t * k >= settings.useful_level)
            .unwrap_or(choices[choices.len() - 1])
    } else {
        short
    }
    .max(short);
    // Steps of at most max_step_stops (or the next choice where the camera has a gap).
    let factor = settings.max_step_stops.max(0.1).exp2();
    let mut times = vec![short];
    let mut t = short;
    while t < long {
        let next = choices
            .iter()
            .copied()
            .rfind(|&c| c > t && c <= t * factor * (1.0 + 1e-9))
            .or_else(|| choices.iter().copied().find(|&c| c > t));
        match next {
            Some(c) => {
                times.push(c);
                t = c;
            }
            None => break,
        }
    }
    Ok(Bracket {
        times,
        meter_clipped: clipped,
        brightest,
        useful,
    })
}
