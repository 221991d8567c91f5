//! What can go wrong, in sentences a person at the capture desk can act on.

/// Errors from merging, response recovery, bracket choice and writing.
#[derive(Debug, thiserror::Error)]
pub enum HdrError {
    /// No frames were given.
    #[error("the bracket has no frames; shoot at least one exposure")]
    NoFrames,
    /// A frame's pixel buffer does not match its stated size.
    #[error(
        "frame {frame} has {got} samples but {width}x{height} RGB needs {need}; the camera driver handed over a truncated or mis-sized image"
    )]
    PixelCount {
        /// Index of the frame in the bracket.
        frame: usize,
        /// Samples given.
        got: usize,
        /// Samples needed (width x height x 3).
        need: usize,
        /// Stated width.
        width: usize,
        /// Stated height.
        height: usize,
    },
    /// Frames of one bracket differ in size.
    #[error(
        "frame {frame} is {got_w}x{got_h} but frame 0 is {width}x{height}; a bracket must be shot at one image size"
    )]
    SizeMismatch {
        /// Index of the offending frame.
        frame: usize,
        /// Its width.
        got_w: usize,
        /// Its height.
        got_h: usize,
        /// Frame 0's width.
        width: usize,
        /// Frame 0's height.
        height: usize,
    },
    /// An image is empty.
    #[error("frame {frame} is empty (0 pixels); the camera returned no image")]
    Empty {
        /// Index of the frame.
        frame: usize,
    },
    /// A frame's EXIF exposure is not usable.
    #[error(
        "frame {frame} has an unusable exposure ({what}); check the EXIF exposure time, ISO and f-number the driver read"
    )]
    BadExposure {
        /// Index of the frame.
        frame: usize,
        /// What is wrong.
        what: String,
    },
    /// Raw black and white levels are inconsistent.
    #[error(
        "frame {frame} has black level {black} and white level {white}; the white (saturation) level must be above the black level"
    )]
    BadLevels {
        /// Index of the frame.
        frame: usize,
        /// Black level.
        black: u16,
        /// White level.
        white: u16,
    },
    /// JPEG and raw frames mixed in one bracket.
    #[error("frame {frame} is {got} but frame 0 is {want}; shoot the whole bracket in one format")]
    MixedKinds {
        /// Index of the frame.
        frame: usize,
        /// Its kind.
        got: &'static str,
        /// Frame 0's kind.
        want: &'static str,
    },
    /// JPEG frames need a camera response to be linearised.
    #[error(
        "JPEG frames need the camera's response; recover it once per session (Response::recover) from a bracket of the lit stage, or shoot raw"
    )]
    NoResponse,
    /// A stored response is damaged.
    #[error(
        "the stored camera response is damaged (each channel needs 256 finite, non-decreasing values); recover it again from a bracket of the lit stage"
    )]
    BadResponse,
    /// Response recovery needs JPEG frames.
    #[error("the camera response is recovered from JPEG frames; raw frames are linear already")]
    ResponseNeedsJpeg,
    /// Not enough well-spread pixels to recover a response.
    #[error(
        "only {got} of the sampled pixels are usable to recover the camera response (need {need}); light the stage and shoot a bracket of at least 3 frames 1-2 stops apart that spans dark to bright"
    )]
    TooFewSamples {
        /// Usable samples found.
        got: usize,
        /// Needed.
        need: usize,
    },
    /// Two images to compare differ in size.
    #[error(
        "the images differ in size ({a_w}x{a_h} vs {b_w}x{b_h}); merge the light and the ambient at the same width"
    )]
    ImageMismatch {
        /// First image's width.
        a_w: usize,
        /// First image's height.
        a_h: usize,
        /// Second image's width.
        b_w: usize,
        /// Second image's height.
        b_h: usize,
    },
    /// No shutter speeds to choose from.
    #[error("the camera offered no usable shutter speeds (all must be positive seconds)")]
    NoShutterChoices,
    /// The EXR could not be encoded.
    #[error("cannot encode the EXR image: {0}")]
    Exr(String),
    /// The EXR could not be written.
    #[error("cannot write {path}: {source}; check the folder exists and is writable")]
    Io {
        /// Destination.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
}
