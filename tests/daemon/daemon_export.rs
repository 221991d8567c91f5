//! `visobjd export usitt` on the looks a running daemon saved, read back by an independent
//! USITT ASCII reader written from the standard (tests/peers/usitt_ascii.py).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::Command;

use crate::common::bin;
use crate::common::daemon::{Daemon, LightLevel, Osc, float, int, string};
use visobjd_testkit::{temp_dir, tools};

/// Reads `file` with the independent reader; its cues as JSON.
fn read_back(file: &std::path::Path) -> serde_json::Value {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new("python3")
        .arg(root.join("tests/peers/usitt_ascii.py"))
        .arg(file)
        .output()
        .expect("run the USITT ASCII reader");
    assert!(
        out.status.success(),
        "the reader refused the file: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        std::fs::read_to_string(file).unwrap_or_default()
    );
    serde_json::from_slice(&out.stdout).expect("the reader's JSON")
}

/// The channel levels a cue must hold: each lit light's intensity in whole percent.
fn levels(look: &[LightLevel]) -> BTreeMap<String, f64> {
    look.iter()
        .filter(|l| (l.intensity * 100.0).round() > 0.0)
        .map(|l| (l.ch.to_string(), f64::from((l.intensity * 100.0).round())))
        .collect()
}

#[test]
fn saved_looks_become_usitt_ascii_cues_any_console_reads() {
    if !tools::python(
        "json",
        "python3 (the independent USITT ASCII reader)",
        "install python3",
    ) {
        return;
    }
    let mut d = Daemon::start("export-ascii");
    d.ok("/vo/light/1/intensity", vec![float(0.62)], "/vo/light");
    d.ok("/vo/light/3/intensity", vec![float(0.09)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(3), string("Act 2 dusk!")],
        "/vo/look/saved",
    );
    let first = d.live();
    d.ok("/vo/light/2/intensity", vec![float(1.0)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(7), string("Storm")],
        "/vo/look/saved",
    );
    let second = d.live();

    let out = temp_dir("export-ascii-out").join("show.asc");
    let run = Command::new(bin())
        .arg("export")
        .arg("usitt")
        .arg("--scene")
        .arg(d.dir.join("scene"))
        .arg("--looks")
        .arg(d.state_dir().join("looks.json"))
        .arg("--out")
        .arg(&out)
        .args(["--first", "10", "--time", "2.5"])
        .output()
        .expect("run visobjd export");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let cues = read_back(&out);
    let cues = cues.as_array().expect("a list of cues");
    assert_eq!(cues.len(), 2, "{cues:?}");
    for (cue, (number, text, look)) in cues
        .iter()
        .zip([("10", "Act 2 dusk.", &first), ("11", "Storm", &second)])
    {
        assert_eq!(cue["cue"], number, "{cue}");
        assert_eq!(cue["text"], text, "{cue}");
        assert_eq!(
            (cue["up"].as_f64(), cue["down"].as_f64()),
            (Some(2.5), Some(2.5))
        );
        let got: BTreeMap<String, f64> = cue["levels"]
            .as_object()
            .expect("levels")
            .iter()
            .map(|(ch, v)| (ch.clone(), v.as_f64().unwrap()))
            .collect();
        assert_eq!(got, levels(look), "cue {number}");
    }
    // Light 2 at full is FL, light 3 at 9 % is 9 (the format has no tens rule).
    assert_eq!(cues[1]["levels"]["2"], 100.0);
    assert_eq!(cues[0]["levels"]["3"], 9.0);

    // Nothing saved: a sentence, no file.
    let empty = temp_dir("export-ascii-empty");
    std::fs::write(empty.join("looks.json"), r#"{"looks":{}}"#).unwrap();
    let run = Command::new(bin())
        .args(["export", "usitt", "--scene"])
        .arg(d.dir.join("scene"))
        .arg("--looks")
        .arg(empty.join("looks.json"))
        .arg("--out")
        .arg(empty.join("show.asc"))
        .output()
        .expect("run visobjd export");
    assert!(!run.status.success());
    assert!(
        String::from_utf8_lossy(&run.stderr).contains("no saved looks to export"),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(!empty.join("show.asc").exists());
}
