//! Cameras for `visobjd capture`: the layer that shoots one frame at a given shutter and
//! says what exposure the frame really had.
//!
//! Every camera operation runs one external process (`gphoto2`, or a command built from a
//! template), so a camera or USB fault kills a child, never visobjd. Each call has a
//! timeout after which the process (and its process group) is killed, and is retried
//! once. Exposures come from the written file's EXIF (`ExposureTime`, `ISOSpeedRatings`,
//! `FNumber`), never from the request, because real shutters differ from their labels;
//! only the command camera may fall back to the requested exposure, and says so
//! ([`ExposureSource::Assumed`]).
//!
//! ```no_run
//! use std::path::Path;
//! use visobjd_camera::{open, CameraOptions};
//! let mut camera = open("gphoto2", CameraOptions::default())?;
//! println!("{}", camera.describe()?.model);
//! let settings = camera.settings()?;
//! for shutter in settings.shutter.shutters() {
//!     let frame = camera.capture(&shutter, Path::new("/tmp/light-01/frame.jpg"))?;
//!     println!("{:?} at {} s", frame.paths, frame.exposure.seconds);
//! }
//! # Ok::<(), visobjd_camera::Error>(())
//! ```
//!
//! See `docs/capture.md` ("Cameras").

mod command;
mod error;
mod exposure;
mod gphoto2;
mod run;
mod shutter;

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Duration;

pub use command::CommandCamera;
pub use error::Error;
pub use exposure::{ExifExposure, ExposureSource, read_exposure};
pub use gphoto2::{Gphoto2, parse_auto_detect, parse_config, tool_message};
pub use shutter::Shutter;

/// The default per-call timeout (`[capture] camera_timeout_s`): long enough for a 30 s
/// exposure plus the download, short enough that a hung camera does not stall a capture
/// run for long.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(60);

/// How camera processes are run. The capture command fills `timeout` from
/// `[capture] camera_timeout_s`.
#[derive(Debug, Clone)]
pub struct CameraOptions {
    /// Per call: after this the process is killed, and the call is tried once more.
    pub timeout: Duration,
    /// The gphoto2 program: a name looked up on `PATH` (the child's `PATH`, if `env` sets
    /// one) or a path. Default `gphoto2`.
    pub gphoto2: PathBuf,
    /// Extra environment for every camera process (tests point the fake camera at its
    /// state here; a site may set `PATH`).
    pub env: Vec<(OsString, OsString)>,
}

impl Default for CameraOptions {
    fn default() -> Self {
        CameraOptions {
            timeout: DEFAULT_TIMEOUT,
            gphoto2: PathBuf::from("gphoto2"),
            env: Vec::new(),
        }
    }
}

/// The camera found: what the capture command logs and writes next to the basis images.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Description {
    /// The model as the driver names it (`Canon EOS 6D`), or `command: PROGRAM`.
    pub model: String,
    /// Where it is (`usb:001,007`); empty for the command camera.
    pub port: String,
}

/// One configuration entry as `gphoto2 --get-config KEY` prints it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CameraSetting {
    /// The key asked for (`shutterspeed`).
    pub key: String,
    /// The camera's label (`Shutter Speed`).
    pub label: String,
    /// The camera refuses to change it (often: the mode dial is not on M).
    pub readonly: bool,
    /// The widget type (`RADIO`, `MENU`, `TEXT`, `RANGE`, `TOGGLE`, `DATE`).
    pub kind: String,
    /// The current value, as the camera spells it.
    pub current: String,
    /// The values the camera accepts, in its order; empty for free-form types.
    pub choices: Vec<String>,
}

impl CameraSetting {
    /// The shutter choices that are times, in the camera's order (`bulb` and other
    /// non-times skipped): what a bracket is chosen from.
    pub fn shutters(&self) -> Vec<Shutter> {
        self.choices
            .iter()
            .filter_map(|c| Shutter::parse(c))
            .collect()
    }

    /// Whether `value` may be set: one of the choices, or anything for a free-form type.
    pub fn accepts(&self, value: &str) -> bool {
        self.choices.is_empty() || self.choices.iter().any(|c| c == value)
    }
}

/// The settings a capture run needs, read in one go before shooting.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settings {
    /// `shutterspeed`: the bracket's choices.
    pub shutter: CameraSetting,
    /// `iso`, if the body has it.
    pub iso: Option<CameraSetting>,
    /// `aperture`, or `f-number` on bodies that call it that (values like `f/8`).
    pub aperture: Option<CameraSetting>,
    /// `imageformat` (JPEG, RAW, RAW + JPEG), if the body has it.
    pub image_format: Option<CameraSetting>,
}

/// One shot: the files written and the exposure they record.
#[derive(Debug, Clone, PartialEq)]
pub struct Shot {
    /// Every file written (RAW + JPEG gives two), in the order written.
    pub paths: Vec<PathBuf>,
    /// The frame's exposure.
    pub exposure: ExifExposure,
    /// Whether `exposure` was read from a file's EXIF or assumed from the request.
    pub source: ExposureSource,
}

/// What the capture command drives. Implemented by [`Gphoto2`] and [`CommandCamera`];
/// [`open`] picks one from the `--camera` value.
pub trait Camera {
    /// Finds the camera: an error if none is connected.
    fn describe(&mut self) -> Result<Description, Error>;

    /// Reads one configuration entry with its choices.
    fn config(&mut self, key: &str) -> Result<CameraSetting, Error>;

    /// Reads shutter, ISO, aperture (or f-number) and image format.
    fn settings(&mut self) -> Result<Settings, Error>;

    /// Sets `key` to `value`, which must be one of its choices: others are refused
    /// without touching the camera, with a sentence naming the choices.
    fn set_config(&mut self, key: &str, value: &str) -> Result<(), Error>;

    /// Shoots one frame at `shutter` into `out` and returns the files written with the
    /// exposure read back from them. The gphoto2 camera writes `out` with its extension
    /// replaced by each file's suffix as the camera names it (`frame.JPG`, and
    /// `frame.CR2` for RAW + JPEG); the command camera writes `out` as given. The shutter
    /// must be one of the camera's choices (gphoto2) and is set in the same process.
    fn capture(&mut self, shutter: &Shutter, out: &Path) -> Result<Shot, Error>;
}

/// Opens the camera named by a `--camera` value: `gphoto2` (the default) or
/// `command:TEMPLATE` (see [`CommandCamera`]). Opening starts no process.
pub fn open(spec: &str, options: CameraOptions) -> Result<Box<dyn Camera + Send>, Error> {
    let spec = spec.trim();
    if spec.is_empty() || spec == "gphoto2" {
        return Ok(Box::new(Gphoto2::new(options)));
    }
    if let Some(template) = spec.strip_prefix("command:") {
        return Ok(Box::new(CommandCamera::new(template, options)?));
    }
    Err(Error::Spec {
        spec: spec.to_string(),
        problem: "expected `gphoto2` or `command:PROGRAM ARGS` with {exposure} and {out}"
            .to_string(),
    })
}
