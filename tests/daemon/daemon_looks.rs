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
