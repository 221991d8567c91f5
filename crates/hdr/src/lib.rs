//! Exposure brackets to linear radiance, for `visobjd capture`.
//!
//! A basis image is one linear-radiance picture of the stage per light at full. A camera
//! cannot see the whole range of a lit stage in one frame, so capture shoots a bracket of
//! frames and this crate merges them. It is pure: frames come in as plain pixel data, and
//! the only I/O is the final EXR write ([`write_exr`]). See `docs/capture.md` ("How
//! brackets are merged") for the method and its settled numbers.
//!
//! The flow for one light:
//! 1. once per session, [`Response::recover`] from a JPEG bracket of a lit stage (raw
//!    frames need none: they are linear);
//! 2. [`propose_bracket`] from a metering frame picks the exposure times;
//! 3. [`merge`] turns the bracket into a [`Radiance`] image (exposure ratios fitted from the
//!    pixels, clipped and near-black pixels masked, area-downsampled on the way);
//! 4. [`subtract_ambient`], [`ambient_drift`] and [`light_test`] against the ambient merges;
//! 5. [`write_exr`] writes `basis/NNN.exr` atomically.

mod ambient;
mod bracket;
mod error;
mod exr_out;
mod frame;
mod merge;
mod resample;
mod response;

pub use ambient::{AmbientDrift, LightTest, ambient_drift, light_test, subtract_ambient};
pub use bracket::{Bracket, BracketSettings, propose_bracket};
pub use error::HdrError;
pub use exr_out::{encode_exr, write_exr};
pub use frame::{BracketFrame, Exposure, Pixels};
pub use merge::{ExposureFit, MergeSettings, Merged, merge};
pub use resample::{downsample, scaled_size};
pub use response::Response;

/// A linear RGB image, interleaved (`pixels[y * width + x]`).
///
/// Units: the fraction of the camera's full scale that the pixel would reach at relative
/// exposure 1 (`t * ISO / N^2 = 1`). Every light's basis shares these units as long as the
/// camera and its response stay the same, which is what relighting needs; capture may
/// apply one common factor ([`Radiance::scale`]) to put display white near 1.0.
#[derive(Debug, Clone, PartialEq)]
pub struct Radiance {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear RGB per pixel, row-major.
    pub pixels: Vec<[f32; 3]>,
}

impl Radiance {
    /// Multiplies every sample by `factor` (one factor for all lights keeps them comparable).
    pub fn scale(&mut self, factor: f32) {
        for p in &mut self.pixels {
            for v in p.iter_mut() {
                *v *= factor;
            }
        }
    }

    /// Takes every pixel through the 3x3 matrix `m` (row-major): camera RGB to linear sRGB
    /// for a raw capture, after the merge (both are linear, so the order does not matter
    /// and the merge works on the sensor's own values).
    pub fn transform(&mut self, m: [[f32; 3]; 3]) {
        for p in &mut self.pixels {
            let c = *p;
            *p = m.map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2]);
        }
    }

    /// Mean of every sample (all channels), in f64.
    pub fn mean(&self) -> f64 {
        let n = self.pixels.len() * 3;
        if n == 0 {
            return 0.0;
        }
        self.pixels
            .iter()
            .flatten()
            .map(|&v| f64::from(v))
            .sum::<f64>()
            / n as f64
    }
}
