//! Export to Eos for the 44-light demo stage: the exact command lines a fake console
//! receives over TCP (OSC 1.0 framing), recorded as a preset.

use std::io::Read;
use std::net::TcpListener;
use std::path::Path;

use rosc::{OscPacket, OscType};
use visobjd::eos::{EosConfig, Protocol, preset_commands, push};
use visobjd_scene::Scene;
use visobjd_scene::look::{Level, Look};

#[test]
fn a_44_light_look_arrives_as_exact_command_lines() {
    let scene = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenes/demo"
    )))
    .unwrap();
    assert_eq!(scene.lights.len(), 44);
    let mut look = Look::off(44);
    for (i, lv) in look.levels.iter_mut().enumerate() {
        *lv = Level {
            intensity: i as f32 / 43.0,
            color: if scene.profile(i).has_colour() {
                [1.0, 0.5, 0.0]
            } else {
                [1.0; 3]
            },
        };
    }
    let console = TcpListener::bind("127.0.0.1:0").unwrap();
    let config = EosConfig {
        address: console.local_addr().unwrap().to_string(),
        protocol: Protocol::Tcp,
    };
    let commands = preset_commands(&scene, &look, 7);
    push(&config, console.local_addr().unwrap(), &commands).unwrap();
    let (mut stream, _) = console.accept().unwrap();
    let mut bytes = Vec::new();
    stream.read_to_end(&mut bytes).unwrap();
    // Length-prefixed packets, each an /eos/newcmd with one string.
    let mut lines = Vec::new();
    let mut rest = bytes.as_slice();
    while !rest.is_empty() {
        let n = u32::from_be_bytes([rest[0], rest[1], rest[2], rest[3]]) as usize;
        match rosc::decoder::decode_udp(&rest[4..4 + n]).unwrap().1 {
            OscPacket::Message(m) if m.addr == "/eos/newcmd" => match m.args.as_slice() {
                [OscType::String(s)] => lines.push(s.clone()),
                other => panic!("{other:?}"),
            },
            other => panic!("{other:?}"),
        }
        rest = &rest[4 + n..];
    }
    let colour = (0..44).filter(|&i| scene.profile(i).has_colour()).count();
    assert_eq!(lines.len(), 44 + colour + 1);
    assert_eq!(lines[0], "Chan 1 At 0 Enter");
    assert!(
        lines.contains(&"Chan 44 At 100 Enter".to_string()),
        "{lines:?}"
    );
    assert!(
        lines.contains(&"Chan 22 At 48.8 Enter".to_string()),
        "{lines:?}"
    );
    // sRGB 0.5 is 21.4% emitter level (linear), as on DMX.
    let first_colour = (0..44).find(|&i| scene.profile(i).has_colour()).unwrap();
    let ch = scene.lights[first_colour].channel;
    assert!(
        lines.contains(&format!("Chan {ch} Red 100 Green 21.4 Blue 0 Enter")),
        "{lines:?}"
    );
    assert_eq!(
        lines.last().unwrap(),
        "Chan 1 Thru 44 Record Preset 7 Enter"
    );
    assert_eq!(lines, commands);
}
