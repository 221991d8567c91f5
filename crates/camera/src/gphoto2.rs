//! The gphoto2 camera: runs the `gphoto2` command-line tool, one process per call, with
//! only `--auto-detect`, `--get-config KEY`, `--set-config KEY=VALUE` and
//! `--capture-image-and-download --filename PATH --force-overwrite`. Its output formats are
//! gphoto2's documented ones (`docs/capture.md`, "Cameras").

use std::collections::HashMap;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use crate::run::{Finished, display, with_retry};
use crate::{
    Camera, CameraOptions, CameraSetting, Description, Error, ExposureSource, Settings, Shot,
    Shutter,
};

/// gphoto2's "Bad parameters": the camera refused a value or a key. Trying again cannot
/// help, so such a call is not retried.
const BAD_PARAMETERS: i32 = -2;

/// A camera driven through the `gphoto2` tool (any body libgphoto2 supports).
#[derive(Debug)]
pub struct Gphoto2 {
    options: CameraOptions,
    /// Settings read so far, so `set_config` and `capture` can check a value against the
    /// choices without a call. Refreshed by `config`.
    known: HashMap<String, CameraSetting>,
}

impl Gphoto2 {
    /// A driver for the first camera gphoto2 finds. Starts no process.
    pub fn new(options: CameraOptions) -> Self {
        Gphoto2 {
            options,
            known: HashMap::new(),
        }
    }

    /// Runs gphoto2 with `args` (timeout, one retry); a failure becomes a sentence that
    /// names the call and carries gphoto2's own error line.
    fn call(&self, args: &[&str]) -> Result<Finished, Error> {
        let args: Vec<OsString> = args.iter().map(OsString::from).collect();
        self.call_os(&args)
    }

    fn call_os(&self, args: &[OsString]) -> Result<Finished, Error> {
        let program = &self.options.gphoto2;
        let done = with_retry(
            program,
            args,
            &self.options.env,
            self.options.timeout,
            |done| error_code(&done.stderr) != Some(BAD_PARAMETERS),
        )?;
        if done.status.success() {
            return Ok(done);
        }
        let message = tool_message(&done.stderr, &done.stdout);
        let code = error_code(&done.stderr);
        Err(Error::Tool {
            call: display(program, args),
            hint: hint(code, &message),
            message,
            code,
        })
    }

    /// The known setting for `key`, reading it if not yet known.
    fn known(&mut self, key: &str) -> Result<CameraSetting, Error> {
        match self.known.get(key) {
            Some(setting) => Ok(setting.clone()),
            None => self.config(key),
        }
    }

    /// Checks `value` against `key`'s choices.
    fn check(&mut self, key: &str, value: &str) -> Result<(), Error> {
        let setting = self.known(key)?;
        if setting.readonly {
            return Err(Error::ReadOnly {
                key: key.to_string(),
            });
        }
        if !setting.accepts(value) {
            return Err(Error::NotAChoice {
                key: key.to_string(),
                value: value.to_string(),
                choices: setting.choices.join(", "),
            });
        }
        Ok(())
    }

    /// `config`, but `None` when the body has no such key.
    fn optional(&mut self, key: &str) -> Result<Option<CameraSetting>, Error> {
        match self.config(key) {
            Ok(setting) => Ok(Some(setting)),
            Err(Error::Tool { message, .. }) if message.contains("not found in configuration") => {
                Ok(None)
            }
            Err(Error::Tool {
                code: Some(BAD_PARAMETERS),
                ..
            }) => Ok(None),
            Err(e) => Err(e),
        }
    }
}

impl Camera for Gphoto2 {
    fn describe(&mut self) -> Result<Description, Error> {
        let done = self.call(&["--auto-detect"])?;
        let call = display(&self.options.gphoto2, &["--auto-detect".into()]);
        let cameras = parse_auto_detect(&done.stdout).map_err(|problem| Error::Parse {
            call: call.clone(),
            problem,
        })?;
        cameras.into_iter().next().ok_or(Error::NoCamera { call })
    }

    fn config(&mut self, key: &str) -> Result<CameraSetting, Error> {
        let done = self.call(&["--get-config", key])?;
        let setting = parse_config(key, &done.stdout).map_err(|problem| Error::Parse {
            call: display(&self.options.gphoto2, &["--get-config".into(), key.into()]),
            problem,
        })?;
        self.known.insert(key.to_string(), setting.clone());
        Ok(setting)
    }

    fn settings(&mut self) -> Result<Settings, Error> {
        let shutter = self.config("shutterspeed")?;
        let iso = self.optional("iso")?;
        let aperture = match self.optional("aperture")? {
            Some(a) => Some(a),
            None => self.optional("f-number")?,
        };
        let image_format = self.optional("imageformat")?;
        Ok(Settings {
            shutter,
            iso,
            aperture,
            image_format,
        })
    }

    fn set_config(&mut self, key: &str, value: &str) -> Result<(), Error> {
        self.check(key, value)?;
        self.call(&["--set-config", &format!("{key}={value}")])?;
        if let Some(setting) = self.known.get_mut(key) {
            setting.current = value.to_string();
        }
        Ok(())
    }

    fn capture(&mut self, shutter: &Shutter, out: &Path) -> Result<Shot, Error> {
        self.check("shutterspeed", shutter.text())?;
        let folder = out.parent().filter(|p| !p.as_os_str().is_empty());
        if let Some(folder) = folder {
            std::fs::create_dir_all(folder).map_err(|source| Error::Io {
                path: folder.to_path_buf(),
                source,
            })?;
        }
        // One file per image format the body is set to: gphoto2 replaces %C with each
        // file's extension.
        let pattern = out.with_extension("%C");
        let args: Vec<OsString> = vec![
            "--set-config".into(),
            format!("shutterspeed={}", shutter.text()).into(),
            "--capture-image-and-download".into(),
            "--filename".into(),
            pattern.clone().into_os_string(),
            "--force-overwrite".into(),
        ];
        let done = self.call_os(&args)?;
        if let Some(setting) = self.known.get_mut("shutterspeed") {
            setting.current = shutter.text().to_string();
        }
        let call = display(&self.options.gphoto2, &args);
        let mut paths: Vec<PathBuf> = saved_files(&done.stdout)
            .into_iter()
            .map(|p| match folder {
                Some(folder) if p.is_relative() && p.parent() == Some(Path::new("")) => {
                    folder.join(p)
                }
                _ => p,
            })
            .filter(|p| p.is_file())
            .collect();
        paths.dedup();
        if paths.is_empty() {
            return Err(Error::NoFile {
                call,
                expected: format!("at {}", pattern.display()),
            });
        }
        for path in &paths {
            if let Some(exposure) = crate::read_exposure(path)? {
                return Ok(Shot {
                    paths,
                    exposure,
                    source: ExposureSource::Exif,
                });
            }
        }
        Err(Error::Exif {
            path: paths[0].clone(),
            problem: "no file of this frame records an ExposureTime in its EXIF".to_string(),
        })
    }
}

/// Reads `gphoto2 --auto-detect`: a `Model`/`Port` header, a dashed line, then one row per
/// camera whose last word is the port. An empty list means no camera.
pub fn parse_auto_detect(stdout: &str) -> Result<Vec<Description>, String> {
    let mut lines = stdout.lines();
    if !lines.any(|l| {
        let t = l.trim();
        !t.is_empty() && t.chars().all(|c| c == '-')
    }) {
        return Err(format!(
            "no table (a `Model  Port` header and a dashed line) in {:?}",
            stdout.trim()
        ));
    }
    let mut cameras = Vec::new();
    for line in lines {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let Some((model, port)) = line.rsplit_once(char::is_whitespace) else {
            return Err(format!("a camera row without a port: {line:?}"));
        };
        cameras.push(Description {
            model: model.trim().to_string(),
            port: port.to_string(),
        });
    }
    Ok(cameras)
}

/// Reads `gphoto2 --get-config KEY`: `Label:`, `Readonly:`, `Type:`, `Current:` and
/// `Choice: N VALUE` lines up to `END`. Unknown lines (`Bottom:`, `Top:`, `Step:` of a
/// range, `Printable:`) are ignored.
pub fn parse_config(key: &str, stdout: &str) -> Result<CameraSetting, String> {
    let mut setting = CameraSetting {
        key: key.to_string(),
        label: String::new(),
        readonly: false,
        kind: String::new(),
        current: String::new(),
        choices: Vec::new(),
    };
    let (mut seen_current, mut seen_end) = (false, false);
    for line in stdout.lines() {
        let line = line.trim_end_matches('\r');
        if line.trim() == "END" {
            seen_end = true;
            break;
        }
        let Some((name, value)) = line.split_once(':') else {
            continue;
        };
        let value = value.strip_prefix(' ').unwrap_or(value);
        match name {
            "Label" => setting.label = value.to_string(),
            "Readonly" => setting.readonly = value.trim() != "0",
            "Type" => setting.kind = value.trim().to_string(),
            "Current" => {
                setting.current = value.to_string();
                seen_current = true;
            }
            "Choice" => {
                // `Choice: 3 1/60`: an index, one space, the value (which may hold spaces).
                let Some((index, choice)) = value.split_once(' ') else {
                    return Err(format!("a choice without a value: {line:?}"));
                };
                if index.parse::<u32>().is_err() {
                    return Err(format!("a choice without an index: {line:?}"));
                }
                setting.choices.push(choice.to_string());
            }
            _ => {}
        }
    }
    if !seen_current || !seen_end {
        return Err(format!(
            "expected `Current:` and `END` for {key}, got {:?}",
            stdout.trim()
        ));
    }
    Ok(setting)
}

/// The files `--capture-image-and-download` says it saved (`Saving file as PATH`).
fn saved_files(stdout: &str) -> Vec<PathBuf> {
    stdout
        .lines()
        .filter_map(|l| l.trim_end().strip_prefix("Saving file as "))
        .map(PathBuf::from)
        .collect()
}

/// gphoto2's error number from its `*** Error (-53: '...') ***` line.
fn error_code(stderr: &str) -> Option<i32> {
    stderr.lines().find_map(|l| {
        let rest = l.trim().strip_prefix("*** Error (")?;
        rest.split(':').next()?.trim().parse().ok()
    })
}

/// What gphoto2 said went wrong: its `*** Error ... ***` lines and the message under a
/// bare `*** Error ***` header (e.g. `shutterspeed not found in configuration tree.`),
/// joined; else its last line of output.
pub fn tool_message(stderr: &str, stdout: &str) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut after_header = false;
    for line in stderr.lines().map(str::trim) {
        if line.is_empty() {
            continue;
        }
        if line == "*** Error ***" {
            after_header = true;
        } else if line.starts_with("*** Error") || after_header {
            parts.push(line.to_string());
            after_header = false;
        }
    }
    if parts.is_empty() {
        // The last line of stderr, else of stdout.
        let last = stderr
            .lines()
            .rev()
            .chain(stdout.lines().rev())
            .map(str::trim)
            .find(|l| !l.is_empty());
        return match last {
            Some(line) => line.to_string(),
            None => "it exited with an error and printed nothing".to_string(),
        };
    }
    parts.join("; ")
}

/// What a person can do about a gphoto2 error.
fn hint(code: Option<i32>, message: &str) -> String {
    let hint = match code {
        Some(-53) => {
            "another program (often the desktop's gvfs-gphoto2-volume-monitor) holds the camera: close it or stop gvfs, then try again"
        }
        Some(-52) | Some(-105) => {
            "the camera is not there any more: check the USB cable and that it is switched on"
        }
        Some(-110) => "the camera is busy: give it a moment (long exposures, writing to the card)",
        Some(BAD_PARAMETERS) if message.contains("not found in configuration") => {
            "this body has no such setting: see `gphoto2 --list-config`"
        }
        Some(BAD_PARAMETERS) => {
            "the camera refused the value (is the mode dial on M? see `gphoto2 --get-config KEY` for its choices)"
        }
        _ if message.contains("No camera found") => {
            "check the USB cable and that the camera is switched on"
        }
        _ => return String::new(),
    };
    format!(": {hint}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_detect_table() {
        let out = "Model                          Port\n\
                   ----------------------------------------------------------\n\
                   Canon EOS 6D                   usb:001,007\n";
        let cams = parse_auto_detect(out).unwrap();
        assert_eq!(
            cams,
            vec![Description {
                model: "Canon EOS 6D".into(),
                port: "usb:001,007".into()
            }]
        );
        let none = "Model                          Port\n---------------------\n";
        assert_eq!(parse_auto_detect(none).unwrap(), vec![]);
        assert!(parse_auto_detect("garbage").is_err());
    }

    #[test]
    fn get_config_lines() {
        let out = "Label: Shutter Speed\nReadonly: 0\nType: RADIO\nCurrent: 1/60\n\
                   Choice: 0 30\nChoice: 1 1/60\nChoice: 2 bulb\nEND\n";
        let s = parse_config("shutterspeed", out).unwrap();
        assert_eq!(s.label, "Shutter Speed");
        assert!(!s.readonly);
        assert_eq!(s.kind, "RADIO");
        assert_eq!(s.current, "1/60");
        assert_eq!(s.choices, vec!["30", "1/60", "bulb"]);
        assert_eq!(s.shutters().len(), 2);
        let fmt = parse_config(
            "imageformat",
            "Label: Image Format\nReadonly: 0\nType: RADIO\nCurrent: RAW + Large Fine JPEG\nChoice: 0 RAW + Large Fine JPEG\nEND\n",
        )
        .unwrap();
        assert_eq!(fmt.choices, vec!["RAW + Large Fine JPEG"]);
        assert!(parse_config("iso", "Label: ISO\n").is_err());
    }

    #[test]
    fn error_lines() {
        let stderr = "\n*** Error (-53: 'Could not claim the USB device') ***       \n\n";
        assert_eq!(error_code(stderr), Some(-53));
        assert_eq!(
            tool_message(stderr, ""),
            "*** Error (-53: 'Could not claim the USB device') ***"
        );
        let ctx = "\n*** Error ***              \naperture not found in configuration tree.\n*** Error (-2: 'Bad parameters') ***\n";
        assert_eq!(
            tool_message(ctx, ""),
            "aperture not found in configuration tree.; *** Error (-2: 'Bad parameters') ***"
        );
        assert_eq!(tool_message("", "something\n"), "something");
    }

    #[test]
    fn saved_file_lines() {
        let out = "New file is in location /capt0000.jpg on the camera\n\
                   Saving file as /tmp/a b/frame.jpg\nDeleting file /capt0000.jpg on the camera\n";
        assert_eq!(saved_files(out), vec![PathBuf::from("/tmp/a b/frame.jpg")]);
    }
}
