//! The console input (`[input.sacn]`, docs/dmx.md#console-input-sacn) of the real daemon on
//! loopback, against consoles played by the test: sACN senders written from the E1.31
//! octets (`visobjd_testkit::wire::encode_sacn`), independent of the daemon's code. The
//! daemon's own sACN output loops back into its input at priority 200, so every test also
//! checks that its own CID is ignored. What the daemon makes of the console is read on its
//! DMX output (`visobjd_testkit::wire`'s decoder), after `/vo/console/grab` or while
//! following.

use std::collections::BTreeMap;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::common::daemon::{
    Daemon, LOCALHOST, Osc, PATIENCE, PROTOS, PatchedLight, STAGE, UNIVERSES, free_port, int,
    look_mismatch, num, text,
};
use rosc::OscType;
use visobjd_testkit::wire::{STREAM_TERMINATED, encode_sacn};

/// E1.31's network data loss timeout.
const SOURCE_LOSS: Duration = Duration::from_millis(2500);

/// A console's state, as its sender thread sends it.
#[derive(Clone)]
pub(crate) struct Show {
    pub(crate) priority: u8,
    /// Levels per universe (512 slots each).
    pub(crate) levels: BTreeMap<u16, Vec<u8>>,
    /// Per-address priorities per universe (sent as 0xDD packets), if any.
    pub(crate) priorities: BTreeMap<u16, Vec<u8>>,
    /// Level packets stop (0xDD packets go on).
    pub(crate) levels_off: bool,
}

/// A console on loopback: sends its show to the daemon's input every 25 ms, as consoles
/// refresh, until dropped or stopped.
pub(crate) struct Console {
    show: Arc<Mutex<Show>>,
    /// Level packets sent so far.
    sent: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Sends the termination.
    sock: UdpSocket,
    to: SocketAddr,
    cid: [u8; 16],
    name: &'static str,
    sequence: Arc<Mutex<BTreeMap<u16, u8>>>,
}

impl Console {
    pub(crate) fn start(to: SocketAddr, id: u8, name: &'static str, show: Show) -> Console {
        Console::start_from(LOCALHOST, to, id, name, show)
    }

    /// [`Console::start`] sending from `from` (any loopback address).
    fn start_from(
        from: std::net::IpAddr,
        to: SocketAddr,
        id: u8,
        name: &'static str,
        show: Show,
    ) -> Console {
        let cid = [id; 16];
        let show = Arc::new(Mutex::new(show));
        let sent = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let sequence = Arc::new(Mutex::new(BTreeMap::<u16, u8>::new()));
        let sock = UdpSocket::bind((from, 0)).expect("bind a console");
        let thread = {
            let (show, sent, stop, sequence) =
                (show.clone(), sent.clone(), stop.clone(), sequence.clone());
            let sock = sock.try_clone().expect("clone");
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let s = show.lock().expect("show").clone();
                    let mut seq = sequence.lock().expect("seq");
                    for (&u, prio) in &s.priorities {
                        let n = seq.entry(u).or_insert(0);
                        *n = n.wrapping_add(1);
                        let p = encode_sacn(cid, name, s.priority, *n, 0, u, 0xdd, prio);
                        sock.send_to(&p, to).expect("send 0xDD");
                    }
                    if !s.levels_off {
                        for (&u, levels) in &s.levels {
                            let n = seq.entry(u).or_insert(0);
                            *n = n.wrapping_add(1);
                            let p = encode_sacn(cid, name, s.priority, *n, 0, u, 0, levels);
                            sock.send_to(&p, to).expect("send levels");
                        }
                        sent.fetch_add(1, Ordering::SeqCst);
                    }
                    drop(seq);
                    std::thread::sleep(Duration::from_millis(25));
                }
            })
        };
        Console {
            show,
            sent,
            stop,
            thread: Some(thread),
            sock,
            to,
            cid,
            name,
            sequence,
        }
    }

    pub(crate) fn change(&self, f: impl FnOnce(&mut Show)) {
        f(&mut self.show.lock().expect("show"));
    }

    /// Waits until `n` more level packets have gone out (each after the last change).
    pub(crate) fn sent_more(&self, n: u64) {
        let from = self.sent.load(Ordering::SeqCst);
        let end = Instant::now() + PATIENCE;
        while self.sent.load(Ordering::SeqCst) < from + n {
            assert!(Instant::now() < end, "the console stopped sending");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Stops sending without a word (a console that died or was unplugged).
    fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().expect("the console thread");
        }
    }

    /// Stops and sends Stream_Terminated on every universe, three times as E1.31 asks.
    fn terminate(&mut self) {
        self.stop();
        let s = self.show.lock().expect("show").clone();
        let mut seq = self.sequence.lock().expect("seq");
        for _ in 0..3 {
            for (&u, levels) in &s.levels {
                let n = seq.entry(u).or_insert(0);
                *n = n.wrapping_add(1);
                let p = encode_sacn(
                    self.cid,
                    self.name,
                    s.priority,
                    *n,
                    STREAM_TERMINATED,
                    u,
                    0,
                    levels,
                );
                self.sock.send_to(&p, self.to).expect("send");
            }
        }
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A show at `priority` with `slots` ((universe, 1-based address, value)) set, the rest 0.
fn show(priority: u8, slots: &[(u16, usize, u8)]) -> Show {
    let mut levels: BTreeMap<u16, Vec<u8>> = UNIVERSES.iter().map(|&u| (u, vec![0; 512])).collect();
    for &(u, a, v) in slots {
        levels.get_mut(&u).expect("a stage universe")[a - 1] = v;
    }
    Show {
        priority,
        levels,
        priorities: BTreeMap::new(),
        levels_off: false,
    }
}

/// A daemon whose `[input.sacn]` listens on loopback, and whose own sACN output also goes
/// there at priority 200 (if its CID were not ignored, its own output would win every slot).
fn daemon(name: &str) -> (Daemon, SocketAddr) {
    daemon_with(name, "")
}

/// [`daemon`] with `more` lines in its `[input.sacn]`.
fn daemon_with(name: &str, more: &str) -> (Daemon, SocketAddr) {
    let port = free_port(LOCALHOST, LOCALHOST);
    let input = SocketAddr::new(LOCALHOST, port);
    let extra = format!(
        r#"
[input.sacn]
bind = "{input}"
universes = [1, 2]
{more}

[[output.sacn]]
destination = "127.0.0.1"
port = {port}
bind = "127.0.0.1:0"
priority = 200
source_name = "visobjd looped back"
"#
    );
    (Daemon::start_with(name, &extra), input)
}

/// One console source in `/vo/status`.
#[derive(Debug, Clone, PartialEq)]
struct Source {
    name: String,
    priority: i32,
    universes: String,
    age: f64,
}

/// The console sources of `/vo/status` (after the word `console` and their count).
fn sources(d: &mut Daemon) -> Vec<Source> {
    let m = d.ok("/vo/status", vec![], "/vo/status");
    let at = m
        .args
        .iter()
        .position(|a| *a == OscType::String("console".into()))
        .unwrap_or_else(|| panic!("no console part in {m:?}"));
    let rest = &m.args[at + 1..];
    let n = num(&rest[0]) as usize;
    assert_eq!(
        rest.len(),
        1 + 4 * n,
        "name priority universes age per source: {m:?}"
    );
    rest[1..]
        .chunks(4)
        .map(|c| Source {
            name: text(&c[0]),
            priority: num(&c[1]) as i32,
            universes: text(&c[2]),
            age: num(&c[3]),
        })
        .collect()
}

/// Polls `/vo/status` until `want` holds for the console sources; returns them.
fn wait_sources(d: &mut Daemon, what: &str, want: impl Fn(&[Source]) -> bool) -> Vec<Source> {
    let end = Instant::now() + 2 * PATIENCE;
    loop {
        let s = sources(d);
        if want(&s) {
            return s;
        }
        assert!(
            Instant::now() < end,
            "the status never showed {what}: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The latest frame of each stage universe on `proto` that left after `t`.
fn frames_after(d: &Daemon, t: Instant) -> Option<[BTreeMap<u16, Vec<u8>>; 2]> {
    let per = |proto| -> Option<BTreeMap<u16, Vec<u8>>> {
        UNIVERSES
            .iter()
            .map(|&u| {
                d.wire
                    .frames(proto, u, t)
                    .last()
                    .map(|f| (u, f.dmx.clone()))
            })
            .collect()
    };
    Some([per(PROTOS[0])?, per(PROTOS[1])?])
}

/// The status line (`/vo/status/text`) as a subscription receives it.
fn status_line(d: &mut Daemon) -> String {
    let got = d.call("/vo/subscribe", vec![], "/vo/subscribed");
    d.ok("/vo/unsubscribe", vec![], "/vo/unsubscribed");
    got.iter()
        .find(|m| m.addr == "/vo/status/text")
        .map(|m| text(&m.args[0]))
        .unwrap_or_else(|| panic!("no /vo/status/text in {got:?}"))
}

/// Where the daemon's output differs from `want` by more than a DMX step on a patched
/// fixture's slots (`want`: the console's slots per universe), or `None`.
fn mismatch(out: &BTreeMap<u16, Vec<u8>>, want: &BTreeMap<u16, Vec<u8>>) -> Option<String> {
    STAGE.iter().find_map(|f: &PatchedLight| {
        let (o, w) = (f.slots(&out[&f.universe]), f.slots(&want[&f.universe]));
        let off = o.iter().zip(w).any(|(a, b)| a.abs_diff(*b) > 1);
        off.then(|| {
            format!(
                "channel {} ({}): out {o:?}, console {w:?}",
                f.channel, f.profile
            )
        })
    })
}

/// Sends `addr` (a grab or follow) until it succeeds and the daemon's sACN and Art-Net
/// output, in frames that left after the reply, shows `want` on every patched slot within
/// a DMX step. Console packets may still be on their way, and a new source is sampled
/// before it counts: hence the retries, bounded.
fn until_output(d: &mut Daemon, addr: &str, args: Vec<OscType>, want: &BTreeMap<u16, Vec<u8>>) {
    let end = Instant::now() + 3 * PATIENCE;
    loop {
        let last = d.call(addr, args.clone(), reply_of(addr));
        let t = Instant::now();
        if last.last().is_some_and(|m| m.addr != "/vo/error") {
            // Two frames' time after the reply shows what the reply made.
            let frame_end = Instant::now() + PATIENCE;
            let out = loop {
                if let Some(out) = frames_after(d, t) {
                    break out;
                }
                assert!(Instant::now() < frame_end, "no frames after {addr}");
                std::thread::sleep(Duration::from_millis(5));
            };
            let why = out.iter().find_map(|o| mismatch(o, want));
            let Some(why) = why else { return };
            assert!(
                Instant::now() < end,
                "{addr} never reproduced the console: {why}"
            );
        } else {
            assert!(Instant::now() < end, "{addr} kept failing: {last:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn reply_of(addr: &str) -> &'static str {
    match addr {
        "/vo/console/grab" => "/vo/console/grabbed",
        _ => "/vo/console/follow",
    }
}

/// Levels every stage profile can send back exactly: dimmers, irgb (dimmer and colour),
/// rgb, and rgbw with no colour past full once the white is added back.
fn console_levels() -> Vec<(u16, usize, u8)> {
    vec![
        (1, 1, 200), // ch 1 dimmer
        (1, 2, 37),  // ch 2 dimmer
        (1, 10, 180),
        (1, 11, 255),
        (1, 12, 90),
        (1, 13, 12), // ch 3 irgb
        (2, 1, 77),
        (2, 2, 30),
        (2, 3, 255),
        (2, 4, 140), // ch 4 irgb
        (2, 10, 250),
        (2, 11, 100),
        (2, 12, 0), // ch 5 rgb
        (2, 20, 0),
        (2, 21, 60),
        (2, 22, 150),
        (2, 23, 90), // ch 6 rgbw
    ]
}

#[test]
fn grab_reproduces_the_console_on_every_light_and_ignores_the_daemons_own_output() {
    let (mut d, input) = daemon("console-grab");
    // Nothing yet: a sentence, and nothing changes.
    let before = d.snapshot();
    let e = d.err("/vo/console/grab", vec![]);
    assert!(e.contains("no console source"), "{e}");
    assert_eq!(d.snapshot(), before);
    // The daemon's own output (priority 200, looped back) is not a source.
    assert!(sources(&mut d).is_empty(), "its own output is not a source");

    // Malformed packets are dropped and logged; the receiver carries on.
    let junk = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let mut lying = encode_sacn([5; 16], "liar", 100, 0, 0, 1, 0, &[255; 512]);
    lying[16..18].copy_from_slice(&0x7005u16.to_be_bytes());
    for p in [&b"ASC-E1.17"[..], &lying[..], &lying[..60]] {
        junk.send_to(p, input).expect("send");
    }
    let end = Instant::now() + PATIENCE;
    while !d.log_text().contains("malformed packet") {
        assert!(
            Instant::now() < end,
            "no malformed-packet line in the log:\n{}",
            d.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }

    let console = Console::start(input, 1, "Eos", show(100, &console_levels()));
    // Each universe's stream is sampled on its own: wait for both.
    let listed = wait_sources(&mut d, "the console on both universes", |s| {
        s.iter().any(|x| x.universes == "1 2")
    });
    assert_eq!(
        listed.len(),
        1,
        "only the console, not the looped-back output: {listed:?}"
    );
    assert_eq!(
        (
            listed[0].name.as_str(),
            listed[0].priority,
            listed[0].universes.as_str()
        ),
        ("Eos", 100, "1 2")
    );
    assert!(listed[0].age >= 0.0 && listed[0].age < SOURCE_LOSS.as_secs_f64());
    let want = console.show.lock().expect("show").levels.clone();
    until_output(&mut d, "/vo/console/grab", vec![], &want);

    // The grab is the base (an undo step): undoing goes back to the dark look.
    let live = d.live();
    assert!(live.iter().any(|l| l.intensity > 0.5), "{live:?}");
    while num(&d.ok("/vo/undo", vec![], "/vo/undone").args[0]) > 0.0 {}
    assert!(d.live().iter().all(|l| l.intensity == 0.0));
    // The status line (tablets, the web page) shows the source.
    let line = status_line(&mut d);
    assert!(line.contains("console: Eos (100, u1 2, "), "{line}");
    drop(console);
}

#[test]
fn priorities_htp_and_per_address_priority_merge_as_e131_says() {
    let (mut d, input) = daemon("console-merge");
    // A at 100 and B at 50: A's levels everywhere, even where B's are higher.
    let a = Console::start(input, 1, "A", show(100, &[(1, 1, 100), (1, 2, 100)]));
    let b = Console::start(input, 2, "B", show(50, &[(1, 1, 200), (1, 2, 20)]));
    wait_sources(&mut d, "A and B", |s| s.len() == 2);
    let merged = |slots: &[(u16, usize, u8)]| show(0, slots).levels;
    until_output(
        &mut d,
        "/vo/console/grab",
        vec![],
        &merged(&[(1, 1, 100), (1, 2, 100)]),
    );

    // B at 100 too: highest takes precedence per slot.
    b.change(|s| s.priority = 100);
    until_output(
        &mut d,
        "/vo/console/grab",
        vec![],
        &merged(&[(1, 1, 200), (1, 2, 100)]),
    );

    // A's 0xDD: slot 1 not sourced by A (0), slot 2 at 150 (over B's 100), the rest at
    // 100. Slot 1 is then B's though A's level is higher, slot 2 A's though B's is higher
    // (HTP would give 255 and 250); A's 0xDD values never show as levels (slots 10-13,
    // 100 each, stay 0).
    b.change(|s| {
        let u1 = s.levels.get_mut(&1).expect("u1");
        u1[0] = 180;
        u1[1] = 250;
    });
    a.change(|s| {
        let mut p = vec![100u8; 512];
        p[0] = 0;
        p[1] = 150;
        s.priorities.insert(1, p);
        s.levels.get_mut(&1).expect("u1")[0] = 255;
    });
    until_output(
        &mut d,
        "/vo/console/grab",
        vec![],
        &merged(&[(1, 1, 180), (1, 2, 100)]),
    );
    let listed = sources(&mut d);
    let prios: Vec<(&str, i32)> = listed
        .iter()
        .map(|s| (s.name.as_str(), s.priority))
        .collect();
    assert_eq!(prios, [("A", 100), ("B", 100)]);
}

#[test]
fn a_console_that_stops_is_dropped_after_2_5_s_even_with_0xdd_still_coming() {
    let (mut d, input) = daemon("console-loss");
    let mut gone = Console::start(input, 1, "stops", show(100, &[(1, 1, 255)]));
    let mut ends = Console::start(input, 2, "terminates", show(90, &[(1, 2, 255)]));
    // `stops` sources only its slot 1 (0xDD 0 elsewhere), so `terminates` has slot 2.
    gone.change(|s| {
        let mut p = vec![0u8; 512];
        p[0] = 100;
        s.priorities.insert(1, p);
    });
    wait_sources(&mut d, "both", |s| s.len() == 2);
    until_output(
        &mut d,
        "/vo/console/grab",
        vec![],
        &show(0, &[(1, 1, 255), (1, 2, 255)]).levels,
    );

    // Level packets stop; 0xDD packets go on. The source is listed until 2.5 s after its
    // last level packet, then dropped.
    gone.change(|s| s.levels_off = true);
    let stopped = Instant::now();
    let left = wait_sources(&mut d, "`stops` dropped", |s| {
        s.iter().all(|s| s.name != "stops")
    });
    assert!(
        stopped.elapsed() >= SOURCE_LOSS - Duration::from_millis(100),
        "dropped {:?} after its levels stopped (E1.31: 2.5 s)",
        stopped.elapsed()
    );
    assert_eq!(left.len(), 1, "{left:?}");
    // The grab now shows only what is left.
    until_output(
        &mut d,
        "/vo/console/grab",
        vec![],
        &show(0, &[(1, 2, 255)]).levels,
    );
    gone.stop();

    // Stream_Terminated: dropped without the wait; nothing left to grab.
    ends.terminate();
    wait_sources(&mut d, "none", |s| s.is_empty());
    let e = d.err("/vo/console/grab", vec![]);
    assert!(e.contains("no console source"), "{e}");
}

#[test]
fn follow_tracks_the_console_until_a_pick() {
    let (mut d, input) = daemon("console-follow");
    let console = Console::start(input, 1, "Eos", show(100, &console_levels()));
    wait_sources(&mut d, "the console", |s| s.len() == 1);
    let levels = |c: &Console| c.show.lock().expect("show").levels.clone();
    until_output(
        &mut d,
        "/vo/console/follow",
        vec![int(1)],
        &levels(&console),
    );
    assert!(status_line(&mut d).contains("console, following: Eos"));

    // The console moves: the stage follows without a grab.
    for v in [10u8, 240, 128] {
        console.change(|s| s.levels.get_mut(&1).expect("u1")[0] = v);
        d.wire
            .wait_both(1, &format!("the followed level {v}"), |dmx| dmx[0] == v);
    }

    // A pick is a visobjd look: following stops, the console no longer moves the stage.
    d.add_objective("warm.png", "both");
    d.generate();
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let picked = d.live();
    for proto in PROTOS {
        d.wire.wait_look(proto, &picked);
    }
    console.change(|s| s.levels.get_mut(&1).expect("u1")[0] = 3);
    // Twenty refreshes with the new level have gone out; the daemon kept the pick.
    console.sent_more(20);
    assert_eq!(d.live(), picked, "following stopped at the pick");
    for proto in PROTOS {
        let wire = d.wire.latest_universes(proto).expect("frames");
        assert_eq!(
            look_mismatch(&picked, &wire),
            None,
            "{proto:?} still shows the pick"
        );
    }
    assert!(!status_line(&mut d).contains("following"));

    // Following again picks it up.
    let want = levels(&console);
    until_output(&mut d, "/vo/console/follow", vec![int(1)], &want);
    d.ok("/vo/console/follow", vec![int(0)], "/vo/console/follow");
}

#[test]
fn a_sender_outside_the_inputs_allow_list_is_refused_and_named_once() {
    let (mut d, input) = daemon_with("console-allow", "allow = [\"127.0.0.1/32\"]");
    let outsider = std::net::IpAddr::V4(std::net::Ipv4Addr::new(127, 0, 0, 2));
    let stranger = Console::start_from(outsider, input, 7, "Stranger", show(150, &[(1, 1, 255)]));
    stranger.sent_more(40);
    let console = Console::start(input, 1, "Eos", show(100, &console_levels()));
    let s = wait_sources(&mut d, "the allowed console alone, counting", |s| {
        s.len() == 1 && s[0].name == "Eos"
    });
    assert_eq!(s[0].priority, 100);
    // A grab reproduces the allowed console alone: the stranger's 255 at 1/1, at a higher
    // priority, is not merged.
    stranger.sent_more(40);
    let want = console.show.lock().expect("show").levels.clone();
    until_output(&mut d, "/vo/console/grab", vec![], &want);
    assert!(sources(&mut d).iter().all(|s| s.name != "Stranger"));
    let refused = d
        .log_text()
        .lines()
        .filter(|l| l.contains("refused 127.0.0.2, not in input.sacn.allow"))
        .count();
    assert_eq!(refused, 1, "logged once per sender:\n{}", d.log_text());
    drop((console, stranger));
}

#[test]
fn without_an_input_the_console_addresses_say_how_to_configure_one() {
    let mut d = Daemon::start("console-none");
    for (addr, args) in [
        ("/vo/console/grab", vec![]),
        ("/vo/console/follow", vec![int(1)]),
    ] {
        let e = d.err(addr, args);
        assert!(e.contains("[input.sacn]"), "{e}");
    }
    let m = d.ok("/vo/status", vec![], "/vo/status");
    assert!(
        !m.args.contains(&OscType::String("console".into())),
        "no console part without an input: {m:?}"
    );
}
