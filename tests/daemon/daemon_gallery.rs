//! Generate, the gallery, pick/next/prev, undo/redo and the constraints of docs/osc.md against
//! the real daemon, each with refused cases that change nothing.

use crate::common::daemon::{
    CLUSTERS, COUNT, Daemon, GENERATE_PATIENCE, LightLevel, Osc, PATIENCE, Proto, STAGE, Udp,
    fixture, float, int, num, same_look, string, text,
};

/// A daemon with one objective and a generated gallery; returns it with the entry sizes.
fn generated(name: &str) -> (Daemon, Vec<i32>) {
    let mut d = Daemon::start(name);
    d.add_objective("warm.png", "both");
    d.generate();
    let sizes = d.gallery();
    (d, sizes)
}

fn check_look(look: &[LightLevel]) {
    assert_eq!(
        look.iter().map(|l| l.ch).collect::<Vec<_>>(),
        STAGE.iter().map(|f| f.channel).collect::<Vec<_>>()
    );
    for l in look {
        assert!((0.0..=1.0).contains(&l.intensity), "{l:?}");
        assert!(l.color.iter().all(|c| (0.0..=1.0).contains(c)), "{l:?}");
        if !fixture(l.ch).has_colour() {
            assert_eq!(l.color, [1.0; 3], "a dimmer reports 1 1 1: {l:?}");
        }
    }
}

#[test]
fn generate_fills_the_gallery() {
    let mut d = Daemon::start("gal-generate");
    // Nothing to aim at yet.
    d.refused("/vo/generate", vec![]);
    d.add_objective("warm.png", "both");
    let r = d.generate();
    assert_eq!(r.args.len(), 4, "candidates clusters ms seed: {r:?}");
    let (n, c) = (num(&r.args[0]) as i32, num(&r.args[1]) as i32);
    assert_eq!(n, COUNT);
    assert!((1..=CLUSTERS).contains(&c), "{r:?}");
    assert!(num(&r.args[2]) >= 0.0, "{r:?}");
    let s = d.status();
    assert_eq!((s.candidates, s.clusters, s.entry), (n, c, 0));
    let sizes = d.gallery();
    assert_eq!(sizes.len() as i32, c);
    assert!(sizes.iter().all(|&s| s >= 1), "{sizes:?}");
    assert_eq!(sizes.iter().sum::<i32>(), n, "every candidate in one entry");
    let mut lit = 0;
    for (k, &size) in sizes.iter().enumerate() {
        for m in [1, size] {
            let look = d.candidate(k as i32 + 1, m);
            check_look(&look);
            lit += look.iter().filter(|l| l.intensity > 0.05).count();
        }
    }
    assert!(lit > 0, "every candidate is dark");
    // Generating does not change the stage.
    assert!(d.live().iter().all(|l| l.intensity == 0.0));
    d.refused("/vo/generatee", vec![]);
}

/// The `/vo/progress` values `listen` is pushed up to and including `/vo/generated` (the
/// generate's reply), checked as docs/osc.md says: 0 first, 1 last, never falling, at most
/// nine between; nothing about progress comes after `/vo/generated`.
fn pushed_progress(listen: &mut Udp) -> Vec<f64> {
    let pushed = listen.collect("/vo/generated", GENERATE_PATIENCE, "a generate's pushes");
    assert_eq!(
        pushed.last().expect("pushes").addr,
        "/vo/generated",
        "{pushed:?}"
    );
    let progress: Vec<f64> = pushed
        .iter()
        .filter(|m| m.addr == "/vo/progress")
        .map(|m| {
            assert_eq!(m.args.len(), 1, "{m:?}");
            num(&m.args[0])
        })
        .collect();
    assert_eq!(progress.first(), Some(&0.0), "{progress:?}");
    assert_eq!(progress.last(), Some(&1.0), "{progress:?}");
    assert!(
        progress.windows(2).all(|w| w[0] <= w[1]),
        "progress fell: {progress:?}"
    );
    assert!(
        progress.len() <= 11,
        "more than a push a tenth: {progress:?}"
    );
    let late = listen.fence();
    assert!(
        late.iter().all(|m| m.addr != "/vo/progress"),
        "progress after /vo/generated: {late:?}"
    );
    progress
}

#[test]
fn a_generate_pushes_its_progress_as_it_goes() {
    let mut d = Daemon::start("gal-progress");
    d.add_objective("warm.png", "both");
    // A thousand candidates: docs/osc.md's largest count, many batches of draws.
    d.ok("/vo/generate/count", vec![int(1000)], "/vo/generate/count");
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence(); // the state pushed at subscription

    let seeded = |d: &mut Daemon| {
        d.send("/vo/generate/seeded", vec![int(77)]);
        let got = d.collect("/vo/generated", GENERATE_PATIENCE, "/vo/generate/seeded 77");
        let r = got.last().expect("a reply");
        assert_eq!(r.addr, "/vo/generated", "{got:?}");
        assert_eq!(num(&r.args[3]) as i32, 77, "{r:?}");
    };
    seeded(&mut d);
    let progress = pushed_progress(&mut listen);
    let inside = progress.iter().filter(|&&f| f > 0.0 && f < 1.0).count();
    assert!(inside >= 3, "{inside} values between 0 and 1: {progress:?}");
    // Counted in work done, not time: the same seed pushes the same values.
    seeded(&mut d);
    assert_eq!(pushed_progress(&mut listen), progress);
    // A plain generate too, whatever its seed.
    d.generate();
    pushed_progress(&mut listen);
}

#[test]
fn count_clusters_and_seed() {
    let mut d = Daemon::start("gal-settings");
    d.add_objective("cool.png", "both");
    let r = d.ok("/vo/generate/count", vec![int(12)], "/vo/generate/count");
    assert_eq!(num(&r.args[0]) as i32, 12);
    let r = d.ok(
        "/vo/generate/clusters",
        vec![int(3)],
        "/vo/generate/clusters",
    );
    assert_eq!(num(&r.args[0]) as i32, 3);
    let r = d.ok("/vo/generate/seed", vec![int(7)], "/vo/generate/seed");
    assert_eq!(num(&r.args[0]) as i32, 7);
    let g = d.generate();
    assert_eq!(num(&g.args[0]) as i32, 12);
    assert!((1..=3).contains(&(num(&g.args[1]) as i32)), "{g:?}");
    assert_eq!(num(&g.args[3]) as i32, 7, "the seed used: {g:?}");
    let first = d.candidate(1, 1);
    let sizes = d.gallery();
    // Same scene, objectives, stage look and seed: the same candidates.
    d.generate();
    assert_eq!(d.gallery(), sizes);
    assert_eq!(d.candidate(1, 1), first);

    for (addr, bad) in [
        ("/vo/generate/count", vec![int(0)]),
        ("/vo/generate/count", vec![int(1001)]),
        ("/vo/generate/count", vec![float(2.5)]),
        ("/vo/generate/count", vec![string("many")]),
        ("/vo/generate/count", vec![]),
        ("/vo/generate/clusters", vec![int(0)]),
        ("/vo/generate/clusters", vec![int(65)]),
        ("/vo/generate/seed", vec![int(-1)]),
        ("/vo/generate/seed", vec![float(1.5)]),
        ("/vo/generate/seed", vec![string("x")]),
    ] {
        d.refused(addr, bad);
    }
    // Still 12 / 3 / 7.
    let g = d.generate();
    assert_eq!(num(&g.args[0]) as i32, 12);
    assert_eq!(num(&g.args[3]) as i32, 7);
    // Seed 0: a new random seed each time, reported.
    d.ok("/vo/generate/seed", vec![int(0)], "/vo/generate/seed");
    let a = num(&d.generate().args[3]) as i64;
    let b = num(&d.generate().args[3]) as i64;
    assert_ne!(a, b, "seed 0 draws a new seed each time");
}

#[test]
fn pick_goes_live_and_becomes_the_base() {
    let mut d = Daemon::start("gal-pick");
    d.add_objective("warm.png", "both");
    d.refused("/vo/pick", vec![int(1)]);
    d.generate();
    let sizes = d.gallery();
    let c = sizes.len() as i32;
    let k = c.min(2);
    let r = d.ok("/vo/pick", vec![int(k)], "/vo/picked");
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (k, 1));
    assert_eq!(d.status().entry, k);
    let want = d.candidate(k, 1);
    // fade_s = 0 in the config: live at once.
    assert!(
        same_look(&d.live(), &want, 1e-6),
        "{:?} vs {want:?}",
        d.live()
    );
    if let Some(big) = sizes.iter().position(|&s| s >= 2) {
        let k = big as i32 + 1;
        let r = d.ok("/vo/pick", vec![int(k), int(2)], "/vo/picked");
        assert_eq!(num(&r.args[1]) as i32, 2);
        assert!(same_look(&d.live(), &d.candidate(k, 2), 1e-6));
    }
    d.ok("/vo/pick", vec![int(k)], "/vo/picked");
    for bad in [
        vec![int(0)],
        vec![int(c + 1)],
        vec![int(1), int(sizes[0] + 1)],
        vec![int(1), int(0)],
        vec![string("one")],
        vec![float(1.5)],
        vec![],
    ] {
        d.refused("/vo/pick", bad);
    }
    // The picked look is the base: locked lights keep it in every new candidate.
    let base = d.live();
    d.ok("/vo/group/side/lock", vec![int(1)], "/vo/group/lock");
    d.generate();
    for (e, &size) in d.gallery().iter().enumerate() {
        for m in 1..=size {
            let cand = d.candidate(e as i32 + 1, m);
            for (got, want) in cand.iter().zip(&base) {
                if fixture(got.ch).group == "side" {
                    assert!(
                        same_look(std::slice::from_ref(got), std::slice::from_ref(want), 1e-4),
                        "locked light {} moved: {got:?} vs base {want:?}",
                        got.ch
                    );
                }
            }
        }
    }
}

#[test]
fn next_and_prev_step_and_wrap() {
    let (mut d, sizes) = generated("gal-next");
    let c = sizes.len() as i32;
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let r = d.ok("/vo/prev", vec![], "/vo/picked");
    assert_eq!(
        (num(&r.args[0]) as i32, num(&r.args[1]) as i32),
        (c, 1),
        "wraps back"
    );
    assert!(same_look(&d.live(), &d.candidate(c, 1), 1e-6));
    let r = d.ok("/vo/next", vec![], "/vo/picked");
    assert_eq!(num(&r.args[0]) as i32, 1, "wraps forward");
    let r = d.ok("/vo/next", vec![], "/vo/picked");
    assert_eq!(num(&r.args[0]) as i32, 2.min(c));
    assert_eq!(d.status().entry, 2.min(c));
    assert!(same_look(&d.live(), &d.candidate(2.min(c), 1), 1e-6));
    d.refused("/vo/nextt", vec![]);
    d.refused("/vo/next/entry", vec![]);

    let mut fresh = Daemon::start("gal-next-empty");
    fresh.refused("/vo/next", vec![]);
    fresh.refused("/vo/prev", vec![]);
}

#[test]
fn undo_and_redo_walk_the_base_history() {
    let (mut d, sizes) = generated("gal-undo");
    let c = sizes.len() as i32;
    assert!(c >= 2, "the test needs two entries, got {sizes:?}");
    d.refused("/vo/redo", vec![]);
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    d.ok("/vo/pick", vec![int(2)], "/vo/picked");
    let (one, two) = (d.candidate(1, 1), d.candidate(2, 1));
    let r = d.ok("/vo/undo", vec![], "/vo/undone");
    let depth = num(&r.args[0]) as i32;
    assert!(depth >= 0, "{r:?}");
    assert!(
        same_look(&d.live(), &one, 1e-6),
        "undo brings back the previous look"
    );
    let r = d.ok("/vo/redo", vec![], "/vo/redone");
    assert!(num(&r.args[0]) as i32 >= 0, "{r:?}");
    assert!(
        same_look(&d.live(), &two, 1e-6),
        "redo brings the undone look back"
    );
    d.refused("/vo/redo", vec![]);
    // Undo all the way back to the dark start, then no further.
    d.ok("/vo/undo", vec![], "/vo/undone");
    let r = d.ok("/vo/undo", vec![], "/vo/undone");
    assert!(num(&r.args[0]) as i32 <= depth, "{r:?}");
    assert!(
        d.live().iter().all(|l| l.intensity == 0.0),
        "{:?}",
        d.live()
    );
    d.refused("/vo/undo", vec![]);
    d.refused("/vo/undoo", vec![]);
    // 32 steps at least.
    for i in 0..33 {
        d.ok("/vo/pick", vec![int(1 + i % 2)], "/vo/picked");
    }
    for i in 0..32 {
        let r = d.call("/vo/undo", vec![], "/vo/undone");
        assert_eq!(
            r.last().map(|m| m.addr.as_str()),
            Some("/vo/undone"),
            "undo {i}: {r:?}"
        );
    }
}

/// The pushes of one change a subscriber hears, up to `listen`'s fence: how many
/// `/vo/status` pushes (every change pushes one).
fn changes_heard(listen: &mut Udp) -> usize {
    let pushed = listen.fence();
    pushed.iter().filter(|m| m.addr == "/vo/status").count()
}

#[test]
fn undo_and_redo_take_a_step_count_as_one_change() {
    let (mut d, sizes) = generated("gal-undo-steps");
    assert!(
        sizes.len() >= 3,
        "the test needs three entries, got {sizes:?}"
    );
    for k in 1..=3 {
        d.ok("/vo/pick", vec![int(k)], "/vo/picked");
    }
    let (one, three) = (d.candidate(1, 1), d.candidate(3, 1));
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence();

    // The dark start, entry 1 and entry 2 are behind: three steps. Counts that are not
    // there, not whole or not numbers are refused and change nothing, pushing nothing.
    let sentence = d.refused("/vo/undo", vec![int(4)]);
    assert!(sentence.contains("there are 3 steps to undo"), "{sentence}");
    for bad in [
        vec![int(-1)],
        vec![float(1.5)],
        vec![string("two")],
        vec![int(1_000_001)],
    ] {
        d.refused("/vo/undo", bad);
    }
    assert_eq!(d.refused("/vo/redo", vec![int(2)]), "nothing to redo");
    // 0 is a button's release, as for every trigger: no reply, no change.
    d.silent("/vo/undo", vec![int(0)]);
    assert_eq!(changes_heard(&mut listen), 0);
    assert!(same_look(&d.live(), &three, 1e-6));

    // Two steps back in one change: one push, entry 1's look live and on the wire.
    let r = d.ok("/vo/undo", vec![int(2)], "/vo/undone");
    assert_eq!(num(&r.args[0]) as i32, 1, "one step left: {r:?}");
    assert!(same_look(&d.live(), &one, 1e-6));
    d.wire.wait_look(Proto::Sacn, &one);
    assert_eq!(changes_heard(&mut listen), 1, "one change for two steps");
    assert_eq!(d.status().entry, 0, "no entry is live after an undo");
    let sentence = d.refused("/vo/redo", vec![int(3)]);
    assert!(sentence.contains("there are 2 steps to redo"), "{sentence}");

    // Forward both again as one, then all the way back and forward; a path number counts
    // too (`/vo/undo/3`).
    let r = d.ok("/vo/redo", vec![int(2)], "/vo/redone");
    assert_eq!(num(&r.args[0]) as i32, 0, "{r:?}");
    assert!(same_look(&d.live(), &three, 1e-6));
    assert_eq!(changes_heard(&mut listen), 1);
    let r = d.ok("/vo/undo/3", vec![], "/vo/undone");
    assert_eq!(num(&r.args[0]) as i32, 0, "{r:?}");
    assert!(
        d.live().iter().all(|l| l.intensity == 0.0),
        "{:?}",
        d.live()
    );
    d.refused("/vo/undo", vec![]);
    // The walked-over steps are still there one at a time.
    let r = d.ok("/vo/redo", vec![float(1.0)], "/vo/redone");
    assert_eq!(num(&r.args[0]) as i32, 2, "{r:?}");
    assert!(same_look(&d.live(), &one, 1e-6));
    d.ok("/vo/redo", vec![], "/vo/redone");
    assert!(same_look(&d.live(), &d.candidate(2, 1), 1e-6));
    let r = d.ok("/vo/redo", vec![int(1)], "/vo/redone");
    assert_eq!(num(&r.args[0]) as i32, 0, "{r:?}");
    assert!(same_look(&d.live(), &three, 1e-6));
    assert_eq!(changes_heard(&mut listen), 4, "one change per command");
}

#[test]
fn candidate_and_gallery_refuse_what_is_not_there() {
    let mut d = Daemon::start("gal-candidate");
    d.refused("/vo/candidate", vec![int(1)]);
    // No gallery yet: zero entries.
    let r = d.ok("/vo/gallery", vec![], "/vo/gallery");
    assert_eq!(r.args.iter().map(num).collect::<Vec<_>>(), [0.0], "{r:?}");
    d.add_objective("grey.png", "both");
    d.generate();
    let sizes = d.gallery();
    let c = sizes.len() as i32;
    let r = d.ok("/vo/candidate/1", vec![], "/vo/candidate");
    assert_eq!(
        (num(&r.args[0]) as i32, num(&r.args[1]) as i32),
        (1, 1),
        "m defaults to 1"
    );
    for bad in [
        vec![int(0)],
        vec![int(c + 1)],
        vec![int(1), int(sizes[0] + 1)],
        vec![string("best")],
        vec![],
    ] {
        d.refused("/vo/candidate", bad);
    }
    d.refused("/vo/galleryy", vec![]);
}

#[test]
fn unreached_and_locked_lights_keep_the_base() {
    let mut d = Daemon::start("gal-targeting");
    // A base look: light 4 (right half) and light 1 (left half) set by faders.
    d.ok("/vo/light/4/intensity", vec![float(0.3)], "/vo/light");
    d.ok(
        "/vo/light/4/color",
        vec![float(0.2), float(0.4), float(0.6)],
        "/vo/light",
    );
    d.ok("/vo/light/1/level", vec![int(70)], "/vo/light");
    let base = d.live();
    let id = d.add_objective("warm.png", "both");
    let r = d.ok(
        &format!("/vo/objective/{id}/region"),
        [0.0, 0.0, 0.5, 1.0].map(float).to_vec(),
        "/vo/objective/region",
    );
    assert_eq!(num(&r.args[5]) as i32, 3);
    let r = d.ok("/vo/light/2/lock", vec![int(1)], "/vo/light/lock");
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (2, 1));
    d.generate();
    let mut moved = 0;
    for (e, &size) in d.gallery().iter().enumerate() {
        for m in 1..=size {
            let cand = d.candidate(e as i32 + 1, m);
            for (got, want) in cand.iter().zip(&base) {
                let same = same_look(std::slice::from_ref(got), std::slice::from_ref(want), 1e-4);
                if got.ch >= 4 || got.ch == 2 {
                    assert!(
                        same,
                        "light {} is unreached or locked: {got:?} vs {want:?}",
                        got.ch
                    );
                } else if !same {
                    moved += 1;
                }
            }
        }
    }
    assert!(moved > 0, "lights 1 and 3 never moved");
}

#[test]
fn constraints_reply_and_refuse() {
    let mut d = Daemon::start("gal-constraints");
    let r = d.ok("/vo/group/front/key", vec![int(1)], "/vo/group/key");
    assert_eq!(
        (text(&r.args[0]).as_str(), num(&r.args[1]) as i32),
        ("front", 1)
    );
    let r = d.ok("/vo/group/front/key", vec![int(0)], "/vo/group/key");
    assert_eq!(num(&r.args[1]) as i32, 0);
    let r = d.ok("/vo/group/back/lock", vec![float(1.0)], "/vo/group/lock");
    assert_eq!(
        (text(&r.args[0]).as_str(), num(&r.args[1]) as i32),
        ("back", 1)
    );
    let r = d.ok("/vo/light/3/lock", vec![string("1")], "/vo/light/lock");
    assert_eq!((num(&r.args[0]) as i32, num(&r.args[1]) as i32), (3, 1));
    for (addr, args) in [
        ("/vo/group/wings/key", vec![int(1)]),
        ("/vo/group/front/key", vec![int(2)]),
        ("/vo/group/front/key", vec![string("yes")]),
        ("/vo/group/front/key", vec![]),
        ("/vo/group/wings/lock", vec![int(1)]),
        ("/vo/group/back/lock", vec![float(0.5)]),
        ("/vo/light/99/lock", vec![int(1)]),
        ("/vo/light/0/lock", vec![int(1)]),
        ("/vo/light/3/lock", vec![int(-1)]),
    ] {
        d.refused(addr, args);
    }
}

#[test]
fn a_colour_only_objective_on_a_dark_stage_lights_its_colours_and_says_so() {
    let mut d = Daemon::start("gal-colour-dark");
    assert!(d.live().iter().all(|l| l.intensity == 0.0), "a dark start");
    d.add_objective("warm.png", "color");
    let r = d.generate();
    // The note follows the reply it explains (a pong sent meanwhile may come between).
    let mut got = d.collect("/vo/note", PATIENCE, "the generate's note");
    got.extend(d.fence());
    let notes: Vec<String> = got
        .into_iter()
        .filter(|m| m.addr == "/vo/note")
        .map(|m| text(&m.args[0]))
        .collect();
    assert_eq!(notes.len(), 1, "{notes:?}\n{}", d.log());
    assert!(
        notes[0].contains("warm.png") && notes[0].contains("colour only"),
        "{notes:?}"
    );
    assert!(num(&r.args[1]) as i32 > 1, "more than one look: {r:?}");
    let lit = d.candidate(1, 1);
    assert!(lit.iter().any(|l| l.intensity > 0.0), "{lit:?}");
    assert!(
        lit.iter()
            .any(|l| fixture(l.ch).has_colour() && l.intensity > 0.0 && l.color != [1.0; 3]),
        "the colours show on lit lights: {lit:?}"
    );
    // With light in the base, intensities are the designer's: no note.
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    d.generate();
    assert!(
        d.fence().iter().all(|m| m.addr != "/vo/note"),
        "no note over a lit base"
    );
}
