//! The virtual stage renderer through its public API: physics, determinism, errors, output.

use std::path::{Path, PathBuf};

use visobjd_synth::{SynthError, VirtualStage, render_light, synth};

/// A 32x18 view looking almost straight down at the floor point (0, 0, 4).
const BASE: &str = r#"
name = "test"
width = 32
height = 18

[stage]
width = 8.0
depth = 8.0
albedo = [0.5, 0.5, 0.5]

[camera]
position = [0.0, 5.0, 3.5]
look_at = [0.0, 0.0, 4.0]
fov = 20.0
"#;

/// The pixel just past the image centre, which sees the floor near (0, 0, 4).
const CENTRE: usize = 9 * 32 + 16;

fn light(position: [f32; 3], aim: [f32; 3]) -> String {
    format!(
        "[[light]]\nchannel = 1\nprofile = \"dimmer\"\nuniverse = 1\naddress = 1\n\
         position = {position:?}\naim = {aim:?}\nbeam = 40.0\nfield = 60.0\nintensity = 1000.0\n"
    )
}

fn parse(text: &str) -> VirtualStage {
    match VirtualStage::parse(text) {
        Ok(r) => r,
        Err(e) => panic!("test rig does not parse: {e}"),
    }
}

fn luminance(p: [f32; 3]) -> f32 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

/// A fresh empty folder under the system temp dir, unique per test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("visobjd-synth-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

#[test]
fn light_falls_off_with_distance_squared() {
    let near = parse(&format!(
        "{BASE}{}",
        light([0.0, 3.0, 4.0], [0.0, 0.0, 4.0])
    ));
    let far = parse(&format!(
        "{BASE}{}",
        light([0.0, 6.0, 4.0], [0.0, 0.0, 4.0])
    ));
    let a = luminance(render_light(&near, 0)[CENTRE]);
    let b = luminance(render_light(&far, 0)[CENTRE]);
    // Lambert: albedo / pi * I / d^2, white light, exposure 0.
    let expected = 0.5 / std::f32::consts::PI * 1000.0 / 9.0;
    assert!(
        (a / expected - 1.0).abs() < 0.02,
        "near {a}, expected {expected}"
    );
    assert!((b / a - 0.25).abs() < 0.01, "far/near = {}", b / a);
}

#[test]
fn light_aimed_at_nothing_adds_nothing() {
    let rig = format!(
        "{BASE}[stage.cyc]\nheight = 4.0\ncove = 1.0\nalbedo = [0.8, 0.8, 0.8]\n\
         [[box]]\nposition = [0.0, 0.0, 4.0]\nsize = [1.0, 1.0, 1.0]\nalbedo = [0.5, 0.5, 0.5]\n{}",
        light([0.0, 5.0, 2.0], [0.0, 10.0, 2.0])
    );
    let img = render_light(&parse(&rig), 0);
    assert!(img.iter().all(|p| *p == [0.0; 3]), "some pixel is lit");
}

#[test]
fn occluder_casts_a_shadow() {
    let lamp = light([-3.0, 4.0, 4.0], [0.0, 0.0, 4.0]);
    let open = parse(&format!("{BASE}{lamp}"));
    // A floating cube half-way along the beam axis, outside the camera's view.
    let blocked = parse(&format!(
        "{BASE}[[box]]\nposition = [-1.5, 1.75, 4.0]\nsize = [0.5, 0.5, 0.5]\n\
         albedo = [0.5, 0.5, 0.5]\n{lamp}"
    ));
    let lit = luminance(render_light(&open, 0)[CENTRE]);
    let shaded = luminance(render_light(&blocked, 0)[CENTRE]);
    assert!(lit > 1.0, "floor not lit without the box: {lit}");
    assert!(shaded < 0.05 * lit, "no shadow: {shaded} vs {lit}");
}

/// A rig using every kind of object, three profiles and two groups.
fn full_rig() -> String {
    format!(
        "exposure = -1.0\n{BASE}\
         [stage.cyc]\nheight = 4.0\ncove = 1.0\nalbedo = [0.8, 0.8, 0.8]\n\
         [stage.legs]\npairs = 2\nwidth = 1.0\nheight = 4.0\nalbedo = [0.02, 0.02, 0.02]\n\
         [[box]]\nname = \"crate\"\nposition = [0.5, 0.0, 4.0]\nsize = [0.5, 0.5, 0.5]\nyaw = 30.0\nalbedo = [0.4, 0.3, 0.2]\n\
         [[cylinder]]\nposition = [-0.5, 0.0, 4.2]\nradius = 0.2\nheight = 1.5\nalbedo = [0.6, 0.2, 0.2]\n\
         [[sphere]]\nposition = [-0.5, 1.62, 4.2]\nradius = 0.12\nalbedo = [0.6, 0.45, 0.35]\n\
         [[light]]\nchannel = 7\nname = \"front\"\ngroup = \"front\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = 1\n\
         position = [-2.0, 4.0, 0.0]\naim = [0.0, 1.0, 4.0]\nbeam = 20.0\nfield = 30.0\nintensity = 5000.0\ngel = [1.0, 0.7, 0.4]\n\
         [[light]]\nchannel = 8\nname = \"cyc\"\ngroup = \"cyc\"\nprofile = \"rgbw\"\nuniverse = 2\naddress = 10\n\
         position = [0.0, 4.5, 6.5]\naim = [0.0, 2.0, 8.0]\nbeam = 60.0\nfield = 90.0\nintensity = 800.0\n\
         [[light]]\nchannel = 9\ngroup = \"front\"\nprofile = \"irgb\"\nuniverse = 1\naddress = 2\n\
         position = [2.0, 4.0, 0.0]\naim = [0.0, 1.0, 4.0]\nbeam = 20.0\nfield = 30.0\nintensity = 5000.0\n"
    )
}

fn write_rig(dir: &Path, text: &str) -> PathBuf {
    let path = dir.join("rig.toml");
    std::fs::write(&path, text).expect("write rig");
    path
}

#[test]
fn same_rig_gives_same_bytes() {
    let dir = scratch("determinism");
    let rig = write_rig(&dir, &full_rig());
    let (a, b) = (dir.join("a"), dir.join("b"));
    synth(&rig, &a).expect("first synth");
    synth(&rig, &b).expect("second synth");
    for f in [
        "scene.toml",
        "basis/001.exr",
        "basis/002.exr",
        "basis/003.exr",
    ] {
        let x = std::fs::read(a.join(f)).expect("read a");
        let y = std::fs::read(b.join(f)).expect("read b");
        assert!(x == y, "{f} differs between runs");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn scene_lists_every_light_with_a_readable_basis() {
    let dir = scratch("scene");
    let rig = write_rig(&dir, &full_rig());
    let out = dir.join("out");
    let report = synth(&rig, &out).expect("synth");
    assert_eq!((report.lights, report.width, report.height), (3, 32, 18));

    let text = std::fs::read_to_string(out.join("scene.toml")).expect("scene.toml");
    let scene: toml::Table = text.parse().expect("scene.toml is TOML");
    assert_eq!(scene["name"].as_str(), Some("test"));
    let groups: Vec<&str> = scene["group"]
        .as_array()
        .expect("[[group]]")
        .iter()
        .filter_map(|g| g["name"].as_str())
        .collect();
    assert_eq!(groups, ["front", "cyc"]);
    let lights = scene["light"].as_array().expect("[[light]]");
    let channels: Vec<i64> = lights
        .iter()
        .filter_map(|l| l["channel"].as_integer())
        .collect();
    assert_eq!(channels, [7, 8, 9]);
    let allowed = [
        "channel", "name", "group", "basis", "profile", "universe", "address",
    ];
    for l in lights {
        let l = l.as_table().expect("light table");
        assert!(
            l.keys().all(|k| allowed.contains(&k.as_str())),
            "extra key in {l:?}"
        );
        for key in ["profile", "universe", "address"] {
            assert!(l.contains_key(key), "{key} missing");
        }
        let basis = out.join(l["basis"].as_str().expect("basis"));
        let image = exr::prelude::read_first_rgba_layer_from_file(
            &basis,
            |res, _| (res.width(), res.height(), 0.0f32),
            |acc, _, (r, g, b, _a): (f32, f32, f32, f32)| acc.2 += r + g + b,
        )
        .unwrap_or_else(|e| panic!("{} does not decode: {e}", basis.display()));
        let (w, h, sum) = image.layer_data.channel_data.pixels;
        assert_eq!((w, h), (32, 18), "{}", basis.display());
        assert!(sum > 0.0, "{} is black", basis.display());
        let meta = exr::meta::MetaData::read_from_file(&basis, false).expect("EXR header");
        let channels = &meta.headers[0].channels.list;
        let names: Vec<String> = channels.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["B", "G", "R"], "{}", basis.display());
        let half = channels
            .iter()
            .all(|c| c.sample_type == exr::meta::attribute::SampleType::F16);
        assert!(half, "{} is not half float", basis.display());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn rig_error(text: &str) -> String {
    match VirtualStage::parse(text) {
        Ok(_) => panic!("accepted a bad rig:\n{text}"),
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "multi-line message: {msg}");
            msg
        }
    }
}

#[test]
fn bad_rigs_give_one_clear_line() {
    let lamp = light([0.0, 3.0, 4.0], [0.0, 0.0, 4.0]);

    let msg = rig_error("name = \n");
    assert!(msg.starts_with("line 1:"), "{msg}");

    let typo = format!(
        "{BASE}{}",
        lamp.replace("intensity", "colr = 1.0\nintensity")
    );
    let line = typo
        .lines()
        .position(|l| l.starts_with("colr"))
        .map(|i| i + 1);
    let msg = rig_error(&typo);
    assert!(msg.contains("colr"), "{msg}");
    assert!(
        msg.starts_with(&format!("line {}:", line.unwrap_or(0))),
        "{msg}"
    );

    let msg = rig_error(&format!(
        "{BASE}{}",
        lamp.replace("beam = 40.0", "beam = -5.0")
    ));
    assert!(msg.contains("beam angle -5"), "{msg}");

    let msg = rig_error(&format!(
        "{BASE}{}",
        lamp.replace("field = 60.0", "field = 30.0")
    ));
    assert!(msg.contains("field angle 30"), "{msg}");

    let msg = rig_error(&format!(
        "{BASE}{}",
        light([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    ));
    assert_eq!(msg, "light 1 aims at its own position");

    let twice = format!("{BASE}{lamp}{}", lamp.replace("channel = 1", "channel = 2"));
    let msg = rig_error(&twice);
    assert!(msg.contains("slot 1 is already used by light 1"), "{msg}");

    let msg = rig_error(&format!(
        "{BASE}{}",
        lamp.replace("address = 1", "address = 4294967295")
    ));
    assert!(msg.contains("does not fit in 1..=512"), "{msg}");

    let msg = rig_error(&BASE.replace("width = 32", "width = 100000"));
    assert!(msg.starts_with("image size 100000x18"), "{msg}");

    let msg = rig_error(&format!("{BASE}{}", lamp.replace("dimmer", "dimmr")));
    assert!(msg.contains("unknown profile `dimmr`"), "{msg}");
}

#[test]
fn synth_errors_name_the_file() {
    let dir = scratch("errors");
    let missing = dir.join("nope.toml");
    match synth(&missing, &dir.join("out")) {
        Err(e @ SynthError::Read { .. }) => assert!(e.to_string().contains("nope.toml")),
        other => panic!("expected a read error, got {other:?}"),
    }
    let rig = write_rig(&dir, "name = \"x\"\nwidth = 0\n");
    match synth(&rig, &dir.join("out")) {
        Err(e @ SynthError::Rig { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("rig.toml: line"), "{msg}");
        }
        other => panic!("expected a rig error, got {other:?}"),
    }
    assert!(!dir.join("out").exists(), "wrote output for a bad rig");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A 96x54 view from downstage and above, looking at the floor point (0, 0, 4), with a
/// moving-light profile.
const MOVER_STAGE: &str = r#"
name = "movers"
width = 96
height = 54

[stage]
width = 8.0
depth = 8.0
albedo = [0.5, 0.5, 0.5]

[camera]
position = [0.0, 6.0, -1.0]
look_at = [0.0, 0.0, 4.0]
fov = 50.0

[[profile]]
name = "mover"
channels = ["intensity", "pan16", "tilt16", "red", "green", "blue", "white"]
tilt_range = 200.0
"#;

/// A mover hung at `position` with focus palettes `(palette, name, aim)`.
fn mover(
    channel: u32,
    address: u32,
    position: [f32; 3],
    focus: &[(u32, &str, [f32; 3])],
) -> String {
    let mut t = format!(
        "[[light]]\nchannel = {channel}\nprofile = \"mover\"\nuniverse = 1\naddress = {address}\n\
         position = {position:?}\nbeam = 10.0\nfield = 16.0\nintensity = 1000.0\n"
    );
    for (palette, name, aim) in focus {
        t += &format!("[[light.focus]]\npalette = {palette}\nname = \"{name}\"\naim = {aim:?}\n");
    }
    t
}

/// Where the floor point `p` lands in the `MOVER_STAGE` camera's image, in pixels: a
/// pinhole with +y up, worked out here from the camera's numbers.
fn project(p: [f32; 3]) -> (f32, f32) {
    let (eye, at, fov, w, h) = ([0.0f32, 6.0, -1.0], [0.0f32, 0.0, 4.0], 50.0f32, 96.0, 54.0);
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let unit = |a: [f32; 3]| {
        let l = dot(a, a).sqrt();
        a.map(|v| v / l)
    };
    let fwd = unit(sub(at, eye));
    // The camera's right is fwd x up, its up right x fwd.
    let right = unit([-fwd[2], 0.0, fwd[0]]);
    let up = [
        right[1] * fwd[2] - right[2] * fwd[1],
        right[2] * fwd[0] - right[0] * fwd[2],
        right[0] * fwd[1] - right[1] * fwd[0],
    ];
    let d = sub(p, eye);
    let th = (fov.to_radians() / 2.0).tan();
    let tw = th * w / h;
    let u = dot(d, right) / dot(d, fwd) / tw;
    let v = dot(d, up) / dot(d, fwd) / th;
    ((u + 1.0) / 2.0 * w, (1.0 - v) / 2.0 * h)
}

/// The luminance-weighted centre, in pixels, of the pixels above a fifth of the brightest.
fn centroid(img: &[[f32; 3]], w: usize) -> (f32, f32) {
    let lum: Vec<f32> = img.iter().map(|&p| luminance(p)).collect();
    let max = lum.iter().copied().fold(0.0, f32::max);
    assert!(max > 0.0, "a black image");
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for (i, &l) in lum.iter().enumerate() {
        if l > max / 5.0 {
            sx += l * ((i % w) as f32 + 0.5);
            sy += l * ((i / w) as f32 + 0.5);
            sw += l;
        }
    }
    (sx / sw, sy / sw)
}

fn read_exr(path: &Path) -> (usize, Vec<[f32; 3]>) {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0.0f32; 3]; res.width() * res.height()]),
        |(w, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| px[pos.y() * *w + pos.x()] = [r, g, b],
    )
    .unwrap_or_else(|e| panic!("{} does not decode: {e}", path.display()));
    image.layer_data.channel_data.pixels
}

#[test]
fn a_mover_renders_one_image_per_focus_lit_where_it_aims() {
    let dir = scratch("mover");
    let (left, right) = ([-1.5f32, 0.0, 3.5], [1.5f32, 0.0, 4.5]);
    let hung = [0.0f32, 4.0, 4.0];
    let rig = write_rig(
        &dir,
        &format!(
            "{MOVER_STAGE}{}",
            mover(5, 1, hung, &[(1, "left", left), (2, "right", right)])
        ),
    );
    let out = dir.join("out");
    let report = synth(&rig, &out).expect("synth");
    assert_eq!((report.lights, report.images), (1, 2));

    let text = std::fs::read_to_string(out.join("scene.toml")).expect("scene.toml");
    let scene: toml::Table = text.parse().expect("scene.toml is TOML");
    let light = scene["light"][0].as_table().expect("the light");
    assert!(
        !light.contains_key("basis"),
        "a mover has one image per position"
    );
    let positions = light["position"].as_array().expect("[[light.position]]");
    assert_eq!(positions.len(), 2);
    for (p, (palette, name, aim)) in positions
        .iter()
        .zip([(1, "left", left), (2, "right", right)])
    {
        assert_eq!(p["palette"].as_integer(), Some(palette));
        assert_eq!(p["name"].as_str(), Some(name));
        assert_eq!(
            p["basis"].as_str(),
            Some(format!("basis/001-fp{palette:02}.exr").as_str())
        );
        // Tilt from straight down: the horizontal run over the drop; pan: the heading of
        // the run, 0 downstage (-z), +90 towards +x.
        let (dx, dz) = (f64::from(aim[0] - hung[0]), f64::from(aim[2] - hung[2]));
        let run = dx.hypot(dz);
        let tilt = (run / f64::from(hung[1] - aim[1])).atan().to_degrees();
        let pan = dx.signum() * (-dz / run).acos().to_degrees();
        let (got_pan, got_tilt) = (
            p["pan"].as_float().expect("pan"),
            p["tilt"].as_float().expect("tilt"),
        );
        assert!(
            (got_pan - pan).abs() <= 0.005,
            "pan {got_pan}, expected {pan}"
        );
        assert!(
            (got_tilt - tilt).abs() <= 0.005,
            "tilt {got_tilt}, expected {tilt}"
        );
        // Each image is lit where its aim point is in the camera's view.
        let (w, img) = read_exr(&out.join(p["basis"].as_str().expect("basis")));
        let (cx, cy) = centroid(&img, w);
        let (ax, ay) = project(aim);
        assert!(
            (cx - ax).abs() < 1.5 && (cy - ay).abs() < 1.5,
            "palette {palette}: lit around ({cx}, {cy}), its aim is at ({ax}, {ay})"
        );
    }
    // The two aims are apart in the image, the left one (-x) to the camera's right.
    let (l, r) = (project(left), project(right));
    assert!(l.0 - r.0 > 15.0, "{l:?} {r:?}");
    // What synth writes loads as a scene with palettes 1 and 2 on that light.
    let loaded = visobjd_scene::Scene::load(&out).expect("the scene loads");
    let numbers: Vec<u32> = loaded.palettes.iter().map(|p| p.number).collect();
    assert_eq!(numbers, [1, 2]);
    assert!(loaded.lights[0].is_moving());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_movers_give_one_clear_line() {
    let hung = [0.0f32, 4.0, 4.0];
    let one = mover(5, 1, hung, &[(1, "left", [-1.5, 0.0, 3.5])]);
    let with = |text: &str| rig_error(&format!("{MOVER_STAGE}{text}"));

    let msg = with(&one.replace("position = [0.0", "aim = [0.0, 0.0, 4.0]\nposition = [0.0"));
    assert_eq!(
        msg,
        "light 1: a moving light (profile `mover`) is aimed by its [[light.focus]] tables, not `aim`"
    );
    let msg = with(&mover(5, 1, hung, &[]));
    assert_eq!(
        msg,
        "light 1: a moving light needs at least one [[light.focus]] (palette, aim)"
    );
    let msg = with(&one.replace("aim = [-1.5", "aim = [nan"));
    assert_eq!(msg, "light 1 focus palette 1 aim: numbers must be finite");
    let msg = with(&one.replace("aim = [-1.5, 0.0, 3.5]", "aim = [0.0, 4.0, 4.0]"));
    assert_eq!(msg, "light 1: focus palette 1 aims at its own position");
    // tilt_range 200: at most 100 degrees from straight down; a point level with the
    // lamp and above it is out of reach.
    let msg = with(&one.replace("aim = [-1.5, 0.0, 3.5]", "aim = [-1.0, 5.0, 4.0]"));
    assert!(
        msg.starts_with("light 1: focus palette 1 needs tilt 135 degrees, outside profile `mover`'s tilt_range 200 (-100..=100)"),
        "{msg}"
    );
    let msg = with(&mover(5, 1, hung, &[(0, "x", [-1.5, 0.0, 3.5])]));
    assert!(
        msg.contains("focus palette 0 is not a palette number (1-9999)"),
        "{msg}"
    );
    let msg = with(&mover(
        5,
        1,
        hung,
        &[(3, "a", [-1.5, 0.0, 3.5]), (3, "b", [1.5, 0.0, 3.5])],
    ));
    assert_eq!(msg, "light 1: focus palette 3 is listed twice");
    let two = format!(
        "{one}{}",
        mover(6, 20, [1.0, 4.0, 4.0], &[(1, "DS left", [1.0, 0.0, 2.0])])
    );
    assert_eq!(
        with(&two),
        "light 2: focus palette 1 is `DS left` here but `left` on light 1: a palette has one name"
    );
    let fixed = light([0.0, 3.0, 4.0], [0.0, 0.0, 4.0])
        + "[[light.focus]]\npalette = 1\naim = [0.0, 0.0, 4.0]\n";
    assert_eq!(
        with(&fixed),
        "light 1: [[light.focus]] is for a moving light, and profile `dimmer` has no pan and tilt slots"
    );
    let msg = with(&format!(
        "{one}[[profile]]\nname = \"mover\"\nchannels = [\"intensity\"]\n"
    ));
    assert_eq!(msg, "profile `mover` is defined twice");
    let msg = with(&one.replace("profile = \"mover\"", "profile = \"mover2\""));
    assert!(msg.contains("unknown profile `mover2`"), "{msg}");
}
