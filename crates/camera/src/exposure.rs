//! A frame's exposure as its file records it (EXIF `ExposureTime`, `ISOSpeedRatings`,
//! `FNumber`), because the HDR merge must weight each frame by what the shutter did, not
//! by what was asked for.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use exif::{In, Tag};

use crate::Error;

/// A frame's exposure as its EXIF records it: the time always, ISO and f-number only
/// when the file has them (capture fills the gaps before the HDR merge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExifExposure {
    /// The exposure time, in seconds.
    pub seconds: f64,
    /// `ISOSpeedRatings` (EXIF 2.3: `PhotographicSensitivity`), if recorded.
    pub iso: Option<f64>,
    /// `FNumber`, if recorded (none for fixed-lens webcams).
    pub f_number: Option<f64>,
}

/// Where a [`crate::Shot`]'s exposure came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExposureSource {
    /// Read from the file's EXIF.
    Exif,
    /// The file has no EXIF exposure (a webcam PNG): the requested exposure is assumed.
    /// Only the command camera returns this.
    Assumed,
}

/// Reads the exposure from a file's EXIF (JPEG, TIFF-based RAW, PNG, HEIF, WebP), looking
/// in IFD0 and its Exif sub-IFD. `Ok(None)` when the file has no EXIF or no
/// `ExposureTime`; an error when the file cannot be opened or its EXIF is broken.
pub fn read_exposure(path: &Path) -> Result<Option<ExifExposure>, Error> {
    let file = File::open(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // Keep the fields read before a quirk (a sub-IFD with a stray next-IFD pointer, as
    // piexif and some cameras write): a readable ExposureTime is all this needs.
    let read = exif::Reader::new()
        .continue_on_error(true)
        .read_from_container(&mut BufReader::new(file))
        .or_else(|e| e.distill_partial_result(|_| {}));
    let exif = match read {
        Ok(exif) => exif,
        Err(exif::Error::NotFound(_) | exif::Error::InvalidFormat(_)) => return Ok(None),
        Err(exif::Error::Io(source)) => {
            return Err(Error::Io {
                path: path.to_path_buf(),
                source,
            });
        }
        Err(e) => {
            return Err(Error::Exif {
                path: path.to_path_buf(),
                problem: format!("its EXIF cannot be read ({e})"),
            });
        }
    };
    // kamadak-exif files the Exif sub-IFD's fields under the primary image (IFD0). TIFF/EP
    // raw files (and TIFFs written by simple tools) carry the same tags in IFD0 itself,
    // which it reads as TIFF-context tags of the same number: take either.
    let number = |tag: Tag| -> Option<f64> {
        let field = exif
            .get_field(tag, In::PRIMARY)
            .or_else(|| exif.get_field(Tag(exif::Context::Tiff, tag.number()), In::PRIMARY))?;
        let value = match &field.value {
            exif::Value::Rational(v) => v.first().map(|r| r.to_f64()),
            exif::Value::SRational(v) => v.first().map(|r| r.to_f64()),
            other => other.get_uint(0).map(f64::from),
        }?;
        (value.is_finite() && value > 0.0).then_some(value)
    };
    let Some(seconds) = number(Tag::ExposureTime) else {
        return Ok(None);
    };
    Ok(Some(ExifExposure {
        seconds,
        iso: number(Tag::PhotographicSensitivity),
        f_number: number(Tag::FNumber),
    }))
}
