//! Storing into a grandMA3 against a fake OSC input (tests/peers/fake_ma3.py: MA3's
//! command syntax, a programmer, presets and cues; it answers nothing, as MA3 does): the
//! values it stored are checked against the DMX on the wire; the exported plugin's XML is
//! read by Python's parser and its Lua run under a stock Lua interpreter with a stub of
//! MA3's `Cmd`, its commands replayed on the same fake.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::common::bin;
use crate::common::daemon::{Daemon, Osc, PATIENCE, float, int, num, string, text};
use crate::daemon_eos::{assert_matches_the_wire, export_daemon_with, wire_parameters};
use visobjd_testkit::{temp_dir, tools};

fn peer() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/peers/fake_ma3.py")
}

/// The fake desk on a loopback UDP port; killed when dropped.
struct FakeMa3 {
    child: std::process::Child,
    port: u16,
    state: PathBuf,
}

impl FakeMa3 {
    /// Starts it; `None` (after [`tools::missing`]) without python-osc.
    fn start(name: &str) -> Option<FakeMa3> {
        if !tools::python_osc() {
            return None;
        }
        let state = temp_dir(&format!("{name}-desk")).join("state.json");
        let mut command = Command::new("python3");
        command.arg(peer()).arg("--state").arg(&state);
        let (child, port) = crate::common::start_peer(command, "the fake grandMA3");
        Some(FakeMa3 { child, port, state })
    }

    /// Its state once it has taken `n` commands in all (UDP arrives on its own time).
    fn state_after(&self, n: usize) -> serde_json::Value {
        let end = Instant::now() + PATIENCE;
        loop {
            let state = read_state(&self.state);
            let got = state["commands"].as_array().map_or(0, Vec::len);
            if got >= n {
                return state;
            }
            assert!(Instant::now() < end, "the desk took {got} of {n} commands");
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }
}

impl Drop for FakeMa3 {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn read_state(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).expect("the fake desk's state");
    serde_json::from_str(&text).expect("the fake desk's state is JSON")
}

/// MA3's attribute for each exported Eos parameter of the test stage.
fn ma3_name(eos: &str) -> &'static str {
    match eos {
        "At" => "Dimmer",
        "Red" => "ColorAdd_R",
        "Green" => "ColorAdd_G",
        "Blue" => "ColorAdd_B",
        "White" => "ColorAdd_W",
        "Amber" => "ColorAdd_RY",
        "Lime" => "ColorAdd_GY",
        "Cyan" => "ColorSub_C",
        "Magenta" => "ColorSub_M",
        "Yellow" => "ColorSub_Y",
        other => panic!("no MA3 attribute for {other}"),
    }
}

/// Waits until the wire shows what the desk stored (`values`: fixture -> attribute ->
/// percent), attribute for attribute within one DMX step, and that it stored no other.
fn assert_stored_matches_the_wire(d: &Daemon, values: &serde_json::Value) {
    let stored: BTreeMap<(u32, String), f64> = values
        .as_object()
        .expect("values by fixture")
        .iter()
        .flat_map(|(f, attrs)| {
            attrs
                .as_object()
                .expect("values by attribute")
                .iter()
                .map(move |(a, v)| ((f.parse().unwrap(), a.clone()), v.as_f64().unwrap()))
        })
        .collect();
    // Eos's parameters in MA3's names; a light without a dimmer has no Dimmer on MA3 (its
    // emitters carry it).
    let wire = |universe, dmx: &[u8]| {
        wire_parameters(universe, dmx)
            .into_iter()
            .filter(|((_, p), _, tol)| !(p == "At" && *tol == 0.0))
            .map(|((ch, p), want, tol)| ((ch, ma3_name(&p).to_string()), want, tol))
            .collect()
    };
    assert_matches_the_wire(d, &stored, wire, "the desk holds");
}

fn ma3_daemon(name: &str, desk: &FakeMa3) -> Daemon {
    export_daemon_with(
        name,
        &format!("\n[ma3]\naddress = \"127.0.0.1:{}\"\n", desk.port),
    )
}

#[test]
fn a_preset_and_a_cue_reach_the_desk_as_ma3_commands_with_the_wire_values() {
    let Some(desk) = FakeMa3::start("ma3-osc") else {
        return;
    };
    let mut d = ma3_daemon("ma3-osc", &desk);
    let r = d.ok(
        "/vo/ma3/preset",
        vec![string("21.5"), string("Dusk")],
        "/vo/ma3/sent",
    );
    assert_eq!(text(&r.args[0]), "Preset 21.5");
    let state = desk.state_after(num(&r.args[1]) as usize);
    assert_eq!(state["errors"], serde_json::json!([]), "{state}");
    assert_eq!(state["presets"]["21.5"]["label"], "Dusk");
    assert_stored_matches_the_wire(&d, &state["presets"]["21.5"]["values"]);
    // What it set is out of the programmer again.
    assert_eq!(state["programmer"], serde_json::json!({}), "{state}");
    let sent = num(&r.args[1]) as usize;

    d.ok("/vo/fade", vec![float(2.5)], "/vo/fade");
    let r = d.ok("/vo/ma3/cue", vec![int(901), int(3)], "/vo/ma3/sent");
    assert_eq!(text(&r.args[0]), "Sequence 901 Cue 3");
    let state = desk.state_after(sent + num(&r.args[1]) as usize);
    assert_eq!(state["errors"], serde_json::json!([]), "{state}");
    assert_eq!(state["cues"]["901/3"]["fade"], 2.5);
    assert_stored_matches_the_wire(&d, &state["cues"]["901/3"]["values"]);
    let mut sent = sent + num(&r.args[1]) as usize;

    // A float from a tablet is read to three decimals.
    let r = d.ok("/vo/ma3/preset", vec![float(21.1)], "/vo/ma3/sent");
    assert_eq!(text(&r.args[0]), "Preset 21.1");
    sent += num(&r.args[1]) as usize;
    let why = d.refused("/vo/ma3/preset", vec![string("21")]);
    assert!(why.contains("POOL.NUMBER"), "{why}");

    // A light whose MA3 fixture ID is not its channel (`ma3_id`), after a reload; two
    // lights with one ID are refused.
    let toml = d.dir.join("scene/scene.toml");
    let scene = std::fs::read_to_string(&toml).unwrap();
    let with_id =
        |id: u32| scene.replacen("channel = 6\n", &format!("channel = 6\nma3_id = {id}\n"), 1);
    std::fs::write(&toml, with_id(5)).unwrap();
    let why = d.err("/vo/reload", vec![]);
    assert!(why.contains("both have grandMA3 fixture ID 5"), "{why}");
    std::fs::write(&toml, with_id(106)).unwrap();
    d.ok("/vo/reload", vec![], "/vo/reloaded");
    let r = d.ok("/vo/ma3/preset", vec![string("21.6")], "/vo/ma3/sent");
    let state = desk.state_after(sent + num(&r.args[1]) as usize);
    let values = &state["presets"]["21.6"]["values"];
    assert!(
        values.get("106").is_some() && values.get("6").is_none(),
        "{values}"
    );
}

#[test]
fn the_exported_plugin_stores_the_saved_looks_with_the_same_commands() {
    if !tools::lua() {
        return;
    }
    let Some(desk) = FakeMa3::start("ma3-plugin") else {
        return;
    };
    let mut d = ma3_daemon("ma3-plugin", &desk);
    d.ok(
        "/vo/look/save",
        vec![int(1), string("One")],
        "/vo/look/saved",
    );
    d.ok("/vo/light/4/intensity", vec![float(1.0)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(2), string("It's two")],
        "/vo/look/saved",
    );

    let out = temp_dir("ma3-plugin-out");
    let run = Command::new(bin())
        .args(["export", "ma3", "--scene"])
        .arg(d.dir.join("scene"))
        .arg("--looks")
        .arg(d.state_dir().join("looks.json"))
        .arg("--out")
        .arg(&out)
        .args(["--sequence", "901", "--time", "3"])
        .output()
        .expect("run visobjd export ma3");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );

    // The XML is well formed and names the Lua file, which is there.
    let xml = Command::new("python3")
        .args([
            "-c",
            "import sys, xml.etree.ElementTree as E; r = E.parse(sys.argv[1]).getroot(); \
             print(r.tag, r.find('UserPlugin/ComponentLua').get('FileName'))",
        ])
        .arg(out.join("visobjd_looks.xml"))
        .output()
        .expect("python3 reads the XML");
    assert!(
        xml.status.success(),
        "{}",
        String::from_utf8_lossy(&xml.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&xml.stdout).trim(),
        "GMA3 visobjd_looks.lua"
    );

    // The Lua under a stock interpreter, MA3's Cmd stubbed: its commands, replayed.
    let runner = out.join("runner.lua");
    std::fs::write(
        &runner,
        "function Cmd(c) io.write(c, '\\n') end\nlocal main = dofile(arg[1])\nmain()\n",
    )
    .unwrap();
    let lua = Command::new("lua")
        .arg(&runner)
        .arg(out.join("visobjd_looks.lua"))
        .output()
        .expect("run lua");
    assert!(
        lua.status.success(),
        "{}",
        String::from_utf8_lossy(&lua.stderr)
    );
    let commands = out.join("commands.txt");
    std::fs::write(&commands, &lua.stdout).unwrap();
    let replayed = out.join("replayed.json");
    let replay = Command::new("python3")
        .arg(peer())
        .arg("--replay")
        .arg(&commands)
        .arg("--state")
        .arg(&replayed)
        .status()
        .expect("replay on the fake desk");
    assert!(replay.success());
    let plugin = read_state(&replayed);
    assert_eq!(plugin["errors"], serde_json::json!([]), "{plugin}");
    assert_eq!(plugin["cues"]["901/1"]["label"], "One");
    assert_eq!(plugin["cues"]["901/2"]["label"], "It's two");
    assert_eq!(plugin["cues"]["901/2"]["fade"], 3.0);
    assert_eq!(plugin["cues"]["901/2"]["values"]["4"]["Dimmer"], 100.0);

    // The live look is saved look 2: over OSC it stores what the plugin stores.
    d.ok("/vo/fade", vec![float(3.0)], "/vo/fade");
    let r = d.ok("/vo/ma3/cue", vec![int(901), int(2)], "/vo/ma3/sent");
    let live = desk.state_after(num(&r.args[1]) as usize);
    assert_eq!(live["cues"]["901/2"], plugin["cues"]["901/2"]);
    assert_stored_matches_the_wire(&d, &plugin["cues"]["901/2"]["values"]);
}

#[test]
fn a_movers_position_reaches_the_desk_as_its_position_preset() {
    let Some(desk) = FakeMa3::start("ma3-movers") else {
        return;
    };
    let extra = format!("\n[ma3]\naddress = \"127.0.0.1:{}\"\n", desk.port);
    let mut d = crate::daemon_eos::mover_daemon("ma3-movers", &extra);
    let r = d.ok("/vo/ma3/preset", vec![string("21.2")], "/vo/ma3/sent");
    let state = desk.state_after(num(&r.args[1]) as usize);
    assert_eq!(state["errors"], serde_json::json!([]), "{state}");
    let commands: Vec<&str> = state["commands"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c.as_str())
        .collect();
    for want in ["Fixture 7 At Preset 2.3", "Fixture 8 At Preset 2.5"] {
        assert!(commands.contains(&want), "{want}: {commands:?}");
    }
    let values = &state["presets"]["21.2"]["values"];
    assert_eq!(values["7"]["Preset"], "2.3", "{values}");
    assert_eq!(values["8"]["Preset"], "2.5", "{values}");
    // A fixed light has no position; nothing of pan or tilt goes as an attribute.
    assert_eq!(values["1"].get("Preset"), None, "{values}");
    assert!(
        !commands
            .iter()
            .any(|c| c.contains("\"Pan\"") || c.contains("\"Tilt\"")),
        "{commands:?}"
    );
}
