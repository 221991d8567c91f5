//! What the real daemon puts on the wire (docs/dmx.md), received on loopback and decoded
//! independently: picks land as the candidate's values through each profile, fades take
//! their time, frames never stop (idle, during a generate, during a flood), a kill -9
//! restarts into the same look, and SIGTERM terminates every sACN universe.

use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{
    Daemon, DmxPacket, GAP, Osc, PROTOS, Proto, STAGE, UNIVERSES, float, int, look_mismatch, num,
    same_look, string,
};

#[test]
fn pick_puts_exactly_the_candidate_on_the_wire() {
    let mut d = Daemon::start("dmx-pick");
    d.add_objective("warm.png", "both");
    d.generate();
    let c = d.gallery().len() as i32;
    for k in 1..=c.min(3) {
        d.ok("/vo/pick", vec![int(k)], "/vo/picked");
        let want = d.candidate(k, 1);
        for proto in PROTOS {
            d.wire.wait_look(proto, &want);
        }
        // Art-Net and sACN say the same, and slots no light uses are 0.
        let sacn = d.wire.latest_universes(Proto::Sacn).expect("frames");
        let art = d.wire.latest_universes(Proto::Artnet).expect("frames");
        for u in UNIVERSES {
            assert_eq!(sacn[&u], art[&u], "universe {u}: Art-Net and sACN differ");
            let used: Vec<usize> = STAGE
                .iter()
                .filter(|f| f.universe == u)
                .flat_map(|f| f.address - 1..f.address - 1 + f.footprint())
                .collect();
            for (i, &b) in sacn[&u].iter().enumerate() {
                assert!(
                    used.contains(&i) || b == 0,
                    "universe {u} slot {} is {b}",
                    i + 1
                );
            }
        }
        // The comparison can tell: a dimmer 10 steps away from the look is a mismatch.
        let mut off = want.clone();
        let dimmer = off
            .iter_mut()
            .find(|l| common::daemon::fixture(l.ch).profile == "dimmer")
            .expect("a dimmer");
        let step = 10.0 / 255.0;
        dimmer.intensity += if dimmer.intensity < 0.5 { step } else { -step };
        assert!(
            look_mismatch(&off, &sacn).is_some(),
            "a changed look still matches"
        );
        // rgbw: the white slot takes the common part, so one of r, g, b is (nearly) 0.
        let rgbw = STAGE.iter().find(|f| f.profile == "rgbw").expect("an rgbw");
        let s = rgbw.slots(&sacn[&rgbw.universe]);
        assert!(
            s[..3].iter().min().copied().unwrap_or(0) <= 1,
            "rgbw slots {s:?}"
        );
    }
}

#[test]
fn a_one_second_fade_takes_about_a_second_and_faders_do_not_fade() {
    let mut d = Daemon::start("dmx-fade");
    d.ok(
        "/vo/look/save",
        vec![int(1), string("dark")],
        "/vo/look/saved",
    );
    d.ok("/vo/light/1/level", vec![int(100)], "/vo/light");
    d.ok(
        "/vo/look/save",
        vec![int(2), string("full")],
        "/vo/look/saved",
    );
    d.ok("/vo/look/recall", vec![int(1)], "/vo/look/recalled");
    d.wire.wait_both(1, "light 1 dark", |dmx| dmx[0] == 0);
    d.ok("/vo/fade", vec![float(1.0)], "/vo/fade");
    let began = Instant::now();
    d.ok("/vo/look/recall", vec![int(2)], "/vo/look/recalled");
    d.wire.wait_both(1, "light 1 full", |dmx| dmx[0] == 255);
    for proto in PROTOS {
        let frames = d.wire.frames(proto, 1, began);
        let end = frames.iter().position(|f| f.dmx[0] == 255).expect("full");
        let took = frames[end].at - began;
        assert!(
            took >= Duration::from_millis(800) && took <= Duration::from_millis(1600),
            "{proto:?}: a 1 s fade reached full after {took:?}"
        );
        let values: Vec<u8> = frames[..=end].iter().map(|f| f.dmx[0]).collect();
        assert!(
            values.windows(2).all(|w| w[0] <= w[1]),
            "{proto:?}: {values:?}"
        );
        let between = values.iter().filter(|&&v| v > 0 && v < 255).count();
        assert!(
            between >= 10,
            "{proto:?}: {between} intermediate frames: {values:?}"
        );
    }
    // A fader applies at once, fade or not.
    let set = Instant::now();
    d.ok("/vo/light/1/level", vec![int(0)], "/vo/light");
    d.wire
        .wait_both(1, "light 1 off at once", |dmx| dmx[0] == 0);
    for proto in PROTOS {
        let values: Vec<u8> = d
            .wire
            .frames(proto, 1, set)
            .iter()
            .map(|f| f.dmx[0])
            .collect();
        assert!(
            values.iter().all(|&v| v == 0 || v == 255),
            "{proto:?} faded: {values:?}"
        );
        assert!(
            values.iter().take_while(|&&v| v == 255).count() <= 2,
            "{values:?}"
        );
    }
}

#[test]
fn frames_flow_at_the_rate_in_sequence() {
    let d = Daemon::start("dmx-rate");
    let from = Instant::now();
    let to = from + Duration::from_secs(1);
    d.wire.wait(Proto::Sacn, 1, "a frame after a second", |_| {
        Instant::now() > to
    });
    d.wire.assert_continuous(from, to, GAP, "while idle");
    for proto in PROTOS {
        for u in UNIVERSES {
            let frames: Vec<DmxPacket> = d
                .wire
                .frames(proto, u, from)
                .into_iter()
                .filter(|f| f.at <= to)
                .collect();
            assert!(
                (15..=25).contains(&frames.len()),
                "{proto:?} {u}: {} frames in 1 s at 20 Hz",
                frames.len()
            );
            for w in frames.windows(2) {
                let want = match proto {
                    Proto::Sacn => w[0].sequence.wrapping_add(1),
                    Proto::Artnet if w[0].sequence == 255 => 1,
                    Proto::Artnet => w[0].sequence + 1,
                };
                assert_eq!(w[1].sequence, want, "{proto:?} universe {u} sequence");
            }
        }
    }
}

#[test]
fn generate_neither_stops_the_frames_nor_the_answers() {
    let mut d = Daemon::start("dmx-generate");
    d.add_objective("warm.png", "both");
    d.add_objective("cool.png", "color");
    d.ok("/vo/generate/count", vec![int(1000)], "/vo/generate/count");
    let mut other = d.client();
    let from = Instant::now();
    d.send("/vo/generate", vec![]);
    let mut pongs_before = 0;
    let generated = loop {
        if let Some(m) = d.next(Duration::from_millis(50)) {
            assert_ne!(m.addr, "/vo/error", "{m:?}");
            if m.addr == "/vo/generated" {
                break m;
            }
        }
        assert!(
            from.elapsed() < common::daemon::GENERATE_PATIENCE,
            "no /vo/generated"
        );
        let asked = Instant::now();
        let r = other.ok("/vo/ping", vec![int(pongs_before)], "/vo/pong");
        assert_eq!(r.args, [int(pongs_before)]);
        let waited = asked.elapsed();
        assert!(
            waited < Duration::from_millis(500),
            "a ping took {waited:?} during a generate"
        );
        pongs_before += 1;
    };
    let to = Instant::now().max(from + Duration::from_millis(500));
    let took = to - from;
    println!(
        "a generate of 1000: {generated:?} after {took:?}; {pongs_before} pings answered meanwhile"
    );
    assert_eq!(generated.args.len(), 4, "{generated:?}");
    assert_eq!(num(&generated.args[0]) as i32, 1000);
    assert!(num(&generated.args[1]) >= 1.0);
    assert!(num(&generated.args[2]) >= 0.0);
    if took > Duration::from_millis(500) {
        assert!(
            pongs_before > 0,
            "no ping answered during a {took:?} generate"
        );
    }
    d.wire
        .wait(Proto::Sacn, 1, "a frame after the generate", |_| {
            Instant::now() > to
        });
    d.wire
        .assert_continuous(from, to, GAP, &format!("during a generate of {took:?}"));
}

#[test]
fn a_flood_of_messages_does_not_stop_the_frames() {
    let mut d = Daemon::start("dmx-flood");
    let to_daemon = ("127.0.0.1", d.port);
    let from = Instant::now();
    let flood = std::thread::spawn(move || {
        let s = UdpSocket::bind("127.0.0.1:0").expect("bind");
        let status =
            rosc::encoder::encode(&common::daemon::msg("/vo/status", vec![])).expect("enc");
        let mut sent = 0;
        // 2,000 messages a second for 2 s, in bursts of 20 every 10 ms.
        for burst in 0..200u32 {
            let due = from + Duration::from_millis(u64::from(burst) * 10);
            if let Some(wait) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            for i in 0..20 {
                let level = (burst * 20 + i) % 100;
                let fader = rosc::encoder::encode(&common::daemon::msg(
                    "/vo/light/1/level",
                    vec![int(level as i32)],
                ))
                .expect("enc");
                let p = if i % 2 == 0 { &status } else { &fader };
                if s.send_to(p, to_daemon).is_ok() {
                    sent += 1;
                }
            }
        }
        sent
    });
    let sent = flood.join().expect("flood");
    let to = Instant::now();
    assert!(sent >= 3900, "sent {sent}");
    d.wire.wait(Proto::Sacn, 2, "a frame after the flood", |_| {
        Instant::now() > to
    });
    d.wire
        .assert_continuous(from, to, GAP, "during a flood of 2,000 messages/s");
    // Still answering.
    let r = d.ok("/vo/ping", vec![string("after")], "/vo/pong");
    assert_eq!(r.args, [string("after")]);
}

#[test]
fn kill_9_restarts_into_the_same_look_from_the_first_frame() {
    let mut d = Daemon::start("dmx-kill");
    d.ok("/vo/light/1/level", vec![int(30)], "/vo/light");
    d.ok(
        "/vo/light/3/color",
        vec![float(1.0), float(0.3), float(0.0)],
        "/vo/light",
    );
    d.ok("/vo/light/3/intensity", vec![float(0.6)], "/vo/light");
    d.ok(
        "/vo/group/back/color",
        vec![float(0.2), float(0.6), float(1.0)],
        "/vo/group",
    );
    d.ok("/vo/group/back/intensity", vec![float(0.8)], "/vo/group");
    let live = d.live();
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    let cid = d.wire.latest(Proto::Sacn, 1).expect("frame").cid;
    // Fader moves are not waited for on disk (a fader sends dozens a second); a recall is
    // a discrete change, answered once it is durable: kill -9 right after its reply.
    d.ok("/vo/look/save", vec![int(1)], "/vo/look/saved");
    d.send("/vo/look/recall", vec![int(1)]);
    let r = d.collect("/vo/look/recalled", common::daemon::PATIENCE, "recall");
    assert_eq!(
        r.last().map(|m| m.addr.as_str()),
        Some("/vo/look/recalled"),
        "{r:?}"
    );
    d.kill();
    // Frames of the killed process still queued on the receivers are read first.
    d.wire.drained_after(Instant::now());
    let restarted = Instant::now();
    d.restart();
    d.wire
        .wait(Proto::Sacn, 2, "a frame after restart", |_| true);
    d.wire
        .wait(Proto::Artnet, 2, "a frame after restart", |_| true);
    for proto in PROTOS {
        let first: BTreeMap<u16, Vec<u8>> = UNIVERSES
            .iter()
            .map(|&u| {
                let f = d.wire.frames(proto, u, restarted);
                (u, f.first().expect("a frame after restart").dmx.clone())
            })
            .collect();
        if let Some(why) = look_mismatch(&live, &first) {
            panic!("{proto:?}: the first frames after restart are not the live look: {why}");
        }
    }
    let after = d.wire.frames(Proto::Sacn, 1, restarted);
    assert_eq!(after[0].cid, cid, "the sACN CID survives a restart");
    assert!(
        same_look(&d.live(), &live, 1e-6),
        "{:?} vs {live:?}",
        d.live()
    );
}

#[test]
fn sigterm_terminates_every_sacn_universe_three_times() {
    let mut d = Daemon::start("dmx-sigterm");
    d.ok("/vo/light/4/intensity", vec![float(1.0)], "/vo/light");
    d.wire
        .wait(Proto::Sacn, 2, "light 4 on", |dmx| dmx[0] == 255);
    let asked = Instant::now();
    let status = d.terminate();
    let exited = Instant::now();
    assert_eq!(
        status.code(),
        Some(0),
        "exit status after SIGTERM: {status}"
    );
    d.wire.drained_after(exited);
    for u in UNIVERSES {
        let frames = d.wire.frames(Proto::Sacn, u, asked);
        let first = frames
            .iter()
            .position(|f| f.terminated)
            .unwrap_or_else(|| panic!("universe {u}: no Stream_Terminated packet"));
        let tail = &frames[first..];
        assert!(
            tail.iter().all(|f| f.terminated),
            "universe {u}: data after termination"
        );
        assert_eq!(
            tail.len(),
            3,
            "universe {u}: {} terminated packets",
            tail.len()
        );
    }
}

/// Per thread of `pid`: its name and nice value, from /proc.
fn threads(pid: u32) -> Vec<(String, i64)> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).expect("/proc task list");
    tasks
        .filter_map(|t| {
            let dir = t.ok()?.path();
            let name = std::fs::read_to_string(dir.join("comm")).ok()?;
            let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
            // Fields after the parenthesised name; nice is the 19th field, 17th after it.
            let nice = stat.rsplit(')').next()?.split_whitespace().nth(16)?;
            Some((name.trim().to_string(), nice.parse().ok()?))
        })
        .collect()
}

#[test]
fn compute_threads_yield_to_the_dmx_clock() {
    let mut d = Daemon::start("dmx-priority");
    d.add_objective("warm.png", "both");
    d.generate();
    let threads = threads(d.pid());
    let compute: Vec<_> = threads
        .iter()
        .filter(|(name, _)| name.starts_with("compute-"))
        .collect();
    assert!(!compute.is_empty(), "no compute threads in {threads:?}");
    for (name, nice) in &compute {
        assert_eq!(*nice, i64::from(visobjd::cli::COMPUTE_NICE), "{name}");
    }
    let dmx = threads.iter().find(|(name, _)| name == "dmx-output");
    assert_eq!(dmx.map(|t| t.1), Some(0), "{threads:?}");
}
