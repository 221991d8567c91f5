//! The prototype's constraints and moves of docs/osc.md against the real daemon: ratios,
//! saturation ranges, exclusions, pins and transfers, checked in every candidate of a
//! generate, on the wire, across a restart, and refused (changing nothing) when hostile.

use crate::common;
use crate::common::daemon::{Daemon, LightLevel, Osc, PROTOS, float, int, num, same_look, string};
use rosc::{OscMessage, OscType};

/// Ratios are held to this in every candidate (docs/method.md).
const RATIO_TOLERANCE: f32 = 1e-4;

/// The `/vo/constraint` and `/vo/pin` messages of `/vo/constraints` (the count checked).
fn constraints(d: &mut Daemon) -> Vec<OscMessage> {
    let mut got = d.call("/vo/constraints", vec![], "/vo/constraints/end");
    let end = got.pop().expect("a reply");
    assert_eq!(end.addr, "/vo/constraints/end", "{end:?}");
    assert_eq!(num(&end.args[0]) as usize, got.len(), "count: {end:?}");
    got
}

/// Every candidate of the gallery, as (entry, member, look).
fn candidates(d: &mut Daemon) -> Vec<(i32, i32, Vec<LightLevel>)> {
    let sizes = d.gallery();
    assert!(!sizes.is_empty(), "a gallery");
    let mut out = Vec::new();
    for (k, &size) in sizes.iter().enumerate() {
        for m in 1..=size {
            let k = k as i32 + 1;
            out.push((k, m, d.candidate(k, m)));
        }
    }
    out
}

fn by_ch(look: &[LightLevel], ch: i32) -> LightLevel {
    look.iter()
        .find(|l| l.ch == ch)
        .expect("a stage light")
        .clone()
}

fn mean(look: &[LightLevel], chs: &[i32]) -> f32 {
    chs.iter().map(|&c| by_ch(look, c).intensity).sum::<f32>() / chs.len() as f32
}

/// HSV saturation of an sRGB colour, written out here on purpose.
fn hsv_saturation(c: [f32; 3]) -> f32 {
    let max = c[0].max(c[1]).max(c[2]);
    let min = c[0].min(c[1]).min(c[2]);
    if max <= 0.0 { 0.0 } else { (max - min) / max }
}

/// A base look with distinct levels and colours, set by faders.
fn set_base(d: &mut Daemon) -> Vec<LightLevel> {
    d.ok("/vo/fade", vec![float(0.0)], "/vo/fade");
    for (ch, v) in [(1, 0.3), (2, 0.7), (3, 0.45), (4, 0.55), (5, 0.2), (6, 0.9)] {
        d.ok(
            &format!("/vo/light/{ch}/intensity"),
            vec![float(v)],
            "/vo/light",
        );
    }
    for (ch, c) in [
        (3, [0.9, 0.5, 0.1]),
        (4, [0.1, 0.4, 0.8]),
        (5, [0.8, 0.8, 0.2]),
        (6, [0.3, 0.9, 0.6]),
    ] {
        d.ok(
            &format!("/vo/light/{ch}/color"),
            c.map(float).to_vec(),
            "/vo/light",
        );
    }
    d.live()
}

#[test]
fn ratio_saturation_and_off_hold_in_every_candidate_on_the_wire_and_after_a_restart() {
    let mut d = Daemon::start("cons-hold");
    set_base(&mut d);
    d.add_objective("warm.png", "both");
    let r = d.ok(
        "/vo/group/back/ratio",
        vec![string("FRONT"), float(0.5)],
        "/vo/group/ratio",
    );
    assert_eq!(
        r.args,
        vec![string("back"), string("front"), OscType::Float(0.5)]
    );
    let r = d.ok(
        "/vo/group/side/saturation",
        vec![float(0.2), float(0.5)],
        "/vo/group/saturation",
    );
    assert_eq!(
        r.args,
        vec![string("side"), OscType::Float(0.2), OscType::Float(0.5)]
    );
    let r = d.ok(
        "/vo/light/2/exclude",
        vec![string("off")],
        "/vo/light/exclude",
    );
    assert_eq!(r.args, vec![int(2), string("off")]);
    let check = |d: &mut Daemon| {
        d.generate();
        let all = candidates(d);
        assert!(all.len() > 5, "{} candidates", all.len());
        for (k, m, look) in &all {
            let (front, back) = (mean(look, &[1, 2]), mean(look, &[5, 6]));
            assert!(
                (back - 0.5 * front).abs() <= RATIO_TOLERANCE,
                "{k}.{m}: back {back} is not half of front {front}: {look:?}"
            );
            assert_eq!(by_ch(look, 2).intensity, 0.0, "{k}.{m}: light 2 is off");
            for ch in [3, 4] {
                let s = hsv_saturation(by_ch(look, ch).color);
                assert!(
                    (0.2 - 1e-5..=0.5 + 1e-5).contains(&s),
                    "{k}.{m}: light {ch} saturation {s}: {look:?}"
                );
            }
        }
        // Front varies across candidates: the ratio follows it rather than freezing it.
        let fronts: Vec<f32> = all.iter().map(|(_, _, l)| mean(l, &[1, 2])).collect();
        assert!(
            fronts.iter().any(|&f| (f - fronts[0]).abs() > 0.01),
            "{fronts:?}"
        );
    };
    // A fixed seed (kept across the restart): with a random one, about one draw in forty
    // puts light 1 at full in every candidate, and "front varies" then cannot hold.
    d.ok("/vo/generate/seed", vec![int(11)], "/vo/generate/seed");
    check(&mut d);
    // On the wire: the picked candidate, light 2 at 0, decoded independently.
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let live = d.live();
    assert!(same_look(&live, &d.candidate(1, 1), 0.0));
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    let listed = constraints(&mut d);
    let want = [
        (
            "/vo/group/side/saturation",
            vec![OscType::Float(0.2), OscType::Float(0.5)],
        ),
        (
            "/vo/group/back/ratio",
            vec![string("front"), OscType::Float(0.5)],
        ),
        ("/vo/light/2/exclude", vec![string("off")]),
    ];
    assert_eq!(listed.len(), want.len(), "{listed:?}");
    for (addr, args) in want {
        let mut a = vec![string(addr)];
        a.extend(args);
        assert!(
            listed
                .iter()
                .any(|m| m.addr == "/vo/constraint" && m.args == a),
            "{addr} is not listed: {listed:?}"
        );
    }
    d.kill();
    d.restart();
    assert_eq!(constraints(&mut d), listed, "kept across the restart");
    check(&mut d);
    // Removing them: ratio 0, the whole range, none.
    d.ok(
        "/vo/group/back/ratio",
        vec![string("front"), int(0)],
        "/vo/group/ratio",
    );
    d.ok(
        "/vo/group/side/saturation",
        vec![int(0), int(1)],
        "/vo/group/saturation",
    );
    d.ok(
        "/vo/light/2/exclude",
        vec![string("none")],
        "/vo/light/exclude",
    );
    assert!(constraints(&mut d).is_empty());
}

#[test]
fn ignored_and_pinned_lights_keep_the_base_and_pins_survive_a_restart() {
    let mut d = Daemon::start("cons-pins");
    let base = set_base(&mut d);
    d.add_objective("cool.png", "both");
    let r = d.ok(
        "/vo/group/front/exclude",
        vec![string("ignore")],
        "/vo/group/exclude",
    );
    assert_eq!(r.args, vec![string("front"), string("ignore")]);
    // Lights light 8-pixel stripes of a 48-pixel stage: x 0.5..0.84 holds lights 4 and 5.
    let r = d.ok(
        "/vo/pin/add",
        [0.5, 0.0, 0.84, 1.0].map(float).to_vec(),
        "/vo/pin/added",
    );
    assert_eq!(r.args, vec![int(1), int(4), int(5)]);
    let pins = d.call("/vo/pins", vec![], "/vo/pins/end");
    assert_eq!(pins.len(), 2, "{pins:?}");
    assert_eq!(pins[0].addr, "/vo/pin");
    assert_eq!(pins[0].args[0], int(1));
    assert_eq!(pins[0].args[5..], [int(4), int(5)]);
    assert_eq!(pins[1].args, vec![int(1)]);
    d.kill();
    d.restart();
    assert_eq!(
        d.call("/vo/pins", vec![], "/vo/pins/end"),
        pins,
        "pins kept across the restart"
    );
    d.generate();
    let mut moved = [false; 7];
    for (k, m, look) in candidates(&mut d) {
        for ch in 1..=6 {
            let (got, want) = (by_ch(&look, ch), by_ch(&base, ch));
            if [1, 2, 4, 5].contains(&ch) {
                assert_eq!(
                    (got.intensity.to_bits(), got.color.map(f32::to_bits)),
                    (want.intensity.to_bits(), want.color.map(f32::to_bits)),
                    "{k}.{m}: light {ch} is ignored or pinned: {got:?} vs {want:?}"
                );
            }
            moved[ch as usize] |= got != want;
        }
    }
    assert_eq!(moved[1..], [false, false, true, false, false, true]);
    let r = d.ok("/vo/pin/1/remove", vec![], "/vo/pin/removed");
    assert_eq!(r.args, vec![int(1)]);
    assert_eq!(
        d.call("/vo/pins", vec![], "/vo/pins/end"),
        vec![rosc::OscMessage {
            addr: "/vo/pins/end".into(),
            args: vec![int(0)]
        }]
    );
    // A new pin never reuses the number.
    let r = d.ok(
        "/vo/pin/add",
        [0.0, 0.0, 0.3, 1.0].map(float).to_vec(),
        "/vo/pin/added",
    );
    assert_eq!(r.args[0], int(2));
}

#[test]
fn transfer_takes_a_group_or_a_region_with_the_fade_as_an_undo_step() {
    let mut d = Daemon::start("cons-transfer");
    let before = set_base(&mut d);
    d.add_objective("warm.png", "both");
    d.generate();
    let k = d.gallery().len().min(2) as i32;
    let from = d.candidate(k, 1);
    let r = d.ok(
        "/vo/transfer",
        vec![int(k), string("group"), string("Side")],
        "/vo/transferred",
    );
    assert_eq!(r.args, vec![int(k), int(3), int(4)]);
    let live = d.live();
    for ch in 1..=6 {
        let want = if [3, 4].contains(&ch) {
            by_ch(&from, ch)
        } else {
            by_ch(&before, ch)
        };
        assert_eq!(by_ch(&live, ch), want, "light {ch}");
    }
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    assert_eq!(d.status().entry, 0, "a transfer is no gallery entry");
    // x 0..0.33 of the stage holds lights 1 and 2.
    let r = d.ok(
        "/vo/transfer",
        [int(1), string("region")]
            .into_iter()
            .chain([0.0, 0.0, 0.33, 1.0].map(float))
            .collect(),
        "/vo/transferred",
    );
    assert_eq!(r.args, vec![int(1), int(1), int(2)]);
    let one = d.candidate(1, 1);
    let after = d.live();
    for ch in 1..=6 {
        let want = match ch {
            1 | 2 => by_ch(&one, ch),
            _ => by_ch(&live, ch),
        };
        assert_eq!(by_ch(&after, ch), want, "light {ch}");
    }
    // Each transfer is one undo step.
    d.ok("/vo/undo", vec![], "/vo/undone");
    assert!(same_look(&d.live(), &live, 0.0));
    d.ok("/vo/undo", vec![], "/vo/undone");
    assert!(same_look(&d.live(), &before, 0.0));
    for proto in PROTOS {
        d.wire.wait_look(proto, &before);
    }
}

#[test]
fn hostile_constraints_and_transfers_are_refused_and_change_nothing() {
    let mut d = Daemon::start("cons-hostile");
    set_base(&mut d);
    d.add_objective("warm.png", "both");
    d.refused(
        "/vo/transfer",
        vec![int(1), string("group"), string("side")],
    );
    d.generate();
    d.ok(
        "/vo/group/side/ratio",
        vec![string("back"), float(2.0)],
        "/vo/group/ratio",
    );
    d.ok(
        "/vo/group/front/ratio",
        vec![string("side"), float(0.5)],
        "/vo/group/ratio",
    );
    d.ok(
        "/vo/pin/add",
        [0.0, 0.0, 0.2, 1.0].map(float).to_vec(),
        "/vo/pin/added",
    );
    let kept = constraints(&mut d);
    // The loop is refused with a sentence that names it.
    let sentence = d.refused("/vo/group/back/ratio", vec![string("front"), float(0.5)]);
    assert!(
        sentence.contains("loop") && sentence.contains("side"),
        "names the loop: {sentence}"
    );
    let region = |k: i32, r: [f32; 4]| -> Vec<OscType> {
        [int(k), string("region")]
            .into_iter()
            .chain(r.map(float))
            .collect()
    };
    let cases: Vec<(&str, Vec<OscType>)> = vec![
        // Ratios: a loop (back -> front -> side -> back), itself, bad numbers, unknown groups.
        ("/vo/group/back/ratio", vec![string("front"), float(0.5)]),
        ("/vo/group/back/ratio", vec![string("back"), float(0.5)]),
        ("/vo/group/back/ratio", vec![string("front"), float(-1.0)]),
        ("/vo/group/back/ratio", vec![string("front"), float(101.0)]),
        ("/vo/group/back/ratio", vec![string("front")]),
        ("/vo/group/back/ratio", vec![]),
        ("/vo/group/wings/ratio", vec![string("front"), float(0.5)]),
        ("/vo/group/back/ratio", vec![string("wings"), float(0.5)]),
        // Saturation: reversed, out of range, a dimmer, a group of dimmers, unknown.
        ("/vo/group/side/saturation", vec![float(0.6), float(0.2)]),
        ("/vo/group/side/saturation", vec![float(1.5), float(2.0)]),
        ("/vo/group/side/saturation", vec![float(-0.1), float(0.5)]),
        ("/vo/group/side/saturation", vec![float(0.1)]),
        ("/vo/light/1/saturation", vec![float(0.0), float(0.5)]),
        ("/vo/group/front/saturation", vec![float(0.0), float(0.5)]),
        ("/vo/light/99/saturation", vec![float(0.0), float(0.5)]),
        // Exclude: unknown modes and targets.
        ("/vo/group/side/exclude", vec![string("maybe")]),
        ("/vo/group/side/exclude", vec![int(1)]),
        ("/vo/group/side/exclude", vec![]),
        ("/vo/light/99/exclude", vec![string("off")]),
        ("/vo/group/wings/exclude", vec![string("off")]),
        // Pins: x1 < x0, too few numbers, out of range, a region with no light, no such pin.
        ("/vo/pin/add", [0.6, 0.0, 0.2, 1.0].map(float).to_vec()),
        ("/vo/pin/add", [0.0, 0.0, 1.0].map(float).to_vec()),
        ("/vo/pin/add", [0.0, 0.0, 2.0, 1.0].map(float).to_vec()),
        ("/vo/pin/7/remove", vec![]),
        ("/vo/pin/abc/remove", vec![]),
        // Transfers: no such entry, group or part; x1 < x0; nothing after the entry.
        (
            "/vo/transfer",
            vec![int(99), string("group"), string("side")],
        ),
        (
            "/vo/transfer",
            vec![int(0), string("group"), string("side")],
        ),
        (
            "/vo/transfer",
            vec![int(1), string("group"), string("wings")],
        ),
        ("/vo/transfer", vec![int(1), string("area"), string("side")]),
        ("/vo/transfer", region(1, [0.5, 0.0, 0.2, 1.0])),
        (
            "/vo/transfer",
            region(1, [0.0, 0.0, 0.5, 1.0])[..5].to_vec(),
        ),
        ("/vo/transfer", vec![int(1)]),
    ];
    for (addr, args) in cases {
        let sentence = d.refused(addr, args.clone());
        assert_eq!(
            constraints(&mut d),
            kept,
            "{addr} {args:?} failed ({sentence}) but changed the constraints"
        );
    }
    // A region that holds no pixel centre selects no light: nothing to pin or transfer.
    d.refused("/vo/pin/add", [0.001, 0.0, 0.002, 1.0].map(float).to_vec());
    d.refused("/vo/transfer", region(1, [0.001, 0.0, 0.002, 1.0]));
    assert_eq!(constraints(&mut d), kept);
}

/// The triggers of this family are buttons too: a release (a single 0) gets no reply.
#[test]
fn constraint_queries_ignore_button_releases() {
    let mut d = Daemon::start("cons-buttons");
    d.silent("/vo/constraints", vec![int(0)]);
    d.silent("/vo/pins", vec![float(0.0)]);
    d.silent("/vo/pin/1/remove", vec![int(0)]);
    let pins = d.call("/vo/pins", vec![], "/vo/pins/end");
    assert_eq!((pins.len(), num(&pins[0].args[0])), (1, 0.0), "{pins:?}");
}

/// A session file edited by hand (or from another scene) with constraints this scene cannot
/// take: each is logged and dropped, the file is kept aside, the rest is restored.
#[test]
fn a_session_file_with_impossible_constraints_restores_the_rest() {
    let mut d = Daemon::start("cons-restore");
    d.ok(
        "/vo/group/back/ratio",
        vec![string("front"), float(0.5)],
        "/vo/group/ratio",
    );
    d.kill();
    let path = d.state_dir().join("session.json");
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("session.json")).expect("JSON");
    file["rules"]["ratios"] = serde_json::json!([
        { "group": "back", "of": "front", "ratio": 0.5 },
        // A loop with the first, a group the scene lacks, a ratio out of range.
        { "group": "front", "of": "back", "ratio": 2.0 },
        { "group": "wings", "of": "front", "ratio": 1.0 },
        { "group": "side", "of": "front", "ratio": -3.0 },
    ]);
    file["rules"]["saturation"] = serde_json::json!([
        { "group": "side", "min": 0.7, "max": 0.2 },
        { "channel": 4, "min": 0.1, "max": 0.3 },
        { "group": "front", "min": 0.1, "max": 0.3 },
    ]);
    file["rules"]["exclude"] = serde_json::json!([{ "channel": 99, "mode": "off" }]);
    file["rules"]["pins"] = serde_json::json!([
        { "id": 3, "region": [0.6, 0.0, 0.2, 1.0], "channels": [1] },
        { "id": 5, "region": [0.0, 0.0, 0.3, 1.0], "channels": [1, 2] },
    ]);
    std::fs::write(&path, file.to_string()).expect("write session.json");
    d.restart();
    let listed = constraints(&mut d);
    let addrs: Vec<(String, Vec<OscType>)> = listed
        .iter()
        .map(|m| (m.addr.clone(), m.args.clone()))
        .collect();
    assert_eq!(
        addrs,
        vec![
            (
                "/vo/constraint".into(),
                vec![
                    string("/vo/group/back/ratio"),
                    string("front"),
                    OscType::Float(0.5)
                ]
            ),
            (
                "/vo/constraint".into(),
                vec![
                    string("/vo/light/4/saturation"),
                    OscType::Float(0.1),
                    OscType::Float(0.3)
                ]
            ),
            (
                "/vo/pin".into(),
                [int(5)]
                    .into_iter()
                    .chain([0.0, 0.0, 0.3, 1.0].map(float))
                    .chain([int(1), int(2)])
                    .collect()
            ),
        ]
    );
    let log = d.log();
    for lost in [
        "loop",
        "wings",
        "-3",
        "saturation range of group `side`",
        "light 99",
        "pin 3",
    ] {
        assert!(log.contains(lost), "the log names {lost}:\n{log}");
    }
    let aside = std::fs::read_dir(d.state_dir())
        .expect("the state folder")
        .filter_map(Result::ok)
        .any(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with("session.json.partial-")
        });
    assert!(aside, "the file was kept aside");
    // A new pin numbers after the restored one.
    let r = d.ok(
        "/vo/pin/add",
        [0.5, 0.0, 1.0, 1.0].map(float).to_vec(),
        "/vo/pin/added",
    );
    assert_eq!(r.args[0], int(6));
}

#[test]
fn constraint_changes_are_pushed_to_subscribers() {
    let mut d = Daemon::start("constraints-push");
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence();
    let ch = common::daemon::STAGE[0].channel;
    for (addr, args, echo) in [
        ("/vo/group/side/key", vec![int(1)], "/vo/group/key"),
        (
            &*format!("/vo/light/{ch}/lock"),
            vec![int(1)],
            "/vo/light/lock",
        ),
        (
            "/vo/group/side/exclude",
            vec![string("off")],
            "/vo/group/exclude",
        ),
        (
            "/vo/group/side/saturation",
            vec![float(0.2), float(0.8)],
            "/vo/group/saturation",
        ),
    ] {
        let reply = d.ok(addr, args, echo);
        let pushed = listen.collect(echo, common::daemon::PATIENCE, addr);
        assert_eq!(pushed.last(), Some(&reply), "{addr}: {pushed:?}");
        listen.fence();
    }
    // A refused one pushes nothing.
    d.err("/vo/group/nowhere/key", vec![int(1)]);
    let after = listen.fence();
    assert!(after.is_empty(), "{after:?}");
}
