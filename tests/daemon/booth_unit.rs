//! The shipped systemd unit, checked without systemd as PID 1: `systemd-analyze verify`
//! accepts it, and the real daemon runs a whole booth session (objective, generate, pick,
//! save, recall, fader, SIGTERM) under the unit's own `SystemCallFilter=` lines, as root and
//! as an unprivileged user who may write only the state folder.
//!
//! The filter is read from `systemd/visobjd.service` and its `@sets` are expanded by
//! `systemd-analyze syscall-filter`, so the test follows the unit and the local systemd. It
//! is stricter than the unit: any call outside the list kills the process (the unit says
//! EPERM), so a call the unit forgot shows up as a dead daemon, not a warning in a log.

use std::collections::{BTreeSet, HashMap};
use std::io::ErrorKind;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::os::unix::net::UnixDatagram;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::str::FromStr;
use std::sync::Arc;
use std::time::Instant;

use seccompiler::{BpfProgram, SeccompAction, SeccompFilter, TargetArch};
use syscalls::Sysno;

use crate::common;
use crate::common::bin;
use crate::common::daemon::{
    Daemon, Osc, PATIENCE, PROTOS, Proto, Setup, UNIVERSES, int, same_look, string,
};
use visobjd_testkit::temp_dir;

/// The unit under test.
const UNIT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/systemd/visobjd.service");

/// `nobody`: the unprivileged user of the second run (DynamicUser picks another unused uid).
const NOBODY: u32 = 65534;

/// Every value of `key=` in the unit, in order (an empty value is kept: it resets a list).
fn directive(unit: &str, key: &str) -> Vec<String> {
    unit.lines()
        .map(str::trim)
        .filter(|l| !l.starts_with('#') && !l.starts_with(';'))
        .filter_map(|l| l.split_once('='))
        .filter(|(k, _)| k.trim() == key)
        .map(|(_, v)| {
            assert!(
                !v.ends_with('\\'),
                "{key}={v}: continued lines are not modelled"
            );
            v.trim().to_string()
        })
        .collect()
}

/// Runs `systemd-analyze` with `args`; panics with the tool's name when it is missing.
fn systemd_analyze(args: &[&str]) -> std::process::Output {
    Command::new("systemd-analyze")
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("systemd-analyze {args:?} did not run ({e}): install systemd's tools")
        })
}

/// The calls of `@set` as `systemd-analyze syscall-filter` lists them, nested sets expanded.
/// The listing is the set's name, then one indented entry a line: `# description`, a
/// nested `@set`, or a call.
fn expand(set: &str, cache: &mut HashMap<String, BTreeSet<String>>) -> BTreeSet<String> {
    if let Some(calls) = cache.get(set) {
        return calls.clone();
    }
    let out = systemd_analyze(&["syscall-filter", "--no-pager", set]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "systemd-analyze syscall-filter {set}: {}{}",
        text,
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(set), "the listing starts with its name");
    let mut calls = BTreeSet::new();
    for entry in lines.map(str::trim).filter(|l| !l.is_empty()) {
        if entry.starts_with('#') {
            continue;
        }
        if entry.starts_with('@') {
            calls.extend(expand(entry, cache));
        } else {
            calls.insert(entry.to_string());
        }
    }
    cache.insert(set.to_string(), calls.clone());
    calls
}

/// What the unit's `SystemCallFilter=` lines let through, by systemd.exec(5)'s rules: the
/// first line decides the mode (a leading `~` makes a deny-list, else an allow-list), later
/// lines add their calls to the list or, when of the other kind, take them out; an empty
/// value starts over.
struct Filter {
    allow_list: bool,
    calls: BTreeSet<String>,
}

fn unit_filter(lines: &[String]) -> Filter {
    let mut cache = HashMap::new();
    let mut filter: Option<Filter> = None;
    for line in lines {
        if line.is_empty() {
            filter = None;
            continue;
        }
        let (deny, list) = match line.strip_prefix('~') {
            Some(rest) => (true, rest),
            None => (false, line.as_str()),
        };
        let f = filter.get_or_insert_with(|| Filter {
            allow_list: !deny,
            // systemd.exec(5), SystemCallFilter=: "the execve(), exit(), exit_group(),
            // getrlimit(), rt_sigreturn(), sigreturn() system calls and the system calls for
            // querying time and sleeping are implicitly allow-listed". systemd adds them as
            // the set @default ("System calls that are always permitted") when the first
            // line makes an allow-list; later `~` lines can still take them out.
            calls: if deny {
                BTreeSet::new()
            } else {
                expand("@default", &mut cache)
            },
        });
        for word in list.split_whitespace() {
            assert!(
                !word.contains(':'),
                "SystemCallFilter={line}: per-call errno (`{word}`) is not modelled"
            );
            let calls = if word.starts_with('@') {
                expand(word, &mut cache)
            } else {
                BTreeSet::from([word.to_string()])
            };
            if deny == f.allow_list {
                f.calls.retain(|c| !calls.contains(c));
            } else {
                f.calls.extend(calls);
            }
        }
    }
    filter.expect("the unit has SystemCallFilter= lines")
}

/// The unit's system call filter as a BPF program for this machine, built before any fork.
/// A call outside it kills the whole process.
fn unit_seccomp() -> BpfProgram {
    let unit = std::fs::read_to_string(UNIT).expect("read the unit");
    // `native`, the only value modelled: seccompiler's program kills a call made through
    // any other architecture's ABI, as systemd does for the unit.
    assert_eq!(
        directive(&unit, "SystemCallArchitectures"),
        ["native"],
        "SystemCallArchitectures= other than native is not modelled"
    );
    let filter = unit_filter(&directive(&unit, "SystemCallFilter"));
    // Names this architecture does not have (mmap2, ugetrlimit, ...) are left out, as
    // systemd leaves them out; in an allow-list that can only make the filter stricter.
    let numbers: BTreeSet<i64> = filter
        .calls
        .iter()
        .filter_map(|c| Sysno::from_str(c).ok())
        .map(|s| i64::from(s.id()))
        .collect();
    assert!(
        numbers.len() > 100,
        "only {} calls resolved from {:?}",
        numbers.len(),
        filter.calls
    );
    let (mismatch, matched) = if filter.allow_list {
        (SeccompAction::KillProcess, SeccompAction::Allow)
    } else {
        (SeccompAction::Allow, SeccompAction::KillProcess)
    };
    let arch =
        TargetArch::try_from(std::env::consts::ARCH).expect("an architecture seccompiler knows");
    let rules = numbers.into_iter().map(|n| (n, Vec::new())).collect();
    SeccompFilter::new(rules, mismatch, matched, arch)
        .and_then(BpfProgram::try_from)
        .expect("the unit's filter compiles to BPF")
}

/// The unit's `WatchdogSec=`, in microseconds (`WATCHDOG_USEC`, as systemd passes it).
fn watchdog_usec() -> u64 {
    let unit = std::fs::read_to_string(UNIT).expect("read the unit");
    let value = directive(&unit, "WatchdogSec");
    let secs: u64 = value
        .last()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("WatchdogSec= in whole seconds, got {value:?}"));
    secs * 1_000_000
}

/// Stands in for systemd's notify socket (`Type=notify`, `WatchdogSec=`).
struct Notify {
    dir: PathBuf,
    sock: UnixDatagram,
}

impl Notify {
    fn bind(name: &str) -> Notify {
        let dir = temp_dir(&format!("notify-{name}"));
        let sock = UnixDatagram::bind(dir.join("notify")).expect("bind the notify socket");
        // Sending to a socket needs write permission on it: the daemon may run as nobody.
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        std::fs::set_permissions(dir.join("notify"), std::fs::Permissions::from_mode(0o666))
            .expect("chmod");
        sock.set_read_timeout(Some(PATIENCE)).expect("timeout");
        Notify { dir, sock }
    }

    fn path(&self) -> PathBuf {
        self.dir.join("notify")
    }

    /// Reads notifications until one has the line `want`, and returns that notification
    /// (all its lines); panics after [`PATIENCE`].
    fn expect(&self, want: &str) -> String {
        let end = Instant::now() + PATIENCE;
        let mut buf = [0u8; 4096];
        let mut got = Vec::new();
        while Instant::now() < end {
            match self.sock.recv(&mut buf) {
                Ok(n) => {
                    let text = String::from_utf8_lossy(&buf[..n]).into_owned();
                    if text.lines().any(|l| l == want) {
                        return text;
                    }
                    got.push(text);
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(e) => panic!("notify socket: {e}"),
            }
        }
        panic!("no {want} on the notify socket; got {got:?}");
    }
}

impl Drop for Notify {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Every folder from `/` down to `path`'s parent must be searchable by others.
fn assert_traversable(path: &Path, what: &str) {
    for dir in path.ancestors().skip(1) {
        let mode = std::fs::metadata(dir).expect("stat an ancestor").mode();
        assert!(
            mode & 0o001 != 0,
            "{} (mode {:o}) is not searchable by uid {NOBODY}, so it cannot reach {what} {}",
            dir.display(),
            mode & 0o7777,
            path.display()
        );
    }
}

/// What `DynamicUser=`, `StateDirectory=` and `ProtectSystem=strict` give the daemon: the
/// state folder its own (`StateDirectoryMode=0750`), everything else it reads readable and
/// not writable. The test's own folders are opened for reading where they are not.
fn prepare_for_nobody(dir: &Path) {
    assert_traversable(dir, "the daemon's folder");
    assert_traversable(Path::new(bin()), "the binary");
    let exe = std::fs::metadata(bin()).expect("stat the binary").mode();
    assert!(
        exe & 0o005 == 0o005,
        "{} is not readable and executable by others",
        bin()
    );
    let state = dir.join("state");
    std::fs::create_dir_all(&state).expect("mkdir state");
    std::os::unix::fs::chown(&state, Some(NOBODY), Some(NOBODY))
        .expect("chown the state folder to uid 65534 (the test runs as root, as CI does)");
    std::fs::set_permissions(&state, std::fs::Permissions::from_mode(0o750)).expect("chmod");
    let mut todo = vec![dir.to_path_buf()];
    while let Some(path) = todo.pop() {
        let meta = std::fs::symlink_metadata(&path).expect("stat");
        let open = if meta.is_dir() { 0o005 } else { 0o004 };
        if meta.mode() & open != open {
            let mode = meta.mode() | open;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode))
                .expect("open for reading");
        }
        let mode = std::fs::metadata(&path).expect("stat").mode();
        let writable = meta.uid() == NOBODY
            || mode & 0o002 != 0
            || (meta.gid() == NOBODY && mode & 0o020 != 0);
        assert!(!writable, "{} is writable by uid {NOBODY}", path.display());
        if meta.is_dir() {
            for entry in std::fs::read_dir(&path).expect("read_dir") {
                let entry = entry.expect("entry").path();
                if entry != state {
                    todo.push(entry);
                }
            }
        }
    }
}

/// Launches the daemon as systemd would for the unit: its working folder, the notify
/// socket and watchdog period, the unit's system call filter, and, with `user`, that uid
/// and gid with no supplementary groups (std drops them when root sets a uid).
fn launch(seccomp: BpfProgram, notify: PathBuf, user: Option<u32>) -> common::daemon::Launch {
    let seccomp = Arc::new(seccomp);
    let watchdog = watchdog_usec().to_string();
    Box::new(move |dir: &Path, command: &mut Command| {
        command
            .current_dir(dir)
            .env("NOTIFY_SOCKET", &notify)
            .env("WATCHDOG_USEC", &watchdog);
        if let Some(id) = user {
            prepare_for_nobody(dir);
            assert_traversable(&notify, "the notify socket");
            command.uid(id).gid(id);
        }
        let seccomp = Arc::clone(&seccomp);
        // SAFETY: the closure runs in the forked child before exec, after std has dropped
        // privileges. It only hands the BPF program, compiled before the fork, to prctl and
        // seccomp: no allocation, no lock. The io::Errors it returns are raw errno values.
        unsafe {
            command.pre_exec(move || {
                seccompiler::apply_filter(&seccomp).map_err(|e| match e {
                    seccompiler::Error::Prctl(e) | seccompiler::Error::Seccomp(e) => e,
                    _ => std::io::Error::from_raw_os_error(libc::EINVAL),
                })
            });
        }
    })
}

/// The value of `key:` in `/proc/PID/status`, its whitespace collapsed.
fn proc_status(pid: u32, key: &str) -> String {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("/proc status");
    status
        .lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix(':'))
        .unwrap_or_else(|| panic!("no {key} in /proc/{pid}/status"))
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// The nice values of the daemon's `compute-N` threads.
fn compute_nice(pid: u32) -> Vec<i64> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .expect("/proc task list")
        .filter_map(|t| {
            let dir = t.ok()?.path();
            let name = std::fs::read_to_string(dir.join("comm")).ok()?;
            let stat = std::fs::read_to_string(dir.join("stat")).ok()?;
            // nice is the 19th field, the 17th after the parenthesised name.
            let nice = stat.rsplit(')').next()?.split_whitespace().nth(16)?;
            name.starts_with("compute-").then(|| nice.parse().ok())?
        })
        .collect()
}

/// Starts the daemon under the unit's filter (as `user` when given) and runs a booth
/// session through to SIGTERM.
fn booth_session(name: &str, user: Option<u32>) {
    let notify = Notify::bind(name);
    let launch = launch(unit_seccomp(), notify.path(), user);
    let mut d = Daemon::start_setup_with(name, Setup::default(), launch);
    let pid = d.pid();
    notify.expect("READY=1");
    notify.expect("WATCHDOG=1");
    // The filter is really on, and the privileges are what the unit gives.
    assert_eq!(
        proc_status(pid, "Seccomp"),
        "2",
        "a seccomp filter is installed"
    );
    assert_eq!(proc_status(pid, "NoNewPrivs"), "1");
    if let Some(id) = user {
        assert_eq!(proc_status(pid, "Uid"), format!("{id} {id} {id} {id}"));
        assert_eq!(proc_status(pid, "Gid"), format!("{id} {id} {id} {id}"));
        assert_eq!(proc_status(pid, "Groups"), "", "no supplementary groups");
    }

    d.add_objective("warm.png", "both");
    d.generate();
    let nice = compute_nice(pid);
    assert!(!nice.is_empty(), "no compute threads");
    assert!(
        nice.iter()
            .all(|&n| n == i64::from(visobjd::cli::COMPUTE_NICE)),
        "compute threads at nice {nice:?}\n--- daemon log ---\n{}",
        d.log_text()
    );
    let entries = d.gallery();
    assert!(!entries.is_empty(), "an empty gallery");
    d.ok("/vo/pick", vec![int(1)], "/vo/picked");
    let picked = d.live();
    d.ok(
        "/vo/look/save",
        vec![int(1), string("booth")],
        "/vo/look/saved",
    );
    // A fader far from the saved level, so the recall has something to undo.
    let saved = picked
        .iter()
        .find(|l| l.ch == 1)
        .expect("light 1")
        .intensity;
    let away = if saved > 0.5 { 0 } else { 100 };
    d.ok("/vo/light/1/level", vec![int(away)], "/vo/light");
    assert!(
        !same_look(&d.live(), &picked, 0.1),
        "the fader changed nothing"
    );
    d.ok("/vo/look/recall", vec![int(1)], "/vo/look/recalled");
    for proto in PROTOS {
        d.wire.wait_look(proto, &picked);
    }
    d.ok("/vo/light/1/level", vec![int(70)], "/vo/light");
    let live = d.live();
    for proto in PROTOS {
        d.wire.wait_look(proto, &live);
    }
    let reloaded_from = Instant::now();

    // `systemctl reload` as the unit defines it, under the same filter and user.
    let reload = directive(
        &std::fs::read_to_string(UNIT).expect("read the unit"),
        "ExecReload",
    );
    let reload = reload.last().expect("an ExecReload= line");
    let reload = reload.replace("$MAINPID", &pid.to_string());
    let mut words = reload.split_whitespace();
    let ran = Command::new(words.next().expect("a command"))
        .args(words)
        .status()
        .expect("ExecReload= runs");
    assert!(ran.success(), "{reload}: {ran}");
    notify.expect("RELOADING=1");
    let ready = notify.expect("READY=1");
    assert!(
        ready.lines().any(|l| l.starts_with("STATUS=reloaded ")),
        "{ready}"
    );
    d.wire
        .assert_continuous_since(reloaded_from, "systemctl reload");

    // Still alive and on the wire at the end.
    assert!(
        d.alive(),
        "the daemon died\n--- daemon log ---\n{}",
        d.log_text()
    );
    d.wire.wait_frames_after(Instant::now(), "the session");

    let stopped = Instant::now();
    let status = d.terminate();
    assert_eq!(
        status.code(),
        Some(0),
        "SIGTERM: {status}\n--- daemon log ---\n{}",
        d.log_text()
    );
    notify.expect("STOPPING=1");
    d.wire.drained_after(Instant::now());
    for u in UNIVERSES {
        assert!(
            d.wire
                .frames(Proto::Sacn, u, stopped)
                .iter()
                .any(|f| f.terminated),
            "universe {u}: no sACN Stream_Terminated after SIGTERM"
        );
    }
}

#[test]
fn a_booth_session_under_the_units_system_call_filter() {
    booth_session("booth-root", None);
}

#[test]
fn a_booth_session_as_an_unprivileged_user_under_the_filter() {
    booth_session("booth-nobody", Some(NOBODY));
}

/// `systemd-analyze verify` on the unit's own text. Its ExecStart= names the installed
/// binary, /opt/visobjd/visobjd, which verify checks exists: the copy verified here has
/// that one path rewritten to the binary cargo built, and nothing else changed.
#[test]
fn systemd_analyze_verify_accepts_the_unit() {
    let text = std::fs::read_to_string(UNIT).expect("read the unit");
    let installed = "ExecStart=/opt/visobjd/visobjd ";
    assert_eq!(
        text.matches(installed).count(),
        1,
        "one ExecStart= of the installed binary"
    );
    let dir = temp_dir("verify");
    let unit = dir.join("visobjd.service");
    std::fs::write(
        &unit,
        text.replace(installed, &format!("ExecStart={} ", bin())),
    )
    .expect("write the unit copy");
    let out = systemd_analyze(&["verify", "--no-pager", unit.to_str().expect("a UTF-8 path")]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "systemd-analyze verify: {}\n{stderr}",
        out.status
    );
    // verify exits 0 on unknown keys or set names (it ignores them): any line about the
    // unit itself is a finding.
    let about_unit: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("visobjd.service"))
        .collect();
    assert!(
        about_unit.is_empty(),
        "systemd-analyze verify: {about_unit:#?}"
    );
    std::fs::remove_dir_all(&dir).expect("remove the copy");
}
