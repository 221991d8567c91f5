//! The command camera (`--camera command:TEMPLATE`): any device a program can shoot with
//! (a webcam through ffmpeg or fswebcam, a vendor tool), one process per frame.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use crate::run::{display, with_retry};
use crate::{
    Camera, CameraOptions, CameraSetting, Description, Error, ExifExposure, ExposureSource,
    Settings, Shot, Shutter, shutter::decimal,
};

/// A camera that runs a command built from a template for each frame.
///
/// The template is split into words at whitespace, with no shell: no quoting, no
/// escapes, no variables, no globs, no pipes or redirections; a word cannot hold a
/// space (put such a command in a script and name the script). In each word,
/// `{exposure}` becomes the exposure in seconds as a plain decimal (`0.016666667`, `2`)
/// and `{out}` the output path. The first word is the program, looked up on `PATH`.
///
/// The frame's exposure is read from the written file's EXIF when it has one; otherwise
/// (a webcam PNG) the requested exposure is assumed and the frame says so
/// ([`ExposureSource::Assumed`]).
#[derive(Debug)]
pub struct CommandCamera {
    words: Vec<String>,
    options: CameraOptions,
}

impl CommandCamera {
    /// Checks the template: a program, and `{out}` somewhere (the frame must land where
    /// the capture command expects it). Starts no process.
    pub fn new(template: &str, options: CameraOptions) -> Result<Self, Error> {
        let words: Vec<String> = template.split_whitespace().map(str::to_string).collect();
        let spec = || format!("command:{template}");
        if words.is_empty() {
            return Err(Error::Spec {
                spec: spec(),
                problem: "no program after `command:`".to_string(),
            });
        }
        if !words.iter().any(|w| w.contains("{out}")) {
            return Err(Error::Spec {
                spec: spec(),
                problem: "the template has no {out}: the command must write the frame there"
                    .to_string(),
            });
        }
        Ok(CommandCamera { words, options })
    }

    fn unsupported(&self, what: &str) -> Error {
        Error::Unsupported(format!(
            "the command camera ({}) has no {what}: its exposure is the {{exposure}} of its template; set anything else in the command",
            self.words[0]
        ))
    }
}

impl Camera for CommandCamera {
    fn describe(&mut self) -> Result<Description, Error> {
        Ok(Description {
            model: format!("command: {}", self.words.join(" ")),
            port: String::new(),
        })
    }

    fn config(&mut self, key: &str) -> Result<CameraSetting, Error> {
        Err(self.unsupported(&format!("setting {key}")))
    }

    fn settings(&mut self) -> Result<Settings, Error> {
        Err(self.unsupported("settings"))
    }

    fn set_config(&mut self, key: &str, _value: &str) -> Result<(), Error> {
        Err(self.unsupported(&format!("setting {key}")))
    }

    fn capture(&mut self, shutter: &Shutter, out: &Path) -> Result<Shot, Error> {
        if let Some(folder) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(folder).map_err(|source| Error::Io {
                path: folder.to_path_buf(),
                source,
            })?;
        }
        let exposure = decimal(shutter.seconds());
        let out_text = out.to_string_lossy();
        let program = PathBuf::from(&self.words[0]);
        let args: Vec<OsString> = self.words[1..]
            .iter()
            .map(|w| {
                if w == "{out}" {
                    // Whole-word {out}: keep the path's bytes exactly.
                    out.as_os_str().to_os_string()
                } else {
                    w.replace("{exposure}", &exposure)
                        .replace("{out}", &out_text)
                        .into()
                }
            })
            .collect();
        // A stale file from an earlier run must not pass for this frame.
        match std::fs::remove_file(out) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => {
                return Err(Error::Io {
                    path: out.to_path_buf(),
                    source,
                });
            }
        }
        let done = with_retry(
            &program,
            &args,
            &self.options.env,
            self.options.timeout,
            |_| true,
        )?;
        let call = display(&program, &args);
        if !done.status.success() {
            let message = done
                .stderr
                .lines()
                .rev()
                .chain(done.stdout.lines().rev())
                .map(str::trim)
                .find(|l| !l.is_empty())
                .map(str::to_string)
                .unwrap_or_else(|| format!("it exited with {}", done.status));
            return Err(Error::Tool {
                call,
                message,
                code: None,
                hint: String::new(),
            });
        }
        if !out.is_file() {
            return Err(Error::NoFile {
                call,
                expected: format!("at {} (its {{out}})", out.display()),
            });
        }
        let (exposure, source) = match crate::read_exposure(out)? {
            Some(exposure) => (exposure, ExposureSource::Exif),
            None => (
                ExifExposure {
                    seconds: shutter.seconds(),
                    iso: None,
                    f_number: None,
                },
                ExposureSource::Assumed,
            ),
        };
        Ok(Shot {
            paths: vec![out.to_path_buf()],
            exposure,
            source,
        })
    }
}
