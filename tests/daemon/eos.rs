//! Export to Eos for the demo stage (44 fixed lights and 6 movers): the exact command
//! lines of a preset (how they reach a console and are confirmed: daemon_eos.rs).

use std::path::Path;

use visobjd::eos::commands::preset_commands;
use visobjd_scene::Scene;
use visobjd_scene::look::{Level, Look};

#[test]
fn a_44_light_look_arrives_as_exact_command_lines() {
    let scene = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/demo"
    )))
    .unwrap();
    let n = scene.lights.len();
    assert_eq!(n, 50);
    let mut look = Look::off(n);
    for (i, lv) in look.levels.iter_mut().enumerate() {
        *lv = Level {
            // The 44 fixed lights from 0 to full, the movers (45-50) at full.
            intensity: (i as f32 / 43.0).min(1.0),
            color: if scene.profile(i).has_colour() {
                [1.0, 0.5, 0.0]
            } else {
                [1.0; 3]
            },
            position: None,
        };
    }
    let lines = preset_commands(&scene, &look, 7, &Default::default());
    let colour = (0..n).filter(|&i| scene.profile(i).has_colour()).count();
    let movers = scene.lights.iter().filter(|l| l.is_moving()).count();
    assert_eq!(lines.len(), n + colour + movers + 1);
    assert_eq!(lines[0], "Chan 1 At 0 Enter");
    // Levels are the wire's: 8-bit bytes as percent with one decimal.
    let has = |l: &str| assert!(lines.contains(&l.to_string()), "{l}: {lines:?}");
    // Channel 22 is an rgb light at 21/43: no dimmer, so intensity is folded into the
    // emitters (bytes 125, 27, 0) and the channel's own intensity stays at full.
    has("Chan 22 At 100 Enter");
    has("Chan 22 Red 49 Green 10.6 Blue 0 Enter");
    // sRGB 0.5 is byte 55 (21.6%) behind a dimmer, as on DMX; rgbw adds its white.
    // The demo's profiles come from its MVR's GDTF types: found by the built-in's slots.
    let first = |p: &str| {
        let slots = visobjd_scene::profile::Profile::built_in(p).unwrap().slots;
        let i = (0..n).find(|&i| scene.profile(i).slots == slots).unwrap();
        (scene.lights[i].channel, i)
    };
    let (ch, i) = first("irgb");
    has(&format!("Chan {ch} Red 100 Green 21.6 Blue 0 Enter"));
    let byte = ((i as f32 / 43.0) * 255.0).round();
    let at = format!("{:.1}", byte / 2.55);
    has(&format!(
        "Chan {ch} At {} Enter",
        at.trim_end_matches('0').trim_end_matches('.')
    ));
    let (ch, _) = first("rgbw");
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with(&format!("Chan {ch} Red ")) && l.ends_with(" White 0 Enter")),
        "{lines:?}"
    );
    assert_eq!(
        lines.last().unwrap(),
        "Chan 1 Thru 50 Record Preset 7 Enter"
    );
}
