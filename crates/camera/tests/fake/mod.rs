//! What the camera tests share: the rule for a missing tool, and whether the fake
//! gphoto2 (`tests/peers/fake_gphoto2.py`) can run here.

use std::process::Command;

/// Under `CI=true` a missing tool fails the test (CI installs it: a skip there would be
/// a pass that tested nothing); elsewhere the test prints a note and returns.
pub fn missing(tool: &str, remedy: &str) {
    let text = format!("{tool} is not available (to fix: {remedy})");
    assert!(
        std::env::var("CI").map_or(true, |v| v != "true"),
        "CI=true and {text}"
    );
    println!("note: test skipped: {text}; under CI=true this fails");
}

/// Whether python3 with Pillow, piexif and numpy (the fake gphoto2's needs) is here; if
/// not, [`missing`] has said so.
pub fn ready() -> bool {
    let ready = Command::new("python3")
        .args(["-c", "import PIL, piexif, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        missing(
            "python3 with Pillow, piexif and numpy (the fake gphoto2)",
            "python3 -m pip install pillow piexif numpy",
        );
    }
    ready
}
