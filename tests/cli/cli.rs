//! The offline subcommands through the real binary: results, and one-line errors for bad
//! input with a non-zero exit and no panic.

use std::path::Path;
use std::process::{Command, Output};

use crate::common::bin;
use visobjd_testkit::{stripes, temp_dir, write_exr, write_png};

fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .expect("run visobjd")
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Asserts the command succeeded, showing its stderr if not.
fn succeeded(out: &Output) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
}

/// Asserts a clean failure: non-zero, one line on stderr mentioning `needle`, no panic.
fn fails_with(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "should fail: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(err.contains(needle), "`{needle}` not in: {err}");
}

fn reference(dir: &Path) -> std::path::PathBuf {
    let p = dir.join("ref.png");
    write_png(&p, 64, 40, |x, y| {
        if x < 40 {
            [250, 120, 30]
        } else if y < 20 {
            [20, 40, 120]
        } else {
            [200, 200, 190]
        }
    });
    p
}

/// Renders `look_json` on `scene` through the binary and returns the image.
fn render(dir: &Path, scene: &Path, look_json: &str) -> image::RgbImage {
    let look = dir.join("look.json");
    std::fs::write(&look, look_json).unwrap();
    let png = dir.join("out.png");
    let out = run(&[
        "render",
        "--scene",
        s(scene),
        "--look",
        s(&look),
        "--out",
        s(&png),
    ]);
    succeeded(&out);
    image::open(&png).unwrap().to_rgb8()
}

#[test]
fn gallery_writes_a_numbered_contact_sheet_and_every_candidate() {
    let dir = temp_dir("cli-gallery");
    let scene = stripes(&dir.join("scene"), 12, true);
    let r = reference(&dir);
    let (sheet, json) = (dir.join("sheet.png"), dir.join("g.json"));
    let args = [
        "gallery",
        "--scene",
        s(&scene),
        "--ref",
        s(&r),
        "--aspects",
        "both",
        "--seed",
        "7",
        "--out",
        s(&sheet),
        "--json",
        s(&json),
    ];
    let out = run(&args);
    succeeded(&out);
    let g: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(g["seed"], 7);
    assert_eq!(g["scene"], "test scene");
    let candidates = g["candidates"].as_array().unwrap();
    assert_eq!(candidates.len(), 100);
    let entries = g["entries"].as_array().unwrap();
    assert!(!entries.is_empty() && entries.len() <= 12);
    for c in candidates {
        let lights = c["lights"].as_array().unwrap();
        assert_eq!(lights.len(), 12, "every light of the scene");
        // Dimmers (even channels here) carry no colour.
        assert!(lights[1].get("color").is_none());
        assert!(lights[0]["color"].is_array());
        let (e, m) = (c["entry"].as_u64().unwrap(), c["member"].as_u64().unwrap());
        let members = entries[e as usize - 1]["members"].as_array().unwrap();
        assert_eq!(members[m as usize - 1], c["index"]);
    }
    let o = &g["objectives"][0];
    assert_eq!(o["image"], "ref.png");
    let weights: f64 = o["palette"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["weight"].as_f64().unwrap())
        .sum();
    assert!((weights - 1.0).abs() < 1e-4);
    let img = image::open(&sheet).unwrap();
    let cols = entries.len().min(4) as u32;
    assert_eq!(
        img.width(),
        8 + cols * (48 + 8),
        "4 columns of 48-px thumbnails"
    );
    // Same seed, same JSON.
    let json2 = dir.join("g2.json");
    let mut again = args.to_vec();
    let n = again.len();
    again[n - 1] = s(&json2);
    succeeded(&run(&again));
    assert_eq!(
        std::fs::read(&json).unwrap(),
        std::fs::read(&json2).unwrap()
    );
}

#[test]
fn gallery_takes_several_references_each_with_its_region() {
    let dir = temp_dir("cli-multi");
    let scene = stripes(&dir.join("scene"), 10, false);
    let r = reference(&dir);
    let json = dir.join("g.json");
    let out = run(&[
        "gallery",
        "--scene",
        s(&scene),
        "--ref",
        s(&r),
        "--aspects",
        "intensity",
        "--ref",
        s(&r),
        "--aspects",
        "color",
        "--region",
        "0,0,0.5,1",
        "--count",
        "20",
        "--clusters",
        "4",
        "--seed",
        "1",
        "--out",
        s(&dir.join("x.png")),
        "--json",
        s(&json),
    ]);
    succeeded(&out);
    let g: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(g["objectives"][0]["aspects"], "intensity");
    assert_eq!(
        g["objectives"][0]["region"],
        serde_json::json!([0.0, 0.0, 1.0, 1.0])
    );
    assert_eq!(g["objectives"][1]["aspects"], "color");
    assert_eq!(
        g["objectives"][1]["region"],
        serde_json::json!([0.0, 0.0, 0.5, 1.0])
    );
    assert!(g["entries"].as_array().unwrap().len() <= 4);
}

#[test]
fn render_draws_a_look_file() {
    let dir = temp_dir("cli-render");
    let scene = stripes(&dir.join("scene"), 4, false);
    let img = render(
        &dir,
        &scene,
        r#"{"label": "test", "lights": [{"channel": 2, "intensity": 0.5, "color": [1.0, 0.0, 0.0]}]}"#,
    );
    assert_eq!(img.dimensions(), (16, 10));
    // Light 2 lights columns 4..8 at 0.5 of white; at half intensity, red: linear 0.25.
    let want = visobjd_compositor::color::encode_srgb8(0.25);
    assert_eq!(img.get_pixel(5, 3).0, [want, 0, 0]);
    assert_eq!(img.get_pixel(0, 3).0, [0, 0, 0]);

    let look = dir.join("bad.json");
    let png = dir.join("bad.png");
    std::fs::write(&look, r#"{"lights": [{"channel": 99, "intensity": 0.5}]}"#).unwrap();
    fails_with(
        &run(&[
            "render",
            "--scene",
            s(&scene),
            "--look",
            s(&look),
            "--out",
            s(&png),
        ]),
        "light 99 is not in the scene (channels 1-4)",
    );
}

#[test]
fn bad_scenes_fail_with_one_line_naming_the_problem() {
    let dir = temp_dir("cli-bad-scene");
    let r = reference(&dir);
    let gallery = |scene: &Path| {
        run(&[
            "gallery",
            "--scene",
            s(scene),
            "--ref",
            s(&r),
            "--out",
            s(&dir.join("o.png")),
        ])
    };

    let missing = stripes(&dir.join("missing"), 3, false);
    std::fs::remove_file(missing.join("basis/002.exr")).unwrap();
    fails_with(&gallery(&missing), "002.exr: file not found");

    let sizes = stripes(&dir.join("sizes"), 3, false);
    write_exr(&sizes.join("basis/003.exr"), 10, 10, |_, _| [1.0; 3]);
    fails_with(&gallery(&sizes), "003.exr: is 10x10 but");

    let truncated = stripes(&dir.join("truncated"), 3, false);
    let path = truncated.join("basis/001.exr");
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    fails_with(&gallery(&truncated), "001.exr");

    // A two-light scene whose scene.toml has `from` replaced by `to` once.
    let edited = |name: &str, from: &str, to: &str| {
        let scene = stripes(&dir.join(name), 2, false);
        let toml = std::fs::read_to_string(scene.join("scene.toml")).unwrap();
        std::fs::write(scene.join("scene.toml"), toml.replacen(from, to, 1)).unwrap();
        scene
    };
    let cases = [
        ("irgb", "movinghead", "unknown profile `movinghead`"),
        (
            "address = 5",
            "address = 3",
            "lights 1 and 2 both use universe 1 slot 3",
        ),
        (
            "address = 5",
            "address = 510",
            "does not fit in slots 1-512",
        ),
        ("universe", "univers", "line "),
        (
            "basis/001.exr",
            "../../etc/passwd",
            "must be a relative path inside the scene folder",
        ),
        (
            "channel = 2",
            "channel = 1",
            "channel 1 is used by two lights",
        ),
    ];
    for (i, (from, to, needle)) in cases.into_iter().enumerate() {
        fails_with(&gallery(&edited(&format!("edit{i}"), from, to)), needle);
    }
}

#[test]
fn bad_references_and_arguments_fail_with_one_line() {
    let dir = temp_dir("cli-bad-ref");
    let scene = stripes(&dir.join("scene"), 3, false);
    let out = dir.join("o.png");
    let gallery = |r: &Path, extra: &[&str]| {
        let mut args = vec![
            "gallery",
            "--scene",
            s(&scene),
            "--ref",
            s(r),
            "--out",
            s(&out),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let empty = dir.join("empty.png");
    std::fs::write(&empty, b"").unwrap();
    fails_with(&gallery(&empty, &[]), "empty.png");

    let text = dir.join("notes.png");
    std::fs::write(&text, b"this is not a picture at all, just words\n").unwrap();
    fails_with(&gallery(&text, &[]), "notes.png");

    let corrupt = dir.join("corrupt.png");
    let good = reference(&dir);
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&corrupt, &bytes[..bytes.len() / 3]).unwrap();
    fails_with(&gallery(&corrupt, &[]), "corrupt.png");

    fails_with(&gallery(&dir.join("nope.png"), &[]), "nope.png");
    fails_with(&gallery(&good, &["--region", "0.6,0,0.4,1"]), "x0 < x1");
    // One seed range everywhere: an offline gallery's seed can be replayed live (int32).
    fails_with(&gallery(&good, &["--seed", "4294967296"]), "0..=2147483647");
    fails_with(&gallery(&good, &["--aspects", "smell"]), "smell");
    fails_with(
        &gallery(&good, &["--key", "nosuch"]),
        "group `nosuch` is not in the scene",
    );
    assert!(!out.exists(), "nothing written on failure");
}

#[test]
fn check_summarises_a_clean_scene_and_refuses_a_broken_one() {
    let dir = temp_dir("cli-check");
    stripes(&dir.join("scene"), 6, true);
    std::fs::create_dir_all(dir.join("config")).unwrap();
    let config = dir.join("config/visobjd.toml");
    std::fs::write(&config, "scene = \"../scene\"\n[[output.sacn]]\n").unwrap();
    let out = run(&["check", "--config", s(&config)]);
    succeeded(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("6 in 6 groups, channels 1-6"), "{text}");
    assert!(text.contains("dimmer x3, irgb x3"), "{text}");
    assert!(text.contains("universe 1: 15/512 slots"), "{text}");
    // The irgb lights are captured at white only: their colours are approximate.
    let words = |t: &str| t.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        words(&text).contains("colour channels 1, 3, 5 approximate (captured at white only"),
        "{text}"
    );
    // Light 3 gets its emitters' images: it is no longer approximate.
    let toml = std::fs::read_to_string(dir.join("scene/scene.toml")).unwrap();
    let mut file: toml::Table = toml.parse().unwrap();
    let lights = file["light"].as_array_mut().unwrap();
    let three = lights
        .iter_mut()
        .find(|l| l["channel"].as_integer() == Some(3))
        .unwrap();
    let basis = three["basis"].as_str().unwrap().to_string();
    let mut images = toml::Table::new();
    for emitter in ["red", "green", "blue"] {
        let image = format!("{basis}-{emitter}.exr");
        std::fs::copy(
            dir.join("scene").join(&basis),
            dir.join("scene").join(&image),
        )
        .unwrap();
        images.insert(emitter.into(), image.into());
    }
    three
        .as_table_mut()
        .unwrap()
        .insert("emitter_basis".into(), images.into());
    std::fs::write(dir.join("scene/scene.toml"), file.to_string()).unwrap();
    let text = String::from_utf8_lossy(&run(&["check", "--config", s(&config)]).stdout).to_string();
    assert!(text.contains("9 basis images"), "{text}");
    assert!(
        words(&text).contains(
            "colour channel 3 previewed from each emitter's image; channels 1, 5 approximate"
        ),
        "{text}"
    );
    std::fs::write(dir.join("scene/scene.toml"), &toml).unwrap();

    std::fs::write(&config, "scene = \"../scene\"\n[output]\nrate_hz = 100\n").unwrap();
    fails_with(&run(&["check", "--config", s(&config)]), "output.rate_hz");
    std::fs::write(&config, "scene = \"../scene\"\nsecne = 1\n").unwrap();
    fails_with(&run(&["check", "--config", s(&config)]), "line 2");
    std::fs::write(&config, "scene = \"../nowhere\"\n").unwrap();
    fails_with(
        &run(&["check", "--config", s(&config)]),
        "nowhere/scene.toml",
    );
    let toml = std::fs::read_to_string(dir.join("scene/scene.toml")).unwrap();
    std::fs::write(
        dir.join("scene/scene.toml"),
        toml.replacen("channel = 2", "channel = 1", 1),
    )
    .unwrap();
    std::fs::write(&config, "scene = \"../scene\"\n").unwrap();
    fails_with(
        &run(&["check", "--config", s(&config)]),
        "channel 1 is used by two lights",
    );
}

/// A few hundred bytes of OpenEXR header declaring a `w` x `h` scanline image of half-float
/// R, G, B, uncompressed, and no pixels: what a hostile or broken basis image looks like.
fn exr_declaring(path: &Path, w: i32, h: i32) {
    fn attribute(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
        for text in [name, kind] {
            out.extend(text.as_bytes());
            out.push(0);
        }
        out.extend((value.len() as i32).to_le_bytes());
        out.extend(value);
    }
    let ints = |v: &[i32]| v.iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<u8>>();
    let mut bytes = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
    let mut channels = Vec::new();
    for c in ["B", "G", "R"] {
        channels.extend(c.as_bytes());
        // Half, not linear, reserved, x and y sampling 1.
        channels.extend([0, 1, 0, 0, 0, 0, 0, 0, 0]);
        channels.extend(ints(&[1, 1]));
    }
    channels.push(0);
    attribute(&mut bytes, "channels", "chlist", &channels);
    attribute(&mut bytes, "compression", "compression", &[0]);
    let window = ints(&[0, 0, w - 1, h - 1]);
    attribute(&mut bytes, "dataWindow", "box2i", &window);
    attribute(&mut bytes, "displayWindow", "box2i", &window);
    attribute(&mut bytes, "lineOrder", "lineOrder", &[0]);
    attribute(
        &mut bytes,
        "pixelAspectRatio",
        "float",
        &1.0f32.to_le_bytes(),
    );
    attribute(&mut bytes, "screenWindowCenter", "v2f", &[0; 8]);
    attribute(
        &mut bytes,
        "screenWindowWidth",
        "float",
        &1.0f32.to_le_bytes(),
    );
    bytes.push(0);
    std::fs::write(path, bytes).expect("write the EXR");
}

#[test]
fn a_basis_image_declaring_too_many_pixels_is_refused_before_reading() {
    let dir = temp_dir("cli-exr-huge");
    let scene = stripes(&dir.join("scene"), 3, false);
    exr_declaring(&scene.join("basis/002.exr"), 100_000, 100_000);
    std::fs::create_dir_all(dir.join("config")).unwrap();
    let config = dir.join("config/visobjd.toml");
    std::fs::write(&config, "scene = \"../scene\"\n").unwrap();
    let started = std::time::Instant::now();
    let limit = "002.exr: is 100000x100000 pixels; a basis image may have at most 16384 a side and 64 megapixels";
    fails_with(&run(&["check", "--config", s(&config)]), limit);
    let look = dir.join("look.json");
    std::fs::write(&look, r#"{"lights": []}"#).unwrap();
    let out = dir.join("out.png");
    let render = [
        "render",
        "--scene",
        s(&scene),
        "--look",
        s(&look),
        "--out",
        s(&out),
    ];
    fails_with(&run(&render), limit);
    // One side over the limit is refused too, however few pixels in all.
    exr_declaring(&scene.join("basis/002.exr"), 20_000, 10);
    fails_with(&run(&render), "is 20000x10 pixels");
    assert!(
        started.elapsed() < std::time::Duration::from_secs(30),
        "refused at once: {:?}",
        started.elapsed()
    );
    assert!(!out.exists(), "nothing written on failure");
}

#[test]
fn check_lists_every_unusable_basis_image() {
    let dir = temp_dir("cli-check-images");
    stripes(&dir.join("scene"), 6, false);
    let config = dir.join("visobjd.toml");
    std::fs::write(&config, "scene = \"scene\"\n").unwrap();
    std::fs::write(dir.join("scene/basis/002.exr"), b"not an EXR").unwrap();
    std::fs::remove_file(dir.join("scene/basis/005.exr")).unwrap();
    let out = run(&["check", "--config", s(&config)]);
    fails_with(&out, "2 of 6 lights have a basis image that cannot be used");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("light 2: ") && err.contains("002.exr"),
        "{err}"
    );
    assert!(
        err.contains("light 5: ") && err.contains("005.exr"),
        "{err}"
    );
}

#[test]
fn check_names_the_movers_their_palettes_and_every_missing_image() {
    let dir = temp_dir("cli-check-movers");
    let scene = stripes(&dir.join("scene"), 2, false);
    let config = dir.join("visobjd.toml");
    std::fs::write(&config, "scene = \"scene\"\n").unwrap();
    let mut toml = std::fs::read_to_string(scene.join("scene.toml")).unwrap();
    toml += "[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n\
             [[light]]\nchannel = 9\nprofile = \"spot\"\nuniverse = 2\naddress = 1\n";
    for (n, name) in [(1, "front"), (2, "back"), (3, "cyc")] {
        toml += &format!(
            "[[light.position]]\npalette = {n}\nname = \"{name}\"\npan = {}\ntilt = 10.0\nbasis = \"basis/009-fp{n}.exr\"\n",
            n * 10
        );
    }
    std::fs::write(scene.join("scene.toml"), toml).unwrap();
    std::fs::copy(scene.join("basis/001.exr"), scene.join("basis/009-fp1.exr")).unwrap();
    let words = |out: &Output| {
        succeeded(out);
        let t = String::from_utf8_lossy(&out.stdout);
        t.split_whitespace().collect::<Vec<_>>().join(" ")
    };
    // Palettes without an image (learned, not yet captured) are left out, and said so.
    let text = words(&run(&["check", "--config", s(&config)]));
    assert!(text.contains("3 basis images, all readable"), "{text}");
    assert!(
        text.contains("movers channel 9, 3 focus palettes: 1 \"front\" on channel 9, 2 \"back\""),
        "{text}"
    );
    assert!(
        text.contains("missing positions are left out of generation until captured")
            && text.contains("light 9 palette 2 (")
            && text.contains("009-fp2.exr), light 9 palette 3 ("),
        "{text}"
    );
    for n in [2, 3] {
        std::fs::copy(
            scene.join("basis/002.exr"),
            scene.join(format!("basis/009-fp{n}.exr")),
        )
        .unwrap();
    }
    let text = words(&run(&["check", "--config", s(&config)]));
    assert!(
        text.contains("5 basis images, all readable") && !text.contains("missing"),
        "{text}"
    );
    // Without its first position's image (its own), the mover is left out.
    std::fs::remove_file(scene.join("basis/009-fp1.exr")).unwrap();
    let out = run(&["check", "--config", s(&config)]);
    fails_with(&out, "1 of 3 lights have a basis image that cannot be used");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("light 9: no image for palette 1 ("), "{err}");
}

#[test]
fn check_says_when_the_references_would_refuse_uploads() {
    let dir = temp_dir("cli-check-refs");
    stripes(&dir.join("scene"), 2, false);
    std::fs::create_dir_all(dir.join("empty")).unwrap();
    let config = dir.join("visobjd.toml");
    let words = |out: &std::process::Output| {
        succeeded(out);
        let t = String::from_utf8_lossy(&out.stdout);
        t.split_whitespace().collect::<Vec<_>>().join(" ")
    };
    // An empty library outside the state folder: nothing to aim with, and read-only under
    // the unit.
    std::fs::write(
        &config,
        "scene = \"scene\"\nreferences = \"empty\"\nstate_dir = \"state\"\n",
    )
    .unwrap();
    let text = words(&run(&["check", "--config", s(&config)]));
    assert!(
        text.contains("empty is empty: objectives need reference images"),
        "{text}"
    );
    assert!(text.contains("outside state_dir"), "{text}");
    // Under the state folder, not made yet, with images shipped in the scene.
    std::fs::create_dir_all(dir.join("scene/refs")).unwrap();
    std::fs::copy(reference(&dir), dir.join("scene/refs/warm.png")).unwrap();
    std::fs::write(
        &config,
        "scene = \"scene\"\nreferences = \"state/refs\"\nstate_dir = \"state\"\n",
    )
    .unwrap();
    let text = words(&run(&["check", "--config", s(&config)]));
    assert!(
        text.contains("does not exist yet: the daemon makes it at start"),
        "{text}"
    );
    assert!(!text.contains("outside state_dir"), "{text}");
    std::fs::create_dir_all(dir.join("state/refs")).unwrap();
    let text = words(&run(&["check", "--config", s(&config)]));
    assert!(text.contains("the daemon copies the scene's"), "{text}");
}

#[test]
fn basis_images_may_be_half_or_float_rgb_or_rgba_scanline_or_tiled() {
    use exr::prelude::*;
    let dir = temp_dir("cli-exr-kinds");
    let scene = stripes(&dir.join("scene"), 4, false);
    let (w, h) = (16, 10);
    let value = |x: usize| if (4..8).contains(&x) { 0.5f32 } else { 0.0 };
    // Light 2 becomes a tiled RGBA half-float image with the same content.
    let layer = Layer::new(
        (w, h),
        LayerAttributes::named("rgba"),
        Encoding {
            compression: Compression::ZIP1,
            blocks: Blocks::Tiles(Vec2(8, 8)),
            line_order: LineOrder::Increasing,
        },
        SpecificChannels::rgba(|Vec2(x, _y): Vec2<usize>| {
            let v = f16::from_f32(value(x));
            (v, v, v, f16::ONE)
        }),
    );
    Image::from_layer(layer)
        .write()
        .to_file(scene.join("basis/002.exr"))
        .unwrap();
    let img = render(
        &dir,
        &scene,
        r#"{"lights": [{"channel": 2, "intensity": 1.0}]}"#,
    );
    let want = visobjd_compositor::color::encode_srgb8(0.5);
    assert_eq!(img.get_pixel(5, 3).0, [want; 3]);
    assert_eq!(img.get_pixel(9, 3).0, [0; 3]);
}

#[test]
fn check_fits_a_small_screen_and_names_the_web_gallery_and_console() {
    let dir = temp_dir("cli-check-booth");
    stripes(&dir.join("scene"), 6, true);
    let config = dir.join("visobjd.toml");
    let allow: Vec<String> = (1..=8).map(|i| format!("\"10.101.{i}.0/24\"")).collect();
    std::fs::write(
        &config,
        format!(
            "scene = \"scene\"\n[osc]\nallow = [{}]\n[http]\nlisten = \"127.0.0.1:8080\"\n\
             [eos]\naddress = \"10.101.0.5:3032\"\nprotocol = \"tcp-slip\"\n\
             [input.sacn]\nbind = \"127.0.0.1:5568\"\nuniverses = [7]\n\
             [[output.sacn]]\ndestination = \"multicast\"\npriority = 120\n\
             [[output.artnet]]\ndestination = \"10.101.0.255\"\nuniverse_offset = -1\n",
            allow.join(", ")
        ),
    )
    .unwrap();
    let out = run(&["check", "--config", s(&config)]);
    succeeded(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    let words = text.split_whitespace().collect::<Vec<_>>().join(" ");
    // Where each output sends, and which universes.
    assert!(
        words.contains(
            "sacn to multicast (239.255.hi.lo per universe) port 5568, universes 1, priority 120"
        ),
        "{text}"
    );
    assert!(
        words.contains("artnet to 10.101.0.255 port 6454, universes 1 as port-addresses 0"),
        "{text}"
    );
    assert!(
        !text.contains("no password"),
        "a loopback page needs none: {text}"
    );
    assert!(
        text.contains("http     web gallery on http://127.0.0.1:8080/"),
        "{text}"
    );
    assert!(
        text.contains("eos      presets to 10.101.0.5:3032 over tcp-slip (OSC 1.1) as user 90"),
        "{text}"
    );
    assert!(
        text.contains("input    console sACN on 127.0.0.1:5568, universes [7],"),
        "{text}"
    );
    assert!(text.contains("not received (they grab dark)"), "{text}");
    // The long allow-list wraps instead of running off a booth screen.
    assert!(text.contains("10.101.8.0/24"), "{text}");
    for line in text.lines().filter(|l| !l.contains(dir.to_str().unwrap())) {
        assert!(line.len() < 80, "{line:?} is {} columns", line.len());
    }
    // A page on every interface without a password is said.
    let booth = std::fs::read_to_string(&config)
        .unwrap()
        .replace("127.0.0.1:8080", "0.0.0.0:8080");
    std::fs::write(&config, booth).unwrap();
    let out = run(&["check", "--config", s(&config)]);
    succeeded(&out);
    let words = String::from_utf8_lossy(&out.stdout)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert!(
        words.contains("the web page on 0.0.0.0:8080 has no password"),
        "{words}"
    );
    let _ = std::fs::remove_dir_all(dir);
}
