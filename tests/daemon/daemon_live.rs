//! The live look, status and feedback addresses of docs/osc.md against the real daemon: each with
//! a success and a refused case that changes nothing.

use crate::common;
use crate::common::daemon::{
    Daemon, Osc, PATIENCE, Proto, STAGE, fixture, float, int, num, string, text,
};

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-4
}

#[test]
fn light_intensity_and_level_are_faders() {
    let mut d = Daemon::start("live-light");
    let r = d.ok("/vo/light/1/intensity", vec![float(0.5)], "/vo/light");
    assert_eq!(num(&r.args[0]) as i32, 1);
    assert!(close(num(&r.args[1]), 0.5), "{r:?}");
    // A dimmer reports colour 1 1 1.
    assert!(r.args[2..].iter().all(|a| close(num(a), 1.0)), "{r:?}");
    let r = d.ok("/vo/light/6/level", vec![int(25)], "/vo/light");
    assert!(close(num(&r.args[1]), 0.25), "{r:?}");
    let live = d.live();
    assert_eq!(
        live.iter().map(|l| l.ch).collect::<Vec<_>>(),
        STAGE.iter().map(|f| f.channel).collect::<Vec<_>>(),
        "one entry per light in channel order"
    );
    assert!(close(live[0].intensity.into(), 0.5) && close(live[5].intensity.into(), 0.25));
    assert!(live[1..5].iter().all(|l| l.intensity == 0.0), "{live:?}");
    // At once (no fade): dimmer 1 at slot 1 of universe 1.
    d.wire.wait_both(1, "light 1 at half", |dmx| dmx[0] == 128);
    let before = d.snapshot();
    for (addr, args) in [
        ("/vo/light/1/intensity", vec![float(1.5)]),
        ("/vo/light/1/intensity", vec![float(-0.1)]),
        ("/vo/light/1/intensity", vec![string("bright")]),
        ("/vo/light/1/intensity", vec![]),
        ("/vo/light/99/intensity", vec![float(0.5)]),
        ("/vo/light/0/intensity", vec![float(0.5)]),
        ("/vo/light/1/level", vec![int(101)]),
        ("/vo/light/1/level", vec![int(-1)]),
        ("/vo/light/99/level", vec![int(50)]),
    ] {
        d.err(addr, args);
    }
    assert_eq!(d.snapshot(), before);
    let sentence = d.err("/vo/light/99/level", vec![int(50)]);
    assert!(
        sentence.contains("99"),
        "the error names the light: {sentence}"
    );
}

#[test]
fn light_color_sets_a_colour_light_and_refuses_a_dimmer() {
    let mut d = Daemon::start("live-color");
    d.ok("/vo/light/3/intensity", vec![float(1.0)], "/vo/light");
    let r = d.ok(
        "/vo/light/3/color",
        vec![float(1.0), float(0.5), float(0.0)],
        "/vo/light",
    );
    let v: Vec<f64> = r.args.iter().map(num).collect();
    assert!(close(v[0], 3.0) && close(v[1], 1.0), "{r:?}");
    assert!(
        close(v[2], 1.0) && close(v[3], 0.5) && close(v[4], 0.0),
        "{r:?}"
    );
    // irgb at 10: intensity 255, red 255, green = linear(0.5) = 0.214 -> 55, blue 0.
    d.wire
        .wait_both(1, "irgb 3 at orange", |dmx| dmx[9..13] == [255, 255, 55, 0]);
    let before = d.snapshot();
    for (addr, args) in [
        (
            "/vo/light/1/color",
            vec![float(1.0), float(0.0), float(0.0)],
        ),
        (
            "/vo/light/3/color",
            vec![float(1.2), float(0.0), float(0.0)],
        ),
        ("/vo/light/3/color", vec![float(1.0), float(0.0)]),
        (
            "/vo/light/3/color",
            vec![string("red"), float(0.0), float(0.0)],
        ),
        (
            "/vo/light/99/color",
            vec![float(1.0), float(0.0), float(0.0)],
        ),
    ] {
        d.err(addr, args);
    }
    assert_eq!(d.snapshot(), before);
    let sentence = d.err(
        "/vo/light/1/color",
        vec![float(1.0), float(0.0), float(0.0)],
    );
    assert!(!sentence.is_empty());
}

#[test]
fn group_faders_and_colour() {
    let mut d = Daemon::start("live-group");
    let r = d.ok("/vo/group/back/intensity", vec![float(0.5)], "/vo/group");
    assert_eq!(
        (text(&r.args[0]).as_str(), num(&r.args[1]) as i32),
        ("back", 2)
    );
    let r = d.ok("/vo/Group/FRONT/level", vec![int(20)], "/vo/group");
    assert_eq!(num(&r.args[1]) as i32, 2, "{r:?}");
    let r = d.ok(
        "/vo/group/side/color",
        vec![float(0.0), float(0.0), float(1.0)],
        "/vo/group",
    );
    assert_eq!(num(&r.args[1]) as i32, 2, "{r:?}");
    let live = d.live();
    for l in &live {
        let f = fixture(l.ch);
        let want = match f.group {
            "back" => 0.5,
            "front" => 0.2,
            _ => 0.0,
        };
        assert!(close(l.intensity.into(), want), "{l:?}");
        if f.group == "side" {
            assert_eq!(l.color, [0.0, 0.0, 1.0], "{l:?}");
        }
    }
    let before = d.snapshot();
    for (addr, args) in [
        ("/vo/group/wings/intensity", vec![float(0.5)]),
        ("/vo/group/back/intensity", vec![float(2.0)]),
        ("/vo/group/back/level", vec![int(101)]),
        ("/vo/group/back/level", vec![string("full")]),
        (
            "/vo/group/side/color",
            vec![float(0.0), float(-1.0), float(1.0)],
        ),
        // Every light of "front" is a dimmer.
        (
            "/vo/group/front/color",
            vec![float(1.0), float(0.0), float(0.0)],
        ),
    ] {
        d.err(addr, args);
    }
    assert_eq!(d.snapshot(), before);
}

#[test]
fn live_lists_every_light() {
    let mut d = Daemon::start("live-live");
    let live = d.live();
    assert_eq!(live.len(), STAGE.len());
    assert!(
        live.iter().all(|l| l.intensity == 0.0),
        "a new stage starts dark: {live:?}"
    );
    for l in &live {
        if !fixture(l.ch).has_colour() {
            assert_eq!(l.color, [1.0; 3], "{l:?}");
        }
    }
    d.refused("/vo/livee", vec![]);
    d.refused("/vo/live/now", vec![]);
}

#[test]
fn fade_sets_the_default_crossfade() {
    let mut d = Daemon::start("live-fade");
    assert_eq!(d.status().fade, 0.0);
    let r = d.ok("/vo/fade", vec![float(2.5)], "/vo/fade");
    assert!(close(num(&r.args[0]), 2.5));
    assert!(close(d.status().fade, 2.5));
    d.ok("/vo/fade", vec![int(600)], "/vo/fade");
    d.ok("/vo/fade", vec![int(0)], "/vo/fade");
    for bad in [float(-1.0), float(600.5), string("slow")] {
        d.refused("/vo/fade", vec![bad]);
    }
    d.refused("/vo/fade", vec![]);
}

#[test]
fn master_scales_output_and_blackout_zeros_it() {
    let mut d = Daemon::start("live-master");
    d.ok("/vo/light/1/intensity", vec![float(1.0)], "/vo/light");
    d.ok("/vo/light/5/intensity", vec![float(1.0)], "/vo/light");
    d.wire.wait_both(1, "dimmer 1 full", |dmx| dmx[0] == 255);
    let r = d.ok("/vo/master", vec![float(0.5)], "/vo/master");
    assert!(close(num(&r.args[0]), 0.5));
    assert!(close(d.status().master, 0.5));
    d.wire.wait_both(1, "dimmer 1 at half", |dmx| dmx[0] == 128);
    // rgb without a dimmer: intensity folded into white emitters.
    d.wire
        .wait_both(2, "rgb 5 at half", |dmx| dmx[9..12] == [128, 128, 128]);
    // The live look is unmastered.
    assert!(close(d.live()[0].intensity.into(), 1.0));
    for bad in [float(1.5), float(-0.5), string("loud")] {
        d.refused("/vo/master", vec![bad]);
    }

    let r = d.ok("/vo/blackout", vec![int(1)], "/vo/blackout");
    assert_eq!(num(&r.args[0]) as i32, 1);
    assert_eq!(d.status().blackout, 1);
    for u in [1, 2] {
        d.wire
            .wait_both(u, "all zeros", |dmx| dmx.iter().all(|&b| b == 0));
    }
    for bad in [int(2), string("on"), float(0.5)] {
        d.refused("/vo/blackout", vec![bad]);
    }
    d.refused("/vo/blackout", vec![]);
    d.ok("/vo/blackout", vec![int(0)], "/vo/blackout");
    assert_eq!(d.status().blackout, 0);
    d.wire.wait_both(1, "back to half", |dmx| dmx[0] == 128);
}

#[test]
fn ping_and_status() {
    let mut d = Daemon::start("live-status");
    for args in [
        vec![],
        vec![int(1)],
        vec![string("hello"), float(2.5), int(-3)],
    ] {
        let r = d.ok("/vo/ping", args.clone(), "/vo/pong");
        assert_eq!(r.args, args);
    }
    let s = d.status();
    assert_eq!(s.scene, "test scene");
    assert_eq!(s.lights, STAGE.len() as i32);
    assert_eq!(
        (s.objectives, s.candidates, s.clusters, s.entry),
        (0, 0, 0, 0)
    );
    assert_eq!((s.fade, s.blackout, s.master), (0.0, 0, 1.0));
    d.refused("/vo/statuss", vec![]);
    d.refused("/vo/ping/pong", vec![]);
}

#[test]
fn subscribe_sends_the_state_then_changes() {
    let mut d = Daemon::start("live-subscribe");
    d.add_objective("warm.png", "both");
    let mut tablet = d.client();
    let mut listen = d.client();
    let port = i32::from(listen.port());
    d.ok(
        "/vo/look/save",
        vec![int(3), string("pre")],
        "/vo/look/saved",
    );

    let got = tablet.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(num(&got[0].args[0]) as i32, port);
    // The whole state arrives at `port`: status, objectives, looks (gallery and live entry
    // in whatever messages the daemon uses).
    let dump = listen.collect("/vo/status", PATIENCE, "the state after subscribing");
    let mut all = dump;
    all.extend(listen.fence());
    let addrs: Vec<&str> = all.iter().map(|m| m.addr.as_str()).collect();
    for want in ["/vo/status", "/vo/objective", "/vo/look"] {
        assert!(addrs.contains(&want), "{want} missing from {addrs:?}");
    }

    // A change from another client is pushed.
    d.ok("/vo/master", vec![float(0.5)], "/vo/master");
    let pushed = listen.collect("/vo/status", PATIENCE, "a pushed status");
    let s = pushed.last().expect("status");
    assert!(close(num(&s.args[8]), 0.5), "{s:?}");
    // So is a generate, with progress.
    d.generate();
    let pushed = listen.collect("/vo/generated", common::daemon::GENERATE_PATIENCE, "push");
    assert_eq!(pushed.last().expect("generated").addr, "/vo/generated");
    // Whatever else the generate pushed (a status, say) is taken out here.
    listen.fence();

    d.refused("/vo/subscribe", vec![int(70000)]);
    d.refused("/vo/subscribe", vec![string("tablet")]);

    let r = tablet.ok("/vo/unsubscribe", vec![], "/vo/unsubscribed");
    assert!(r.args.is_empty() || r.args.len() == 1, "{r:?}");
    d.ok("/vo/master", vec![float(0.75)], "/vo/master");
    let late = listen.fence();
    assert!(
        late.iter().all(|m| m.addr != "/vo/status"),
        "still pushed after unsubscribing: {late:?}"
    );
    d.refused("/vo/unsubscribe/now", vec![]);
}

#[test]
fn eos_preset_without_a_console_is_refused() {
    let mut d = Daemon::start("live-eos");
    // docs/config.md: no Eos console by default: nothing to push to.
    d.refused("/vo/eos/preset", vec![int(1)]);
    d.refused("/vo/eos/preset", vec![string("one")]);
    d.refused("/vo/eos/preset", vec![]);
}

#[test]
fn receivers_see_the_configured_source() {
    let d = Daemon::start("live-source");
    d.wire.wait(Proto::Sacn, 1, "any frame", |_| true);
    let f = d.wire.latest(Proto::Sacn, 1).expect("a frame");
    assert_eq!((f.source_name.as_str(), f.priority), ("visobjd test", 100));
    assert!(!f.terminated);
}

#[test]
fn pushes_keep_the_order_of_the_changes() {
    // Two tablets move the master at the same moment, again and again: the last status a
    // subscriber is pushed must be the state the daemon ends in, never the change that
    // lost the race (a tablet would be left showing a stale value).
    let mut d = Daemon::start("live-order");
    let mut listen = d.client();
    let port = i32::from(listen.port());
    listen.call("/vo/subscribe", vec![int(port)], "/vo/subscribed");
    listen.fence();
    let (mut a, mut b) = (d.client(), d.client());
    for round in 0..400 {
        let (va, vb) = (
            f64::from(round % 97) / 100.0,
            0.99 - f64::from(round % 89) / 100.0,
        );
        std::thread::scope(|s| {
            s.spawn(|| a.ok("/vo/master", vec![float(va as f32)], "/vo/master"));
            s.spawn(|| b.ok("/vo/master", vec![float(vb as f32)], "/vo/master"));
        });
        // Both replies are in, so both changes' pushes were sent: the fence sees them.
        let pushed = listen.fence();
        let last = pushed
            .iter()
            .rev()
            .find(|m| m.addr == "/vo/status")
            .unwrap_or_else(|| panic!("round {round}: no status pushed: {pushed:?}"));
        let now = d.status().master;
        let shown = common::daemon::Status::parse(last).master;
        assert!(
            close(shown, now),
            "round {round}: the master is {now} but the last push says {shown} ({va} and {vb} sent at once)"
        );
    }
}
