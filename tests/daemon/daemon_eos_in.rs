//! An Eos console with its OSC TX pointed at the daemon: its implicit `/eos/out/...` output
//! (as the Eos manual's "Implicit OSC Output" lists it) is taken without a word, the DMX
//! keeps running through a flood of it, and the selected channels it reports on
//! `/eos/out/active/chan` become `/vo/console/selection`, which locks lights or keys them.

use std::time::Instant;

use crate::common::daemon::{Daemon, Osc, TcpFraming, fixture, float, int, num, same_look, string};
use rosc::OscType;

/// One of each kind of message Eos sends with OSC TX on, `i` varying the values.
fn eos_output(i: i32) -> Vec<(String, Vec<OscType>)> {
    let f = i as f32;
    vec![
        (
            "/eos/out/active/chan".into(),
            vec![string(&format!("{} [{}]", 1 + i % 6, i % 101))],
        ),
        (
            "/eos/out/cmd".into(),
            vec![string(&format!("LIVE: Chan {i} At"))],
        ),
        ("/eos/out/user/1/cmd".into(), vec![string("LIVE: Cue 1 : ")]),
        ("/eos/out/user".into(), vec![int(1)]),
        ("/eos/out/ping".into(), vec![int(i)]),
        (
            "/eos/out/active/wheel/1".into(),
            vec![string("Intens [62]"), int(1), float(62.0)],
        ),
        (
            "/eos/out/active/cue/1/2.5".into(),
            vec![float((f / 2000.0).min(1.0))],
        ),
        (
            "/eos/out/active/cue/text".into(),
            vec![string("1/2.5 Dusk 0:05 75%")],
        ),
        (
            "/eos/out/pending/cue/text".into(),
            vec![string("1/3 Night 0:30")],
        ),
        (
            "/eos/out/color/hs".into(),
            vec![float(f % 360.0), float(50.0)],
        ),
        (
            "/eos/out/pantilt".into(),
            vec![float(-270.0), float(270.0), float(0.0), float(f)],
        ),
        ("/eos/out/ds/1".into(), vec![string("Color Palettes [1]")]),
        ("/eos/out/fader/1/1/name".into(), vec![string("Sub 1")]),
        ("/eos/out/show/name".into(), vec![string("Act 2")]),
        ("/eos/out/softkey/1".into(), vec![string("Record")]),
        (
            "/eos/out/get/patch/12/0/list/0/14".into(),
            vec![int(12), string("uid"), string("Source Four")],
        ),
        ("/eos/out/event/state".into(), vec![int(1)]),
    ]
}

/// Sends at least 2000 messages of Eos's output from `console`; nothing may come back.
fn flood(console: &mut impl Osc) {
    let kinds = eos_output(0).len() as i32;
    let mut sent = 0;
    for i in 0..(2000 / kinds + 1) {
        for (addr, args) in eos_output(i) {
            console.send(&addr, args);
            sent += 1;
        }
        // The daemon answers a fence ping only after the earlier messages: nothing else
        // may come back meanwhile.
        if i % 20 == 0 {
            assert_eq!(console.fence(), Vec::new(), "after {sent} Eos messages");
        }
    }
    assert!(sent >= 2000);
    assert_eq!(console.fence(), Vec::new(), "after all {sent} Eos messages");
}

#[test]
fn a_flood_of_eos_output_gets_no_answer_and_the_dmx_keeps_running() {
    let mut d = Daemon::start("eos-flood");
    d.ok("/vo/light/1/level", vec![int(62)], "/vo/light");
    let before = Instant::now();
    // Eos's OSC UDP TX, then a TCP connection in each framing (Eos's TCP modes).
    flood(&mut d.client());
    flood(&mut d.tcp(TcpFraming::LengthPrefix));
    flood(&mut d.tcp(TcpFraming::Slip));
    d.wire.assert_continuous_since(before, "through the flood");
    // Still serving: the live look is what it was.
    let live = d.live();
    assert!((live[0].intensity - 0.62).abs() < 1e-4, "{live:?}");
}

#[test]
fn the_console_selection_locks_and_keys_lights() {
    let mut d = Daemon::start("eos-selection");
    // Nothing selected yet: an empty reply, and lock/key are refused.
    let r = d.ok("/vo/console/selection", vec![], "/vo/console/selection");
    assert!(r.args.is_empty(), "{r:?}");
    let e = d.refused("/vo/console/selection/lock", vec![int(1)]);
    assert!(e.contains("/eos/out/active/chan"), "{e}");

    // The console selects channels 3, 5 and 6 (and 99, which the scene does not have).
    let mut console = d.client();
    console.send(
        "/eos/out/active/chan",
        vec![string("3 + 5 Thru 6 + 99 Source Four LED [62]")],
    );
    assert_eq!(console.fence(), Vec::new());
    let r = d.ok("/vo/console/selection", vec![], "/vo/console/selection");
    let chans: Vec<i32> = r.args.iter().map(|a| num(a) as i32).collect();
    assert_eq!(chans, [3, 5, 6]);

    // A base look, then lock the selection: those lights keep it in every candidate.
    d.ok("/vo/light/3/intensity", vec![float(0.3)], "/vo/light");
    d.ok("/vo/light/5/intensity", vec![float(0.7)], "/vo/light");
    let base = d.live();
    let r = d.ok(
        "/vo/console/selection/lock",
        vec![int(1)],
        "/vo/console/selection/lock",
    );
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (1, 3));
    d.add_objective("warm.png", "both");
    d.generate();
    let mut moved = 0;
    for (e, &size) in d.gallery().iter().enumerate() {
        for m in 1..=size {
            let cand = d.candidate(e as i32 + 1, m);
            for (got, want) in cand.iter().zip(&base) {
                let same = same_look(std::slice::from_ref(got), std::slice::from_ref(want), 1e-4);
                if [3, 5, 6].contains(&got.ch) {
                    assert!(same, "locked light {} moved: {got:?} vs {want:?}", got.ch);
                } else if !same {
                    moved += 1;
                }
            }
        }
    }
    assert!(moved > 0, "the unlocked lights never moved");

    // A new selection (channel 3 alone, as Eos reports a single channel) keys its group.
    console.send("/eos/out/active/chan", vec![string("3 [30]")]);
    assert_eq!(console.fence(), Vec::new());
    let r = d.ok(
        "/vo/console/selection/key",
        vec![int(1)],
        "/vo/console/selection/key",
    );
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (1, 1));
    let session: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.state_dir().join("session.json")).unwrap())
            .unwrap();
    assert_eq!(
        session["key_groups"],
        serde_json::json!([fixture(3).group]),
        "{session}"
    );
    assert_eq!(
        session["locked_lights"],
        serde_json::json!([3, 5, 6]),
        "{session}"
    );
    // An empty selection (Eos sends an empty text when nothing is selected).
    console.send("/eos/out/active/chan", vec![string("")]);
    assert_eq!(console.fence(), Vec::new());
    d.refused("/vo/console/selection/key", vec![int(1)]);
}
