//! The command line (cli.md): argument parsing and one module per subcommand.

mod bench;
mod check;
mod gallery;
mod render;
mod run;
mod send;
mod touchosc;

use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, Subcommand};

/// visobjd: reference images in, stage lighting looks out.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
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
}

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
    let result = match cli.command {
        Command::Run(args) => run::run(args),
        Command::Gallery(args) => gallery::run(args, sub),
        Command::Render(args) => render::run(args),
        Command::Check(args) => check::run(args),
        Command::Synth { rig, out } => crate::synth::synth(&rig, &out)
            .map(|r| {
                println!(
                    "synth: {} lights at {}x{} in {:.1} s -> {}",
                    r.lights,
                    r.width,
                    r.height,
                    r.seconds,
                    out.display()
                )
            })
            .map_err(anyhow::Error::from),
        Command::Send(args) => send::run(args),
        Command::Touchosc(args) => touchosc::run(args),
        Command::Bench(args) => bench::run(args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", format!("{e:#}").replace('\n', " "));
            std::process::ExitCode::FAILURE
        }
    }
}
