//! The camera layer's errors: each a sentence a person at the rig can act on, naming the
//! call that failed and, for gphoto2, its own `*** Error (...) ***` line.

use std::path::PathBuf;

/// A camera call that did not give a usable answer.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The program could not be started at all.
    #[error(
        "could not start `{call}`: {source} (is `{program}` installed and on PATH? for gphoto2: apt-get install gphoto2)"
    )]
    Spawn {
        /// The program.
        program: String,
        /// The call, as a command line.
        call: String,
        /// Why.
        source: std::io::Error,
    },

    /// The second try ran past the timeout and was killed (the first failed or timed out too).
    #[error(
        "`{call}` timed out after {seconds} s and was killed, on its second try of two; the camera may be busy or hung: check it, switch it off and on, or raise [capture] camera_timeout_s for long exposures"
    )]
    TimedOut {
        /// The call, as a command line.
        call: String,
        /// The timeout, in seconds.
        seconds: f64,
    },

    /// The tool exited with an error (after one retry, unless retrying could not help).
    #[error("`{call}` failed: {message}{hint}")]
    Tool {
        /// The call, as a command line.
        call: String,
        /// The tool's own error line(s), e.g. `*** Error (-53: 'Could not claim the USB device') ***`.
        message: String,
        /// gphoto2's error number (`-53`), when it printed one.
        code: Option<i32>,
        /// What to do about it, starting with `: `, or empty.
        hint: String,
    },

    /// `--auto-detect` listed no camera.
    #[error(
        "`{call}` found no camera: check the USB cable, that the camera is switched on and not asleep, and that no other program (often the desktop's gvfs-gphoto2-volume-monitor) holds it"
    )]
    NoCamera {
        /// The call, as a command line.
        call: String,
    },

    /// A value not among the camera's choices; the camera was not asked.
    #[error("{key} cannot be {value:?}: the camera offers {choices}")]
    NotAChoice {
        /// The key.
        key: String,
        /// The value refused.
        value: String,
        /// The choices, listed.
        choices: String,
    },

    /// The entry cannot be changed now.
    #[error(
        "{key} is read-only on this camera (is the mode dial on M, and the lens switch on manual where it matters?)"
    )]
    ReadOnly {
        /// The key.
        key: String,
    },

    /// The tool succeeded but printed something this layer cannot read.
    #[error("could not read the output of `{call}`: {problem}")]
    Parse {
        /// The call, as a command line.
        call: String,
        /// What was wrong.
        problem: String,
    },

    /// The capture call succeeded but no file is where it should be.
    #[error(
        "`{call}` succeeded but wrote no file {expected}; is the camera's capture target the memory card with downloads allowed?"
    )]
    NoFile {
        /// The call, as a command line.
        call: String,
        /// Where the file was expected.
        expected: String,
    },

    /// The frame's file has no readable exposure, so its exposure is unknown.
    #[error("{path}: {problem}; the frame's exposure cannot be known without it")]
    Exif {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        problem: String,
    },

    /// A `--camera` value that names no camera.
    #[error("--camera {spec:?}: {problem}")]
    Spec {
        /// The value given.
        spec: String,
        /// What was wrong.
        problem: String,
    },

    /// The camera has no such operation (the command camera has no settings).
    #[error("{0}")]
    Unsupported(String),

    /// A file operation around a capture failed.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}
