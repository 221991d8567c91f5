//! One frame of a bracket: its exposure as read from EXIF and its pixels.

use crate::HdrError;

/// A frame's exposure as the camera reports it in EXIF.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Exposure {
    /// Exposure time in seconds (`ExposureTime`).
    pub seconds: f64,
    /// ISO speed (`ISOSpeedRatings` / `PhotographicSensitivity`).
    pub iso: f64,
    /// Aperture f-number (`FNumber`).
    pub f_number: f64,
}

impl Exposure {
    /// The exposure relative to 1 s at ISO 1 and f/1: `t * ISO / N^2`. Radiance is
    /// pixel value over this, so frames shot at different ISO or aperture merge too.
    pub fn relative(&self) -> f64 {
        self.seconds * self.iso / (self.f_number * self.f_number)
    }

    pub(crate) fn check(&self, frame: usize) -> Result<f64, HdrError> {
        let bad = |what: String| Err(HdrError::BadExposure { frame, what });
        if !(self.seconds.is_finite() && self.seconds > 0.0) {
            return bad(format!("exposure time {} s", self.seconds));
        }
        if !(self.iso.is_finite() && self.iso > 0.0) {
            return bad(format!("ISO {}", self.iso));
        }
        if !(self.f_number.is_finite() && self.f_number > 0.0) {
            return bad(format!("f-number {}", self.f_number));
        }
        Ok(self.relative())
    }
}

/// A frame's pixels, RGB interleaved, row-major. Borrowed, so a 24-megapixel bracket is
/// never copied.
#[derive(Debug, Clone, Copy)]
pub enum Pixels<'a> {
    /// 8-bit camera JPEG values, through the camera's unknown tone curve; linearised with a
    /// [`crate::Response`].
    Jpeg(&'a [u8]),
    /// Linear raw values (demosaiced, white-balanced or not, but not tone-mapped).
    Raw {
        /// The samples.
        values: &'a [u16],
        /// The value a dark pixel reads (the sensor's black level).
        black: u16,
        /// The saturation level: a sample at or above it is clipped.
        white: u16,
    },
}

impl Pixels<'_> {
    pub(crate) fn kind(&self) -> &'static str {
        match self {
            Pixels::Jpeg(_) => "JPEG",
            Pixels::Raw { .. } => "raw",
        }
    }

    fn len(&self) -> usize {
        match self {
            Pixels::Jpeg(p) => p.len(),
            Pixels::Raw { values, .. } => values.len(),
        }
    }
}

/// One frame of a bracket.
#[derive(Debug, Clone, Copy)]
pub struct BracketFrame<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The exposure from EXIF (the merge refits the ratios between frames from the data).
    pub exposure: Exposure,
    /// The pixels.
    pub pixels: Pixels<'a>,
}

/// Checks a bracket (sizes, kinds, exposures, levels); returns the relative exposures.
pub(crate) fn check_bracket(frames: &[BracketFrame<'_>]) -> Result<Vec<f64>, HdrError> {
    let first = frames.first().ok_or(HdrError::NoFrames)?;
    let mut rel = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        if f.width == 0 || f.height == 0 {
            return Err(HdrError::Empty { frame: i });
        }
        if (f.width, f.height) != (first.width, first.height) {
            return Err(HdrError::SizeMismatch {
                frame: i,
                got_w: f.width,
                got_h: f.height,
                width: first.width,
                height: first.height,
            });
        }
        let need = f.width * f.height * 3;
        if f.pixels.len() != need {
            return Err(HdrError::PixelCount {
                frame: i,
                got: f.pixels.len(),
                need,
                width: f.width,
                height: f.height,
            });
        }
        if f.pixels.kind() != first.pixels.kind() {
            return Err(HdrError::MixedKinds {
                frame: i,
                got: f.pixels.kind(),
                want: first.pixels.kind(),
            });
        }
        if let Pixels::Raw { black, white, .. } = f.pixels
            && white <= black
        {
            return Err(HdrError::BadLevels {
                frame: i,
                black,
                white,
            });
        }
        rel.push(f.exposure.check(i)?);
    }
    Ok(rel)
}
