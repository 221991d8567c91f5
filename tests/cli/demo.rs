//! The shipped demo stage: it loads clean, and its references give galleries whose
//! brightness follows theirs.

use std::path::Path;

use crate::common;
use rand::SeedableRng;
use visobjd_compositor::color::{lightness, luminance, srgb8_to_linear_table};
use visobjd_method::objective::{Aspects, Objective, Region, analyze, decode_reference};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_scene::look::Look;

const DEMO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/demo");

/// Mean L* of an sRGB image.
fn mean_lightness(img: &image::RgbImage) -> f32 {
    let lut = srgb8_to_linear_table();
    let sum: f32 = img
        .pixels()
        .map(|p| lightness(luminance(p.0.map(|v| lut[v as usize]))))
        .sum();
    sum / (img.width() * img.height()) as f32
}

#[test]
fn check_reports_the_shipped_config_clean() {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/config/visobjd.toml");
    let out = std::process::Command::new(common::bin())
        .args(["check", "--config", config])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("50 in "), "{text}");
    assert!(
        text.contains("universe 1:") && text.contains("universe 2:"),
        "{text}"
    );
}

#[test]
fn gallery_brightness_follows_the_references() {
    let stage = Stage::load(Path::new(DEMO), 240).unwrap();
    let mut refs: Vec<_> = std::fs::read_dir(Path::new(DEMO).join("refs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    refs.sort();
    assert!(refs.len() >= 8, "{} references", refs.len());
    let base = Look::off(stage.scene.lights.len());
    let constraints = Constraints::none(&stage.rig);
    let mut rows = Vec::new();
    for path in &refs {
        let img = decode_reference(path).unwrap();
        let objective = Objective {
            image: path.display().to_string(),
            aspects: Aspects::Both,
            region: Region::FULL,
            analysis: analyze(&img, Region::FULL, 5),
        };
        let reference_l = objective.analysis.stats.mean_l;
        let g = stage.generate(
            &GenerateRequest {
                objectives: std::slice::from_ref(&objective),
                constraints: &constraints,
                base: &base,
                spread: Spread::default(),
                count: 100,
                clusters: 12,
                steer: None,
            },
            &mut rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1),
        );
        let reps: Vec<&Look> = g.entries.iter().map(|e| &g.candidates[e[0]]).collect();
        let thumbs = stage.thumbnails(&reps);
        let gallery_l = thumbs.iter().map(mean_lightness).sum::<f32>() / thumbs.len() as f32;
        println!(
            "{:>40}  reference L* {reference_l:5.1}  gallery L* {gallery_l:5.1}",
            path.display()
        );
        rows.push((reference_l, gallery_l));
    }
    // Every pair of references that differ clearly in brightness gives galleries in the
    // same order.
    for a in &rows {
        for b in &rows {
            if a.0 > b.0 + 10.0 {
                assert!(
                    a.1 > b.1,
                    "reference L* {} > {} but gallery {} <= {}",
                    a.0,
                    b.0,
                    a.1,
                    b.1
                );
            }
        }
    }
}

#[test]
fn gallery_warns_that_a_lock_without_a_base_holds_the_group_off() {
    let dir = visobjd_testkit::temp_dir("cli-lock-no-base");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "gallery".to_string(),
            "--scene".into(),
            DEMO.into(),
            "--ref".into(),
            format!("{DEMO}/refs/sunset.png"),
            "--lock".into(),
            "front warm".into(),
            "--count".into(),
            "10".into(),
            "--clusters".into(),
            "2".into(),
            "--seed".into(),
            "1".into(),
            "--out".into(),
            dir.join("g.png").display().to_string(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        std::process::Command::new(common::bin())
            .args(&args)
            .output()
            .expect("visobjd gallery runs")
    };
    let out = run(&[]);
    assert!(out.status.success(), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--lock front warm without --base"), "{err}");
    let base = dir.join("base.json");
    std::fs::write(&base, r#"{"lights": [{"channel": 1, "intensity": 0.5}]}"#).unwrap();
    let out = run(&["--base", &base.display().to_string()]);
    assert!(out.status.success(), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("without --base"), "{err}");
}

#[test]
fn render_draws_the_readmes_example_and_a_look_the_daemon_saved() {
    let dir = visobjd_testkit::temp_dir("cli-render-saved");
    let render = |look: &str, out: &Path| {
        std::process::Command::new(common::bin())
            .args(["render", "--scene", DEMO, "--look", look, "--out"])
            .arg(out)
            .args(["--width", "160"])
            .output()
            .expect("visobjd render runs")
    };
    let example = format!("{DEMO}/looks/example.json");
    let out = render(&example, &dir.join("example.png"));
    assert!(out.status.success(), "{out:?}");
    assert!(mean_lightness(&image::open(dir.join("example.png")).unwrap().to_rgb8()) > 1.0);

    // looks.json as the daemon writes it: looks by number.
    let looks = dir.join("looks.json");
    std::fs::write(
        &looks,
        r#"{"looks": {"3": {"label": "act 1", "lights": [{"channel": 1, "intensity": 1.0}]}}}"#,
    )
    .unwrap();
    let saved = format!("{}#3", looks.display());
    let out = render(&saved, &dir.join("saved.png"));
    assert!(out.status.success(), "{out:?}");
    let out = render(&format!("{}#4", looks.display()), &dir.join("none.png"));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no saved look 4 (saved: 3)"), "{err}");
}
