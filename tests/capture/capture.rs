//! `visobjd capture` end to end with the simulated camera: the real binary drives the rig
//! over sACN, the sim photographs the scene's own basis images lit by the DMX it receives,
//! and the captured basis must match those images. Also: the wire shows capture's
//! priority and only the light being shot at full; a stopped capture resumes; a light
//! that adds nothing is named and the exit status says so; `visobjd run` loads the result,
//! generates from it and puts a pick on the wire.

use std::net::UdpSocket;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::common::bin;
use crate::common::capture::{W, basis_errors, config, light_6_is_untouched, listen, lit, stage};
use crate::common::daemon::{Daemon, Osc, Proto, Setup, int, same_look};
use visobjd_testkit::temp_dir;

fn capture(config: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(bin())
        .args(["capture", "--config"])
        .arg(config)
        .args([
            "--camera", "sim", "--settle", "0.02", "--seed", "3", "--width",
        ])
        .arg(W.to_string())
        .args(extra)
        .output()
        .expect("visobjd capture runs")
}

fn end_to_end(format: &str) {
    let dir = temp_dir(&format!("capture-{format}"));
    stage(&dir);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind a receiver");
    let port = socket.local_addr().expect("addr").port();
    let done = Arc::new(AtomicBool::new(false));
    let wire = listen(socket, Arc::clone(&done));
    let cfg = config(&dir, &[port], "");
    let out = capture(&cfg, &["--format", format]);
    done.store(true, Ordering::SeqCst);
    let packets = wire.join().expect("listener");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let errors = basis_errors(&dir, format == "jpeg");
    eprintln!("{format}: median relative errors {errors:?}");
    for (ch, e) in (1..=5).zip(&errors) {
        assert!(
            *e < 0.02,
            "{format}: light {ch}: median relative error {e:.4}"
        );
    }
    // Light 6 adds nothing: named, and the exit status says so.
    assert!(!out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("light 6 (Ch 6) shows no light"),
        "{stdout}\n{stderr}"
    );
    assert!(stdout.contains("5 lights written"), "{stdout}\n{stderr}");
    // Light 6's image is not replaced: it keeps the scene's black one.
    assert!(light_6_is_untouched(&dir));
    // On the wire: capture's priority, and at most one light at full at a time, once the
    // response bracket (every light at full) is over.
    assert!(!packets.is_empty(), "no sACN reached the test");
    assert!(packets.iter().all(|p| p.priority == 200), "priority 200");
    assert!(
        packets.iter().any(|p| p.terminated),
        "the streams are terminated at the end"
    );
    let singles = packets.iter().filter(|p| lit(&p.dmx).0.len() == 1).count();
    assert!(singles > 0, "each light is shot alone");
    // `visobjd run` loads the captured scene (light 6 keeps its black image), generates
    // from it and puts a pick on the wire.
    let mut d = Daemon::start_setup(
        &format!("captured-{format}"),
        Setup {
            scene_from: Some(dir.join("scene")),
            ..Setup::default()
        },
    );
    d.add_objective("warm.png", "both");
    let generated = d.generate();
    assert!(!generated.args.is_empty(), "a gallery: {generated:?}");
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    assert!(same_look(&d.live(), &d.candidate(1, 1), 1e-6));
    d.wire.wait(Proto::Sacn, 1, "the picked look", |dmx| {
        dmx.iter().any(|&b| b > 0)
    });
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn jpeg_capture_matches_the_basis_within_two_percent() {
    end_to_end("jpeg");
}

#[test]
fn raw_capture_matches_the_basis_within_two_percent() {
    end_to_end("raw");
}

#[test]
fn a_stopped_capture_resumes_where_it_left_off() {
    let dir = temp_dir("capture-resume");
    stage(&dir);
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let cfg = config(&dir, &[socket.local_addr().expect("addr").port()], "");
    let first = capture(&cfg, &["--lights", "1-2"]);
    assert!(
        first.status.success(),
        "{}",
        String::from_utf8_lossy(&first.stderr)
    );
    let record = std::fs::read_to_string(dir.join("scene/capture.json")).expect("capture.json");
    assert!(record.contains("\"response\""), "the response is recorded");
    let second = capture(&cfg, &["--lights", "1-5"]);
    let stdout = String::from_utf8_lossy(&second.stdout);
    assert!(
        second.status.success() && stdout.contains("3 lights written, 2 already done"),
        "{stdout}\n{}",
        String::from_utf8_lossy(&second.stderr)
    );
    for (ch, e) in (1..=5).zip(basis_errors(&dir, true)) {
        assert!(e < 0.02, "light {ch} after resuming: {e:.4}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The CIEDE2000 between sRGB `target` and what light `ch` of `scene` makes of it on the
/// sim's fixtures: the look's DMX bytes read at the light's slots (its profile's order:
/// an optional intensity, then red, green, blue and white) mixed by the true emitters
/// (`truth` xy and flux for red, green, blue; white as the test's `emitters.json` says),
/// compared in chromaticity (both at Y = 0.4 under D65).
fn sent_colour_error(
    scene: &visobjd_scene::Scene,
    ch: u32,
    target: [f32; 3],
    truth: &[[f64; 3]; 3],
) -> f64 {
    use visobjd_scene::emitter::colour::{ciede2000, linear_srgb_to_xyz, xyy_to_xyz, xyz_to_lab};
    use visobjd_scene::look::{Level, Look};
    let l = scene.light_index(ch).expect("light in scene");
    let mut look = Look::off(scene.lights.len());
    look.levels[l] = Level {
        intensity: 1.0,
        color: target,
        position: None,
    };
    let patch = visobjd_dmx::Patch::new(scene);
    let bytes = patch.quantise(&patch.levels(&look, 1.0));
    let light = &scene.lights[l];
    let at = usize::from(light.address) - 1;
    let names = scene.profile(l).channel_names();
    let mut emitters = truth.to_vec();
    emitters.push([0.40, 0.39, 0.8]);
    let mut reached = [0.0; 3];
    let dimmer = names
        .iter()
        .position(|n| n == "intensity")
        .map_or(1.0, |k| f64::from(bytes[0][at + k]) / 255.0);
    for (k, name) in names.iter().enumerate() {
        let Some(e) = ["red", "green", "blue", "white"]
            .iter()
            .position(|n| n == name)
        else {
            continue;
        };
        let [x, y, flux] = emitters[e];
        let level = dimmer * f64::from(bytes[0][at + k]) / 255.0;
        for (r, v) in reached.iter_mut().zip(xyy_to_xyz(x, y, flux)) {
            *r += level * v;
        }
    }
    let want =
        linear_srgb_to_xyz(target.map(|c| f64::from(visobjd_scene::srgb::srgb_to_linear(c))));
    let lab = |xyz: [f64; 3]| xyz_to_lab(xyz.map(|v| v * 0.4 / xyz[1]));
    ciede2000(lab(reached), lab(want))
}

/// The issue's colour test: lights 2 (irgb), 3 (rgb) and 4 (rgbw) are really other than
/// their profiles say (the sim's `emitters.json`: an orange red, a yellowish green, a warm
/// white). Captured per emitter, the preview of a saturated look (the per-emitter images
/// weighed by the solved levels) matches a shot of it within 3 Delta E 2000; the preview
/// from the white images alone, which trusts the profiles, misses by more.
#[test]
fn per_emitter_preview_matches_a_shot_where_white_only_misses() {
    let dir = temp_dir("capture-emitters");
    let scene = stage(&dir);
    let sim = scene.join("capture/sim");
    std::fs::create_dir_all(&sim).expect("mkdir sim");
    let rgb = r#"{"name": "red", "xy": [0.60, 0.35], "flux": 0.25},
                 {"name": "green", "xy": [0.33, 0.52], "flux": 0.6},
                 {"name": "blue", "xy": [0.16, 0.11], "flux": 0.1}"#;
    std::fs::write(
        sim.join("emitters.json"),
        format!(
            r#"{{"2": [{rgb}], "3": [{rgb}], "4": [{rgb}, {{"name": "white", "xy": [0.40, 0.39], "flux": 0.8}}]}}"#
        ),
    )
    .expect("write emitters.json");
    let socket = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let cfg = config(&dir, &[socket.local_addr().expect("addr").port()], "");
    let out = capture(&cfg, &["--lights", "2-4", "--emitters", "--format", "raw"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("emitters: 10 images written"), "{stdout}");
    // scene.toml names every emitter's image of the three lights.
    let toml = std::fs::read_to_string(scene.join("scene.toml")).expect("scene.toml");
    for image in ["002-red.exr", "003-blue.exr", "004-white.exr"] {
        assert!(toml.contains(image), "{image} in scene.toml:\n{toml}");
        assert!(scene.join("basis").join(image).is_file(), "{image} written");
    }
    let line = stdout
        .lines()
        .find(|l| l.starts_with("colour validation:"))
        .unwrap_or_else(|| panic!("no colour validation in:\n{stdout}"));
    let figures: Vec<f64> = line
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter(|w| w.contains('.'))
        .filter_map(|w| w.trim_end_matches('.').parse().ok())
        .collect();
    eprintln!("{line}");
    let [per_emitter, white_only] = figures[..] else {
        panic!("two figures in: {line}");
    };
    assert!(per_emitter < 3.0, "{line}");
    assert!(white_only > 3.0 && white_only > per_emitter, "{line}");
    // The emitters measured from the images aim the solve: a saturated colour sent to the
    // fixtures, its DMX bytes read back here and mixed by the sim's true emitters, lands
    // near the target; aimed with the profiles' emitters it misses.
    let measured = visobjd_scene::Scene::load(&scene).expect("captured scene loads");
    let mut file = visobjd_scene::SceneFile::parse(&scene.join("scene.toml"), &toml)
        .expect("scene.toml parses");
    assert!(
        file.light
            .iter()
            .filter(|l| !l.emitter_measured.is_empty())
            .count()
            == 3,
        "every captured light has emitter_measured:\n{toml}"
    );
    for l in &mut file.light {
        l.emitter_measured.clear();
    }
    let profiles = visobjd_scene::Scene::parse(&scene, &file.to_toml().expect("toml"))
        .expect("the scene without measurements loads");
    let mut figures = Vec::new();
    let truth = [[0.60, 0.35, 0.25], [0.33, 0.52, 0.6], [0.16, 0.11, 0.1]];
    for (ch, target) in [
        (2, [0.85, 0.35, 0.75]),
        (3, [0.9, 0.6, 0.25]),
        (4, [0.4, 0.55, 0.9]),
    ] {
        let [aimed, trusting] =
            [&measured, &profiles].map(|s| sent_colour_error(s, ch, target, &truth));
        eprintln!(
            "light {ch}, sRGB {target:?}: Delta E 2000 {aimed:.2} aimed with the measured emitters, {trusting:.2} with the profile's"
        );
        figures.push((ch, aimed, trusting));
    }
    for (ch, aimed, trusting) in figures {
        assert!(aimed < 4.0, "light {ch}: {aimed:.2} with measured emitters");
        assert!(
            trusting > 2.0 * aimed,
            "light {ch}: {trusting:.2} with the profile's"
        );
    }
    // Run again: every image is there, nothing is shot twice.
    let again = capture(&cfg, &["--lights", "2-4", "--emitters", "--format", "raw"]);
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(
        again.status.success() && stdout.contains("0 lights written, 3 already done"),
        "{stdout}"
    );
    assert!(!stdout.contains("emitters:"), "{stdout}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `visobjd capture --help` and the command's synopsis in docs/capture.md name the same
/// options, and each default the help gives is the value the synopsis shows.
#[test]
fn capture_help_and_the_docs_synopsis_agree() {
    let out = Command::new(bin())
        .args(["capture", "--help"])
        .output()
        .expect("visobjd capture --help runs");
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    let docs =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/capture.md"))
            .expect("docs/capture.md");
    let synopsis = docs
        .split("## The command")
        .nth(1)
        .and_then(|s| s.split("```sh").nth(1))
        .and_then(|s| s.split("```").next())
        .expect("docs/capture.md has a ```sh synopsis under \"## The command\"");
    // The synopsis: each `--option` and the word after it (its value, or its default).
    let words: Vec<&str> = synopsis.split_whitespace().collect();
    let documented: std::collections::BTreeMap<&str, &str> = words
        .iter()
        .enumerate()
        .filter_map(|(i, w)| {
            let name = w.trim_start_matches('[').trim_end_matches(']');
            let value = words.get(i + 1).filter(|v| !v.starts_with('['));
            name.starts_with("--")
                .then(|| (name, value.map_or("", |v| v.trim_end_matches(']'))))
        })
        .collect();
    // The help: each option line (`  -h, --help`, `      --config <CONFIG>`) and what
    // follows it up to the next one, where clap puts `[default: X]`.
    let mut helped: std::collections::BTreeMap<String, String> = Default::default();
    let mut current: Option<String> = None;
    for line in help.lines() {
        let t = line.trim_start();
        let option = t
            .split_whitespace()
            .map(|w| w.trim_end_matches(','))
            .find(|w| w.starts_with("--"))
            .filter(|_| t.starts_with('-'));
        if let Some(name) = option {
            current = Some(name.to_string());
            helped.insert(name.to_string(), t.to_string());
        } else if let Some(name) = &current {
            helped.entry(name.clone()).or_default().push_str(t);
        }
    }
    helped.remove("--help");
    let help_names: Vec<&str> = helped.keys().map(String::as_str).collect();
    let doc_names: Vec<&str> = documented.keys().copied().collect();
    assert_eq!(
        help_names, doc_names,
        "--help:\n{help}\nsynopsis:\n{synopsis}"
    );
    for (name, text) in &helped {
        if let Some(default) = text
            .split("[default: ")
            .nth(1)
            .and_then(|d| d.split(']').next())
        {
            assert!(
                documented[name.as_str()].contains(default),
                "{name}: --help gives the default {default}, the synopsis `{}`",
                documented[name.as_str()]
            );
        }
    }
}
