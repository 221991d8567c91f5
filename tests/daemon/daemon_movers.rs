//! Moving lights through the real daemon (docs/osc.md, docs/dmx.md): a mover goes to a
//! focus palette by hand and from the gallery, its pan and tilt decoded off sACN and
//! Art-Net as degrees through its profile's range, a fade moves a lit mover with the fade
//! and a dark one at once; a palette learned from where a console (an E1.31 sender written
//! from the standard's octets) aims the movers.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::bin;
use crate::common::daemon::{
    Daemon, LOCALHOST, Osc, PATIENCE, PROTOS, Setup, float, free_port, int, num, string, text,
};
use crate::daemon_console::{Console, Show};
use visobjd_testkit::{temp_dir, write_exr};

/// Image size of the mover stage.
const W: usize = 120;
const H: usize = 40;

/// One palette of a test mover: number, name, pan, tilt, and where its spot lands (x).
pub(crate) type Palette = (u32, &'static str, f64, f64, usize);

/// The movers: channel, address, and their palettes.
pub(crate) const MOVERS: [(u32, usize, [Palette; 3]); 2] = [
    (
        11,
        11,
        [
            (1, "SL", -60.0, 30.0, 20),
            (2, "C", 0.0, 35.0, 60),
            (3, "SR", 60.0, 30.0, 100),
        ],
    ),
    (
        12,
        21,
        [
            (1, "SL", -50.0, 25.0, 22),
            (2, "C", 5.0, 40.0, 58),
            (3, "SR", 55.0, 25.0, 98),
        ],
    ),
];

/// Two washes (stage left and right halves) and the two movers, each spot lighting a
/// disc around its palette's centre: written as scene.toml and its images.
pub(crate) fn mover_stage(dir: &Path) -> PathBuf {
    let scene = dir.join("mover-scene");
    std::fs::create_dir_all(scene.join("basis")).expect("mkdir");
    let mut toml = String::from(
        "name = \"movers\"\n[[group]]\nname = \"wash\"\n[[group]]\nname = \"movers\"\n\
         [[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n",
    );
    for (ch, left) in [(1u32, true), (2, false)] {
        let basis = format!("basis/{ch:03}.exr");
        write_exr(&scene.join(&basis), W, H, |x, _| {
            if (x < W / 2) == left {
                [0.3; 3]
            } else {
                [0.0; 3]
            }
        });
        toml += &format!(
            "[[light]]\nchannel = {ch}\ngroup = \"wash\"\nbasis = \"{basis}\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = {ch}\n"
        );
    }
    for (ch, address, palettes) in MOVERS {
        toml += &format!(
            "[[light]]\nchannel = {ch}\ngroup = \"movers\"\nprofile = \"spot\"\nuniverse = 1\naddress = {address}\n"
        );
        for (n, name, pan, tilt, cx) in palettes {
            let basis = format!("basis/{ch:03}-fp{n}.exr");
            write_exr(&scene.join(&basis), W, H, |x, y| {
                let d2 = (x as f64 - cx as f64).powi(2) + (y as f64 - 20.0).powi(2);
                if d2 < 144.0 { [0.9; 3] } else { [0.0; 3] }
            });
            toml += &format!(
                "[[light.position]]\npalette = {n}\nname = \"{name}\"\npan = {pan}\ntilt = {tilt}\nbasis = \"{basis}\"\n"
            );
        }
    }
    std::fs::write(scene.join("scene.toml"), toml).expect("write scene.toml");
    scene
}

fn start(name: &str) -> Daemon {
    let dir = temp_dir(&format!("movers-{name}"));
    Daemon::start_setup(
        name,
        Setup {
            scene_from: Some(mover_stage(&dir)),
            ..Setup::default()
        },
    )
}

/// A 16-bit pair at 1-based slot `at` of a universe's DMX.
fn word(dmx: &[u8], at: usize) -> u16 {
    u16::from(dmx[at - 1]) << 8 | u16::from(dmx[at])
}

/// The 16-bit value of `degrees` from centre through a `range`-degree travel.
fn dmx16(degrees: f64, range: f64) -> u16 {
    ((0.5 + degrees / range) * 65535.0).round() as u16
}

/// Mover `m`'s (pan, tilt) words on the wire in palette `n`, as the profile's default
/// ranges (540 and 270 degrees) put them.
fn aimed(m: usize, n: u32) -> (u16, u16) {
    let (_, _, palettes) = MOVERS[m];
    let p = palettes.iter().find(|p| p.0 == n).expect("a palette");
    (dmx16(p.2, 540.0), dmx16(p.3, 270.0))
}

/// Mover `m`'s (pan, tilt) words in `dmx`.
fn aim_of(dmx: &[u8], m: usize) -> (u16, u16) {
    let at = MOVERS[m].1;
    (word(dmx, at + 1), word(dmx, at + 3))
}

/// Which palette mover `m`'s pan and tilt in `dmx` are (within one 16-bit step).
pub(crate) fn palette_on_wire(dmx: &[u8], m: usize) -> Option<u32> {
    let got = aim_of(dmx, m);
    MOVERS[m].2.iter().map(|p| p.0).find(|&n| {
        let want = aimed(m, n);
        want.0.abs_diff(got.0) <= 1 && want.1.abs_diff(got.1) <= 1
    })
}

#[test]
fn a_mover_goes_to_its_palette_by_hand_and_refuses_one_it_lacks() {
    let mut d = start("by-hand");
    d.ok("/vo/light/11/level", vec![int(100)], "/vo/light");
    let r = d.ok("/vo/light/11/position", vec![int(3)], "/vo/light/position");
    assert_eq!(r.args, [int(11), int(3)]);
    for proto in PROTOS {
        let dmx = d.wire.wait(proto, 1, "mover 11 at SR", |dmx| {
            palette_on_wire(dmx, 0) == Some(3)
        });
        assert_eq!(aim_of(&dmx, 0), aimed(0, 3), "{proto:?}: exactly, 16-bit");
        assert_eq!(dmx[10], 255, "{proto:?}: its intensity");
        assert_eq!(
            palette_on_wire(&dmx, 1),
            Some(1),
            "{proto:?}: 12 at its first"
        );
    }
    let r = d.ok(
        "/vo/group/movers/position",
        vec![int(2)],
        "/vo/group/position",
    );
    assert_eq!(r.args, [string("movers"), int(2), int(2)]);
    d.wire.wait_both(1, "both movers at C", |dmx| {
        palette_on_wire(dmx, 0) == Some(2) && palette_on_wire(dmx, 1) == Some(2)
    });
    let (_, positions) = d.live_aimed();
    assert_eq!(positions, [(11, 2), (12, 2)]);

    for (addr, arg, says) in [
        ("/vo/light/1/position", 1, "light 1 is not a moving light"),
        (
            "/vo/light/11/position",
            9,
            "light 11 has no palette 9 (it has 1, 2, 3)",
        ),
        (
            "/vo/group/wash/position",
            1,
            "group `wash` has no moving light with palette 1",
        ),
        ("/vo/light/11/position", 0, "focus palette must be 1..=9999"),
    ] {
        let sentence = d.refused(addr, vec![int(arg)]);
        assert!(sentence.contains(says), "{addr} {arg}: {sentence}");
    }
    // It holds across a restart, the palette as saved.
    d.kill();
    d.restart();
    let (_, positions) = d.live_aimed();
    assert_eq!(positions, [(11, 2), (12, 2)]);
}

#[test]
fn the_gallery_aims_the_movers_at_the_objectives_region() {
    let mut d = start("gallery");
    let id = d.add_objective("warm.png", "intensity");
    for (region, want) in [([0.7f32, 0.0, 1.0, 1.0], 3u32), ([0.0, 0.0, 0.3, 1.0], 1)] {
        let mut args = vec![];
        args.extend(region.map(float));
        d.ok(
            &format!("/vo/objective/{id}/region"),
            args,
            "/vo/objective/region",
        );
        d.generate();
        let entries = d.gallery().len() as i32;
        assert!(entries >= 2, "{entries} entries");
        for k in 1..=entries {
            let mut got = d.call("/vo/candidate", vec![int(k), int(1)], "/vo/candidate");
            assert_eq!(got.pop().map(|m| m.addr), Some("/vo/candidate".into()));
            let rest = d.fence();
            assert_eq!(rest.len(), 1, "{rest:?}");
            assert_eq!(rest[0].addr, "/vo/candidate/positions");
            let listed: Vec<i32> = rest[0].args[2..].iter().map(|a| num(a) as i32).collect();
            assert_eq!(listed, [11, want as i32, 12, want as i32], "entry {k}");
            // Picked, the wire says so: each mover's own pan and tilt for that palette.
            d.ok("/vo/pick", vec![int(k)], "/vo/picked");
            for proto in PROTOS {
                d.wire.wait(proto, 1, "the movers aimed", |dmx| {
                    palette_on_wire(dmx, 0) == Some(want) && palette_on_wire(dmx, 1) == Some(want)
                });
            }
        }
    }
}

#[test]
fn a_fade_moves_a_lit_mover_steadily_and_a_dark_one_at_once() {
    let mut d = start("fade");
    let save = |d: &mut Daemon, n: i32, level: i32, palette: i32| {
        d.ok("/vo/light/11/level", vec![int(level)], "/vo/light");
        d.ok(
            "/vo/light/11/position",
            vec![int(palette)],
            "/vo/light/position",
        );
        d.ok(
            "/vo/look/save",
            vec![int(n), string(&format!("look {n}"))],
            "/vo/look/saved",
        );
    };
    save(&mut d, 1, 100, 1);
    save(&mut d, 2, 100, 3);
    save(&mut d, 3, 0, 1);
    save(&mut d, 4, 0, 3);
    d.ok("/vo/fade", vec![float(1.0)], "/vo/fade");
    let (from, to) = (aimed(0, 1).0, aimed(0, 3).0);
    for (start, end, lit) in [(1, 2, true), (3, 4, false)] {
        d.ok("/vo/look/recall", vec![int(start)], "/vo/look/recalled");
        d.wire
            .wait_both(1, "at the start", |dmx| aim_of(dmx, 0).0 == from);
        let began = Instant::now();
        d.ok("/vo/look/recall", vec![int(end)], "/vo/look/recalled");
        d.wire
            .wait_both(1, "at the end", |dmx| aim_of(dmx, 0).0 == to);
        for proto in PROTOS {
            let pans: Vec<u16> = d
                .wire
                .frames(proto, 1, began)
                .iter()
                .map(|f| aim_of(&f.dmx, 0).0)
                .collect();
            let arrived = pans.iter().position(|&p| p == to).expect("arrives");
            let between = pans[..arrived].iter().filter(|&&p| p != from).count();
            assert!(
                pans[..=arrived].windows(2).all(|w| w[0] <= w[1]),
                "{proto:?}: pan goes one way: {pans:?}"
            );
            if lit {
                assert!(
                    between >= 10,
                    "{proto:?}: a lit mover sweeps with the fade: {pans:?}"
                );
            } else {
                assert_eq!(
                    between, 0,
                    "{proto:?}: a dark mover moves at once: {pans:?}"
                );
            }
        }
    }
}

/// `/vo/positions`: (palette, name, channels) per palette, checked against its end's count.
fn palettes(d: &mut Daemon) -> Vec<(i32, String, Vec<i32>)> {
    let mut got = d.call("/vo/positions", vec![], "/vo/positions/end");
    let end = got.pop().expect("an end");
    assert_eq!(end.addr, "/vo/positions/end", "{end:?}");
    let listed: Vec<(i32, String, Vec<i32>)> = got
        .iter()
        .map(|m| {
            assert_eq!(m.addr, "/vo/position", "{m:?}");
            (
                num(&m.args[0]) as i32,
                text(&m.args[1]),
                m.args[2..].iter().map(|a| num(a) as i32).collect(),
            )
        })
        .collect();
    assert_eq!(end.args, [int(listed.len() as i32)]);
    listed
}

/// Sends `/vo/position/learn` until the console's source counts (it is sampled for 1.5 s
/// first; until then the learn is refused and changes nothing); returns its reply.
fn learn(d: &mut Daemon, args: Vec<rosc::OscType>) -> rosc::OscMessage {
    let end = Instant::now() + 2 * PATIENCE;
    loop {
        let mut got = d.call("/vo/position/learn", args.clone(), "/vo/position/learned");
        let last = got.pop().expect("a reply");
        if last.addr == "/vo/position/learned" {
            assert!(got.is_empty(), "{got:?}");
            return last;
        }
        let why = text(&last.args[1]);
        assert!(
            why.contains("no console source") && Instant::now() < end,
            "learn refused: {why}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_palette_learned_from_the_console_holds_where_it_aimed_the_movers() {
    let dir = temp_dir("movers-learn");
    let scene = mover_stage(&dir);
    // Mover 12 on universe 2, which the console does not send: it is not learned.
    let toml = scene.join("scene.toml");
    let text_was = std::fs::read_to_string(&toml).expect("scene.toml");
    let on_2 = text_was.replacen(
        "channel = 12\ngroup = \"movers\"\nprofile = \"spot\"\nuniverse = 1\n",
        "channel = 12\ngroup = \"movers\"\nprofile = \"spot\"\nuniverse = 2\n",
        1,
    );
    assert_ne!(on_2, text_was, "mover 12 moved to universe 2");
    std::fs::write(&toml, on_2).expect("write scene.toml");
    let input = SocketAddr::new(LOCALHOST, free_port(LOCALHOST, LOCALHOST));
    let mut d = Daemon::start_setup(
        "movers-learn",
        Setup {
            scene_from: Some(scene),
            extra: format!("\n[input.sacn]\nbind = \"{input}\"\nuniverses = [1, 2]\n"),
            ..Setup::default()
        },
    );
    let scene_toml = d.dir.join("scene/scene.toml");
    let before = std::fs::read(&scene_toml).expect("the daemon's scene.toml");
    let why = d.refused("/vo/position/learn", vec![int(4), string("US left")]);
    assert!(why.contains("no console source"), "{why}");
    for (args, says) in [
        (vec![int(0)], "focus palette must be 1..=9999"),
        (vec![int(4), string(" ")], "a palette name is not blank"),
        (vec![int(4), int(2)], "expected a string for palette name"),
    ] {
        let why = d.refused("/vo/position/learn", args.clone());
        assert!(why.contains(says), "{args:?}: {why}");
    }
    assert_eq!(
        std::fs::read(&scene_toml).expect("read"),
        before,
        "nothing written"
    );

    // The console aims mover 11 (dimmer at 11, pan16 at 12-13, tilt16 at 14-15).
    let (pan, tilt) = (0xa357u16, 0x2e91u16);
    let mut levels = vec![0u8; 512];
    levels[10] = 255;
    levels[11..13].copy_from_slice(&pan.to_be_bytes());
    levels[13..15].copy_from_slice(&tilt.to_be_bytes());
    let console = Console::start(
        input,
        7,
        "a console",
        Show {
            priority: 100,
            levels: BTreeMap::from([(1, levels)]),
            priorities: BTreeMap::new(),
            levels_off: false,
        },
    );
    console.sent_more(1);
    let r = learn(&mut d, vec![int(4), string("US left")]);
    assert_eq!(
        r.args,
        [int(4), int(1), string("US left")],
        "one mover learned"
    );
    // Written into scene.toml: pan and tilt within one 16-bit step of what the console
    // sent, through the profile's ranges (540 and 270 degrees); the image capture shoots.
    let written = visobjd_scene::Scene::load(&d.dir.join("scene")).expect("the scene loads");
    let degrees = |v: u16, range: f64| (f64::from(v) / 65535.0 - 0.5) * range;
    let light = &written.lights[written.light_index(11).expect("light 11")];
    let p = &light.positions[light.position_index(4).expect("palette 4")];
    assert!(
        (p.pan - degrees(pan, 540.0)).abs() <= 540.0 / 65535.0,
        "pan {}",
        p.pan
    );
    assert!(
        (p.tilt - degrees(tilt, 270.0)).abs() <= 270.0 / 65535.0,
        "tilt {}",
        p.tilt
    );
    assert!(p.basis.ends_with("basis/011-fp04.exr"), "{:?}", p.basis);
    let mover_12 = &written.lights[written.light_index(12).expect("light 12")];
    assert_eq!(
        mover_12.position_index(4),
        None,
        "12 is on a universe not sent"
    );
    // Running now: listed, and a mover sent there carries the console's pan and tilt.
    assert_eq!(
        palettes(&mut d),
        [
            (1, "SL".into(), vec![11, 12]),
            (2, "C".into(), vec![11, 12]),
            (3, "SR".into(), vec![11, 12]),
            (4, "US left".into(), vec![11]),
        ]
    );
    d.ok("/vo/light/11/position", vec![int(4)], "/vo/light/position");
    for proto in PROTOS {
        let dmx = d.wire.wait(proto, 1, "mover 11 at palette 4", |dmx| {
            let (p, t) = aim_of(dmx, 0);
            p.abs_diff(pan) <= 1 && t.abs_diff(tilt) <= 1
        });
        assert_eq!(
            dmx[10], 0,
            "{proto:?}: its level is the session's, not the console's"
        );
    }
    // Its image is not shot yet: `visobjd check` names it (the light's other positions
    // still work).
    let check = std::process::Command::new(bin())
        .args(["check", "--config"])
        .arg(d.config_path())
        .output()
        .expect("visobjd check runs");
    let said = String::from_utf8_lossy(&check.stderr).to_string()
        + &String::from_utf8_lossy(&check.stdout);
    assert!(
        check.status.success()
            && said.contains("light 11 palette 4")
            && said.contains("011-fp04.exr"),
        "{said}"
    );

    // Learned again without a name, an existing palette keeps its name and takes the aim.
    let r = learn(&mut d, vec![int(2)]);
    assert_eq!(r.args, [int(2), int(1), string("C")]);
    let listed = palettes(&mut d);
    assert_eq!(listed[1], (2, "C".into(), vec![11, 12]));
    let again = visobjd_scene::Scene::load(&d.dir.join("scene")).expect("the scene loads");
    let light = &again.lights[again.light_index(11).expect("light 11")];
    let p2 = &light.positions[light.position_index(2).expect("palette 2")];
    assert_eq!((p2.pan, p2.tilt), (p.pan, p.tilt));
    let (_, positions) = d.live_aimed();
    assert_eq!(
        positions,
        [(11, 4), (12, 1)],
        "the live look kept its palettes"
    );
}
