//! Export to Eos against a fake console (tests/peers/fake_eos_console.py: a command line
//! per user, cue lists, presets and cues, reading levels as Eos does) over TCP
//! (length-prefixed or SLIP) or UDP: the command lines the daemon sends and what the
//! console stored are checked against the DMX the daemon puts on the wire (decoded by the
//! tests' own decoder), parameter by parameter; records are confirmed or refused as the
//! console answers.

use std::collections::BTreeMap;
use std::net::TcpListener;
use std::path::PathBuf;

use crate::common;
use crate::common::daemon::{Daemon, Osc, PATIENCE, Proto, Setup, float, int, num};
use visobjd_testkit::{TestLight, temp_dir, tools, write_scene};

/// Each test profile's slots in DMX order as the Eos parameter they should be exported as:
/// `At16` is a 16-bit pair, `-` a slot left out (uv, fixed).
const PROFILES: &[(&str, &[&str])] = &[
    ("dimmer", &["At"]),
    ("irgb", &["At", "Red", "Green", "Blue"]),
    ("rgb", &["Red", "Green", "Blue"]),
    ("rgbw", &["Red", "Green", "Blue", "White"]),
    (
        "full16",
        &[
            "At16", "Red", "Green", "Blue", "White", "Amber", "Lime", "-", "-",
        ],
    ),
    ("cmy", &["At", "Cyan", "Magenta", "Yellow", "-"]),
    ("irgbl", &["At", "Red", "Green", "Blue", "Lime"]),
];

/// The custom profiles as scene.toml writes them.
const CUSTOM: &str = r#"
[[profile]]
name = "full16"
channels = ["intensity16", "red", "green", "blue", "white", "amber", "lime", "uv", "fixed:255"]

[[profile]]
name = "cmy"
channels = ["intensity", "cyan", "magenta", "yellow", "fixed:7"]

[[profile]]
name = "irgbl"
channels = ["intensity", "red", "green", "blue", "lime"]
"#;

/// A light of the export stage: channel, profile, universe, address.
type Patched = (u32, &'static str, u16, usize);

/// Six lights covering every exported parameter: 16-bit intensity with white, amber and
/// lime (and a uv and fixed slot left out), CMY flags, an rgbw without a dimmer, a dimmer,
/// lime alone, an rgb.
const STAGE: [Patched; 6] = [
    (1, "full16", 1, 1),
    (2, "cmy", 1, 20),
    (3, "rgbw", 1, 30),
    (4, "dimmer", 2, 1),
    (5, "irgbl", 2, 10),
    (6, "rgb", 2, 20),
];

/// The export stage's scene folder, written under `dir`.
fn export_scene(dir: &std::path::Path) -> PathBuf {
    let lights: Vec<TestLight> = STAGE
        .iter()
        .enumerate()
        .map(|(i, &(channel, profile, universe, address))| TestLight {
            channel,
            group: None,
            profile,
            universe,
            address: address as u16,
            pixel: Box::new(move |x, _| if x / 8 == i { [0.5; 3] } else { [0.0; 3] }),
        })
        .collect();
    let scene = write_scene(&dir.join("eos-scene"), 48, 20, &[], &lights);
    let toml = scene.join("scene.toml");
    let text = std::fs::read_to_string(&toml).unwrap() + CUSTOM;
    std::fs::write(&toml, text).unwrap();
    scene
}

/// A look that drives every parameter away from 0 and 100 somewhere (lime on light 5).
fn set_export_look(d: &mut Daemon) {
    let looks: [(u32, f32, [f32; 3]); 6] = [
        (1, 0.6237, [1.0, 0.8, 0.3]),
        (2, 0.5, [0.2, 0.6, 1.0]),
        (3, 0.7, [1.0, 0.9, 0.6]),
        (4, 0.09, [1.0; 3]),
        (5, 0.8, [0.9, 1.0, 0.2]),
        (6, 0.4, [0.5, 0.5, 1.0]),
    ];
    for (ch, intensity, color) in looks {
        d.ok(
            &format!("/vo/light/{ch}/intensity"),
            vec![float(intensity)],
            "/vo/light",
        );
        if ch != 4 {
            d.ok(
                &format!("/vo/light/{ch}/color"),
                color.map(float).to_vec(),
                "/vo/light",
            );
        }
    }
}

/// The command lines as (channel, parameter) -> percent; the record line is left out.
fn parameters(lines: &[String]) -> BTreeMap<(u32, String), f64> {
    let mut out = BTreeMap::new();
    for line in lines.iter().filter(|l| !l.contains("Record")) {
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(
            (words[0], words.last().copied()),
            ("Chan", Some("Enter")),
            "{line}"
        );
        let ch: u32 = words[1].parse().expect("a channel number");
        for pair in words[2..words.len() - 1].chunks(2) {
            let value: f64 = pair[1].parse().expect("a level");
            let old = out.insert((ch, pair[0].to_string()), value);
            assert!(old.is_none(), "{} set twice for channel {ch}", pair[0]);
        }
    }
    out
}

/// What the wire's slots `dmx` of universe `universe` say each exported parameter must
/// be, with the tolerance of one DMX step; a light without a dimmer is `At 100`.
pub fn wire_parameters(universe: u16, dmx: &[u8]) -> Vec<((u32, String), f64, f64)> {
    let mut out = Vec::new();
    for &(ch, profile, u, address) in STAGE.iter().filter(|s| s.2 == universe) {
        assert_eq!(u, universe);
        let slots = PROFILES.iter().find(|p| p.0 == profile).unwrap().1;
        let mut at = address - 1;
        if !slots.iter().any(|s| s.starts_with("At")) {
            out.push(((ch, "At".to_string()), 100.0, 0.0));
        }
        for &s in slots {
            match s {
                "At16" => {
                    let v = f64::from(dmx[at]) * 256.0 + f64::from(dmx[at + 1]);
                    out.push(((ch, "At".into()), v / 655.35, 100.0 / 65535.0));
                    at += 2;
                }
                "-" => at += 1,
                p => {
                    out.push(((ch, p.into()), f64::from(dmx[at]) / 2.55, 100.0 / 255.0));
                    at += 1;
                }
            }
        }
    }
    out
}

/// Waits until the wire shows what the command lines say, parameter for parameter within
/// one DMX step, and checks the lines hold no other parameter.
fn assert_lines_match_the_wire(d: &Daemon, lines: &[String]) {
    assert_matches_the_wire(d, &parameters(lines), wire_parameters, "exported");
}

/// Waits until the wire shows `held` (`(channel, parameter)` -> percent), parameter for
/// parameter within one DMX step as `wire` reads a universe's slots (the parameters it
/// must hold, the level and the tolerance), and checks `held` has no other; `who` holds it.
pub fn assert_matches_the_wire(
    d: &Daemon,
    held: &BTreeMap<(u32, String), f64>,
    wire: impl Fn(u16, &[u8]) -> Vec<((u32, String), f64, f64)>,
    who: &str,
) {
    let mut expected = 0;
    for universe in [1, 2] {
        let mismatch = |dmx: &[u8]| -> Option<String> {
            wire(universe, dmx)
                .into_iter()
                .find_map(|(key, want, tol)| match held.get(&key) {
                    Some(got) if (got - want).abs() <= tol + 1e-9 => None,
                    got => Some(format!("{key:?}: {who} {got:?}, wire {want}")),
                })
        };
        let dmx = d.wire.wait(Proto::Sacn, universe, "the levels", |dmx| {
            mismatch(dmx).is_none()
        });
        assert_eq!(mismatch(&dmx), None);
        expected += wire(universe, &dmx).len();
    }
    assert_eq!(held.len(), expected, "extra parameters {who}: {held:?}");
}

/// The export stage with `[eos]` pointing at `console`.
fn export_daemon(
    name: &str,
    console: std::net::SocketAddr,
    protocol: &str,
    user: Option<u32>,
) -> Daemon {
    let mut extra = format!("\n[eos]\naddress = \"{console}\"\nprotocol = \"{protocol}\"\n");
    if let Some(u) = user {
        extra += &format!("user = {u}\n");
    }
    export_daemon_with(name, &extra)
}

/// The export stage with `extra` config, its look set ([`set_export_look`]).
pub fn export_daemon_with(name: &str, extra: &str) -> Daemon {
    let dir = temp_dir(&format!("{name}-scene"));
    let mut d = Daemon::start_setup(
        name,
        Setup {
            extra: extra.to_string(),
            scene_from: Some(export_scene(&dir)),
            ..Setup::default()
        },
    );
    set_export_look(&mut d);
    d
}

/// Checks what every export must hold beyond the levels: every parameter kind, a 16-bit
/// intensity with decimals, the record line last.
fn assert_every_parameter(lines: &[String], n: u32) {
    let sent = parameters(lines);
    for p in [
        "Red", "Green", "Blue", "White", "Amber", "Lime", "Cyan", "Magenta", "Yellow",
    ] {
        assert!(
            sent.keys().any(|(_, q)| q == p),
            "no {p} exported: {lines:?}"
        );
    }
    assert!(sent[&(5, "Lime".to_string())] > 0.0, "{lines:?}");
    assert!(sent[&(1, "Amber".to_string())] > 0.0, "{lines:?}");
    let at = lines
        .iter()
        .find(|l| l.starts_with("Chan 1 At "))
        .expect("light 1's intensity");
    assert!(at.contains('.'), "16-bit intensity without decimals: {at}");
    assert!(!lines.iter().any(|l| l.contains("Uv")), "{lines:?}");
    assert_eq!(
        lines.last().unwrap(),
        &format!("Chan 1 Thru 6 Record Preset {n} Enter")
    );
}

/// The fake Eos console (`tests/peers/fake_eos_console.py`: a command line per user,
/// cue lists, presets and cues, answering as Eos does) on a loopback port; killed when
/// dropped.
struct FakeConsole {
    child: std::process::Child,
    addr: std::net::SocketAddr,
    state: PathBuf,
}

impl FakeConsole {
    /// Starts it with `args` (`--protocol` and the rest); `None` (after
    /// [`tools::missing`]) without python-osc.
    fn start(name: &str, args: &[&str]) -> Option<FakeConsole> {
        if !tools::python_osc() {
            return None;
        }
        let state = temp_dir(&format!("{name}-console")).join("state.json");
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        let mut command = std::process::Command::new("python3");
        command
            .arg(root.join("tests/peers/fake_eos_console.py"))
            .args(args)
            .arg("--state")
            .arg(&state);
        let (child, port) = common::start_peer(command, "the fake Eos console");
        Some(FakeConsole {
            child,
            addr: ([127, 0, 0, 1], port).into(),
            state,
        })
    }

    /// What it holds now: each user's command lines, presets and cues.
    fn state(&self) -> serde_json::Value {
        let text = std::fs::read_to_string(&self.state).expect("the fake console's state");
        serde_json::from_str(&text).expect("the fake console's state is JSON")
    }

    /// The command lines user `user` was sent.
    fn lines(&self, user: u32) -> Vec<String> {
        self.state()["lines"][user.to_string()]
            .as_array()
            .map(|a| a.iter().map(|l| l.as_str().unwrap().to_string()).collect())
            .unwrap_or_default()
    }
}

impl Drop for FakeConsole {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A stored preset's or cue's levels as the console read them (a one-digit level is
/// tens there), as (channel, parameter) -> percent.
fn stored(levels: &serde_json::Value) -> BTreeMap<(u32, String), f64> {
    let mut out = BTreeMap::new();
    for (ch, params) in levels.as_object().expect("levels by channel") {
        for (p, v) in params.as_object().expect("levels by parameter") {
            out.insert((ch.parse().unwrap(), p.clone()), v.as_f64().unwrap());
        }
    }
    out
}

/// Waits until the wire shows what the console stored, parameter for parameter within
/// one DMX step, and checks it stored no other parameter.
fn assert_stored_matches_the_wire(d: &Daemon, levels: &serde_json::Value) {
    assert_matches_the_wire(d, &stored(levels), wire_parameters, "stored");
}

#[test]
fn a_preset_reaches_a_tcp_console_as_its_own_user_with_the_wire_levels() {
    for (protocol, user) in [("tcp", Some(7)), ("tcp-slip", None)] {
        let Some(console) = FakeConsole::start(protocol, &["--protocol", protocol]) else {
            return;
        };
        let mut d = export_daemon(&format!("eos-{protocol}"), console.addr, protocol, user);
        let r = d.ok("/vo/eos/preset", vec![int(5)], "/vo/eos/preset");
        assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (5, 6));
        // The default user is 90; nothing went to any other.
        let user = user.unwrap_or(90);
        let lines = console.lines(user);
        assert_eq!(
            console.state()["lines"].as_object().unwrap().len(),
            1,
            "{}",
            console.state()
        );
        assert_every_parameter(&lines, 5);
        assert!(
            lines.iter().any(|l| l == "Chan 4 At 09 Enter"),
            "a light at 9 % is written with a leading zero: {lines:?}"
        );
        assert_lines_match_the_wire(&d, &lines);
        assert_stored_matches_the_wire(&d, &console.state()["presets"]["5"]["levels"]);
    }
}

#[test]
fn a_cue_is_recorded_with_its_time_and_label_and_a_missing_list_is_eoss_error() {
    let Some(console) = FakeConsole::start("eos-cue", &["--protocol", "tcp", "--lists", "1,2"])
    else {
        return;
    };
    let mut d = export_daemon("eos-cue", console.addr, "tcp", None);
    d.ok("/vo/fade", vec![float(2.5)], "/vo/fade");
    let r = d.ok(
        "/vo/eos/cue",
        vec![int(2), float(7.5), common::daemon::string("Act 2 dusk")],
        "/vo/eos/recorded",
    );
    assert_eq!((num(&r.args[0]), num(&r.args[1])), (2.0, 7.5));
    let cue = &console.state()["cues"]["2/7.5"];
    assert_eq!(cue["label"], "Act 2 dusk", "{cue}");
    assert_eq!(cue["time"], 2.5, "{cue}");
    assert_stored_matches_the_wire(&d, &cue["levels"]);
    let lines = console.lines(90);
    assert!(
        lines.contains(&"Chan 1 Thru 6 Record Cue 2/7.5 Enter".to_string()),
        "{lines:?}"
    );

    // A list the console does not have: Eos's own words, and no cue.
    let why = d.err("/vo/eos/cue", vec![int(9), int(1)]);
    assert!(why.contains("Cue List Does Not Exist"), "{why}");
    assert!(why.contains("cue 9/1"), "{why}");
    assert!(console.state()["cues"].get("9/1").is_none());

    // The live look is a saved look: the cue takes its label.
    d.ok(
        "/vo/look/save",
        vec![int(4), common::daemon::string("Storm")],
        "/vo/look/saved",
    );
    d.ok("/vo/eos/cue", vec![int(1), int(3)], "/vo/eos/recorded");
    assert_eq!(console.state()["cues"]["1/3"]["label"], "Storm");
}

#[test]
fn saved_looks_become_cues_in_a_row_over_udp() {
    if !tools::python_osc() {
        return;
    }
    // The console answers to the daemon's OSC port (its OSC TX), so the daemon starts
    // first, pointed at a console port picked now.
    let console_port =
        common::daemon::free_port(common::daemon::LOCALHOST, common::daemon::LOCALHOST);
    let addr: std::net::SocketAddr = ([127, 0, 0, 1], console_port).into();
    let mut d = export_daemon("eos-udp", addr, "udp", Some(12));
    let (tx, port) = (d.port.to_string(), console_port.to_string());
    let Some(console) = FakeConsole::start(
        "eos-udp",
        &["--protocol", "udp", "--tx", &tx, "--port", &port],
    ) else {
        return;
    };
    assert_eq!(console.addr, addr);
    d.ok(
        "/vo/look/save",
        vec![int(1), common::daemon::string("One")],
        "/vo/look/saved",
    );
    d.ok("/vo/light/4/intensity", vec![float(1.0)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(2), common::daemon::string("Two")],
        "/vo/look/saved",
    );
    // One /vo/eos/recorded per cue, in order.
    let mut replies = d.call("/vo/eos/cues", vec![int(1), int(10)], "/vo/eos/recorded");
    replies.extend(d.collect("/vo/eos/recorded", PATIENCE, "the second cue"));
    let numbers: Vec<f64> = replies.iter().map(|r| num(&r.args[1])).collect();
    assert_eq!(numbers, [10.0, 11.0]);
    let cues = &console.state()["cues"];
    assert_eq!(cues["1/10"]["label"], "One", "{cues}");
    assert_eq!(cues["1/11"]["label"], "Two", "{cues}");
    assert_eq!(cues["1/10"]["levels"]["4"]["At"], 9.0, "{cues}");
    assert_eq!(cues["1/11"]["levels"]["4"]["At"], 100.0, "{cues}");
}

#[test]
fn a_console_that_does_not_answer_is_an_error_not_a_success() {
    let Some(console) = FakeConsole::start("eos-silent", &["--protocol", "tcp", "--silent"]) else {
        return;
    };
    let extra = format!(
        "\n[eos]\naddress = \"{}\"\nprotocol = \"tcp\"\ntimeout_s = 0.5\n",
        console.addr
    );
    let mut d = Daemon::start_with("eos-silent", &extra);
    let why = d.err("/vo/eos/preset", vec![int(3)]);
    assert!(
        why.contains("did not confirm preset 3 within 0.5 s"),
        "{why}"
    );
    // It was sent, it is just not confirmed.
    assert!(!console.lines(90).is_empty());

    // A console that is not listening: a clear error, nothing changes.
    let closed = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let extra = format!("\n[eos]\naddress = \"{closed}\"\nprotocol = \"tcp\"\n");
    let mut d = Daemon::start_with("eos-closed", &extra);
    d.refused("/vo/eos/preset", vec![int(1)]);
}

#[test]
fn a_bad_eos_user_is_refused_at_start() {
    let dir = temp_dir("eos-bad-user");
    let config = dir.join("c.toml");
    std::fs::write(&config, "[eos]\nuser = 0\n").unwrap();
    let out = std::process::Command::new(common::bin())
        .arg("check")
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("eos.user must be 1..=99"), "{err}");
}

/// The moving lights' scene: an irgb (channel 1) and two movers (7 and 8, intensity and
/// 16-bit pan and tilt) whose first positions are palette 3 (light 7) and palette 5
/// (light 8), written under `dir`.
pub fn mover_scene(dir: &std::path::Path) -> PathBuf {
    let lights: Vec<TestLight> = [(1, "irgb", 1), (7, "spot", 40), (8, "spot", 50)]
        .into_iter()
        .enumerate()
        .map(|(i, (channel, profile, address))| TestLight {
            channel,
            group: None,
            profile,
            universe: 1,
            address,
            pixel: Box::new(move |x, _| if x / 16 == i { [0.5; 3] } else { [0.0; 3] }),
        })
        .collect();
    let scene = write_scene(&dir.join("mover-scene"), 48, 20, &[], &lights);
    let toml = scene.join("scene.toml");
    let mut text = std::fs::read_to_string(&toml).unwrap();
    for (ch, positions) in MOVERS {
        let basis = format!("basis = \"basis/{ch:03}.exr\"\n");
        let block = format!("channel = {ch}\n{basis}");
        assert!(text.contains(&block), "{text}");
        text = text.replacen(&block, &format!("channel = {ch}\n"), 1);
        let address = format!("address = {}\n", if ch == 7 { 40 } else { 50 });
        let mut tables = address.clone();
        for (palette, name, pan, tilt) in positions {
            tables += &format!(
                "[[light.position]]\npalette = {palette}\nname = \"{name}\"\npan = {pan}\n\
                 tilt = {tilt}\nbasis = \"basis/{ch:03}.exr\"\n"
            );
        }
        let at = text.find(&format!("channel = {ch}\n")).unwrap();
        let end = at + text[at..].find(&address).unwrap();
        text.replace_range(end..end + address.len(), &tables);
    }
    text += "\n[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n";
    std::fs::write(&toml, text).unwrap();
    scene
}

/// A position of a test mover: palette, name, pan, tilt.
pub type TestPosition = (u32, &'static str, f64, f64);

/// The movers of [`mover_scene`]: channel, then its positions.
pub const MOVERS: [(u32, [TestPosition; 2]); 2] = [
    (
        7,
        [(3, "DS centre", -12.5, 41.0), (5, "US wide", 30.0, -7.25)],
    ),
    (
        8,
        [(5, "US wide", 5.0, -7.25), (3, "DS centre", 60.0, 20.0)],
    ),
];

/// A daemon on [`mover_scene`] with `extra` config, every light at half.
pub fn mover_daemon(name: &str, extra: &str) -> Daemon {
    let dir = temp_dir(&format!("{name}-scene"));
    let mut d = Daemon::start_setup(
        name,
        Setup {
            extra: extra.to_string(),
            scene_from: Some(mover_scene(&dir)),
            ..Setup::default()
        },
    );
    for ch in [1, 7, 8] {
        d.ok(
            &format!("/vo/light/{ch}/intensity"),
            vec![float(0.5)],
            "/vo/light",
        );
    }
    d
}

#[test]
fn a_movers_position_is_its_focus_palette_where_the_console_has_it_and_pan_and_tilt_else() {
    // The console has palette 3 (light 7's first position), not 5 (light 8's).
    let Some(console) = FakeConsole::start(
        "eos-movers",
        &["--protocol", "tcp", "--fp", "3=DS centre=7-8"],
    ) else {
        return;
    };
    let extra = format!(
        "\n[eos]\naddress = \"{}\"\nprotocol = \"tcp\"\n",
        console.addr
    );
    let mut d = mover_daemon("eos-movers", &extra);
    d.ok("/vo/eos/preset", vec![int(4)], "/vo/eos/preset");
    let lines = console.lines(90);
    assert!(
        lines.iter().any(|l| l == "Chan 7 Focus_Palette 3 Enter"),
        "{lines:?}"
    );
    // Pan 5 and tilt -7.25 with a leading zero on the one-digit whole part.
    assert!(
        lines.iter().any(|l| l == "Chan 8 Pan 05 Tilt -07.25 Enter"),
        "{lines:?}"
    );
    assert!(
        !lines.iter().any(|l| l.starts_with("Chan 1 Pan")),
        "{lines:?}"
    );
    let stored = &console.state()["presets"]["4"]["levels"];
    assert_eq!(stored["7"]["Focus_Palette"], 3.0, "{stored}");
    assert_eq!(stored["7"].get("Pan"), None, "{stored}");
    // What the console read back is the scene's position, in degrees.
    let (_, positions) = MOVERS[1];
    assert_eq!(
        stored["8"]["Pan"].as_f64(),
        Some(positions[0].2),
        "{stored}"
    );
    assert_eq!(
        stored["8"]["Tilt"].as_f64(),
        Some(positions[0].3),
        "{stored}"
    );
    assert_eq!(
        stored["1"].get("Pan"),
        None,
        "a fixed light has no position: {stored}"
    );
}

#[test]
fn without_the_consoles_palettes_every_position_goes_as_pan_and_tilt() {
    // The console has no focus palettes.
    let Some(console) = FakeConsole::start("eos-movers-none", &["--protocol", "tcp"]) else {
        return;
    };
    let extra = format!(
        "\n[eos]\naddress = \"{}\"\nprotocol = \"tcp\"\n",
        console.addr
    );
    let mut d = mover_daemon("eos-movers-none", &extra);
    let r = d.ok("/vo/eos/cue", vec![int(1), int(2)], "/vo/eos/recorded");
    assert_eq!(num(&r.args[1]), 2.0);
    let lines = console.lines(90);
    for want in [
        "Chan 7 Pan -12.5 Tilt 41 Enter",
        "Chan 8 Pan 05 Tilt -07.25 Enter",
    ] {
        assert!(lines.iter().any(|l| l == want), "{want}: {lines:?}");
    }
    assert!(
        !lines.iter().any(|l| l.contains("Focus_Palette")),
        "{lines:?}"
    );
    let stored = &console.state()["cues"]["1/2"]["levels"];
    assert_eq!(stored["7"]["Pan"], -12.5, "{stored}");
    assert_eq!(stored["7"]["Tilt"], 41.0, "{stored}");
}
