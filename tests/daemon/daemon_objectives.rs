//! Objective addresses of docs/osc.md against the real daemon: add (with the L* statistics),
//! aspects, region, palette, colour, remove, clear and the listing, each with refused cases
//! that change nothing, and hostile image paths.

use crate::common::daemon::{Daemon, Osc, Setup, float, int, num, string, text};
use rosc::OscMessage;
use visobjd_testkit::TestLight;

fn near(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// `(id, image, aspects, region)` of one `/vo/objective` message.
fn listed(m: &OscMessage) -> (i32, String, String, [f64; 4]) {
    assert_eq!(m.args.len(), 7, "id image aspects x0 y0 x1 y1: {m:?}");
    (
        num(&m.args[0]) as i32,
        text(&m.args[1]),
        text(&m.args[2]),
        [3, 4, 5, 6].map(|i| num(&m.args[i])),
    )
}

#[test]
fn add_measures_the_image_and_lists_it() {
    let mut d = Daemon::start("obj-add");
    // Uniform sRGB 128 grey: L* 53.59 everywhere; nothing is brighter than the mean.
    let r = d.ok(
        "/vo/objective/add",
        vec![string("grey.png")],
        "/vo/objective/added",
    );
    assert_eq!(r.args.len(), 5, "{r:?}");
    let grey = num(&r.args[0]) as i32;
    assert_eq!(text(&r.args[1]), "both", "aspects default to both");
    assert!(near(num(&r.args[2]), 53.59, 0.6), "mean_l {r:?}");
    assert!(near(num(&r.args[3]), 53.59, 0.6), "key_l {r:?}");
    assert!(near(num(&r.args[4]), 0.0, 0.01), "bright {r:?}");
    // Half white, half black: mean L* 50, the brightest 15% are white, half is bright.
    let r = d.ok(
        "/vo/objective/add",
        vec![string("split.png"), string("intensity")],
        "/vo/objective/added",
    );
    let split = num(&r.args[0]) as i32;
    assert_ne!(grey, split);
    assert_eq!(text(&r.args[1]), "intensity");
    assert!(near(num(&r.args[2]), 50.0, 0.6), "mean_l {r:?}");
    assert!(near(num(&r.args[3]), 100.0, 0.6), "key_l {r:?}");
    assert!(near(num(&r.args[4]), 0.5, 0.02), "bright {r:?}");
    d.add_objective("warm.png", "color");
    assert_eq!(d.status().objectives, 3);
    let list: Vec<_> = d.objectives().iter().map(listed).collect();
    assert_eq!(list.len(), 3);
    assert_eq!(
        list[0],
        (grey, "grey.png".into(), "both".into(), [0.0, 0.0, 1.0, 1.0])
    );
    assert_eq!(
        list[1],
        (
            split,
            "split.png".into(),
            "intensity".into(),
            [0.0, 0.0, 1.0, 1.0]
        )
    );
    assert_eq!(
        (list[2].1.as_str(), list[2].2.as_str()),
        ("warm.png", "color")
    );
}

#[test]
fn add_refuses_bad_arguments() {
    let mut d = Daemon::start("obj-add-bad");
    d.add_objective("grey.png", "both");
    for args in [
        vec![],
        vec![int(3)],
        vec![string("missing.png")],
        vec![string("grey.png"), string("loud")],
        vec![string("grey.png"), int(1)],
        vec![string("")],
    ] {
        d.refused("/vo/objective/add", args);
    }
    let sentence = d.err("/vo/objective/add", vec![string("missing.png")]);
    assert!(
        sentence.contains("missing.png"),
        "names the file: {sentence}"
    );
}

#[test]
fn hostile_image_paths_are_refused() {
    let mut d = Daemon::start("obj-hostile");
    let refs = d.refs();
    let outside = d.dir.join("outside.png");
    std::os::unix::fs::symlink(&outside, refs.join("link.png")).expect("symlink out");
    std::os::unix::fs::symlink("grey.png", refs.join("alias.png")).expect("symlink in");
    std::fs::write(refs.join("notes.png"), "not an image\n").expect("write");
    std::fs::create_dir_all(refs.join("folder.png")).expect("mkdir");
    visobjd_testkit::png_header_only(&refs.join("huge.png"), 9000, 9000);
    d.add_objective("grey.png", "both");
    for image in [
        "../outside.png".to_string(),
        "./../outside.png".into(),
        outside.display().to_string(),
        "/etc/passwd".into(),
        "link.png".into(),
        "notes.png".into(),
        "folder.png".into(),
        "huge.png".into(),
    ] {
        d.refused("/vo/objective/add", vec![string(&image)]);
    }
    // A link that stays inside the folder is an ordinary file name.
    d.add_objective("alias.png", "both");
}

#[test]
fn aspects_change_and_refuse() {
    let mut d = Daemon::start("obj-aspects");
    let id = d.add_objective("warm.png", "both");
    for a in ["intensity", "color", "both"] {
        let r = d.ok(
            &format!("/vo/objective/{id}/aspects"),
            vec![string(a)],
            "/vo/objective/aspects",
        );
        assert_eq!(
            (num(&r.args[0]) as i32, text(&r.args[1])),
            (id, a.to_string())
        );
        assert_eq!(listed(&d.objectives()[0]).2, a);
    }
    d.ok(
        &format!("/vo/objective/{id}/aspects"),
        vec![string("color")],
        "/vo/objective/aspects",
    );
    for args in [vec![string("loud")], vec![int(2)], vec![]] {
        d.refused(&format!("/vo/objective/{id}/aspects"), args);
    }
    d.refused(
        &format!("/vo/objective/{}/aspects", id + 100),
        vec![string("both")],
    );
}

#[test]
fn region_selects_lights_and_refuses_nonsense() {
    let mut d = Daemon::start("obj-region");
    let id = d.add_objective("warm.png", "both");
    let addr = format!("/vo/objective/{id}/region");
    // Stripes of 8 of 48 pixels: the left half is lights 1-3, the right half 4-6.
    for (region, lights) in [
        ([0.0, 0.0, 0.5, 1.0], 3),
        ([0.5, 0.0, 1.0, 1.0], 3),
        ([0.0, 0.0, 1.0, 1.0], 6),
    ] {
        let r = d.ok(
            &addr,
            region.iter().map(|&v| float(v)).collect(),
            "/vo/objective/region",
        );
        let v: Vec<f64> = r.args.iter().map(num).collect();
        assert_eq!(v.len(), 6, "{r:?}");
        assert_eq!(v[0] as i32, id);
        assert_eq!([v[1], v[2], v[3], v[4]], region.map(f64::from));
        assert_eq!(v[5] as i32, lights, "lights selected by {region:?}");
    }
    d.ok(
        &addr,
        [0.0, 0.0, 0.5, 1.0].map(float).to_vec(),
        "/vo/objective/region",
    );
    assert_eq!(listed(&d.objectives()[0]).3, [0.0, 0.0, 0.5, 1.0]);
    // No arguments: the whole stage.
    let r = d.ok(&addr, vec![], "/vo/objective/region");
    assert_eq!(num(&r.args[5]) as i32, 6, "{r:?}");
    assert_eq!(listed(&d.objectives()[0]).3, [0.0, 0.0, 1.0, 1.0]);
    for args in [
        [0.0, 0.0, 1.5, 1.0].map(float).to_vec(),
        [-0.1, 0.0, 1.0, 1.0].map(float).to_vec(),
        [0.6, 0.0, 0.4, 1.0].map(float).to_vec(),
        [0.0, 0.0, 1.0].map(float).to_vec(),
        vec![string("left"), float(0.0), float(1.0), float(1.0)],
    ] {
        d.refused(&addr, args);
    }
    d.refused(
        &format!("/vo/objective/{}/region", id + 100),
        [0.0, 0.0, 1.0, 1.0].map(float).to_vec(),
    );
}

/// `(rgb, weight)` pairs of a palette reply for objective `id`.
fn palette(m: &OscMessage, id: i32) -> Vec<([f64; 3], f64)> {
    assert_eq!(num(&m.args[0]) as i32, id, "{m:?}");
    let rest = &m.args[1..];
    assert!(
        !rest.is_empty() && rest.len().is_multiple_of(4),
        "r g b w each: {m:?}"
    );
    rest.chunks(4)
        .map(|c| ([num(&c[0]), num(&c[1]), num(&c[2])], num(&c[3])))
        .collect()
}

#[test]
fn palette_and_colour_edit() {
    let mut d = Daemon::start("obj-palette");
    let id = d.add_objective("cool.png", "both");
    let r = d.ok(
        &format!("/vo/objective/{id}/palette"),
        vec![],
        "/vo/objective/palette",
    );
    let p = palette(&r, id);
    let total: f64 = p.iter().map(|(_, w)| w).sum();
    assert!(near(total, 1.0, 0.01), "weights sum to 1: {p:?}");
    // cool.png is blue (40, 80..113, 255): the weighted palette is too.
    let mean = [0, 1, 2].map(|i| p.iter().map(|(c, w)| c[i] * w).sum::<f64>());
    assert!(mean[2] > 0.9 && mean[0] < 0.3 && mean[1] < 0.5, "{p:?}");

    let addr = format!("/vo/objective/{id}/color");
    let r = d.ok(
        &addr,
        vec![int(1), float(1.0), float(0.5), float(0.0)],
        "/vo/objective/palette",
    );
    let q = palette(&r, id);
    assert_eq!(q.len(), p.len());
    assert!(near(q[0].0[0], 1.0, 1e-3) && near(q[0].0[1], 0.5, 1e-3) && near(q[0].0[2], 0.0, 1e-3));
    assert_eq!(q[1..], p[1..], "the other colours stay");
    assert!(
        q.iter().zip(&p).all(|(a, b)| near(a.1, b.1, 1e-6)),
        "weights stay"
    );
    let again = d.ok(
        &format!("/vo/objective/{id}/palette"),
        vec![],
        "/vo/objective/palette",
    );
    assert_eq!(palette(&again, id), q);

    let k_past = p.len() as i32 + 1;
    for args in [
        vec![int(0), float(1.0), float(0.0), float(0.0)],
        vec![int(k_past), float(1.0), float(0.0), float(0.0)],
        vec![int(1), float(1.5), float(0.0), float(0.0)],
        vec![int(1), float(1.0), float(0.0)],
        vec![string("first"), float(1.0), float(0.0), float(0.0)],
    ] {
        d.refused(&addr, args);
    }
    let unknown = id + 100;
    d.refused(&format!("/vo/objective/{unknown}/palette"), vec![]);
    d.refused(
        &format!("/vo/objective/{unknown}/color"),
        vec![int(1), float(1.0), float(0.0), float(0.0)],
    );
    // The palette is unchanged by all that.
    let r = d.ok(
        &format!("/vo/objective/{id}/palette"),
        vec![],
        "/vo/objective/palette",
    );
    assert_eq!(palette(&r, id), q);
}

#[test]
fn remove_clear_and_list() {
    let mut d = Daemon::start("obj-remove");
    let a = d.add_objective("warm.png", "both");
    let b = d.add_objective("cool.png", "color");
    let c = d.add_objective("grey.png", "intensity");
    let r = d.ok(
        &format!("/vo/objective/{b}/remove"),
        vec![],
        "/vo/objective/removed",
    );
    assert_eq!(num(&r.args[0]) as i32, b);
    let ids: Vec<i32> = d.objectives().iter().map(|m| listed(m).0).collect();
    assert_eq!(ids, [a, c]);
    assert_eq!(d.status().objectives, 2);
    d.refused(&format!("/vo/objective/{b}/remove"), vec![]);
    d.refused("/vo/objective/frobnicate", vec![]);
    d.refused(&format!("/vo/objective/{a}/frobnicate"), vec![]);
    d.refused("/vo/objectivess", vec![]);

    let r = d.ok("/vo/objective/clear", vec![], "/vo/objective/cleared");
    assert_eq!(num(&r.args[0]) as i32, 2);
    assert!(d.objectives().is_empty());
    assert_eq!(d.status().objectives, 0);
    let r = d.ok("/vo/objective/clear", vec![], "/vo/objective/cleared");
    assert_eq!(num(&r.args[0]) as i32, 0);
    d.refused(&format!("/vo/objective/{a}/aspects"), vec![string("both")]);
}

#[test]
fn a_region_that_selects_no_light_is_refused_and_says_so() {
    // Two lights on the left half of the stage; the right half stays dark.
    let scene = visobjd_testkit::temp_dir("obj-dark-half");
    let lights = vec![
        TestLight::rect(1, Some("left"), "dimmer", 1, (0, 0, 12, 24), 0.6),
        TestLight::rect(2, Some("left"), "dimmer", 2, (12, 0, 24, 24), 0.6),
    ];
    visobjd_testkit::write_scene(&scene, 48, 24, &["left"], &lights);
    let mut d = Daemon::start_setup(
        "obj-dark-region",
        Setup {
            scene_from: Some(scene.clone()),
            ..Setup::default()
        },
    );
    let id = d.add_objective("warm.png", "both");
    let addr = format!("/vo/objective/{id}/region");
    d.ok(
        &addr,
        [0.0, 0.0, 0.5, 1.0].map(float).to_vec(),
        "/vo/objective/region",
    );
    let why = d.refused(&addr, [0.6, 0.0, 1.0, 1.0].map(float).to_vec());
    assert!(why.contains("selects no light"), "{why}");
    assert_eq!(listed(&d.objectives()[0]).3, [0.0, 0.0, 0.5, 1.0]);
    std::fs::remove_dir_all(&scene).ok();
}

/// A session keeps at most 64 objectives, each image named in at most 100 characters
/// (docs/osc.md, "Limits"): an add past them is refused and changes nothing.
#[test]
fn a_session_keeps_at_most_64_objectives() {
    let mut d = Daemon::start("obj-limits");
    for _ in 0..64 {
        d.ok(
            "/vo/objective/add",
            vec![string("grey.png")],
            "/vo/objective/added",
        );
    }
    let why = d.refused("/vo/objective/add", vec![string("grey.png")]);
    assert!(
        why.starts_with("there are already 64 objectives, the most a session keeps"),
        "{why}"
    );
    let long = format!("{}.png", "g".repeat(97));
    let why = d.refused("/vo/objective/add", vec![string(&long)]);
    assert_eq!(
        why,
        "an objective's image name is at most 100 characters, got 101"
    );
    d.ok("/vo/objective/last/remove", vec![], "/vo/objective/removed");
    d.ok(
        "/vo/objective/add",
        vec![string("grey.png")],
        "/vo/objective/added",
    );
}
