//! The command template camera: shell-free argv from a template, the exposure from the
//! written file's EXIF when it has one, else the request (and the frame says so).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use visobjd_camera::{CameraOptions, Error, ExposureSource, Shutter, open};
use visobjd_testkit::tools;

fn folder(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("camera-command")
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("test folder");
    dir
}

/// A 1×1 PNG without EXIF: what a webcam tool writes.
const PNG: &[u8] =
    b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x01\0\0\0\x01\x08\x06\0\0\0\x1f\x15\xc4\x89\
\0\0\0\nIDATx\x9cc\0\x01\0\0\x05\0\x01\r\n-\xb4\0\0\0\0IEND\xaeB`\x82";

#[test]
fn a_file_without_exif_gives_the_requested_exposure_marked_assumed() {
    let dir = folder("assumed");
    let source = dir.join("webcam.png");
    std::fs::write(&source, PNG).expect("png");
    let template = format!("command:cp {} {{out}}", source.display());
    let mut camera = open(&template, CameraOptions::default()).expect("a template");
    let out = dir.join("light-02").join("frame.png");
    let frame = camera
        .capture(&Shutter::from_seconds(0.25).expect("0.25 s"), &out)
        .expect("a frame");
    assert_eq!(frame.paths, vec![out.clone()]);
    assert!(out.is_file());
    assert_eq!(frame.source, ExposureSource::Assumed);
    assert_eq!(frame.exposure.seconds, 0.25);
    assert_eq!(frame.exposure.f_number, None);
}

#[test]
fn a_file_with_exif_gives_its_exposure_not_the_request() {
    if !tools::fake_gphoto2() {
        return;
    }
    let dir = folder("exif");
    let fake = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/peers/fake_gphoto2.py")
        .canonicalize()
        .expect("the fake");
    // The fake camera as a command: it shoots at its own shutter (1/60, really 1/64 s),
    // whatever {exposure} asks; the frame must report what the file records.
    let template = format!(
        "command:{} --capture-image-and-download --filename {{out}} --force-overwrite",
        fake.display()
    );
    let options = CameraOptions {
        env: vec![(
            OsString::from("FAKE_GPHOTO2_STATE"),
            dir.join("state.json").into_os_string(),
        )],
        ..CameraOptions::default()
    };
    let mut camera = open(&template, options).expect("a template");
    let out = dir.join("frame.jpg");
    let frame = camera
        .capture(&Shutter::from_seconds(2.0).expect("2 s"), &out)
        .expect("a frame");
    assert_eq!(frame.source, ExposureSource::Exif);
    assert_eq!(frame.exposure.seconds, 1.0 / 64.0);
    assert_eq!(frame.exposure.iso, Some(100.0));
}

#[test]
fn placeholders_fill_whole_and_partial_words_without_a_shell() {
    let dir = folder("argv");
    // `touch` gets the expanded words as they are: `$HOME` and `*` stay literal.
    let template = "command:touch {out} {out}.{exposure}s {out}.$HOME*";
    let mut camera = open(template, CameraOptions::default()).expect("a template");
    let out = dir.join("f.png");
    let frame = camera
        .capture(&Shutter::parse("1/8").expect("1/8"), &out)
        .expect("a frame");
    assert_eq!(
        frame.source,
        ExposureSource::Assumed,
        "an empty file has no EXIF"
    );
    assert!(dir.join("f.png.$HOME*").is_file(), "no shell expanded it");
    assert!(
        dir.join("f.png.0.125s").is_file(),
        "{{exposure}} as a decimal"
    );
}

#[test]
fn a_failing_command_is_a_sentence_naming_it() {
    let dir = folder("fails");
    let mut camera = open("command:false {out}", CameraOptions::default()).expect("a template");
    let err = camera
        .capture(
            &Shutter::from_seconds(1.0).expect("1 s"),
            &dir.join("f.png"),
        )
        .expect_err("false fails");
    assert!(matches!(err, Error::Tool { .. }), "{err:?}");
    assert!(err.to_string().contains("`false "), "{err}");

    let mut camera = open("command:true {out}", CameraOptions::default()).expect("a template");
    let err = camera
        .capture(
            &Shutter::from_seconds(1.0).expect("1 s"),
            &dir.join("f.png"),
        )
        .expect_err("true writes nothing");
    assert!(matches!(err, Error::NoFile { .. }), "{err:?}");
}

#[test]
fn templates_without_a_program_or_out_are_refused_and_it_has_no_settings() {
    for bad in ["command:", "command:   ", "command:cp a b", "webcam"] {
        let err = open(bad, CameraOptions::default()).err().expect("refused");
        assert!(matches!(err, Error::Spec { .. }), "{bad}: {err:?}");
    }
    let mut camera = open("command:cp a {out}", CameraOptions::default()).expect("a template");
    assert!(matches!(camera.settings(), Err(Error::Unsupported(_))));
    assert!(matches!(
        camera.set_config("iso", "100"),
        Err(Error::Unsupported(_))
    ));
    assert_eq!(
        camera.describe().expect("a description").model,
        "command: cp a {out}"
    );
}
