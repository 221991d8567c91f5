//! Runs one camera process with a deadline: spawn in its own process group, read its
//! output on two threads, poll for its exit, and kill the whole group at the deadline (a
//! wrapper script's children die with it, and the output pipes close so the readers end).

use std::ffi::OsString;
use std::io::Read;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use std::os::unix::process::CommandExt;

/// How often the driver looks whether the process has exited. Not a synchronisation
/// stand-in: the wait is bounded by the process's exit or the deadline.
const POLL: Duration = Duration::from_millis(20);

/// A finished process.
pub(crate) struct Finished {
    pub status: ExitStatus,
    pub stdout: String,
    pub stderr: String,
}

/// What went wrong running one process.
pub(crate) enum Failure {
    /// It could not be started.
    Spawn(std::io::Error),
    /// It ran past the deadline and was killed.
    TimedOut,
}

/// Runs `program args` with `env` added, stdin closed, `LC_ALL=C` (so gphoto2 prints the
/// English headers and error lines this layer reads), until it exits or `timeout` passes.
pub(crate) fn run(
    program: &Path,
    args: &[OsString],
    env: &[(OsString, OsString)],
    timeout: Duration,
) -> Result<Finished, Failure> {
    let mut command = Command::new(program);
    command
        .args(args)
        .env("LC_ALL", "C")
        .envs(env.iter().map(|(k, v)| (k, v)))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
    let mut child = command.spawn().map_err(Failure::Spawn)?;
    let stdout = reader(child.stdout.take());
    let stderr = reader(child.stderr.take());
    let deadline = Instant::now() + timeout;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Some(status),
            Ok(None) if Instant::now() >= deadline => break None,
            Ok(None) => thread::sleep(POLL),
            // try_wait only fails if the child was already reaped; treat as gone.
            Err(_) => break None,
        }
    };
    let Some(status) = status else {
        kill_group(&mut child);
        let _ = stdout.join();
        let _ = stderr.join();
        return Err(Failure::TimedOut);
    };
    Ok(Finished {
        status,
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
    })
}

fn reader<R: Read + Send + 'static>(pipe: Option<R>) -> thread::JoinHandle<String> {
    thread::spawn(move || {
        let mut bytes = Vec::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_end(&mut bytes);
        }
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

/// Kills the child's process group, then reaps the child. Only called while the child
/// is unreaped, so its pid (the group id: it was spawned with `process_group(0)`) cannot
/// have been reused by another process.
fn kill_group(child: &mut Child) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) takes plain integers and touches no memory of ours; the group is
        // the unreaped child's own (see above), so no other program's processes are hit.
        unsafe {
            libc::kill(-pid, libc::SIGKILL);
        }
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// A command line as a person would type it, for error sentences.
pub(crate) fn display(program: &Path, args: &[OsString]) -> String {
    let mut words = vec![program.to_string_lossy().into_owned()];
    for arg in args {
        let arg = arg.to_string_lossy();
        if arg.is_empty() || arg.contains(char::is_whitespace) {
            words.push(format!("{arg:?}"));
        } else {
            words.push(arg.into_owned());
        }
    }
    words.join(" ")
}

/// Runs a call, and runs it once more if it timed out or if it failed and `retry`
/// says trying again may help. Returns the last process's result, successful or not;
/// the caller turns a failure into its own sentence.
pub(crate) fn with_retry(
    program: &Path,
    args: &[OsString],
    env: &[(OsString, OsString)],
    timeout: Duration,
    retry: impl Fn(&Finished) -> bool,
) -> Result<Finished, crate::Error> {
    let spawn_error = |source| crate::Error::Spawn {
        program: program.to_string_lossy().into_owned(),
        call: display(program, args),
        source,
    };
    match run(program, args, env, timeout) {
        Ok(done) if done.status.success() || !retry(&done) => return Ok(done),
        Ok(_) | Err(Failure::TimedOut) => {}
        Err(Failure::Spawn(source)) => return Err(spawn_error(source)),
    }
    match run(program, args, env, timeout) {
        Ok(done) => Ok(done),
        Err(Failure::Spawn(source)) => Err(spawn_error(source)),
        Err(Failure::TimedOut) => Err(crate::Error::TimedOut {
            call: display(program, args),
            seconds: timeout.as_secs_f64(),
        }),
    }
}
