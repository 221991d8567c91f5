//! `visobjd import` through the real binary: a plot made around a published GDTF becomes a
//! scene `visobjd check` accepts; a re-import keeps what a person or a capture added;
//! wrong input is a one-line error naming the file and the fixture and changes nothing;
//! and the rig crate's reading of published MVR and GDTF files agrees with Python's own
//! zipfile and xml.etree reading of them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common::bin;
use visobjd_scene::profile::Slot;
use visobjd_testkit::{temp_dir, tools, write_exr};

const PAR: &str = "BlenderDMX@LED_PAR_64_RGBW@v0.3.gdtf";
const PROFILE: &str = "BlenderDMX LED PAR 64 RGBW (Default)";

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/rig")
}

fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .expect("run visobjd")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn stdout(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Asserts a clean failure: non-zero, one line on stderr containing every `needle`.
fn fails_with(out: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "should fail: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    for n in needles {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

/// One `<Fixture>` of a General Scene Description.
fn fixture(name: &str, id: &str, numeric: Option<u32>, mode: &str, address: &str) -> String {
    let numeric = numeric.map_or(String::new(), |n| {
        format!("<FixtureIDNumeric>{n}</FixtureIDNumeric>")
    });
    format!(
        r#"<Fixture name="{name}" uuid="00000000-0000-0000-0000-{id:0>12}">
  <Matrix>{{1,0,0}}{{0,1,0}}{{0,0,1}}{{0,0,0}}</Matrix>
  <GDTFSpec>{PAR}</GDTFSpec><GDTFMode>{mode}</GDTFMode>
  <Addresses><Address break="0">{address}</Address></Addresses>
  <FixtureID>{id}</FixtureID>{numeric}<UnitNumber>0</UnitNumber>
</Fixture>"#
    )
}

/// Writes an MVR: a General Scene Description with `children` in one layer, and the
/// published LED PAR GDTF its fixtures name.
fn write_mvr(path: &Path, children: &str) {
    let xml = format!(
        r#"<?xml version="1.0" encoding="UTF-8" standalone="no" ?>
<GeneralSceneDescription verMajor="1" verMinor="6">
  <Scene><Layers><Layer name="Lighting" uuid="00000000-0000-0000-0000-0000000000aa">
    <ChildList>{children}</ChildList>
  </Layer></Layers></Scene>
</GeneralSceneDescription>"#
    );
    let gdtf = std::fs::read(fixtures().join(PAR)).expect("the published GDTF");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).expect("create mvr"));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("GeneralSceneDescription.xml", opts)
        .expect("zip entry");
    zip.write_all(xml.as_bytes()).expect("zip write");
    zip.start_file(PAR, opts).expect("zip entry");
    zip.write_all(&gdtf).expect("zip write");
    zip.finish().expect("zip finish");
}

/// The plot of the first import: two fixtures in a named group, one in a group without a
/// name, one outside any group, and one not patched.
fn plot() -> String {
    format!(
        r#"<GroupObject name="Front" uuid="00000000-0000-0000-0000-0000000000b1"><ChildList>
  {}{}
</ChildList></GroupObject>
<GroupObject uuid="00000000-0000-0000-0000-0000000000b2"><ChildList>{}</ChildList></GroupObject>
{}{}"#,
        fixture("FOH 1", "1", None, "Default", "1"),
        fixture("FOH 2", "2", None, "Default", "6"),
        fixture("Back", "B7", Some(7), "Default", "2.1"),
        fixture("Spare", "10", None, "Default", "520"),
        fixture("Unpatched", "11", None, "Default", "0"),
    )
}

fn scene_toml(dir: &Path) -> toml::Table {
    let text = std::fs::read_to_string(dir.join("scene.toml")).expect("scene.toml");
    text.parse().expect("scene.toml is TOML")
}

/// The `[[light]]` with `channel`.
fn light(scene: &toml::Table, channel: i64) -> toml::Table {
    scene["light"]
        .as_array()
        .expect("lights")
        .iter()
        .filter_map(|l| l.as_table())
        .find(|l| l["channel"].as_integer() == Some(channel))
        .unwrap_or_else(|| panic!("no light {channel}"))
        .clone()
}

fn channels(scene: &toml::Table) -> Vec<i64> {
    scene["light"]
        .as_array()
        .expect("lights")
        .iter()
        .filter_map(|l| l["channel"].as_integer())
        .collect()
}

/// Writes an 8x4 EXR for every light's basis path and a config for `scene`.
fn ready_for_check(dir: &Path, scene: &Path) -> PathBuf {
    let table = scene_toml(scene);
    for l in table["light"].as_array().expect("lights") {
        let basis = scene.join(l["basis"].as_str().expect("basis"));
        std::fs::create_dir_all(basis.parent().expect("folder")).expect("mkdir");
        write_exr(&basis, 8, 4, |x, _| [x as f32 / 8.0; 3]);
    }
    let config = dir.join("visobjd.toml");
    std::fs::write(
        &config,
        format!("scene = \"{}\"\n[[output.sacn]]\n", s(scene)),
    )
    .expect("config");
    config
}

#[test]
fn an_mvr_becomes_a_scene_check_accepts() {
    let dir = temp_dir("import-mvr");
    let mvr = dir.join("plot.mvr");
    write_mvr(&mvr, &plot());
    let scene = dir.join("scene");
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    assert!(out.contains("import: 4 lights"), "{out}");
    assert!(
        out.contains("basis images to capture: channels 1-2, 7, 10"),
        "{out}"
    );
    assert!(
        out.contains("not a light: channel 11 \"Unpatched\": not patched"),
        "{out}"
    );

    let t = scene_toml(&scene);
    assert_eq!(t["name"].as_str(), Some("plot"));
    assert_eq!(channels(&t), [1, 2, 7, 10]);
    // FixtureID "B7" is not a number: FixtureIDNumeric 7 is the channel. Address "2.1" is
    // universe 2 address 1; the absolute 520 is (2 - 1) * 512 + 8.
    let back = light(&t, 7);
    assert_eq!(back["name"].as_str(), Some("Back"));
    assert_eq!(back["group"].as_str(), Some("group 1"));
    assert_eq!(
        (back["universe"].as_integer(), back["address"].as_integer()),
        (Some(2), Some(1))
    );
    let spare = light(&t, 10);
    assert_eq!(
        (
            spare["universe"].as_integer(),
            spare["address"].as_integer()
        ),
        (Some(2), Some(8))
    );
    assert!(spare.get("group").is_none());
    let foh2 = light(&t, 2);
    assert_eq!(foh2["group"].as_str(), Some("Front"));
    assert_eq!(foh2["basis"].as_str(), Some("basis/002.exr"));
    assert_eq!(foh2["profile"].as_str(), Some(PROFILE));
    // The profile from the GDTF: Dimmer, ColorAdd_R/G/B/W at offsets 1-5, and the
    // emitters' `Color="0.640100,0.330000,21.260000"` (Red) ... from its description.xml.
    let profile = t["profile"].as_array().expect("profiles")[0]
        .as_table()
        .expect("profile")
        .clone();
    assert_eq!(profile["name"].as_str(), Some(PROFILE));
    let names: Vec<&str> = profile["channels"]
        .as_array()
        .expect("channels")
        .iter()
        .filter_map(|c| c.as_str())
        .collect();
    assert_eq!(names, ["intensity", "red", "green", "blue", "white"]);
    let red = profile["emitter"].as_array().expect("emitters")[0]
        .as_table()
        .expect("emitter")
        .clone();
    assert_eq!(red["name"].as_str(), Some("red"));
    let xy: Vec<f64> = red["xy"]
        .as_array()
        .expect("xy")
        .iter()
        .filter_map(|v| v.as_float())
        .collect();
    assert_eq!(xy, [0.6401, 0.33]);
    assert_eq!(red["flux"].as_float(), Some(21.26));

    // Check wants the basis images a capture writes; with them the scene is a good one.
    let config = ready_for_check(&dir, &scene);
    let text = stdout(&run(&["check", "--config", s(&config)]));
    assert!(text.contains("4 in 3 groups, channels 1-10"), "{text}");
    assert!(text.contains(&format!("{PROFILE} x4")), "{text}");
    assert!(
        text.contains("universe 1: 10/512 slots, universe 2: 10/512 slots"),
        "{text}"
    );
}

#[test]
fn a_reimport_keeps_what_the_scene_added() {
    let dir = temp_dir("import-again");
    let mvr = dir.join("plot.mvr");
    write_mvr(&mvr, &plot());
    let scene = dir.join("scene");
    stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));

    // In visobjd: a name and exposure, light 1's capture under another name, a group
    // for the ungrouped light 10, and a practical (99) on a profile of the scene's own.
    let text = std::fs::read_to_string(scene.join("scene.toml")).expect("read");
    let text = text.replace(
        "basis = \"basis/001.exr\"",
        "basis = \"basis/foh-1-take-2.exr\"",
    );
    let text = text.replace("channel = 10\n", "channel = 10\ngroup = \"specials\"\n");
    let text = text.replace("name = \"plot\"\n", "name = \"Booth\"\nexposure = 1.5\n");
    let text = format!(
        "{text}\n[[group]]\nname = \"specials\"\n[[light]]\nchannel = 99\nname = \"Practical\"\nbasis = \"basis/practical.exr\"\nprofile = \"relay\"\nuniverse = 3\naddress = 1\n[[profile]]\nname = \"relay\"\nchannels = [\"fixed:255\", \"intensity\"]\n"
    );
    std::fs::write(scene.join("scene.toml"), text).expect("write");

    // The plot changes: FOH 1 renamed and moved, FOH 2 gone, a new fixture 12.
    let changed = format!(
        r#"<GroupObject name="Front" uuid="00000000-0000-0000-0000-0000000000b1"><ChildList>{}</ChildList></GroupObject>
<GroupObject uuid="00000000-0000-0000-0000-0000000000b2"><ChildList>{}</ChildList></GroupObject>
{}{}"#,
        fixture("FOH 1 DS", "1", None, "Default", "11"),
        fixture("Back", "B7", Some(7), "Default", "2.1"),
        fixture("Spare", "10", None, "Default", "520"),
        fixture("New", "12", None, "Default", "3.101"),
    );
    write_mvr(&mvr, &changed);
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    assert!(out.contains("import: 4 lights"), "{out}");
    assert!(out.contains("basis images to capture: channel 12"), "{out}");
    assert!(
        out.contains("kept, not in the source: channels 2, 99"),
        "{out}"
    );

    let t = scene_toml(&scene);
    assert_eq!(t["name"].as_str(), Some("Booth"));
    assert_eq!(t["exposure"].as_float(), Some(1.5));
    assert_eq!(channels(&t), [1, 2, 7, 10, 12, 99]);
    let foh1 = light(&t, 1);
    assert_eq!(foh1["name"].as_str(), Some("FOH 1 DS"));
    assert_eq!(foh1["address"].as_integer(), Some(11));
    assert_eq!(foh1["basis"].as_str(), Some("basis/foh-1-take-2.exr"));
    assert_eq!(foh1["group"].as_str(), Some("Front"));
    assert_eq!(light(&t, 10)["group"].as_str(), Some("specials"));
    assert_eq!(light(&t, 12)["basis"].as_str(), Some("basis/012.exr"));
    assert_eq!(light(&t, 99)["profile"].as_str(), Some("relay"));
    let profiles: Vec<&str> = t["profile"]
        .as_array()
        .expect("profiles")
        .iter()
        .filter_map(|p| p["name"].as_str())
        .collect();
    assert_eq!(profiles, [PROFILE, "relay"]);
    let config = ready_for_check(&dir, &scene);
    stdout(&run(&["check", "--config", s(&config)]));

    // A plot that moves a fixture onto the kept practical's slots: refused, naming both.
    let before = std::fs::read(scene.join("scene.toml")).expect("read");
    write_mvr(&mvr, &fixture("Moved", "12", None, "Default", "3.1"));
    fails_with(
        &run(&["import", s(&mvr), "--out", s(&scene)]),
        &[
            "lights 12 and 99 both use universe 3 slot 1",
            "--prune drops them",
        ],
    );
    assert_eq!(
        std::fs::read(scene.join("scene.toml")).expect("read"),
        before
    );
    write_mvr(&mvr, &changed);

    // --prune drops the lights the plot does not have, and the profile only they used.
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&scene), "--prune"]));
    assert!(
        out.contains("dropped, not in the source: channels 2, 99"),
        "{out}"
    );
    let t = scene_toml(&scene);
    assert_eq!(channels(&t), [1, 7, 10, 12]);
    assert_eq!(t["profile"].as_array().expect("profiles").len(), 1);
    assert_eq!(
        light(&t, 1)["basis"].as_str(),
        Some("basis/foh-1-take-2.exr")
    );
}

#[test]
fn an_mvr_missing_one_fixture_type_imports_the_rest_and_names_the_type_once() {
    let dir = temp_dir("import-missing-type");
    let mvr = dir.join("plot.mvr");
    let missing = (10..=13)
        .map(|c| {
            fixture(
                &format!("Wash {c}"),
                &c.to_string(),
                None,
                "Default",
                &(c * 10).to_string(),
            )
            .replace(PAR, "Acme@Wash 7.gdtf")
        })
        .collect::<String>();
    write_mvr(
        &mvr,
        &(fixture("FOH 1", "1", None, "Default", "1") + &missing),
    );
    let scene = dir.join("scene");
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    assert_eq!(channels(&scene_toml(&scene)), [1], "{out}");
    let lines: Vec<&str> = out
        .lines()
        .filter(|l| l.contains("Acme@Wash 7.gdtf"))
        .collect();
    assert_eq!(lines.len(), 1, "said once: {out}");
    assert!(
        lines[0].contains("needs a profile: Acme@Wash 7.gdtf, channels 10-13: its GDTFSpec"),
        "{out}"
    );
}

#[test]
fn an_mvr_whose_gdtf_lacks_a_mode_imports_the_rest_and_says_it_once_with_the_channels() {
    let dir = temp_dir("import-missing-mode");
    let mvr = dir.join("plot.mvr");
    let wrong = (10..=13)
        .map(|c| {
            fixture(
                &format!("Wash {c}"),
                &c.to_string(),
                None,
                "Mode 9",
                &(c * 10).to_string(),
            )
        })
        .collect::<String>();
    write_mvr(
        &mvr,
        &(fixture("FOH 1", "1", None, "Default", "1") + &wrong),
    );
    let scene = dir.join("scene");
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    assert_eq!(channels(&scene_toml(&scene)), [1], "{out}");
    let lines: Vec<&str> = out.lines().filter(|l| l.contains("Mode 9")).collect();
    assert_eq!(lines.len(), 1, "said once: {out}");
    assert!(
        lines[0].contains(&format!(
            "needs a profile: {PAR} (Mode 9), channels 10-13: its GDTF `{PAR}` has no DMX mode `Mode 9` (modes: `Default`): fix or replace the GDTF"
        )),
        "{out}"
    );
}

#[test]
fn wrong_input_is_one_line_naming_the_file_and_the_fixture_and_changes_nothing() {
    let dir = temp_dir("import-errors");
    let mvr = dir.join("plot.mvr");
    write_mvr(&mvr, &plot());
    let scene = dir.join("scene");
    stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    let before = std::fs::read(scene.join("scene.toml")).expect("scene.toml");
    let bad = dir.join("bad.mvr");
    let plot_file = s(&bad).to_string();

    // A plot none of whose fixtures becomes a light, into a new scene: the GDTF lacks the
    // mode. (Into a scene that has the light, it is kept: see the missing-mode test.)
    write_mvr(&bad, &fixture("FOH 1", "1", None, "Nope", "1"));
    let fresh = dir.join("fresh");
    fails_with(
        &run(&["import", s(&bad), "--out", s(&fresh)]),
        &[&format!(
            "{plot_file}: no fixture became a light (needs a profile: {PAR} (Nope), channel 1: its GDTF `{PAR}` has no DMX mode `Nope` (modes: `Default`): fix or replace the GDTF in the MVR, or give the type a profile)"
        )],
    );
    assert!(!fresh.exists(), "nothing written");

    let cases: Vec<(String, Vec<String>)> = vec![
        (
            fixture("FOH 1", "1", None, "Default", "1")
                + &fixture("FOH 2", "2", None, "Default", "3"),
            vec![format!(
                "{plot_file}: channel 2 \"FOH 2\": universe 1 slot 3 is also used by channel 1 \"FOH 1\""
            )],
        ),
        (
            fixture("FOH 1", "1", None, "Default", "1")
                + &fixture("FOH 1 again", "1", None, "Default", "100"),
            vec![format!(
                "{plot_file}: channel 1 \"FOH 1 again\": channel 1 is also \"FOH 1\""
            )],
        ),
        (
            fixture("FOH 1", "1", None, "Default", "9.999"),
            vec!["channel 1 \"FOH 1\": Address `9.999` is neither".to_string()],
        ),
    ];
    for (children, needles) in cases {
        write_mvr(&bad, &children);
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        fails_with(&run(&["import", s(&bad), "--out", s(&scene)]), &needles);
        assert_eq!(
            std::fs::read(scene.join("scene.toml")).expect("read"),
            before
        );
    }

    // A GDTF inside the plot that is not a zip.
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&bad).expect("create"));
    let opts = zip::write::SimpleFileOptions::default();
    zip.start_file("GeneralSceneDescription.xml", opts)
        .expect("entry");
    zip.write_all(
        format!(
            r#"<GeneralSceneDescription verMajor="1" verMinor="6"><Scene><Layers><Layer name="L"><ChildList>{}</ChildList></Layer></Layers></Scene></GeneralSceneDescription>"#,
            fixture("FOH 1", "1", None, "Default", "1")
        )
        .as_bytes(),
    )
    .expect("write");
    zip.start_file(PAR, opts).expect("entry");
    zip.write_all(b"not a zip").expect("write");
    zip.finish().expect("finish");
    fails_with(
        &run(&["import", s(&bad), "--out", s(&fresh)]),
        &[&format!(
            "{plot_file}: no fixture became a light (needs a profile: {PAR} (Default), channel 1: its GDTF {PAR}: not a readable zip"
        )],
    );
    assert!(!fresh.exists(), "nothing written");

    // A broken zip (the plot cut short), and the real but truncated GDTF.
    let good = std::fs::read(&mvr).expect("mvr");
    std::fs::write(&bad, &good[..good.len() / 2]).expect("write");
    fails_with(
        &run(&["import", s(&bad), "--out", s(&scene)]),
        &[&format!("{plot_file}: not a readable zip")],
    );
    let gdtf = std::fs::read(fixtures().join(PAR)).expect("gdtf");
    let cut = dir.join("cut.gdtf");
    std::fs::write(&cut, &gdtf[..gdtf.len() - 100]).expect("write");
    fails_with(
        &run(&["import", s(&cut)]),
        &["cut.gdtf: not a readable zip"],
    );
    assert_eq!(
        std::fs::read(scene.join("scene.toml")).expect("read"),
        before
    );

    // An Eos CSV export without the patch.
    let csv = dir.join("patch.csv");
    std::fs::write(&csv, "START_TARGETS\n1,Cue\nEND_TARGETS\n").expect("write");
    fails_with(
        &run(&["import", s(&csv), "--out", s(&scene)]),
        &["patch.csv", "no START_CHANNELS block"],
    );
    assert_eq!(
        std::fs::read(scene.join("scene.toml")).expect("read"),
        before
    );

    // The published Capture show: its fixture types are stubs with no dimmer, so nothing
    // can be a light; the error lists what needs a profile.
    let capture = fixtures().join("capture_demo_show.mvr");
    fails_with(
        &run(&["import", s(&capture), "--out", s(&dir.join("capture"))]),
        &[
            "no fixture became a light",
            "needs a profile: Robe Robin MMX Spot (1) (38 channels), channels 29-52",
        ],
    );
    assert!(!dir.join("capture/scene.toml").exists());
}

#[test]
fn a_fixture_type_lists_its_modes_and_adds_them_to_a_scene() {
    let dir = temp_dir("import-types");
    let mvr = dir.join("plot.mvr");
    write_mvr(&mvr, &plot());
    let scene = dir.join("scene");
    stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    let lustr = fixtures().join("etc-source-four-led-series-2-lustr.json");
    let out = stdout(&run(&["import", s(&lustr)]));
    assert!(out.contains("profile \"Source Four LED Series 2 Lustr (Direct)\": 10 slots: red, lime, amber, green, emitter:cyan, blue, emitter:indigo, intensity, fixed:0, fixed:0"), "{out}");
    assert!(out.contains("needs a profile: Source Four LED Series 2 Lustr (RGB Plus 7) (15 channels): emitter `red` is used by two slots"), "{out}");
    let out = stdout(&run(&["import", s(&lustr), "--out", s(&scene)]));
    assert!(out.contains("import: 7 profiles"), "{out}");
    let t = scene_toml(&scene);
    assert_eq!(t["profile"].as_array().expect("profiles").len(), 8);
    let config = ready_for_check(&dir, &scene);
    stdout(&run(&["check", "--config", s(&config)]));
    // Without a scene there is nothing to add them to.
    fails_with(
        &run(&["import", s(&lustr), "--out", s(&dir.join("none"))]),
        &["no scene.toml to add"],
    );
}

/// A published moving head (the Stairville MH-100 from the Open Fixture Library) is listed
/// with its pan and tilt slots and travel, and its profiles go into scene.toml with the
/// travel as `pan_range` and `tilt_range` (its `angleEnd`s, 630 and 220 degrees).
#[test]
fn a_moving_head_type_keeps_its_pan_and_tilt_travel() {
    let dir = temp_dir("import-mover");
    let mvr = dir.join("plot.mvr");
    write_mvr(&mvr, &plot());
    let scene = dir.join("scene");
    stdout(&run(&["import", s(&mvr), "--out", s(&scene)]));
    let mover = fixtures().join("stairville-mh-100.json");
    let out = stdout(&run(&["import", s(&mover)]));
    assert!(
        out.contains("profile \"MH-100 (9-Channel)\": 9 slots: pan, tilt, fixed:0, intensity, red, green, blue, white, fixed:0; pan 630 and tilt 220 degrees of travel"),
        "{out}"
    );
    assert!(
        out.contains(
            "profile \"MH-100 (14-Channel)\": 14 slots: pan16, tilt16, fixed:0, intensity,"
        ),
        "{out}"
    );
    stdout(&run(&["import", s(&mover), "--out", s(&scene)]));
    let t = scene_toml(&scene);
    let profiles = t["profile"].as_array().expect("profiles");
    let wide = profiles
        .iter()
        .find(|p| p["name"].as_str() == Some("MH-100 (14-Channel)"))
        .expect("the 14-channel mode");
    assert_eq!(wide["pan_range"].as_float(), Some(630.0));
    assert_eq!(wide["tilt_range"].as_float(), Some(220.0));
    let par = profiles
        .iter()
        .find(|p| p["name"].as_str() == Some(PROFILE))
        .expect("the PAR");
    assert!(par.get("pan_range").is_none(), "a PAR has no travel");
    let config = ready_for_check(&dir, &scene);
    stdout(&run(&["check", "--config", s(&config)]));
    std::fs::remove_dir_all(&dir).ok();
}

/// Python's zipfile and xml.etree, not our code, read every fixture of the published
/// Capture show (`FixtureID`, the break-0 `Address` as universe and address) and every
/// mode of the published iSpiiderX GDTF (footprint = its highest `Offset`; the emitters'
/// `Color`); the rig crate must read the same.
#[test]
fn the_rig_crate_reads_what_python_reads() {
    if !tools::python(
        "zipfile, xml.etree.ElementTree",
        "python3",
        "apt-get install python3",
    ) {
        return;
    }
    let script = r#"
import sys, zipfile, xml.etree.ElementTree as ET
kind, path = sys.argv[1], sys.argv[2]
z = zipfile.ZipFile(path)
if kind == "mvr":
    root = ET.fromstring(z.read("GeneralSceneDescription.xml"))
    for f in root.iter("Fixture"):
        a = min(f.iter("Address"), key=lambda a: int(a.get("break", "0")))
        n = int(a.text)
        print(f.findtext("FixtureID").strip(), (n - 1) // 512 + 1, (n - 1) % 512 + 1)
else:
    ft = ET.fromstring(z.read("description.xml")).find("FixtureType")
    for m in ft.iter("DMXMode"):
        offs = [int(o) for c in m.iter("DMXChannel") for o in (c.get("Offset") or "").split(",") if o.strip() not in ("", "None")]
        print("mode", m.get("Name"), max(offs))
    for e in ft.iter("Emitter"):
        print("emitter", e.get("Name"), e.get("Color"))
"#;
    let python = |kind: &str, path: &Path| {
        let out = Command::new("python3")
            .args(["-c", script, kind, s(path)])
            .output()
            .expect("python3");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };

    let path = fixtures().join("capture_demo_show.mvr");
    let bytes = std::fs::read(&path).expect("mvr");
    let rig = visobjd_rig::mvr::parse("capture_demo_show.mvr", &bytes).expect("parses");
    let ours: String = rig
        .fixtures
        .iter()
        .map(|f| format!("{} {} {}\n", f.channel, f.universe, f.address))
        .collect();
    let theirs = python("mvr", &path);
    assert_eq!(theirs.lines().count(), 76);
    assert_eq!(ours, theirs);

    let path = fixtures().join("Robe@Robin_iSpiiderX@python-gdtf-test1.gdtf");
    let bytes = std::fs::read(&path).expect("gdtf");
    let ty = visobjd_rig::gdtf::GdtfType::parse("iSpiiderX", &bytes).expect("parses");
    let mut ours: String = ty
        .modes
        .iter()
        .map(|m| format!("mode {} {}\n", m.name, m.footprint()))
        .collect();
    for e in &ty.emitters {
        let [x, y, big_y] = e.color.expect("colour");
        ours += &format!("emitter {} {x:.6},{y:.6},{big_y:.6}\n", e.name);
    }
    assert_eq!(ours, python("gdtf", &path));
}

/// The demo's `scene.toml` is generated from its MVR (`scenes/demo/demo.mvr`, with a GDTF
/// type per fixture) by `visobjd import`: importing the shipped MVR into a copy of the
/// shipped scene gives the same bytes (so the two cannot drift), and into an empty folder
/// the same scene but for its name and the movers' positions (so it is the MVR, not the
/// kept scene, that decides everything else). The positions come from `visobjd synth`,
/// not the MVR: a fresh import gives each of the six movers a `basis/NNN.exr` instead of
/// its five `[[light.position]]` tables, and nothing else differs.
#[test]
fn the_demo_scene_is_imported_from_its_mvr() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let demo = root.join("scenes/demo");
    let shipped = std::fs::read_to_string(demo.join("scene.toml")).expect("scene.toml");
    let dir = temp_dir("import-demo-shipped");
    let again = dir.join("again");
    std::fs::create_dir_all(&again).expect("mkdir");
    std::fs::write(again.join("scene.toml"), &shipped).expect("copy scene.toml");
    let mvr = demo.join("demo.mvr");
    let out = stdout(&run(&["import", s(&mvr), "--out", s(&again)]));
    assert!(
        out.contains("import: 50 lights") && out.contains("(0 new)"),
        "{out}"
    );
    let got = std::fs::read_to_string(again.join("scene.toml")).expect("imported");
    assert!(
        got == shipped,
        "scenes/demo/scene.toml is not what `visobjd import scenes/demo/demo.mvr --out scenes/demo` writes:\n{got}"
    );
    let fresh = dir.join("fresh");
    stdout(&run(&["import", s(&mvr), "--out", s(&fresh)]));
    let got = std::fs::read_to_string(fresh.join("scene.toml")).expect("imported");
    let parse = |name: &str, text: &str| {
        visobjd_scene::SceneFile::parse(Path::new(name), text).expect("scene.toml parses")
    };
    let (mut want, got) = (parse("shipped", &shipped), parse("fresh", &got));
    let movers: Vec<u32> = want
        .light
        .iter()
        .filter(|l| !l.positions.is_empty())
        .map(|l| l.channel)
        .collect();
    assert_eq!(movers, [45, 46, 47, 48, 49, 50]);
    // The movers' type as the MVR's visobjd@mover.gdtf has it: Dimmer at offset 1, Pan at
    // "2,3" from -270 to 270, Tilt at "4,5" from -125 to 125, ColorAdd_R, _G, _B, _W.
    let mover = got
        .profile
        .iter()
        .find(|p| p.name == "visobjd mover (Default)")
        .expect("the movers' profile");
    assert_eq!(
        mover.channels,
        [
            "intensity",
            "pan16",
            "tilt16",
            "red",
            "green",
            "blue",
            "white"
        ]
    );
    assert_eq!((mover.pan_range, mover.tilt_range), (None, Some(250.0)));
    for l in want.light.iter_mut().filter(|l| !l.positions.is_empty()) {
        assert_eq!(l.positions.len(), 5, "light {}", l.channel);
        assert_eq!(l.basis, None, "light {}", l.channel);
        l.positions.clear();
        l.basis = Some(format!("basis/{:03}.exr", l.channel));
    }
    want.name = got.name.clone();
    assert_eq!(got.to_toml(), want.to_toml());
    std::fs::remove_dir_all(&dir).ok();
}

/// The demo's patch exported as an MVR by the independent exporter
/// `tests/peers/export_mvr.py` imports back as the same patch: every light's channel,
/// name, group, universe, address and profile slots, emitters and pan and tilt travel
/// (the movers' GDTF `PhysicalFrom`/`PhysicalTo`), and the same DMX bytes for the same
/// looks.
#[test]
fn the_demo_rig_round_trips_through_mvr() {
    use visobjd_scene::Scene;
    use visobjd_scene::look::{Level, Look};

    if !tools::python(
        "tomllib, zipfile",
        "python3 (3.11 or later)",
        "apt-get install python3",
    ) {
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let demo = root.join("scenes/demo");
    let dir = temp_dir("import-demo");
    let exported = dir.join("demo.mvr");
    let out = Command::new("python3")
        .arg(root.join("tests/peers/export_mvr.py"))
        .args([s(&demo.join("scene.toml")), s(&exported)])
        .output()
        .expect("python3");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let scene_dir = dir.join("scene");
    let out = stdout(&run(&["import", s(&exported), "--out", s(&scene_dir)]));
    assert!(out.contains("import: 50 lights"), "{out}");
    let original = Scene::load(&demo).expect("demo scene");
    let imported = Scene::load(&scene_dir).expect("imported scene");
    assert_eq!(original.lights.len(), imported.lights.len());
    for (i, (a, b)) in original.lights.iter().zip(&imported.lights).enumerate() {
        assert_eq!(
            (a.channel, &a.name, a.universe, a.address),
            (b.channel, &b.name, b.universe, b.address)
        );
        assert_eq!(original.groups[a.group].name, imported.groups[b.group].name);
        let (pa, pb) = (original.profile(i), imported.profile(i));
        assert_eq!(
            (&pa.slots, &pa.emitters, pa.pan_range, pa.tilt_range),
            (&pb.slots, &pb.emitters, pb.pan_range, pb.tilt_range),
            "light {}",
            a.channel
        );
        assert_eq!(pb.name, format!("visobjd {} (Default)", pa.name));
    }
    let (pa, pb) = (
        visobjd_dmx::Patch::new(&original),
        visobjd_dmx::Patch::new(&imported),
    );
    assert_eq!(pa.universes(), pb.universes());
    for k in 0..4 {
        let look = Look {
            levels: (0..original.lights.len())
                .map(|i| Level {
                    intensity: ((i + k) % 5) as f32 / 4.0,
                    color: [1.0, ((i * 3 + k) % 7) as f32 / 6.0, (k % 2) as f32],
                    position: None,
                })
                .collect(),
        };
        // Every slot the same but a mover's pan and tilt: its positions come from synth,
        // not from the MVR, so the import holds it at centre.
        let slots = |p: &visobjd_dmx::Patch| -> Vec<Vec<(Slot, f32)>> {
            p.light_slots(&p.levels(&look, 1.0))
                .into_iter()
                .map(|l| l.into_iter().filter(|(s, _)| !s.is_position()).collect())
                .collect()
        };
        assert_eq!(slots(&pa), slots(&pb));
        assert_eq!(pa.universes(), pb.universes());
    }
    let movers = original.lights.iter().filter(|l| l.is_moving()).count();
    assert!(movers >= 6, "the demo's movers: {movers}");
}

// ---- Eos: a CSV patch export, and the console live over OSC TCP ----

/// The Eos patch export the console tests serve and import (tests/fixtures/rig/README.md).
const EOS_CSV: &str = "eos-patch.csv";

/// The fake Eos console (`tests/peers/fake_eos.py`) serving an export's patch on a
/// loopback port; killed when dropped.
struct FakeEos {
    child: std::process::Child,
    port: u16,
}

impl FakeEos {
    /// Starts it with `args`; `None` (after [`tools::missing`]) without python-osc.
    fn start(args: &[&str]) -> Option<FakeEos> {
        FakeEos::serve(&fixtures().join(EOS_CSV), args)
    }

    /// Starts it serving the patch of the export `csv`.
    fn serve(csv: &Path, args: &[&str]) -> Option<FakeEos> {
        if !tools::python_osc() {
            return None;
        }
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let mut command = Command::new("python3");
        command
            .arg(root.join("tests/peers/fake_eos.py"))
            .arg("--csv")
            .arg(csv)
            .args(args);
        let (child, port) = crate::common::start_peer(command, "the fake Eos console");
        Some(FakeEos { child, port })
    }

    fn url(&self, scheme: &str) -> String {
        format!("{scheme}://127.0.0.1:{}", self.port)
    }
}

impl Drop for FakeEos {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn an_eos_console_and_its_csv_export_build_the_same_scene() {
    let Some(console) = FakeEos::start(&[]) else {
        return;
    };
    let Some(slip) = FakeEos::start(&["--slip"]) else {
        return;
    };
    let dir = temp_dir("import-eos-same");
    let lib = fixtures();
    let (from_csv, from_tcp, from_slip) = (dir.join("csv"), dir.join("tcp"), dir.join("slip"));
    let csv_out = stdout(&run(&[
        "import",
        s(&lib.join(EOS_CSV)),
        "--out",
        s(&from_csv),
        "--fixtures",
        s(&lib),
    ]));
    let [tcp_out, slip_out] = [
        (console.url("eos"), &from_tcp),
        (slip.url("eos+slip"), &from_slip),
    ]
    .map(|(url, out)| {
        stdout(&run(&[
            "import",
            &url,
            "--out",
            s(out),
            "--fixtures",
            s(&lib),
        ]))
    });
    let csv = scene_toml(&from_csv);
    assert_eq!(csv["name"].as_str(), Some("eos-patch"));
    assert_eq!(
        scene_toml(&from_tcp)["name"].as_str(),
        Some("eos 127.0.0.1")
    );
    // Everything but the name is the same, whichever way the patch came.
    let strip = |dir: &Path| {
        let mut t = scene_toml(dir);
        t.remove("name");
        t
    };
    assert_eq!(strip(&from_tcp), strip(&from_csv));
    assert_eq!(strip(&from_slip), strip(&from_csv));
    // And it is the patch the export holds (read by hand from tests/fixtures/rig/eos-patch.csv).
    assert_eq!(channels(&csv), [1, 2, 11, 12, 21, 22, 31]);
    let l = light(&csv, 22);
    assert_eq!(l["name"].as_str(), Some("Cyc 2, right"));
    assert_eq!(
        l["profile"].as_str(),
        Some("ColorSource PAR Deep Blue (Direct)")
    );
    assert_eq!(
        (l["universe"].as_integer(), l["address"].as_integer()),
        (Some(2), Some(7))
    );
    assert_eq!(light(&csv, 12)["profile"].as_str(), Some(PROFILE));
    assert_eq!(light(&csv, 12)["address"].as_integer(), Some(16));
    assert_eq!(
        light(&csv, 31)["profile"].as_str(),
        Some("ROOT PAR 6 (8-channel)")
    );
    assert_eq!(light(&csv, 2)["profile"].as_str(), Some("dimmer"));
    for out in [&csv_out, &tcp_out, &slip_out] {
        assert!(
            out.contains(
                "needs a profile: JB_Lighting P18_Profile_Mk2_HP_M1 (42 channels), channels 41-42"
            ),
            "{out}"
        );
        assert!(
            out.contains("needs a profile: Custom HMI_Zündung_ARRI (1 channel), channel 51"),
            "{out}"
        );
        assert!(
            out.contains("channel 51 \"\" (Custom Farbwechsler_HMI,_MagVader_300,_Gera): part 2"),
            "{out}"
        );
        assert!(
            out.contains("channel 60 \"Spare\" (Generic Dimmer): not patched"),
            "{out}"
        );
    }
}

#[test]
fn an_eos_consoles_groups_become_the_scenes_groups() {
    let Some(console) = FakeEos::start(&["--group", "Front=1-2", "--group", "Cyc=21,22,1"]) else {
        return;
    };
    let dir = temp_dir("import-eos-groups");
    let out = dir.join("scene");
    stdout(&import_eos(&console, &out, &[]));
    let scene = scene_toml(&out);
    // Channel 1 is in both: the first group holding it wins.
    assert_eq!(light(&scene, 1)["group"].as_str(), Some("Front"));
    assert_eq!(light(&scene, 22)["group"].as_str(), Some("Cyc"));
    assert!(light(&scene, 11).get("group").is_none());
}

/// `visobjd import` from the fake console into `out` with the test fixtures, and `extra`
/// arguments.
fn import_eos(console: &FakeEos, out: &Path, extra: &[&str]) -> Output {
    let url = console.url("eos");
    let mut args = vec!["import", &url, "--out", s(out), "--fixtures"];
    let fixtures = fixtures();
    args.push(s(&fixtures));
    args.extend_from_slice(extra);
    run(&args)
}

/// The focus palettes the palette tests' console holds (`--fp`): two whole ones on the
/// spots (channels 41 and 42), and a decimal one.
const FOCUS_PALETTES: [&str; 6] = [
    "--fp",
    "3=DS centre=41-42",
    "--fp",
    "5=US wide=41",
    "--fp",
    "2.5=Half=42",
];

#[test]
fn an_eos_consoles_focus_palettes_are_listed_and_name_the_scenes_positions() {
    let Some(first) = FakeEos::start(&FOCUS_PALETTES) else {
        return;
    };
    let dir = temp_dir("import-eos-palettes");
    let out = dir.join("scene");
    let import = |console: &FakeEos| stdout(&import_eos(console, &out, &[]));
    let printed = import(&first);
    for want in [
        "focus palette 3 \"DS centre\": channels 41-42",
        "focus palette 5 \"US wide\": channel 41",
        "focus palette 2.5 \"Half\": channel 42 (not a whole number",
    ] {
        assert!(printed.contains(want), "{want}: {printed}");
    }
    // The spots need a profile: the scene gets them by hand, as movers with positions,
    // one the console has (3, under another name) and one it does not (7).
    let toml = out.join("scene.toml");
    let mut text = std::fs::read_to_string(&toml).expect("scene.toml");
    text += "\n[[profile]]\nname = \"p18\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n";
    for (ch, address) in [(41, 1), (42, 43)] {
        text += &format!(
            "\n[[light]]\nchannel = {ch}\nprofile = \"p18\"\nuniverse = 3\naddress = {address}\n\
             [[light.position]]\npalette = 3\nname = \"old\"\npan = -10.5\ntilt = 20\n\
             basis = \"basis/{ch:03}-fp3.exr\"\n\
             [[light.position]]\npalette = 7\nname = \"mine\"\npan = 1\ntilt = 2\n\
             basis = \"basis/{ch:03}-fp7.exr\"\n"
        );
    }
    std::fs::write(&toml, text).expect("scene.toml");
    let Some(second) = FakeEos::start(&FOCUS_PALETTES) else {
        return;
    };
    let printed = import(&second);
    assert!(
        printed.contains("positions named after the console's palettes: channels 41-42"),
        "{printed}"
    );
    let scene = scene_toml(&out);
    for ch in [41, 42] {
        let positions = light(&scene, ch)["position"]
            .as_array()
            .expect("the positions are kept")
            .clone();
        let p = |k: usize, key: &str| positions[k][key].clone();
        assert_eq!(p(0, "name").as_str(), Some("DS centre"));
        // Pan, tilt and basis stay; palette 7 is not the console's and keeps its name.
        assert_eq!(p(0, "pan").as_float(), Some(-10.5));
        assert_eq!(p(0, "tilt").as_float(), Some(20.0));
        assert_eq!(
            p(0, "basis").as_str(),
            Some(format!("basis/{ch:03}-fp3.exr").as_str())
        );
        assert_eq!(p(1, "name").as_str(), Some("mine"));
    }
}

#[test]
fn a_console_that_does_not_answer_about_palettes_still_gives_its_patch() {
    let Some(console) = FakeEos::start(&["--fp", "3=DS centre=41", "--fp-silent"]) else {
        return;
    };
    let dir = temp_dir("import-eos-palettes-silent");
    let out = dir.join("scene");
    let printed = stdout(&import_eos(&console, &out, &["--timeout", "0.5"]));
    assert!(
        printed.contains(
            "focus palettes not read: Eos did not answer within 0.5 s while reading the focus \
             palette count (the patch is imported without them)"
        ),
        "{printed}"
    );
    assert_eq!(channels(&scene_toml(&out)), [1, 2, 11, 12, 21, 22, 31]);
}

#[test]
fn a_console_that_stops_answering_is_an_error_that_writes_nothing() {
    let Some(console) = FakeEos::start(&["--hang-after", "3"]) else {
        return;
    };
    let dir = temp_dir("import-eos-hang");
    let out = dir.join("scene");
    let r = import_eos(&console, &out, &["--timeout", "1"]);
    fails_with(
        &r,
        &[
            &console.url("eos"),
            "stopped answering",
            "the patch (3 of 12 entries in)",
        ],
    );
    assert!(!out.exists(), "nothing is written");
    // Nobody listening at all.
    let free = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = free.local_addr().expect("its port").port();
    drop(free);
    let url = format!("eos://127.0.0.1:{port}");
    fails_with(
        &run(&["import", &url, "--out", s(&out), "--timeout", "1"]),
        &[&url, "cannot connect"],
    );
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn eos_csv_errors_name_the_line_and_types_resolve_only_through_fixtures() {
    let dir = temp_dir("import-eos-csv");
    let text = std::fs::read_to_string(fixtures().join(EOS_CSV)).expect("the export");
    // Line 7 is channel 21; its address loses the `<`.
    let broken = text.replacen(" 2/1<6,", " 2/1x6,", 1);
    assert_ne!(broken, text);
    let csv = dir.join("broken.csv");
    std::fs::write(&csv, broken).expect("write");
    let out = dir.join("scene");
    fails_with(
        &run(&[
            "import",
            s(&csv),
            "--out",
            s(&out),
            "--fixtures",
            s(&fixtures()),
        ]),
        &["broken.csv: line 7: channel 21: ADDRESS `2/1x6`"],
    );
    assert!(!out.exists(), "nothing is written");
    // Without --fixtures only Eos's own dimmers are lights; every other type is listed.
    let printed = stdout(&run(&[
        "import",
        s(&fixtures().join(EOS_CSV)),
        "--out",
        s(&out),
    ]));
    assert_eq!(channels(&scene_toml(&out)), [1, 2]);
    for t in [
        "BlenderDMX LED_PAR_64_RGBW (5 channels), channels 11-12",
        "ETC ColorSource_PAR_Deep_Blue_Direct (6 channels), channels 21-22",
        "Cameo ROOT_PAR_6_8-channel (8 channels), channel 31",
    ] {
        assert!(
            printed.contains(&format!("needs a profile: {t}")),
            "{t}: {printed}"
        );
    }
    // A library is for sources that only name their types.
    fails_with(
        &run(&[
            "import",
            s(&fixtures().join(PAR)),
            "--fixtures",
            s(&fixtures()),
        ]),
        &["--fixtures", "only name fixture types"],
    );
}

#[test]
fn a_large_console_patch_comes_through_whole() {
    // 300 dimmers on two universes, more than visobjd asks for at once.
    let dir = temp_dir("import-eos-large");
    let mut csv = String::from("START_CHANNELS\nCHANNEL,FIXTURE_TYPE,MANUFACTURER,ADDRESS,LABEL\n");
    for c in 1..=300u32 {
        csv += &format!(
            "{c},Dimmer,Generic, {}/{},D{c}\n",
            1 + (c - 1) / 200,
            1 + (c - 1) % 200
        );
    }
    csv += "END_CHANNELS\n";
    let path = dir.join("large.csv");
    std::fs::write(&path, csv).expect("write");
    let Some(console) = FakeEos::serve(&path, &[]) else {
        return;
    };
    let (a, b) = (dir.join("tcp"), dir.join("csv"));
    stdout(&run(&["import", &console.url("eos"), "--out", s(&a)]));
    stdout(&run(&["import", s(&path), "--out", s(&b)]));
    let scene = scene_toml(&a);
    assert_eq!(channels(&scene), (1..=300).collect::<Vec<i64>>());
    let l = light(&scene, 250);
    assert_eq!(
        (l["universe"].as_integer(), l["address"].as_integer()),
        (Some(2), Some(50))
    );
    let strip = |dir: &Path| {
        let mut t = scene_toml(dir);
        t.remove("name");
        t
    };
    assert_eq!(strip(&a), strip(&b));
}

// ---- hostile sizes: each a sentence naming the file and the limit, in bounded time ----

/// Runs `import` with `args`, which must fail within `within` with one line holding every
/// `needle`, writing nothing to `out`.
fn refused_within(args: &[&str], out: &Path, within: Duration, needles: &[&str]) {
    let started = Instant::now();
    fails_with(&run(args), needles);
    assert!(
        started.elapsed() < within,
        "refused at once: {:?}",
        started.elapsed()
    );
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn an_mvr_nested_too_deep_is_refused_without_overflowing_the_stack() {
    let dir = temp_dir("import-mvr-deep");
    let (open, close) = (
        r#"<GroupObject name="g" uuid="00000000-0000-0000-0000-0000000000b1"><ChildList>"#,
        "</ChildList></GroupObject>",
    );
    let levels = 10_000;
    let children = format!(
        "{}{}{}",
        open.repeat(levels),
        fixture("Deep", "1", None, "Default", "1"),
        close.repeat(levels)
    );
    let mvr = dir.join("deep.mvr");
    write_mvr(&mvr, &children);
    let out = dir.join("scene");
    refused_within(
        &["import", s(&mvr), "--out", s(&out)],
        &out,
        Duration::from_secs(30),
        &[
            "deep.mvr: GeneralSceneDescription.xml",
            "elements nested more than 64 deep",
        ],
    );
}

#[test]
fn an_eos_csv_with_too_many_rows_is_refused_while_it_is_read() {
    let dir = temp_dir("import-eos-rows");
    let mut csv = String::from("START_CHANNELS\nCHANNEL,FIXTURE_TYPE,MANUFACTURER,ADDRESS,LABEL\n");
    for c in 1..=1_000_000u32 {
        csv += &format!("{c},Dimmer,Generic,,\n");
    }
    csv += "END_CHANNELS\n";
    let path = dir.join("huge.csv");
    std::fs::write(&path, csv).expect("write");
    let out = dir.join("scene");
    refused_within(
        &["import", s(&path), "--out", s(&out)],
        &out,
        Duration::from_secs(30),
        &["huge.csv: line 100003", "more than 100000 channel parts"],
    );
}

#[test]
fn a_fixture_folder_with_a_symlink_loop_is_walked_once() {
    let dir = temp_dir("import-fixtures-loop");
    let lib = dir.join("lib");
    std::fs::create_dir_all(lib.join("a/b")).expect("mkdir");
    std::fs::copy(fixtures().join(PAR), lib.join("a/b").join(PAR)).expect("copy the GDTF");
    std::os::unix::fs::symlink("../..", lib.join("a/b/up")).expect("a loop");
    std::os::unix::fs::symlink(&lib, lib.join("a/again")).expect("another");
    let out = dir.join("scene");
    let started = Instant::now();
    let printed = stdout(&run(&[
        "import",
        s(&fixtures().join(EOS_CSV)),
        "--out",
        s(&out),
        "--fixtures",
        s(&lib),
    ]));
    assert!(started.elapsed() < Duration::from_secs(30), "{printed}");
    // The GDTF is found (once) through the loop: channels 11-12 are lights.
    assert_eq!(channels(&scene_toml(&out)), [1, 2, 11, 12]);
    // A folder deeper than the walk goes is a sentence.
    let deep = dir.join("deep");
    let mut d = deep.clone();
    for _ in 0..40 {
        d = d.join("d");
    }
    std::fs::create_dir_all(&d).expect("mkdir");
    let out = dir.join("scene-deep");
    refused_within(
        &[
            "import",
            s(&fixtures().join(EOS_CSV)),
            "--out",
            s(&out),
            "--fixtures",
            s(&deep),
        ],
        &out,
        Duration::from_secs(30),
        &["--fixtures", "more than 32 folders deep"],
    );
}

#[test]
fn a_console_reporting_too_many_groups_is_refused_and_a_slow_one_is_bounded() {
    let Some(huge) = FakeEos::start(&["--groups-reported", "100000000"]) else {
        return;
    };
    let dir = temp_dir("import-eos-counts");
    let out = dir.join("scene");
    refused_within(
        &["import", &huge.url("eos"), "--out", s(&out)],
        &out,
        Duration::from_secs(30),
        &[
            &huge.url("eos"),
            "reports 100000000 groups",
            "at most 100000",
        ],
    );
    // A console that answers, but too slowly to ever finish: the whole read is bounded by
    // 120 times --timeout.
    let mut csv = String::from("START_CHANNELS\nCHANNEL,FIXTURE_TYPE,MANUFACTURER,ADDRESS,LABEL\n");
    for c in 1..=400u32 {
        csv += &format!("{c},Dimmer,Generic, 1/{c},D{c}\n");
    }
    csv += "END_CHANNELS\n";
    let path = dir.join("slow.csv");
    std::fs::write(&path, csv).expect("write");
    let Some(slow) = FakeEos::serve(&path, &["--delay", "0.05"]) else {
        return;
    };
    refused_within(
        &[
            "import",
            &slow.url("eos"),
            "--out",
            s(&out),
            "--timeout",
            "0.1",
        ],
        &out,
        Duration::from_secs(19),
        &[&slow.url("eos"), "gave up after 12 s", "of 400 entries in"],
    );
}
