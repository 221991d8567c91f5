//! What the daemon's black-box tests share beside `visobjd_testkit`: the built binary, the
//! length of a long run, the running daemon ([`daemon`]), an HTTP client for its web page
//! ([`http`]) and the capture stage ([`capture`]). Each test binary compiles it once; not
//! every binary uses all of it.
#![allow(dead_code)]

pub mod capture;
pub mod daemon;
pub mod http;

/// Path of the built `visobjd` binary.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_visobjd")
}

/// The size of a long run (kills, seconds, simulated minutes): the environment variable
/// `knob` when set, else `full` with `VISOBJD_FULL=1`, else `short`. One test serves both:
/// `cargo test` and CI run the short form, the documented command the full one.
pub fn size(knob: &str, short: u64, full: u64) -> u64 {
    if let Ok(v) = std::env::var(knob) {
        return v
            .parse()
            .unwrap_or_else(|_| panic!("{knob}={v:?} is not a whole number"));
    }
    if std::env::var("VISOBJD_FULL").is_ok_and(|v| v == "1") {
        full
    } else {
        short
    }
}

/// Starts `command`, an independent peer (a fake console) that prints the port it listens
/// on as its first line once it listens, and returns it with that port. `what` names it.
pub fn start_peer(mut command: std::process::Command, what: &str) -> (std::process::Child, u16) {
    use std::io::BufRead;
    let mut child = command
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("start {what}: {e}"));
    // A blocking read: it prints at once, or exits and the read ends.
    let mut line = String::new();
    let stdout = child.stdout.take().expect("its stdout");
    std::io::BufReader::new(stdout)
        .read_line(&mut line)
        .unwrap_or_else(|e| panic!("read {what}'s port: {e}"));
    match line.trim().parse() {
        Ok(port) => (child, port),
        Err(_) => {
            let _ = child.kill();
            panic!("{what} did not start: `{line}`")
        }
    }
}
