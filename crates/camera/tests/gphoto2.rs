//! The gphoto2 camera against an independent fake `gphoto2` (`tests/peers/fake_gphoto2.py`,
//! Python with Pillow, piexif and numpy), found on the spawned process's `PATH` as the real
//! tool would be. The fake keeps its state in a JSON file and logs each call's argv, so a
//! test can tell how many processes ran.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use visobjd_camera::{Camera, CameraOptions, Error, ExposureSource, Gphoto2, Shutter};
use visobjd_testkit::tools;

/// The fake camera's folder: a `bin/gphoto2` link to the fake, its state and its log.
struct Rig {
    dir: PathBuf,
    log: PathBuf,
    options: CameraOptions,
}

impl Rig {
    /// A fresh rig for test `name` with extra fake settings `env`; `None` (after a note,
    /// or a failure under CI) when python3 with Pillow, piexif and numpy is missing.
    fn new(name: &str, env: &[(&str, &str)]) -> Option<Rig> {
        if !tools::fake_gphoto2() {
            return None;
        }
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join("camera-gphoto2")
            .join(name);
        let _ = std::fs::remove_dir_all(&dir);
        let bin = dir.join("bin");
        std::fs::create_dir_all(&bin).expect("test folder");
        let fake = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/peers/fake_gphoto2.py");
        let fake = fake
            .canonicalize()
            .expect("tests/peers/fake_gphoto2.py exists");
        std::os::unix::fs::symlink(&fake, bin.join("gphoto2")).expect("link the fake");

        let mut path = OsString::from(&bin);
        path.push(":");
        path.push(std::env::var_os("PATH").unwrap_or_default());
        let log = dir.join("calls.log");
        let mut vars: Vec<(OsString, OsString)> = vec![
            ("PATH".into(), path),
            ("FAKE_GPHOTO2_STATE".into(), dir.join("state.json").into()),
            ("FAKE_GPHOTO2_LOG".into(), log.clone().into()),
        ];
        vars.extend(env.iter().map(|(k, v)| (k.into(), v.into())));
        let options = CameraOptions {
            env: vars,
            ..CameraOptions::default()
        };
        Some(Rig { dir, log, options })
    }

    fn camera(&self) -> Gphoto2 {
        Gphoto2::new(self.options.clone())
    }

    /// The argv of every call the fake received, one line each.
    /// How many logged calls contain `needle`.
    fn count(&self, needle: &str) -> usize {
        self.calls().iter().filter(|c| c.contains(needle)).count()
    }

    fn calls(&self) -> Vec<String> {
        std::fs::read_to_string(&self.log)
            .unwrap_or_default()
            .lines()
            .map(str::to_string)
            .collect()
    }
}

fn shutter(text: &str) -> Shutter {
    Shutter::parse(text).expect("a shutter time")
}

#[test]
fn auto_detect_reads_the_model_and_port() {
    let Some(rig) = Rig::new("auto_detect", &[]) else {
        return;
    };
    let found = rig.camera().describe().expect("a camera");
    assert_eq!(found.model, "Canon EOS 6D");
    assert_eq!(found.port, "usb:001,007");
}

#[test]
fn no_camera_tells_what_to_check() {
    let Some(rig) = Rig::new("no_camera", &[("FAKE_GPHOTO2_NO_CAMERA", "1")]) else {
        return;
    };
    let err = rig.camera().describe().expect_err("no camera");
    assert!(matches!(err, Error::NoCamera { .. }), "{err:?}");
    let text = err.to_string();
    assert!(text.contains("cable") && text.contains("gvfs"), "{text}");
}

#[test]
fn get_config_reads_current_and_choices() {
    let Some(rig) = Rig::new("get_config", &[]) else {
        return;
    };
    let mut camera = rig.camera();
    let shutter = camera.config("shutterspeed").expect("shutterspeed");
    assert_eq!(shutter.label, "Shutter Speed");
    assert_eq!(shutter.kind, "RADIO");
    assert!(!shutter.readonly);
    assert_eq!(shutter.current, "1/60");
    assert_eq!(shutter.choices.first().map(String::as_str), Some("bulb"));
    assert!(shutter.choices.iter().any(|c| c == "1/4000"));
    let times = shutter.shutters();
    assert_eq!(times.len(), shutter.choices.len() - 1, "bulb is skipped");
    assert_eq!(times[0].seconds(), 30.0);

    let settings = camera.settings().expect("settings");
    assert_eq!(settings.iso.expect("iso").current, "100");
    let aperture = settings.aperture.expect("aperture");
    assert_eq!(
        (aperture.key.as_str(), aperture.current.as_str()),
        ("aperture", "8")
    );
    assert_eq!(
        settings.image_format.expect("imageformat").current,
        "Large Fine JPEG"
    );
}

#[test]
fn f_number_bodies_are_read_too() {
    let Some(rig) = Rig::new("f_number", &[("FAKE_GPHOTO2_APERTURE_KEY", "f-number")]) else {
        return;
    };
    let aperture = rig
        .camera()
        .settings()
        .expect("settings")
        .aperture
        .expect("f-number");
    assert_eq!(
        (aperture.key.as_str(), aperture.current.as_str()),
        ("f-number", "f/8")
    );
}

#[test]
fn set_config_refuses_a_value_not_among_the_choices_without_calling_gphoto2() {
    let Some(rig) = Rig::new("set_refused_here", &[]) else {
        return;
    };
    let mut camera = rig.camera();
    camera.config("iso").expect("iso");
    let before = rig.calls().len();
    let err = camera
        .set_config("iso", "123")
        .expect_err("123 is no choice");
    assert!(matches!(err, Error::NotAChoice { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("iso") && text.contains("100, 200, 400"),
        "{text}"
    );
    assert_eq!(rig.calls().len(), before, "gphoto2 was not run");

    camera.set_config("iso", "400").expect("400 is a choice");
    assert_eq!(camera.config("iso").expect("iso").current, "400");
}

#[test]
fn set_config_surfaces_gphoto2s_refusal() {
    let Some(rig) = Rig::new("set_refused_there", &[("FAKE_GPHOTO2_REFUSE", "iso=6400")]) else {
        return;
    };
    let mut camera = rig.camera();
    let err = camera
        .set_config("iso", "6400")
        .expect_err("the camera refuses");
    let Error::Tool { code, message, .. } = &err else {
        panic!("{err:?}")
    };
    assert_eq!(*code, Some(-2));
    assert!(
        message.contains("*** Error (-2: 'Bad parameters') ***"),
        "{message}"
    );
    let text = err.to_string();
    assert!(
        text.contains("--set-config iso=6400"),
        "names the call: {text}"
    );
    let sets = rig.count("iso=6400");
    assert_eq!(sets, 1, "a refused value is not retried");
}

#[test]
fn capture_returns_the_exposure_the_file_records() {
    let Some(rig) = Rig::new("capture", &[]) else {
        return;
    };
    let mut camera = rig.camera();
    let out = rig.dir.join("light-01").join("frame.jpg");
    let frame = camera.capture(&shutter("1/60"), &out).expect("a frame");
    assert_eq!(
        frame.paths,
        vec![rig.dir.join("light-01").join("frame.JPG")]
    );
    assert!(frame.paths[0].is_file());
    assert_eq!(frame.source, ExposureSource::Exif);
    // The fake's shutter gives the true third stop, 1/64 s, not the label's 1/60 s.
    assert_eq!(frame.exposure.seconds, 1.0 / 64.0);
    assert_ne!(frame.exposure.seconds, 1.0 / 60.0);
    assert_eq!(frame.exposure.iso, Some(100.0));
    assert_eq!(frame.exposure.f_number, Some(8.0));

    // An independent reader (piexif) sees the same ExposureTime.
    let read = Command::new("python3")
        .args([
            "-c",
            "import sys, piexif; print(piexif.load(sys.argv[1])['Exif'][33434])",
        ])
        .arg(&frame.paths[0])
        .output()
        .expect("python3");
    assert_eq!(String::from_utf8_lossy(&read.stdout).trim(), "(1, 64)");
    let shots = rig.count("--capture-image-and-download");
    assert_eq!(shots, 1);
}

#[test]
fn raw_plus_jpeg_returns_both_files() {
    let Some(rig) = Rig::new("raw_jpeg", &[]) else {
        return;
    };
    let mut camera = rig.camera();
    camera
        .set_config("imageformat", "RAW + Large Fine JPEG")
        .expect("RAW + JPEG");
    let frame = camera
        .capture(&shutter("0.5"), &rig.dir.join("f.jpg"))
        .expect("a frame");
    let names: Vec<_> = frame.paths.iter().filter_map(|p| p.file_name()).collect();
    assert_eq!(names, ["f.DNG", "f.JPG"]);
    assert_eq!(frame.exposure.seconds, 0.5);
}

#[test]
fn a_hang_is_killed_at_the_timeout_and_retried_once() {
    let Some(mut rig) = Rig::new("hang_once", &[("FAKE_GPHOTO2_HANG_CAPTURE", "1")]) else {
        return;
    };
    rig.options.timeout = Duration::from_secs(2);
    let frame = rig
        .camera()
        .capture(&shutter("1/125"), &rig.dir.join("f.jpg"))
        .expect("the retry succeeds");
    assert!(frame.paths[0].is_file());
    assert_eq!(frame.exposure.seconds, 1.0 / 128.0);
    let shots = rig.count("--capture-image-and-download");
    assert_eq!(shots, 2, "one try, one retry");
}

#[test]
fn a_persistent_hang_is_an_error_that_says_timed_out() {
    let Some(mut rig) = Rig::new("hang_twice", &[("FAKE_GPHOTO2_HANG_CAPTURE", "1,2")]) else {
        return;
    };
    rig.options.timeout = Duration::from_secs(2);
    let err = rig
        .camera()
        .capture(&shutter("1/125"), &rig.dir.join("f.jpg"))
        .expect_err("both tries hang");
    assert!(matches!(err, Error::TimedOut { .. }), "{err:?}");
    let text = err.to_string();
    assert!(
        text.contains("timed out") && text.contains("--capture-image-and-download"),
        "{text}"
    );
    let shots = rig.count("--capture-image-and-download");
    assert_eq!(shots, 2, "one try, one retry");
}

#[test]
fn a_passing_usb_fault_is_retried() {
    let Some(rig) = Rig::new("fail_once", &[("FAKE_GPHOTO2_FAIL_CALL", "1")]) else {
        return;
    };
    rig.camera().describe().expect("the retry succeeds");
    assert_eq!(rig.calls().len(), 2);
}

#[test]
fn a_persistent_usb_fault_names_gphoto2s_message() {
    let Some(rig) = Rig::new("fail_always", &[("FAKE_GPHOTO2_FAIL_CALL", "all")]) else {
        return;
    };
    let err = rig.camera().describe().expect_err("the camera is claimed");
    let Error::Tool { code, .. } = &err else {
        panic!("{err:?}")
    };
    assert_eq!(*code, Some(-53));
    let text = err.to_string();
    assert!(text.contains("--auto-detect"), "names the call: {text}");
    assert!(
        text.contains("-53: 'Could not claim the USB device'"),
        "{text}"
    );
    assert!(text.contains("gvfs"), "says what to do: {text}");
    assert_eq!(rig.calls().len(), 2, "one try, one retry");
}

#[test]
fn capture_refuses_a_shutter_the_camera_does_not_offer() {
    let Some(rig) = Rig::new("capture_refused", &[]) else {
        return;
    };
    let err = rig
        .camera()
        .capture(&shutter("1/7"), &rig.dir.join("f.jpg"))
        .expect_err("1/7 is no choice");
    assert!(matches!(err, Error::NotAChoice { .. }), "{err:?}");
    let shots = rig.count("--capture-image-and-download");
    assert_eq!(shots, 0);
}
