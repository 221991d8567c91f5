//! A backup that takes over (docs/reliability.md, "Backup"), with two real daemons on
//! loopback: the backup mirrors the main's objectives, gallery, looks and live look; and,
//! measured on the wire by an E1.31 merging receiver written here (per universe the
//! highest-priority source heard within 2.5 s wins), kill -9 of the main leaves the stage
//! on the main's last look, a pick made just before the kill is what the backup shows, and
//! a restarted main takes the stage back without a frame that differs. A backup started
//! (or restarted) after the main's generate takes the gallery, history and console
//! selection with the state, so a pick or an undo on the main gives both daemons the same
//! look on the wire.

use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::common;
use crate::common::daemon::{
    Daemon, GENERATE_PATIENCE, LightLevel, Osc, PATIENCE, STAGE, Setup, TcpFraming, UNIVERSES, int,
    look_mismatch, num, string, text,
};
use rosc::OscMessage;
use visobjd_testkit::wire::parse_sacn;

/// E1.31's network data loss time: a source unheard this long is dropped.
const HOLD: Duration = Duration::from_millis(2500);
/// The main's configured priority (tests/common/daemon.rs) and the backup's default.
const MAIN: u8 = 100;
const BACKUP: u8 = 90;

/// One source of one universe as the merger last heard it.
struct Source {
    priority: u8,
    dmx: Vec<u8>,
    seen: Instant,
}

/// What the merged receiver output for a universe after a packet: the winning priority
/// and the slots.
#[derive(Debug, Clone)]
struct Merged {
    at: Instant,
    priority: u8,
    dmx: Vec<u8>,
}

#[derive(Default)]
struct MergeLog {
    sources: BTreeMap<(u16, [u8; 16]), Source>,
    out: BTreeMap<u16, Vec<Merged>>,
}

/// An E1.31 receiver merging by priority (HTP between sources of the top priority), on
/// its own thread.
struct Merger {
    port: u16,
    log: Arc<Mutex<MergeLog>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Merger {
    fn start() -> Merger {
        let sock = UdpSocket::bind("127.0.0.1:0").expect("bind the merger");
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .expect("timeout");
        let port = sock.local_addr().expect("addr").port();
        let log = Arc::new(Mutex::new(MergeLog::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (l, s) = (log.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 1500];
            while !s.load(Ordering::Relaxed) {
                let Ok(n) = sock.recv(&mut buf) else { continue };
                let at = Instant::now();
                let Some(p) = parse_sacn(&buf[..n]) else {
                    continue;
                };
                let mut log = l.lock().expect("merge log");
                let key = (p.universe, p.cid);
                if p.terminated {
                    log.sources.remove(&key);
                } else {
                    log.sources.insert(
                        key,
                        Source {
                            priority: p.priority,
                            dmx: p.dmx,
                            seen: at,
                        },
                    );
                }
                log.sources
                    .retain(|_, src| at.duration_since(src.seen) <= HOLD);
                let live: Vec<&Source> = log
                    .sources
                    .iter()
                    .filter(|((u, _), _)| *u == p.universe)
                    .map(|(_, src)| src)
                    .collect();
                let Some(top) = live.iter().map(|src| src.priority).max() else {
                    continue;
                };
                let mut dmx = vec![0u8; live.iter().map(|src| src.dmx.len()).max().unwrap_or(0)];
                for src in live.iter().filter(|src| src.priority == top) {
                    for (d, &v) in dmx.iter_mut().zip(&src.dmx) {
                        *d = (*d).max(v);
                    }
                }
                let merged = Merged {
                    at,
                    priority: top,
                    dmx,
                };
                log.out.entry(p.universe).or_default().push(merged);
            }
        });
        Merger {
            port,
            log,
            stop,
            thread: Some(thread),
        }
    }

    /// The latest merged output of every test universe, if each has one.
    fn latest(&self) -> Option<BTreeMap<u16, Merged>> {
        let log = self.log.lock().expect("merge log");
        UNIVERSES
            .iter()
            .map(|u| Some((*u, log.out.get(u)?.last()?.clone())))
            .collect()
    }

    /// Waits until the latest merged output of every universe satisfies `want`; returns it.
    fn wait(
        &self,
        within: Duration,
        what: &str,
        want: impl Fn(&BTreeMap<u16, Merged>) -> bool,
    ) -> BTreeMap<u16, Merged> {
        let end = Instant::now() + within;
        loop {
            if let Some(m) = self.latest().filter(|m| want(m)) {
                return m;
            }
            assert!(
                Instant::now() < end,
                "the merged wire never showed {what}: latest {:?}",
                self.latest()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The slots the source sending at `priority` last sent, per test universe, if it
    /// sent all of them: one daemon's own stream, decoded before any merge.
    fn sent_at(&self, priority: u8) -> Option<BTreeMap<u16, Vec<u8>>> {
        let log = self.log.lock().expect("merge log");
        UNIVERSES
            .iter()
            .map(|u| {
                let src = log
                    .sources
                    .iter()
                    .find(|((su, _), src)| su == u && src.priority == priority)?;
                Some((*u, src.1.dmx.clone()))
            })
            .collect()
    }

    /// Every merged frame of every universe since `from`.
    fn since(&self, from: Instant) -> Vec<(u16, Merged)> {
        let log = self.log.lock().expect("merge log");
        log.out
            .iter()
            .flat_map(|(u, frames)| {
                frames
                    .iter()
                    .filter(|m| m.at >= from)
                    .map(|m| (*u, m.clone()))
            })
            .collect()
    }
}

impl Drop for Merger {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn slots(m: &BTreeMap<u16, Merged>) -> BTreeMap<u16, Vec<u8>> {
    m.iter().map(|(u, f)| (*u, f.dmx.clone())).collect()
}

fn all_from(priority: u8) -> impl Fn(&BTreeMap<u16, Merged>) -> bool {
    move |m| m.values().all(|f| f.priority == priority)
}

/// A main and its backup, both sending sACN to `merger`.
fn pair(name: &str, merger: &Merger) -> (Daemon, Daemon) {
    let main = main_alone(name, merger);
    let backup = backup_of(name, &main, merger);
    (main, backup)
}

/// A main sending sACN to `merger`, with no backup yet.
fn main_alone(name: &str, merger: &Merger) -> Daemon {
    Daemon::start_setup(
        &format!("{name}-main"),
        Setup {
            sacn_port: Some(merger.port),
            ..Setup::default()
        },
    )
}

/// A backup of `main` sending sACN to `merger`, once it has taken the main's state.
fn backup_of(name: &str, main: &Daemon, merger: &Merger) -> Daemon {
    let backup = Daemon::start_setup(
        &format!("{name}-backup"),
        Setup {
            sacn_port: Some(merger.port),
            artnet: false,
            extra: format!("\n[backup]\nmain = \"{}\"\n", main.tcp_addr()),
            ..Setup::default()
        },
    );
    wait_following(&backup, 1);
    backup
}

/// Waits until `done` holds, polling, or fails naming `what`.
fn eventually(what: &str, mut done: impl FnMut() -> bool) {
    let end = Instant::now() + PATIENCE;
    while !done() {
        assert!(Instant::now() < end, "never: {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Waits until the backup has taken the main's state `times` times since it started.
fn wait_following(backup: &Daemon, times: usize) {
    let end = Instant::now() + PATIENCE;
    while backup
        .log_text()
        .matches("backup: following the main")
        .count()
        < times
    {
        assert!(
            Instant::now() < end,
            "the backup never followed the main:\n{}",
            backup.log_text()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What a backup must hold as its main does, read over OSC.
#[derive(Debug, PartialEq)]
struct Mirror {
    live: Vec<LightLevel>,
    objectives: Vec<rosc::OscMessage>,
    looks: Vec<(i32, String)>,
    entry: i32,
    gallery: Vec<Vec<LightLevel>>,
}

fn mirror_of(d: &mut Daemon) -> Mirror {
    let sizes = d.gallery();
    let mut gallery = Vec::new();
    for (k, &n) in sizes.iter().enumerate() {
        for m in 1..=n {
            gallery.push(d.candidate(k as i32 + 1, m));
        }
    }
    Mirror {
        live: d.live(),
        objectives: d.objectives(),
        looks: d.looks(),
        entry: d.status().entry,
        gallery,
    }
}

/// Waits until the backup holds what the main holds.
fn wait_mirrored(main: &mut Daemon, backup: &mut Daemon) {
    let want = mirror_of(main);
    let end = Instant::now() + PATIENCE;
    loop {
        let got = mirror_of(backup);
        if got == want {
            return;
        }
        assert!(
            Instant::now() < end,
            "the backup differs from the main:\nmain   {want:?}\nbackup {got:?}\n--- backup log ---\n{}",
            backup.log_text()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_backup_mirrors_the_main_and_refuses_changes_from_others() {
    let merger = Merger::start();
    let (mut main, mut backup) = pair("mirror", &merger);
    main.add_objective("warm.png", "both");
    main.add_objective("cool.png", "color");
    main.generate();
    main.ok("/vo/pick", vec![int(2), int(1)], "/vo/picked");
    let ch = STAGE[0].channel;
    main.ok(&format!("/vo/light/{ch}/level"), vec![int(37)], "/vo/light");
    main.ok(
        "/vo/look/save",
        vec![int(3), string("act two")],
        "/vo/look/saved",
    );
    main.ok("/vo/objective/1/remove", vec![], "/vo/objective/removed");
    assert!(!main.gallery().is_empty());
    wait_mirrored(&mut main, &mut backup);

    // A second generate (a new random seed each time on the main) gives the backup the
    // same gallery too.
    main.generate();
    main.ok("/vo/pick", vec![int(1), int(1)], "/vo/picked");
    wait_mirrored(&mut main, &mut backup);

    // Changes sent to the backup are refused, naming the main; queries are answered.
    let before = mirror_of(&mut backup);
    let why = backup.err(&format!("/vo/light/{ch}/level"), vec![int(80)]);
    assert!(
        why.contains("backup of") && why.contains(&main.tcp_addr().to_string()),
        "{why}"
    );
    backup.err("/vo/generate", vec![]);
    let state = vec![string("{}"), string("{}"), string("{}"), string("{}")];
    backup.err("/vo/backup/state", state.clone());
    let why = main.err("/vo/backup/state", state);
    assert!(why.contains("only a backup"), "{why}");
    let why = backup.err("/vo/backup/gallery", vec![string("{}")]);
    assert!(why.contains("backup of"), "{why}");
    let why = main.err("/vo/backup/gallery", vec![string("{}")]);
    assert!(why.contains("only a backup"), "{why}");
    assert_eq!(mirror_of(&mut backup), before);

    // The wire: the main's look at its priority wins; the backup sends the same look
    // below it, all the time.
    let live = main.live();
    merger.wait(PATIENCE, "the main's look", |m| {
        all_from(MAIN)(m) && look_mismatch(&live, &slots(m)).is_none()
    });
    let log = merger.log.lock().expect("merge log");
    let backup_heard = log
        .sources
        .values()
        .filter(|s| s.priority == BACKUP)
        .count();
    assert_eq!(
        backup_heard,
        UNIVERSES.len(),
        "the backup sends every universe"
    );
}

#[test]
fn an_explore_drag_reaches_the_backup_as_its_last_gallery() {
    let merger = Merger::start();
    let (mut main, mut backup) = pair("explore", &merger);
    let id = main.add_objective("warm.png", "both");
    main.ok("/vo/explore", vec![int(1)], "/vo/explore");
    let path = format!("/vo/objective/{id}/region");
    for i in 0..30 {
        let t = i as f32 / 60.0;
        let r = [t, 0.0, t + 0.5, 1.0].map(common::daemon::float).to_vec();
        main.ok(&path, r, "/vo/objective/region");
    }
    main.ok("/vo/explore", vec![int(0)], "/vo/explore");
    wait_mirrored(&mut main, &mut backup);
    // A pick of the explored gallery is the same look on the backup.
    main.ok("/vo/pick", vec![int(2), int(1)], "/vo/picked");
    wait_mirrored(&mut main, &mut backup);
    backup.err("/vo/explore", vec![int(1)]);
}

#[test]
fn kill_9_leaves_the_mains_last_look_and_a_restarted_main_takes_it_back() {
    let merger = Merger::start();
    let (mut main, mut backup) = pair("failover", &merger);
    main.add_objective("warm.png", "both");
    main.generate();
    main.ok("/vo/pick", vec![int(1), int(1)], "/vo/picked");
    let ch = STAGE[1].channel;
    main.ok(&format!("/vo/light/{ch}/level"), vec![int(61)], "/vo/light");
    // A saved setting after the fader: the live look with it is on disk (the writer
    // writes the latest state), so the restarted main restores this very look.
    main.ok("/vo/generate/count", vec![int(30)], "/vo/generate/count");
    let live = main.live();
    let before = merger.wait(PATIENCE, "the main's look", |m| {
        all_from(MAIN)(m) && look_mismatch(&live, &slots(m)).is_none()
    });
    let last = slots(&before);
    wait_mirrored(&mut main, &mut backup);

    let killed = Instant::now();
    main.kill();
    let taken = merger.wait(HOLD * 3, "the backup taking over", all_from(BACKUP));
    let after_kill = taken.values().map(|f| f.at).min().expect("universes") - killed;
    eprintln!(
        "the backup's look was on the merged wire {:.3} s after kill -9",
        after_kill.as_secs_f32()
    );
    assert_eq!(slots(&taken), last, "the backup's look, slot for slot");

    let restarted = Instant::now();
    main.restart();
    let back = merger.wait(PATIENCE, "the main taking the stage back", all_from(MAIN));
    let took = back.values().map(|f| f.at).max().expect("universes") - restarted;
    eprintln!(
        "the restarted main was on the merged wire {:.3} s after it was started",
        took.as_secs_f32()
    );
    for (u, f) in merger.since(killed - Duration::from_millis(1)) {
        assert_eq!(
            f.dmx,
            last[&u],
            "universe {u}: a merged frame {:?} after the kill (priority {}) differs from the look",
            f.at - killed,
            f.priority
        );
    }
    // The backup re-syncs from the restarted main's state.
    wait_following(&backup, 2);

    // A main stopped cleanly terminates its streams: receivers take the backup at once,
    // with the same look.
    let stopped = Instant::now();
    assert!(main.terminate().success());
    let taken = merger.wait(PATIENCE, "the backup after SIGTERM", all_from(BACKUP));
    eprintln!(
        "the backup's look was on the merged wire {:.3} s after SIGTERM",
        (taken.values().map(|f| f.at).min().expect("universes") - stopped).as_secs_f32()
    );
    main.restart();
    merger.wait(PATIENCE, "the main again", all_from(MAIN));
    for (u, f) in merger.since(stopped) {
        assert_eq!(
            f.dmx, last[&u],
            "universe {u}: a frame after SIGTERM differs"
        );
    }
    wait_following(&backup, 3);
    assert_eq!(backup.live(), main.live());
    main.ok(&format!("/vo/light/{ch}/level"), vec![int(12)], "/vo/light");
    let end = Instant::now() + PATIENCE;
    while backup.live() != main.live() {
        assert!(
            Instant::now() < end,
            "the backup did not follow after the restart"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_pick_just_before_the_kill_is_what_the_backup_shows() {
    let merger = Merger::start();
    let (mut main, mut backup) = pair("pick", &merger);
    main.add_objective("split.png", "both");
    main.generate();
    let sizes = main.gallery();
    let k = sizes.len() as i32;
    let picked = main.candidate(k, 1);
    wait_mirrored(&mut main, &mut backup);
    main.ok("/vo/pick", vec![int(k), int(1)], "/vo/picked");
    main.kill();
    let taken = merger.wait(HOLD * 3, "the backup taking over", all_from(BACKUP));
    assert_eq!(look_mismatch(&picked, &slots(&taken)), None);
}

/// Waits until the main's stream (at its priority) and the backup's (at its own) both
/// decode, slot for slot, to `look`; returns the slots.
fn both_streams_show(merger: &Merger, look: &[LightLevel], what: &str) -> BTreeMap<u16, Vec<u8>> {
    let mut shown = BTreeMap::new();
    eventually(&format!("both streams showing {what}"), || {
        match (merger.sent_at(MAIN), merger.sent_at(BACKUP)) {
            (Some(main), Some(backup))
                if main == backup && look_mismatch(look, &main).is_none() =>
            {
                shown = main;
                true
            }
            _ => false,
        }
    });
    shown
}

#[test]
fn a_backup_started_after_the_generate_picks_undoes_and_takes_over_as_the_main() {
    let merger = Merger::start();
    let mut main = main_alone("late", &merger);
    main.add_objective("warm.png", "both");
    main.add_objective("cool.png", "color");
    main.generate();
    main.ok("/vo/pick", vec![int(1), int(1)], "/vo/picked");

    // The backup subscribes after the generate and the pick: the state carries the
    // gallery, the live entry and the undo history.
    let mut backup = backup_of("late", &main, &merger);
    wait_mirrored(&mut main, &mut backup);

    // A pick on the main: both daemons send the picked look, each at its priority.
    let k = main.gallery().len() as i32;
    let picked = main.candidate(k, 1);
    main.ok("/vo/pick", vec![int(k), int(1)], "/vo/picked");
    both_streams_show(&merger, &picked, "the picked look");
    wait_mirrored(&mut main, &mut backup);

    // Undo steps back over the pick made before the backup existed, redo comes back.
    let first = main.candidate(1, 1);
    main.ok("/vo/undo", vec![], "/vo/undone");
    both_streams_show(&merger, &first, "the look undone to");
    main.ok("/vo/redo", vec![], "/vo/redone");
    both_streams_show(&merger, &picked, "the look redone to");
    // A step count is forwarded with the command: two steps back to the dark start and
    // forward again, each one change on both.
    let r = main.ok("/vo/undo", vec![int(2)], "/vo/undone");
    assert_eq!(num(&r.args[0]) as i32, 0, "{r:?}");
    let start = main.live();
    assert!(start.iter().all(|l| l.intensity == 0.0), "{start:?}");
    both_streams_show(&merger, &start, "the look two steps back");
    wait_mirrored(&mut main, &mut backup);
    main.ok("/vo/redo", vec![int(2)], "/vo/redone");
    both_streams_show(&merger, &picked, "the look two steps forward");
    wait_mirrored(&mut main, &mut backup);

    // The backup restarted after another generate takes the new gallery the same way.
    backup.kill();
    main.generate();
    backup.restart();
    wait_following(&backup, 1);
    wait_mirrored(&mut main, &mut backup);
    let k = main.gallery().len() as i32;
    let m = main.gallery()[k as usize - 1];
    let picked = main.candidate(k, m);
    main.ok("/vo/pick", vec![int(k), int(m)], "/vo/picked");
    let last = both_streams_show(&merger, &picked, "the pick after the backup's restart");

    // kill -9 of the main: after the hold the merged wire shows the backup's picked look.
    let killed = Instant::now();
    main.kill();
    let taken = merger.wait(HOLD * 3, "the backup taking over", all_from(BACKUP));
    eprintln!(
        "late backup: its look was on the merged wire {:.3} s after kill -9",
        (taken.values().map(|f| f.at).min().expect("universes") - killed).as_secs_f32()
    );
    assert_eq!(slots(&taken), last, "the backup's look, slot for slot");
    assert_eq!(look_mismatch(&picked, &slots(&taken)), None);
}

/// Eos's selection report (`/eos/out/active/chan`), sent to the main.
fn select(console: &mut impl Osc, text: &str) {
    console.send("/eos/out/active/chan", vec![string(text)]);
}

/// What the console selection and the constraints are on `d`.
fn selection_and_constraints(d: &mut Daemon) -> (OscMessage, Vec<OscMessage>) {
    let selection = d.ok("/vo/console/selection", vec![], "/vo/console/selection");
    (
        selection,
        d.call("/vo/constraints", vec![], "/vo/constraints/end"),
    )
}

#[test]
fn the_console_selection_reaches_a_late_backup_and_its_changes_keep_their_order() {
    let merger = Merger::start();
    let mut main = main_alone("selection", &merger);
    let mut console = main.client();
    select(&mut console, "3 + 5 [62]");
    assert_eq!(console.fence(), Vec::new());

    // The selection was reported before the backup existed: it comes with the state, so
    // locking it on the main locks the same lights on the backup.
    let mut backup = backup_of("selection", &main, &merger);
    main.ok(
        "/vo/console/selection/lock",
        vec![int(1)],
        "/vo/console/selection/lock",
    );
    let want = selection_and_constraints(&mut main);
    assert!(
        want.1
            .iter()
            .any(|m| m.args.first().map(text) == Some("/vo/light/5/lock".into())),
        "{want:?}"
    );
    eventually("the backup holding the main's selection and locks", || {
        selection_and_constraints(&mut backup) == want
    });

    // The console changes its selection while a tablet locks and keys it, concurrently:
    // the backup applies the selections, locks and keys in the main's order, so it ends
    // with the main's constraints.
    let mut tablet = main.tcp(TcpFraming::LengthPrefix);
    let eos = std::thread::spawn(move || {
        for i in 0..300 {
            select(
                &mut console,
                &format!("{} + {} [50]", 1 + i % 6, 1 + (i * 7 + 3) % 6),
            );
        }
        assert_eq!(console.fence(), Vec::new());
    });
    for i in 0..150 {
        let (addr, on) = if i % 3 == 0 {
            ("/vo/console/selection/key", i % 2)
        } else {
            ("/vo/console/selection/lock", (i / 3) % 2)
        };
        // Every selection has lights, so neither is refused.
        tablet.ok(addr, vec![int(on)], addr);
    }
    eos.join().expect("the console thread");
    let want = selection_and_constraints(&mut main);
    eventually(
        "the backup holding the main's constraints after the race",
        || selection_and_constraints(&mut backup) == want,
    );
}

#[test]
fn a_pick_while_the_main_generates_is_the_same_pick_on_the_backup() {
    let merger = Merger::start();
    let (mut main, mut backup) = pair("racing", &merger);
    main.add_objective("warm.png", "both");
    main.generate();
    let old = main.candidate(2, 1);
    wait_mirrored(&mut main, &mut backup);

    // A pick sent right behind a generate (a long one) picks from the gallery the main has
    // when it takes the pick: the backup installs the new gallery where the main did, so
    // it picks the same look.
    main.ok("/vo/generate/count", vec![int(400)], "/vo/generate/count");
    main.send("/vo/generate", vec![]);
    main.send("/vo/pick", vec![int(2), int(1)]);
    let mut got = main.collect("/vo/generated", GENERATE_PATIENCE, "/vo/generate");
    if !got.iter().any(|m| m.addr == "/vo/picked") {
        got.extend(main.collect("/vo/picked", PATIENCE, "/vo/pick"));
    }
    assert!(got.iter().all(|m| m.addr != "/vo/error"), "{got:?}");
    // The main took the pick before the new gallery was installed if no entry of the new
    // gallery is live (installing it clears the live entry); replies may come either way.
    let during = main.status().entry == 0;
    let picked = if during { old } else { main.candidate(2, 1) };
    eprintln!(
        "racing: the main took the pick {} the generate installed its gallery",
        if during { "before" } else { "after" }
    );
    assert_eq!(main.live(), picked);
    both_streams_show(&merger, &picked, "the pick made during the generate");
    wait_mirrored(&mut main, &mut backup);
}
