//! The command line (docs/cli.md): argument parsing and one module per subcommand.

mod bench;
mod capture;
mod check;
mod export;
mod gallery;
mod import;
mod logs;
mod render;
mod run;
mod send;
mod touchosc;

use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser};

/// visobjd: reference images in, stage lighting looks out.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Subcommand,
}

#[derive(clap::Subcommand)]
enum Subcommand {
    /// The daemon: loads the scene, listens for OSC, outputs DMX until SIGINT/SIGTERM.
    Run(run::Args),
    /// Offline: one generate from reference images, written as a contact sheet (and JSON).
    Gallery(gallery::Args),
    /// Renders one look file to a PNG.
    Render(render::Args),
    /// Validates the config and its scene and prints a summary.
    Check(check::Args),
    /// Renders a virtual stage's basis images and scene.toml from a rig description.
    Synth {
        /// The rig description (TOML).
        #[arg(long)]
        rig: std::path::PathBuf,
        /// The scene folder to write.
        #[arg(long)]
        out: std::path::PathBuf,
    },
    /// A small OSC client: sends one message, prints the replies that arrive within --wait.
    Send(send::Args),
    /// Writes the TouchOSC layout for the booth tablet (regenerate it when addresses change).
    Touchosc(touchosc::Args),
    /// Measures the FLOP bound and the performance targets on this machine.
    Bench(bench::Args),
    /// Shoots the scene's basis images light by light with a tethered camera.
    Capture(capture::Args),
    /// Builds or updates a scene from an MVR plot, or lists a GDTF/OFL fixture type's modes as profiles.
    Import(import::Args),
    /// Writes the daemon's saved looks as a file a console imports (USITT ASCII).
    Export(export::Args),
}

/// Starts rayon's global pool, which renders and generates run on, with its threads named
/// `compute-N` and one step down in priority (nice 10): a generate keeps both cores busy,
/// and the DMX clock and the OSC threads must then get a core the moment they wake, not at
/// the end of a scheduler slice. Where the pool already runs, or the system refuses the
/// priority, work carries on as it is (logged).
fn start_compute_pool() {
    let built = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("compute-{i}"))
        .start_handler(|_| {
            #[cfg(target_os = "linux")]
            {
                // SAFETY: plain system calls on this thread's own id; on Linux the nice
                // value set through PRIO_PROCESS with a thread id is that thread's alone.
                let done = unsafe {
                    let tid = libc::gettid() as libc::id_t;
                    libc::setpriority(libc::PRIO_PROCESS, tid, COMPUTE_NICE)
                };
                if done != 0 {
                    tracing::warn!(
                        "compute threads stay at normal priority: {}",
                        std::io::Error::last_os_error()
                    );
                }
            }
        })
        .build_global();
    if let Err(e) = built {
        tracing::debug!("compute pool: {e}");
    }
}

/// The compute threads' nice value (0 is normal, 19 the lowest).
pub const COMPUTE_NICE: i32 = 10;

/// Runs the command line; returns the process exit code. User mistakes print one line on
/// stderr and exit non-zero, never a panic.
pub fn main() -> std::process::ExitCode {
    let matches = Cli::command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    let sub: &ArgMatches = matches
        .subcommand()
        .map(|(_, m)| m)
        .expect("clap requires a subcommand");
    // The daemon logs what it does; the offline commands only what went wrong.
    let level = match &cli.command {
        Subcommand::Run(args) => args.log_level.as_str(),
        _ => "warn",
    };
    if let Err(e) = logs::init(level) {
        eprintln!("error: {e}");
        return std::process::ExitCode::FAILURE;
    }
    let result = match cli.command {
        Subcommand::Run(args) => run::run(args),
        Subcommand::Gallery(args) => gallery::run(args, sub),
        Subcommand::Render(args) => render::run(args),
        Subcommand::Check(args) => check::run(args),
        Subcommand::Synth { rig, out } => visobjd_synth::synth(&rig, &out)
            .map(|r| {
                println!(
                    "synth: {} lights, {} images at {}x{} in {:.1} s -> {}",
                    r.lights,
                    r.images,
                    r.width,
                    r.height,
                    r.seconds,
                    out.display()
                )
            })
            .map_err(anyhow::Error::from),
        Subcommand::Send(args) => send::run(args),
        Subcommand::Touchosc(args) => touchosc::run(args),
        Subcommand::Bench(args) => bench::run(args),
        Subcommand::Capture(args) => capture::run(args),
        Subcommand::Import(args) => import::run(args),
        Subcommand::Export(args) => export::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            std::process::ExitCode::FAILURE
        }
    }
}
