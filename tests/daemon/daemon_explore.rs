//! Exploration that follows the hand (docs/osc.md, "Explore"), against the real daemon over
//! OSC on loopback: `/vo/explore 1` streams galleries to a subscriber while the region
//! moves; after `/vo/explore 0` the gallery is the last region's, and the same seed replayed
//! with a normal generate gives the same gallery; a flood of region updates is answered in
//! full with far fewer galleries; bad input during a drag is refused and changes nothing.

use crate::common::daemon::{
    Daemon, GENERATE_PATIENCE, LightLevel, Osc, PATIENCE, TcpFraming, Udp, float, int, num, string,
    text,
};
use rosc::OscType;

/// The region of step `i` of a drag: a half-stage window sliding right and down.
fn window(i: usize) -> [f32; 4] {
    let t = (i % 50) as f32 / 100.0;
    [t, t / 2.0, t + 0.5, t / 2.0 + 0.5]
}

fn region_args(r: [f32; 4]) -> Vec<OscType> {
    r.into_iter().map(float).collect()
}

/// A subscriber: `tablet` subscribes, pushes go to `listen`.
fn subscriber(d: &Daemon) -> Udp {
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence(); // the state pushed at subscription
    listen
}

/// Every candidate of the gallery, entry by entry.
fn gallery(d: &mut Daemon) -> Vec<Vec<LightLevel>> {
    let sizes = d.gallery();
    let mut all = Vec::new();
    for (k, &n) in sizes.iter().enumerate() {
        for m in 1..=n {
            all.push(d.candidate(k as i32 + 1, m));
        }
    }
    all
}

/// The region `/vo/objectives` lists for objective `id`.
fn region_of(d: &mut Daemon, id: i32) -> [f32; 4] {
    let objectives = d.objectives();
    let o = objectives
        .iter()
        .find(|m| num(&m.args[0]) as i32 == id)
        .unwrap_or_else(|| panic!("objective {id} in {objectives:?}"));
    std::array::from_fn(|i| num(&o.args[3 + i]) as f32)
}

/// `/vo/explore 0`: its reply `[0, galleries, seed]`.
fn stop(hand: &mut impl Osc) -> (usize, i32) {
    let r = hand.ok("/vo/explore", vec![int(0)], "/vo/explore");
    assert_eq!(r.args.len(), 3, "{r:?}");
    assert_eq!(num(&r.args[0]), 0.0, "{r:?}");
    (num(&r.args[1]) as usize, num(&r.args[2]) as i32)
}

/// `/vo/explore 1`: the drag's seed.
fn start(hand: &mut impl Osc) -> i32 {
    let r = hand.ok("/vo/explore", vec![int(1)], "/vo/explore");
    assert_eq!(r.args.len(), 2, "{r:?}");
    assert_eq!(num(&r.args[0]), 1.0, "{r:?}");
    num(&r.args[1]) as i32
}

/// The last gallery is the last region's: it equals a normal generate with the drag's seed
/// from the same session (the objectives listing shows that region).
fn assert_replayable(d: &mut Daemon, last: [f32; 4], seed: i32) {
    let shown = region_of(d, 1);
    for (got, want) in shown.iter().zip(last) {
        assert!((got - want).abs() < 1e-6, "region {shown:?}, sent {last:?}");
    }
    let explored = gallery(d);
    assert!(!explored.is_empty(), "a gallery after the drag");
    d.send("/vo/generate/seeded", vec![int(seed)]);
    let got = d.collect("/vo/generated", GENERATE_PATIENCE, "the replay");
    let r = got.last().expect("a reply");
    assert_eq!(r.addr, "/vo/generated", "replay refused: {r:?}");
    assert_eq!(num(&r.args[3]) as i32, seed, "{r:?}");
    assert_eq!(
        gallery(d),
        explored,
        "the drag's last gallery is not what its region and seed give"
    );
}

#[test]
fn explore_streams_galleries_while_the_region_moves() {
    let mut d = Daemon::start("explore-stream");
    let id = d.add_objective("warm.png", "both");
    let mut listen = subscriber(&d);
    let mut hand = d.client();

    let seed = start(&mut hand);
    let pushed = listen.collect("/vo/explore", PATIENCE, "the explore push");
    assert_eq!(
        pushed.last().map(|m| m.args.clone()),
        Some(vec![int(1), int(seed)])
    );
    // Each region update brings a gallery to the subscriber, while the drag goes on.
    let mut streamed = 0;
    for i in 0..12 {
        let r = hand.ok(
            &format!("/vo/objective/{id}/region"),
            region_args(window(i)),
            "/vo/objective/region",
        );
        assert_eq!(num(&r.args[0]) as i32, id, "{r:?}");
        let got = listen.collect("/vo/generated", GENERATE_PATIENCE, "a streamed gallery");
        let g = got.last().expect("a push");
        assert_eq!(g.addr, "/vo/generated", "{got:?}");
        // Up to 50 galleries a second: no progress bar flickers through each.
        assert!(
            got.iter().all(|m| m.addr != "/vo/progress"),
            "an explore gallery pushed progress: {got:?}"
        );
        assert_eq!(num(&g.args[3]) as i32, seed, "one seed for the drag: {g:?}");
        assert!(num(&g.args[1]) >= 1.0, "entries: {g:?}");
        streamed += 1;
        let text_line = got
            .iter()
            .find(|m| m.addr == "/vo/status/text")
            .map(|m| text(&m.args[0]));
        if let Some(line) = text_line {
            assert!(line.contains("exploring"), "{line}");
        }
    }
    // A normal generate waits for the end of the drag.
    let why = d.err("/vo/generate", vec![]);
    assert!(why.contains("/vo/explore 0"), "{why}");

    let last = [0.1, 0.2, 0.7, 0.9];
    hand.ok(
        &format!("/vo/objective/{id}/region"),
        region_args(last),
        "/vo/objective/region",
    );
    let (galleries, stopped_seed) = stop(&mut hand);
    assert_eq!(stopped_seed, seed);
    assert!(
        galleries >= streamed,
        "{galleries} galleries, {streamed} seen"
    );
    let after = listen.collect("/vo/explore", PATIENCE, "the end of explore pushed");
    let streamed_seeds: Vec<i32> = after
        .iter()
        .filter(|m| m.addr == "/vo/generated")
        .map(|m| num(&m.args[3]) as i32)
        .collect();
    assert!(
        streamed_seeds.iter().all(|&s| s == seed),
        "{streamed_seeds:?}"
    );
    let line = status_line(&d);
    assert!(!line.contains("exploring"), "{line}");
    assert_replayable(&mut d, last, seed);
}

#[test]
fn a_flood_of_region_updates_is_answered_with_far_fewer_galleries() {
    let mut d = Daemon::start("explore-flood");
    let id = d.add_objective("cool.png", "both");
    let mut listen = subscriber(&d);
    // Over TCP: a burst of 1000 datagrams and their 1000 replies would overflow the
    // sockets' buffers (UDP drops, by design), and every update must arrive to be counted.
    let mut hand = d.tcp(TcpFraming::LengthPrefix);
    let seed = start(&mut hand);
    const UPDATES: usize = 1000;
    let path = format!("/vo/objective/{id}/region");
    for i in 0..UPDATES {
        hand.send(&path, region_args(window(i)));
    }
    // Another client is answered meanwhile.
    let mut other = d.client();
    other.ok("/vo/ping", vec![string("during the flood")], "/vo/pong");
    // Every update is answered, in order.
    let mut answered = 0;
    while answered < UPDATES {
        let m = hand
            .next(GENERATE_PATIENCE)
            .unwrap_or_else(|| panic!("only {answered} of {UPDATES} updates answered"));
        assert_eq!(m.addr, "/vo/objective/region", "{m:?}");
        let got: Vec<f32> = m.args[1..5].iter().map(|a| num(a) as f32).collect();
        assert_eq!(got, window(answered).to_vec(), "update {answered}");
        answered += 1;
    }
    let (galleries, _) = stop(&mut hand);
    let pushed = listen.collect("/vo/explore", GENERATE_PATIENCE, "the end pushed");
    let streamed = pushed.iter().filter(|m| m.addr == "/vo/generated").count();
    assert!(
        galleries >= 1 && streamed <= galleries,
        "{streamed} of {galleries}"
    );
    assert!(
        galleries * 2 < UPDATES,
        "{galleries} galleries for {UPDATES} updates: stale updates were not dropped"
    );
    other.ok("/vo/ping", vec![string("after")], "/vo/pong");
    assert_replayable(&mut d, window(UPDATES - 1), seed);
}

#[test]
fn bad_input_during_a_drag_is_refused_and_changes_nothing() {
    let mut d = Daemon::start("explore-bad");
    // No objective: nothing to explore.
    let why = d.refused("/vo/explore", vec![int(1)]);
    assert!(why.contains("no objectives"), "{why}");
    let id = d.add_objective("warm.png", "intensity");
    let mut listen = subscriber(&d);
    let seed = start(&mut d);
    // The gallery of the touch is in: from here the state holds still.
    listen.collect("/vo/generated", GENERATE_PATIENCE, "the first gallery");
    listen.fence();

    let path = format!("/vo/objective/{id}/region");
    let why = d.refused("/vo/objective/9/region", region_args([0.0, 0.0, 0.5, 0.5]));
    assert!(why.contains("objective 9 does not exist"), "{why}");
    d.refused(&path, region_args([0.6, 0.0, 0.5, 0.5])); // x0 > x1
    d.refused(&path, region_args([0.0, 0.0, 1.5, 0.5])); // out of range
    d.refused(&path, vec![float(0.1), float(0.2)]); // too few
    d.refused(
        &path,
        vec![string("left"), float(0.0), float(0.5), float(0.5)],
    );
    d.refused("/vo/explore", vec![int(2)]);
    d.refused("/vo/explore", vec![]);
    d.refused("/vo/objective/zz/region", region_args([0.0, 0.0, 0.5, 0.5]));
    let extra = listen.fence();
    assert!(
        extra.iter().all(|m| m.addr != "/vo/generated"),
        "a refused update made a gallery: {extra:?}"
    );

    // The drag goes on after them.
    let last = [0.25, 0.0, 0.75, 1.0];
    d.ok(&path, region_args(last), "/vo/objective/region");
    let (_, stopped) = stop(&mut d);
    assert_eq!(stopped, seed);
    // Stopping again is harmless.
    assert_eq!(stop(&mut d), (0, 0));
    assert_replayable(&mut d, last, seed);
}

/// The status line now, as a new subscriber gets it.
fn status_line(d: &Daemon) -> String {
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    let state = listen.collect("/vo/status/text", PATIENCE, "the status line");
    text(&state.last().expect("status text").args[0])
}

#[test]
fn a_daemon_stopped_mid_drag_exits_and_keeps_the_last_region() {
    let mut d = Daemon::start("explore-stop");
    let id = d.add_objective("warm.png", "both");
    start(&mut d);
    let last = [0.3, 0.1, 0.8, 0.6];
    d.ok(
        &format!("/vo/objective/{id}/region"),
        region_args(last),
        "/vo/objective/region",
    );
    // No /vo/explore 0: the tablet vanished, then the daemon is stopped.
    let status = d.terminate();
    assert!(status.success(), "{status:?}\n{}", d.log_text());
    d.restart();
    let kept = region_of(&mut d, id);
    for (got, want) in kept.iter().zip(last) {
        assert!((got - want).abs() < 1e-6, "kept {kept:?}, sent {last:?}");
    }
}
