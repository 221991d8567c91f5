//! Soak: an hour of simulated use against the real daemon: a scripted, seeded mix of
//! generates, picks, next/prev, fades, faders, saves and recalls, one command per simulated
//! second, as a designer working a tablet. Reports RSS growth, open file descriptors, the
//! DMX frame rate and its worst gap, and every unexpected error.
//!
//! Time is simulated by pacing alone: a simulated second is 10 ms of real time in
//! `cargo test` and CI (100x, about 40 s), 100 ms in the full run (10x, six minutes). Both
//! send the same 3,600 commands, so growth per command (memory, state) shows in either;
//! the full run also holds the daemon's frame clock for six minutes:
//! `VISOBJD_FULL=1 cargo test --release --test long daemon_soak -- --nocapture`
//! (`VISOBJD_SOAK_MINUTES` sets the simulated minutes, `VISOBJD_SOAK_STEP_MS` the real
//! milliseconds per simulated second.)

use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{
    Daemon, GAP, Osc, PROTOS, RATE_HZ, UNIVERSES, float, int, num, string,
};

#[test]
fn an_hour_of_simulated_use() {
    // Its worst gap is the daemon's under this use alone, not beside a load run.
    let _alone = crate::alone();
    let steps = 60 * common::size("VISOBJD_SOAK_MINUTES", 60, 60);
    let step_ms = common::size("VISOBJD_SOAK_STEP_MS", 10, 100);
    let mut d = Daemon::start("soak");
    for proto in PROTOS {
        for u in UNIVERSES {
            d.wire.wait(proto, u, "a first frame", |_| true);
        }
    }
    d.add_objective("warm.png", "both");
    d.add_objective("split.png", "intensity");
    let rss_start = d.rss_kib();
    let fds_start = d.open_fds();
    let start = Instant::now();
    let mut seed = 0x5eed_u64;
    let mut rand = move |n: u64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed % n
    };
    let mut counts = std::collections::BTreeMap::<&str, u64>::new();
    let mut errors = Vec::new();
    let mut rss_samples = vec![(0u64, rss_start)];
    let mut fd_samples = vec![fds_start];
    let mut entries = 0i32;
    // One step every `step_ms` of real time = 1 s of the simulated hour.
    for step in 1..=steps {
        let due = start + Duration::from_millis(step_ms * step);
        let (addr, args, reply): (&str, Vec<rosc::OscType>, &str) = match (step % 60, rand(10)) {
            // A generate every simulated minute.
            (0, _) => ("/vo/generate", vec![], "/vo/generated"),
            _ if entries == 0 => ("/vo/status", vec![], "/vo/status"),
            (_, 0..=2) => (
                "/vo/pick",
                vec![int(1 + rand(entries as u64) as i32)],
                "/vo/picked",
            ),
            (_, 3) => ("/vo/next", vec![], "/vo/picked"),
            (_, 4) => ("/vo/prev", vec![], "/vo/picked"),
            (_, 5) => ("/vo/fade", vec![float(rand(5) as f32 * 0.1)], "/vo/fade"),
            (_, 6) => (
                "/vo/light/3/level",
                vec![int(rand(101) as i32)],
                "/vo/light",
            ),
            (_, 7) => (
                "/vo/look/save",
                vec![int(1 + rand(20) as i32), string("soak")],
                "/vo/look/saved",
            ),
            (_, 8) if step > 100 => ("/vo/look/recall", vec![int(1 + rand(20) as i32)], ""),
            _ => ("/vo/status", vec![], "/vo/status"),
        };
        *counts.entry(addr).or_default() += 1;
        if addr == "/vo/generate" {
            let g = d.generate();
            entries = num(&g.args[1]) as i32;
        } else if reply.is_empty() {
            // A recall of a number that may not be saved: either answer is fine.
            let got = d.call(addr, args, "/vo/look/recalled");
            if let Some(m) = got.last().filter(|m| m.addr == "/vo/error") {
                let why = common::daemon::text(&m.args[1]);
                if !why.contains("no saved look") {
                    errors.push(format!("{addr}: {why}"));
                }
            }
        } else {
            let got = d.call(addr, args, reply);
            if let Some(m) = got.last().filter(|m| m.addr != reply) {
                errors.push(format!("{addr}: {m:?}"));
            }
        }
        // Steps are simulated seconds.
        if step.is_multiple_of(60) {
            rss_samples.push((step / 60, d.rss_kib()));
            fd_samples.push(d.open_fds());
        }
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    let end = Instant::now();
    let rss_end = d.rss_kib();
    let fds_end = d.open_fds();
    let mut max_gap = Duration::ZERO;
    let mut frames = 0usize;
    // Gaps over the bound: (seconds into the run, length), every universe and protocol.
    let mut over = Vec::new();
    for p in PROTOS {
        for u in UNIVERSES {
            max_gap = max_gap.max(d.wire.max_gap(p, u, start, end));
            let times: Vec<Instant> = d
                .wire
                .frames(p, u, start)
                .iter()
                .map(|f| f.at)
                .filter(|&t| t <= end)
                .collect();
            frames += times.len();
            over.extend(
                times
                    .windows(2)
                    .filter(|w| w[1] - w[0] > GAP)
                    .map(|w| ((w[0] - start).as_secs_f32().round(), w[1] - w[0])),
            );
        }
    }
    let real = (end - start).as_secs_f64();
    let fps = frames as f64 / 4.0 / real;
    println!("soak: {real:.0} s real ({steps} simulated seconds), commands {counts:?}");
    println!(
        "soak: RSS {rss_start} KiB -> {rss_end} KiB (samples by simulated minute: {rss_samples:?})"
    );
    println!(
        "soak: DMX {fps:.2} frames/s per universe and protocol (rate {RATE_HZ}), worst gap {max_gap:?}; gaps over {GAP:?} (s into the run, length): {over:?}"
    );
    println!("soak: open fds {fds_start} -> {fds_end} (by simulated minute: {fd_samples:?})");
    println!("soak: {} unexpected errors: {errors:?}", errors.len());
    assert!(errors.is_empty(), "{errors:?}");
    assert!(max_gap <= GAP, "worst DMX gap {max_gap:?}");
    assert!(
        rss_end.saturating_sub(rss_start) < 64 * 1024,
        "RSS grew {rss_start} -> {rss_end} KiB"
    );
    // A file being written adds one to a sample now and then; a leak raises the floor.
    let floor = fd_samples.iter().rev().take(10).min().copied();
    assert!(
        floor <= Some(fds_start),
        "open fds {fds_start} -> at least {floor:?} over the last 10 simulated minutes: {fd_samples:?}"
    );
}
