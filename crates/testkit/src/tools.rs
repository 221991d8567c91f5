//! The external tools and host features some tests need (tshark, Chromium, python-osc,
//! `unshare`, tmpfs mounts, IPv6 loopback), and what a test does without one. Outside CI it
//! skips with a note; under `CI=true` it fails, naming the tool and its remedy, because CI
//! installs every tool (`.ci/run`) and a skip there would be a pass that tested nothing.

use std::process::Command;

/// Whether this is a CI run: the `CI` environment variable is `true`.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Called by a test that cannot go on because `tool` `problem` (for example "is not
/// installed"): panics under `CI=true`, else prints a note; the test then returns.
/// `remedy` says how to get it (for example "apt-get install tshark").
pub fn missing(tool: &str, problem: &str, remedy: &str) {
    let text = format!("{tool} {problem} (to fix: {remedy})");
    assert!(!in_ci(), "CI=true and {text}");
    println!("note: test skipped: {text}; under CI=true this fails");
}

/// Whether python3 can import `modules` (comma-separated, as in an `import` line); if not,
/// [`missing`] has said so, naming `what` and `remedy` (and failed the test under CI).
pub fn python(modules: &str, what: &str, remedy: &str) -> bool {
    let ready = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        missing(what, "is not importable by python3", remedy);
    }
    ready
}

/// Whether python3 can import python-osc (an independent OSC peer); see [`python`].
pub fn python_osc() -> bool {
    python(
        "pythonosc",
        "python-osc",
        "python3 -m pip install python-osc",
    )
}

/// Whether python3 has Pillow, piexif, numpy and PiDNG (what `tests/peers/fake_gphoto2.py`
/// needs); see [`python`].
pub fn fake_gphoto2() -> bool {
    python(
        "PIL, piexif, numpy, pidng",
        "python3 with Pillow, piexif, numpy and PiDNG (the fake gphoto2)",
        "python3 -m pip install pillow piexif numpy pidng",
    )
}

/// Whether a stock Lua interpreter (`lua`) runs: the grandMA3 plugin test runs the
/// exported plugin's Lua under it with a stub of MA3's `Cmd`.
pub fn lua() -> bool {
    let ready = Command::new("lua")
        .args(["-e", "assert(load)"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        missing("lua", "is not installed", "apt-get install lua5.4");
    }
    ready
}
