//! Saved looks of docs/osc.md against the real daemon: save, recall, delete and the listing,
//! refused cases that change nothing, and what survives a kill -9.

use crate::common::daemon::{Daemon, Osc, PROTOS, float, int, num, same_look, string};

#[test]
fn save_recall_delete_and_list() {
    let mut d = Daemon::start("looks-basic");
    d.ok("/vo/light/1/level", vec![int(40)], "/vo/light");
    d.ok(
        "/vo/light/3/color",
        vec![float(1.0), float(0.0), float(0.5)],
        "/vo/light",
    );
    d.ok("/vo/light/3/intensity", vec![float(0.8)], "/vo/light");
    let saved = d.live();
    let r = d.ok(
        "/vo/look/save",
        vec![int(12), string("Act 2 dusk")],
        "/vo/look/saved",
    );
    assert_eq!(num(&r.args[0]) as i32, 12);
    d.ok("/vo/look/save", vec![int(9999)], "/vo/look/saved");
    let looks = d.looks();
    assert_eq!(looks.len(), 2, "{looks:?}");
    assert_eq!(looks[0], (12, "Act 2 dusk".to_string()));
    assert_eq!(looks[1].0, 9999);

    // Change the stage, then recall.
    d.ok("/vo/group/front/level", vec![int(100)], "/vo/group");
    d.ok("/vo/light/3/intensity", vec![float(0.0)], "/vo/light");
    let r = d.ok("/vo/look/recall", vec![int(12)], "/vo/look/recalled");
    assert_eq!(num(&r.args[0]) as i32, 12);
    assert!(
        same_look(&d.live(), &saved, 1e-6),
        "{:?} vs {saved:?}",
        d.live()
    );
    for proto in PROTOS {
        d.wire.wait_look(proto, &saved);
    }
    // Saving again under the same number replaces it.
    d.ok("/vo/light/1/level", vec![int(10)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(12), string("Act 2 night")],
        "/vo/look/saved",
    );
    assert_eq!(d.looks()[0], (12, "Act 2 night".to_string()));

    let r = d.ok("/vo/look/delete", vec![int(9999)], "/vo/look/deleted");
    assert_eq!(num(&r.args[0]) as i32, 9999);
    assert_eq!(d.looks().len(), 1);

    for (addr, args) in [
        ("/vo/look/save", vec![int(0)]),
        ("/vo/look/save", vec![int(10000)]),
        ("/vo/look/save", vec![float(1.5)]),
        ("/vo/look/save", vec![string("first")]),
        ("/vo/look/save", vec![]),
        ("/vo/look/recall", vec![int(9999)]),
        ("/vo/look/recall", vec![int(0)]),
        ("/vo/look/recall", vec![]),
        ("/vo/look/delete", vec![int(9999)]),
        ("/vo/look/delete", vec![string("all")]),
        ("/vo/looks/all", vec![]),
        ("/vo/lookss", vec![]),
    ] {
        d.refused(addr, args);
    }
}

#[test]
fn looks_objectives_and_the_live_look_survive_kill_9() {
    let mut d = Daemon::start("looks-kill");
    d.ok("/vo/light/2/level", vec![int(60)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(5), string("preshow")],
        "/vo/look/saved",
    );
    d.ok(
        "/vo/light/4/color",
        vec![float(0.0), float(1.0), float(0.5)],
        "/vo/light",
    );
    d.ok("/vo/light/4/intensity", vec![float(0.9)], "/vo/light");
    let id = d.add_objective("cool.png", "color");
    let live = d.live();
    let looks = d.looks();
    let objectives = d.objectives();
    d.kill();
    d.restart();
    assert!(
        same_look(&d.live(), &live, 1e-6),
        "{:?} vs {live:?}",
        d.live()
    );
    assert_eq!(d.looks(), looks);
    assert_eq!(d.objectives(), objectives);
    assert_eq!(d.status().objectives, 1);
    d.ok(
        &format!("/vo/objective/{id}/aspects"),
        vec![string("both")],
        "/vo/objective/aspects",
    );
    d.ok("/vo/look/recall", vec![int(5)], "/vo/look/recalled");
    assert!(d.live()[3].intensity == 0.0, "look 5 predates light 4");
}

/// Corrupt state files are kept aside (never deleted) and the daemon starts without them;
/// a save writes a fresh file that a restart reads back.
#[test]
fn corrupt_state_files_are_kept_aside_and_the_daemon_starts() {
    let mut d = Daemon::start("looks-corrupt");
    d.ok(
        "/vo/look/save",
        vec![int(1), string("first")],
        "/vo/look/saved",
    );
    d.kill();
    let state = d.state_dir();
    for name in ["live.json", "looks.json", "session.json"] {
        std::fs::write(state.join(name), b"{ this is not json").unwrap();
    }
    d.restart();
    assert!(d.looks().is_empty(), "the corrupt looks file was not used");
    let kept: Vec<String> = std::fs::read_dir(&state)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".corrupt-"))
        .collect();
    assert_eq!(kept.len(), 3, "{kept:?}");
    for name in &kept {
        assert_eq!(
            std::fs::read(state.join(name)).unwrap(),
            b"{ this is not json"
        );
    }
    d.ok(
        "/vo/look/save",
        vec![int(2), string("again")],
        "/vo/look/saved",
    );
    d.kill();
    d.restart();
    assert_eq!(d.looks(), vec![(2, "again".to_string())]);
}

/// Numbers the state files hold are checked on restore: one that is not finite (`1e39`
/// reads as infinity) or out of range is dropped and named with its file, and the rest is
/// restored, each file kept aside as a copy. The live look goes on the wire, a generate
/// gives finite levels, and the next start reads every file whole (nothing set aside).
#[test]
fn numbers_not_finite_or_out_of_range_are_dropped_and_the_rest_restored() {
    let mut d = Daemon::start("looks-numbers");
    d.ok("/vo/light/1/level", vec![int(40)], "/vo/light");
    d.ok("/vo/light/2/level", vec![int(60)], "/vo/light");
    d.ok(
        "/vo/light/3/color",
        vec![float(1.0), float(0.0), float(0.5)],
        "/vo/light",
    );
    d.ok("/vo/light/3/intensity", vec![float(0.8)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(1), string("one")],
        "/vo/look/saved",
    );
    d.ok(
        "/vo/look/save",
        vec![int(2), string("two")],
        "/vo/look/saved",
    );
    d.add_objective("warm.png", "both");
    d.add_objective("cool.png", "both");
    d.ok("/vo/fade", vec![float(1.5)], "/vo/fade");
    d.ok("/vo/master", vec![float(0.5)], "/vo/master");
    let mut live = d.live();
    let objectives = d.objectives();
    assert!(d.terminate().success());

    let state = d.state_dir();
    let edit = |name: &str, change: &dyn Fn(&mut serde_json::Value)| {
        let path = state.join(name);
        let text = std::fs::read_to_string(&path).expect("a state file");
        let mut v: serde_json::Value = serde_json::from_str(&text).expect("JSON");
        change(&mut v);
        std::fs::write(&path, v.to_string()).expect("write the state file");
    };
    // Light `ch`'s entry of a look file.
    fn light(look: &mut serde_json::Value, ch: i32) -> &mut serde_json::Value {
        let lights = look["lights"].as_array_mut().expect("lights");
        lights
            .iter_mut()
            .find(|l| l["channel"] == ch)
            .expect("the light's entry")
    }
    let huge = serde_json::json!(1e39);
    edit("session.json", &|v| {
        v["fade_s"] = huge.clone();
        v["count"] = serde_json::json!(5000);
        v["objectives"][1]["mean_l"] = huge.clone();
    });
    edit("live.json", &|v| {
        v["master"] = huge.clone();
        light(&mut v["live"], 2)["intensity"] = huge.clone();
        light(&mut v["base"], 3)["color"][0] = serde_json::json!(1.5);
    });
    edit("looks.json", &|v| {
        light(&mut v["looks"]["2"], 1)["intensity"] = huge.clone();
    });
    d.restart();

    // Each lost value is named with its file; nothing else is.
    let log = d.log_text();
    let lost: Vec<&str> = log.lines().filter(|l| l.contains("not restored")).collect();
    for (file, what) in [
        ("session.json", "fade_s inf is not a finite number"),
        ("session.json", "count 5000 is outside 1..=1000"),
        (
            "session.json",
            "objective 2 (`cool.png`): mean_l inf is not a finite number",
        ),
        ("live.json", "master inf is not a finite number"),
        (
            "live.json",
            "live look: light 2: intensity inf is not a finite number",
        ),
        (
            "live.json",
            "base look: light 3: colour [1.5, 0.0, 0.5] is outside 0..1",
        ),
        (
            "looks.json",
            "look 2: light 1: intensity inf is not a finite number",
        ),
    ] {
        assert!(
            lost.iter().any(|l| l.contains(file) && l.contains(what)),
            "no line names {file}: {what}:\n{log}"
        );
    }
    assert_eq!(lost.len(), 7, "{lost:#?}");
    // The rest is restored: light 2 is left out (off), the defaults stand for the others.
    live[1].intensity = 0.0;
    assert!(
        same_look(&d.live(), &live, 1e-6),
        "{:?} vs {live:?}",
        d.live()
    );
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    let status = d.status();
    assert_eq!((status.master, status.fade), (1.0, 0.0), "{status:?}");
    assert_eq!(d.objectives(), objectives[..1]);
    assert_eq!(
        d.looks(),
        vec![(1, "one".to_string()), (2, "two".to_string())]
    );
    let aside = |tag: &str| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(&state)
            .expect("the state folder")
            .map(|e| {
                e.expect("an entry")
                    .file_name()
                    .to_string_lossy()
                    .into_owned()
            })
            .filter(|n| n.contains(tag))
            .map(|n| n[..n.find('.').expect("a name")].to_string())
            .collect();
        names.sort();
        names
    };
    assert_eq!(aside(".partial-"), ["live", "looks", "session"]);
    d.ok("/vo/look/recall", vec![int(2)], "/vo/look/recalled");
    assert_eq!(d.live()[0].intensity, 0.0, "look 2 lost light 1");

    // A generate from what was restored gives levels, and a pick of it is saved whole.
    d.generate();
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let picked = d.live();
    assert!(
        picked
            .iter()
            .all(|l| l.intensity.is_finite() && l.color.iter().all(|c| c.is_finite())),
        "{picked:?}"
    );
    assert!(d.terminate().success());
    d.restart();
    assert_eq!(aside(".corrupt-"), Vec::<String>::new(), "{}", d.log());
    let log = d.log_text();
    assert!(!log.contains("not restored"), "{log}");
    assert!(
        same_look(&d.live(), &picked, 1e-6),
        "{:?} vs {picked:?}",
        d.live()
    );
    assert_eq!(d.objectives(), objectives[..1]);
    assert_eq!(d.looks().len(), 2);
}

/// A session keeps at most 1000 saved looks, each label at most 100 characters (docs/osc.md,
/// "Limits"): a save past them is refused and changes nothing, and a looks.json holding
/// more (edited by hand, or from before the limits) is restored to them, each cut named.
#[test]
fn a_session_keeps_at_most_1000_looks_with_labels_of_100_characters() {
    let mut d = Daemon::start("looks-limits");
    assert!(d.terminate().success());
    let lights = serde_json::json!([{"channel": 1, "intensity": 0.5}]);
    let mut looks: serde_json::Map<String, serde_json::Value> = (1..=1001)
        .map(|n| {
            let file = serde_json::json!({"label": format!("Look {n}"), "lights": lights});
            (n.to_string(), file)
        })
        .collect();
    looks["7"]["label"] = serde_json::json!("y".repeat(65_000));
    let path = d.state_dir().join("looks.json");
    std::fs::write(&path, serde_json::json!({ "looks": looks }).to_string()).expect("write");
    d.restart();
    let log = d.log_text();
    for what in [
        "1 saved looks past the 1000 a session keeps: looks 1001 and above were left out",
        "look 7: its label of 65000 characters was cut to 100",
    ] {
        assert!(
            log.lines()
                .any(|l| l.contains("looks.json: not restored") && l.contains(what)),
            "not said: {what}\n{log}"
        );
    }
    let listed = |d: &mut Daemon| {
        // Over TCP: a thousand replies over UDP on loopback may lose some.
        let mut tcp = d.tcp(crate::common::daemon::TcpFraming::LengthPrefix);
        tcp.call("/vo/looks", vec![], "/vo/looks/end")
    };
    let got = listed(&mut d);
    assert_eq!(got.last().map(|m| m.args.clone()), Some(vec![int(1000)]));
    let seventh = got.iter().find(|m| m.args[0] == int(7)).expect("look 7");
    assert_eq!(seventh.args[1], string(&"y".repeat(100)));

    let why = d.err("/vo/look/save", vec![int(5000)]);
    assert!(
        why.starts_with("look 5000 was not saved: there are already 1000 saved looks"),
        "{why}"
    );
    let why = d.err("/vo/look/save", vec![int(3), string(&"z".repeat(101))]);
    assert_eq!(why, "a look's label is at most 100 characters, got 101");
    assert_eq!(listed(&mut d), got, "the refused saves changed nothing");
    // Saving over a look, or after deleting one, is within the limit.
    d.ok(
        "/vo/look/save",
        vec![int(3), string("over")],
        "/vo/look/saved",
    );
    d.ok("/vo/look/delete", vec![int(4)], "/vo/look/deleted");
    d.ok("/vo/look/save", vec![int(5000)], "/vo/look/saved");
    let got = listed(&mut d);
    assert_eq!(got.last().map(|m| m.args.clone()), Some(vec![int(1000)]));
}
