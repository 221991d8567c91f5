//! Hostile input against the real daemon: broken, oversized and too-deep packets,
//! non-finite and out-of-range numbers, unknown names, references that lead out of the
//! folder or are not what they claim, a decompression bomb. Every message gets one
//! `/vo/error` (non-OSC garbage gets nothing, docs/osc.md), nothing changes, the daemon keeps
//! answering, and DMX goes on with no gap over two frame periods throughout. Cases already
//! in daemon_args.rs and daemon_objectives.rs are not repeated here.

use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{
    Daemon, Osc, PATIENCE, PROTOS, TcpFraming, UNIVERSES, double, float, int, long, msg, num,
    string, text,
};
use rosc::{OscArray, OscBundle, OscPacket, OscTime, OscType};

/// Starts a daemon and waits until every universe is on the wire; returns that moment.
fn started(name: &str) -> (Daemon, Instant) {
    let d = Daemon::start(name);
    for proto in PROTOS {
        for u in UNIVERSES {
            d.wire.wait(proto, u, "a first frame", |_| true);
        }
    }
    (d, Instant::now())
}

/// Checks the daemon still answers and DMX had no gap over [`GAP`] since `from`.
fn still_running(d: &mut Daemon, from: Instant, during: &str) {
    assert!(d.alive(), "the daemon exited {during}\n{}", d.log());
    let r = d.ok("/vo/ping", vec![string("alive")], "/vo/pong");
    assert_eq!(r.args, [string("alive")]);
    d.wire.assert_continuous_since(from, during);
}

/// Sends raw bytes that must get exactly one `/vo/error` naming `addr` and change nothing.
fn refused_raw(d: &mut Daemon, bytes: &[u8], addr: &str) -> String {
    let before = d.snapshot();
    let mut c = d.client();
    c.send_raw(bytes);
    let got = c.collect("/vo/error", PATIENCE, addr);
    assert_eq!(got.len(), 1, "{addr}: {got:?}");
    assert_eq!(text(&got[0].args[0]), addr, "{got:?}");
    let extra = c.fence();
    assert!(extra.is_empty(), "{addr}: more after the error: {extra:?}");
    assert_eq!(d.snapshot(), before, "{addr} failed but changed something");
    text(&got[0].args[1])
}

fn encode(p: &OscPacket) -> Vec<u8> {
    rosc::encoder::encode(p).expect("encode")
}

fn nest(levels: usize, inner: OscPacket) -> OscPacket {
    (0..levels).fold(inner, |p, _| {
        OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content: vec![p],
        })
    })
}

#[test]
fn broken_oversized_and_deep_packets_are_answered_and_change_nothing() {
    let (mut d, from) = started("hostile-packets");
    d.ok("/vo/light/1/level", vec![int(20)], "/vo/light");
    let fader = encode(&msg("/vo/light/1/level", vec![int(50)]));

    // Cut inside the arguments or the type tags: the address is intact, so it is named.
    for cut in [1, 2, 4, 8] {
        let sentence = refused_raw(&mut d, &fader[..fader.len() - cut], "/vo/light/1/level");
        assert!(sentence.contains("cut short"), "{sentence}");
    }
    // Cut inside the address: garbage, answered by nothing.
    let mut c = d.client();
    c.send_raw(&fader[..6]);
    assert!(c.fence().is_empty());

    // A truncated bundle runs the whole elements before the cut and names the broken one.
    let bundle = encode(&OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content: vec![
            msg("/vo/light/2/level", vec![int(30)]),
            msg("/vo/light/1/level", vec![int(90)]),
        ],
    }));
    c.send_raw(&bundle[..bundle.len() - 2]);
    let got = c.collect("/vo/error", PATIENCE, "a truncated bundle");
    let addrs: Vec<&str> = got.iter().map(|m| m.addr.as_str()).collect();
    assert_eq!(addrs, ["/vo/light", "/vo/error"], "{got:?}");
    assert_eq!(text(&got[1].args[0]), "/vo/light/1/level");
    let live = d.live();
    assert!((live[0].intensity - 0.2).abs() < 1e-6, "light 1 unchanged");
    assert!((live[1].intensity - 0.3).abs() < 1e-6, "light 2 ran");

    // Bundles nested 100 deep, and arguments nested 100 deep: refused whole.
    let deep = encode(&nest(100, msg("/vo/light/1/level", vec![int(70)])));
    let sentence = refused_raw(&mut d, &deep, "/vo/light/1/level");
    assert!(sentence.contains("deeper than"), "{sentence}");
    let arrays = (0..100).fold(vec![int(1)], |inner, _| {
        vec![OscType::Array(OscArray { content: inner })]
    });
    refused_raw(&mut d, &encode(&msg("/vo/master", arrays)), "/vo/master");

    // UDP carries at most 64 KiB: a 60 KB name is an ordinary refusal. An error that
    // would echo it twice (address and sentence) is cut to fit one datagram.
    let long_name = "a".repeat(60_000);
    d.refused("/vo/objective/add", vec![string(&long_name)]);
    let before = d.snapshot();
    let long_addr = format!("/vo/group/{long_name}/level");
    c.send(&long_addr, vec![int(50)]);
    let got = c.collect("/vo/error", PATIENCE, "a 60 KB group name");
    assert_eq!(got.len(), 1, "one error");
    assert!(text(&got[0].args[0]).starts_with("/vo/group/aaaa"));
    assert!(c.fence().is_empty());
    assert_eq!(
        d.snapshot(),
        before,
        "the 60 KB group name changed something"
    );

    // TCP: a 10 MB string argument is over the frame limit in either framing. It is
    // skipped without being buffered, named in the error, and the connection goes on.
    let ten_mb = "x".repeat(10 * 1024 * 1024);
    for framing in [TcpFraming::LengthPrefix, TcpFraming::Slip] {
        let before = d.snapshot();
        let rss = d.rss_kib();
        let mut t = d.tcp(framing);
        t.send("/vo/objective/add", vec![string(&ten_mb)]);
        let got = t.collect("/vo/error", PATIENCE, "a 10 MB string over TCP");
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(text(&got[0].args[0]), "/vo/objective/add");
        assert!(text(&got[0].args[1]).contains("limit"), "{got:?}");
        let r = t.ok("/vo/ping", vec![int(7)], "/vo/pong");
        assert_eq!(r.args, [int(7)]);
        assert_eq!(
            d.snapshot(),
            before,
            "{framing:?}: the 10 MB message changed something"
        );
        let grown = d.rss_kib().saturating_sub(rss);
        assert!(
            grown < 8 * 1024,
            "{framing:?}: 10 MB in, RSS grew by {grown} KiB"
        );
    }
    still_running(&mut d, from, "while hostile packets arrived");
}

#[test]
fn non_finite_and_out_of_range_numbers_and_unknown_names_are_refused() {
    let (mut d, from) = started("hostile-numbers");
    d.add_objective("grey.png", "both");
    d.ok("/vo/look/save", vec![int(1)], "/vo/look/saved");
    let bad_numbers = [
        float(f32::NAN),
        float(f32::INFINITY),
        float(f32::NEG_INFINITY),
        double(f64::NAN),
        double(f64::NEG_INFINITY),
        string("NaN"),
        string("inf"),
        string("1e999"),
    ];
    for v in bad_numbers.iter().cloned() {
        d.refused("/vo/light/1/intensity", vec![v.clone()]);
        d.refused("/vo/light/3/level", vec![v.clone()]);
        d.refused("/vo/group/side/intensity", vec![v.clone()]);
        d.refused("/vo/light/3/color", vec![float(0.5), v.clone(), float(0.5)]);
        d.refused("/vo/fade", vec![v.clone()]);
        d.refused("/vo/blackout", vec![v.clone()]);
        d.refused(
            "/vo/objective/1/region",
            vec![float(0.0), float(0.0), v.clone(), float(1.0)],
        );
        d.refused(
            "/vo/objective/1/color",
            vec![int(1), v.clone(), int(0), int(0)],
        );
        d.refused("/vo/generate/count", vec![v.clone()]);
        d.refused("/vo/look/save", vec![v]);
    }
    for (addr, args) in [
        ("/vo/light/-1/level", vec![int(50)]),
        ("/vo/light/0/level", vec![int(50)]),
        ("/vo/light/4294967296/intensity", vec![float(0.5)]),
        ("/vo/light/99999999999999999999/lock", vec![int(1)]),
        (
            "/vo/light/2147483648/color",
            vec![float(1.0), float(0.0), float(0.0)],
        ),
        ("/vo/light/1.5/level", vec![int(50)]),
        ("/vo/light/1/level", vec![int(-1)]),
        ("/vo/light/1/level", vec![long(i64::MAX)]),
        ("/vo/light/1/intensity", vec![double(1e300)]),
        ("/vo/look/save", vec![int(-1)]),
        ("/vo/look/save", vec![long(i64::MIN)]),
        ("/vo/look/recall", vec![int(i32::MAX)]),
        ("/vo/pick", vec![int(-5)]),
        ("/vo/candidate", vec![int(i32::MIN)]),
        ("/vo/generate/clusters", vec![long(1 << 40)]),
        ("/vo/generate/seed", vec![double(-1e20)]),
        ("/vo/objective/-1/remove", vec![]),
        ("/vo/objective/4294967297/aspects", vec![string("color")]),
        ("/vo/group/nosuch/intensity", vec![float(0.5)]),
        (
            "/vo/group/nosuch/color",
            vec![float(1.0), float(0.0), float(0.0)],
        ),
        ("/vo/group/nosuch/lock", vec![int(1)]),
        ("/vo/group/nosuch/key", vec![int(1)]),
        ("/vo/group/../level", vec![int(10)]),
    ] {
        d.refused(addr, args);
    }
    still_running(&mut d, from, "while bad numbers arrived");
}

#[test]
fn hostile_references_are_refused_and_a_bomb_does_not_stall_osc() {
    let (mut d, from) = started("hostile-refs");
    let refs = d.refs();
    // A link to a folder outside, and a path that climbs out through a subfolder.
    std::os::unix::fs::symlink(&d.dir, refs.join("up")).expect("symlink a folder");
    std::fs::create_dir_all(refs.join("sub")).expect("mkdir");
    // A text file with an image's name, and a PNG cut after its header.
    std::fs::write(refs.join("notes.jpg"), "not a JPEG at all\n").expect("write");
    let whole = std::fs::read(refs.join("warm.png")).expect("read");
    std::fs::write(refs.join("cut.png"), &whole[..whole.len() / 2]).expect("write");
    // Enormous dimensions in a tiny file, refused from the header alone.
    visobjd_testkit::png_header_only(&refs.join("wide.png"), 100_000, 100_000);
    visobjd_testkit::png_header_only(&refs.join("tall.png"), 1, 64_000_001);
    for image in [
        "up/outside.png",
        "sub/../../outside.png",
        "sub/../up/outside.png",
        "notes.jpg",
        "cut.png",
        "wide.png",
        "tall.png",
        "grey.png/",
        "sub",
    ] {
        d.refused("/vo/objective/add", vec![string(image)]);
    }

    // A real decompression bomb under the 64-megapixel limit: a small file that decodes to
    // 108 MB. It is read off the OSC receive task: a ping sent meanwhile is answered first.
    visobjd_testkit::png_bomb(&refs.join("bomb.png"), 6000, 6000);
    let size = std::fs::metadata(refs.join("bomb.png"))
        .expect("bomb")
        .len();
    assert!(size < 2 << 20, "a bomb is small on disk: {size} bytes");
    // An add queued behind it whose file goes before it is read.
    std::fs::copy(refs.join("cool.png"), refs.join("doomed.png")).expect("copy");
    let mut adder = d.client();
    adder.send("/vo/objective/add", vec![string("bomb.png")]);
    adder.send("/vo/objective/add", vec![string("doomed.png")]);
    std::fs::remove_file(refs.join("doomed.png")).expect("rm");
    let mut other = d.client();
    let r = other.ok("/vo/ping", vec![string("meanwhile")], "/vo/pong");
    assert_eq!(r.args, [string("meanwhile")]);
    // Read on the receive task, the bomb would have held the ping until it was in.
    assert_eq!(
        adder.next(Duration::from_millis(1)),
        None,
        "the ping was answered only after the bomb was read"
    );
    let got = adder.collect(
        "/vo/objective/added",
        common::daemon::GENERATE_PATIENCE,
        "the bomb",
    );
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].addr, "/vo/objective/added", "{got:?}");
    let bomb_id = num(&got[0].args[0]) as i32;
    let got = adder.collect("/vo/error", PATIENCE, "the deleted reference");
    assert_eq!(got.len(), 1, "{got:?}");
    assert!(text(&got[0].args[1]).contains("doomed.png"), "{got:?}");

    // A reference deleted between add and generate: the objective keeps what it measured.
    let warm = d.add_objective("warm.png", "both");
    std::fs::remove_file(refs.join("warm.png")).expect("rm");
    let g = d.generate();
    assert!(num(&g.args[0]) >= 1.0, "{g:?}");
    let listed: Vec<i32> = d
        .objectives()
        .iter()
        .map(|m| num(&m.args[0]) as i32)
        .collect();
    assert_eq!(listed, [bomb_id, warm]);
    d.refused("/vo/objective/add", vec![string("warm.png")]);
    still_running(&mut d, from, "while hostile references were read");
}

/// Each thread of `pid`: its name, CPU time so far (clock ticks) and nice value.
fn threads(pid: u32) -> std::collections::HashMap<u32, (String, u64, i64)> {
    let mut out = std::collections::HashMap::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return out;
    };
    for task in tasks.flatten() {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        // "tid (name) state ...": the name may hold spaces and parentheses.
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let rest: Vec<&str> = stat[close + 1..].split_whitespace().collect();
        let field = |i: usize| rest.get(i).and_then(|v| v.parse::<i64>().ok()).unwrap_or(0);
        let tid = stat[..open].trim().parse().unwrap_or(0);
        // After the name: state (field 3), ..., utime (14), stime (15), ..., nice (19).
        let cpu = (field(11) + field(12)) as u64;
        out.insert(tid, (stat[open + 1..close].to_string(), cpu, field(16)));
    }
    out
}

/// The thread of `pid` that took the most CPU while `work` ran: its name and nice value.
fn busiest_during(pid: u32, work: impl FnOnce()) -> (String, i64, u64) {
    let before = threads(pid);
    work();
    let after = threads(pid);
    after
        .into_iter()
        .map(|(tid, (name, cpu, nice))| {
            let used = cpu - before.get(&tid).map_or(0, |b| b.1.min(cpu));
            (name, nice, used)
        })
        .max_by_key(|t| t.2)
        .expect("the daemon has threads")
}

/// The daemon's peak resident memory (VmHWM), in KiB.
fn peak_kib(pid: u32) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .expect("/proc/PID/status")
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("a VmHWM line")
}

#[test]
fn a_big_reference_decodes_within_its_bound_below_the_clock() {
    let (mut d, addr) = common::http::start("hostile-decode");
    for proto in PROTOS {
        for u in UNIVERSES {
            d.wire.wait(proto, u, "a first frame", |_| true);
        }
    }
    let from = Instant::now();
    let refs = d.refs();
    // 64 megapixels of 16-bit RGBA: 512 MB at its own depth, a few MB on disk.
    visobjd_testkit::png16(&refs.join("big16.png"), 8000, 8000);
    let big = std::fs::read(refs.join("big16.png")).expect("read");
    // A progressive JPEG of 49 megapixels keeps every coefficient while it decodes.
    visobjd_testkit::progressive_jpeg_claiming(&refs.join("huge.jpg"), 7000, 7000);
    let huge = std::fs::read(refs.join("huge.jpg")).expect("read");
    let before_kib = d.rss_kib();

    // Over the bound: refused from its header, the sentence naming the file and the limit.
    let e = d.refused("/vo/objective/add", vec![string("huge.jpg")]);
    assert!(
        e.starts_with(
            "huge.jpg would take 427 MiB to decode (a 7000x7000 progressive JPEG), over the 256 MiB"
        ),
        "{e}"
    );
    let r = common::http::send(addr, "PUT", "/references/huge2.jpg", &[], &huge);
    assert_eq!(r.status, 400);
    let e = r.json()["error"].as_str().unwrap_or_default().to_string();
    assert!(
        e.starts_with("upload `huge2.jpg`: would take 427 MiB") && e.contains("over the 256 MiB"),
        "{e}"
    );
    assert!(!refs.join("huge2.jpg").exists());

    // Within: decoded and analysed on a compute thread, niced below the clock.
    let pid = d.pid();
    let mut id = 0;
    let (name, nice, ticks) = busiest_during(pid, || id = d.add_objective("big16.png", "both"));
    assert!(id > 0);
    println!("the add: {ticks} ticks on `{name}` at nice {nice}");
    assert!(
        name.starts_with("compute-") && nice == 10,
        "the decode ran on `{name}` at nice {nice} ({ticks} ticks)"
    );
    // Five uploads of it, each checked by a whole decode, the same way.
    for i in 0..5 {
        let mut status = 0;
        let (name, nice, ticks) = busiest_during(pid, || {
            let path = format!("/references/copy{i}.png");
            status = common::http::send(addr, "PUT", &path, &[], &big).status;
        });
        assert_eq!(status, 201, "upload {i}");
        println!("upload {i}: {ticks} ticks on `{name}` at nice {nice}");
        assert!(
            name.starts_with("compute-") && nice == 10,
            "upload {i} was decoded on `{name}` at nice {nice} ({ticks} ticks)"
        );
    }
    // The most the daemon ever held: its size before plus one bounded decode (the 8-bit
    // image, 183 MiB, and the analysis's 24 MB), never the 16-bit image's 512 MB.
    let grew = peak_kib(pid).saturating_sub(before_kib);
    println!("the daemon's peak grew by {} MiB", grew / 1024);
    assert!(
        grew <= 256 * 1024,
        "the daemon's peak grew by {} MiB",
        grew / 1024
    );
    still_running(&mut d, from, "while big references were decoded");
}
