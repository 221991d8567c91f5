//! `visobjd export`: the daemon's saved looks written as files a console imports, for a
//! console without a network link to visobjd: USITT ASCII (docs/export.md), a grandMA3
//! plugin (docs/ma3.md).

mod ma3;
mod usitt;

use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::engine::persist::LooksFile;
use visobjd_scene::Scene;

/// Arguments of `export`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    format: Format,
}

#[derive(clap::Subcommand)]
enum Format {
    /// USITT ASCII (Ident 3:0): every saved look as a cue of channel levels, which Eos,
    /// Ion, Element, Strand and many other consoles import.
    Usitt(usitt::Args),
    /// A grandMA3 plugin (XML and Lua) that stores every saved look as a preset or a cue
    /// when run on the desk.
    Ma3(ma3::Args),
}

/// Runs `export`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.format {
        Format::Usitt(a) => usitt::run(a),
        Format::Ma3(a) => ma3::run(a),
    }
}

/// What every export reads: the daemon's saved looks, the scene they were saved on, and
/// the time each stored cue takes.
#[derive(clap::Args)]
struct Saved {
    /// The scene folder the looks were saved on (its channels are the console's).
    #[arg(long)]
    scene: PathBuf,
    /// The daemon's saved looks: its state folder's `looks.json`.
    #[arg(long)]
    looks: PathBuf,
    /// Every cue's time, in seconds.
    #[arg(long, default_value_t = 3.0)]
    time: f32,
}

impl Saved {
    /// The scene and the saved looks (at least one), the time checked.
    fn load(&self) -> anyhow::Result<(Scene, LooksFile)> {
        if !(self.time.is_finite() && (0.0..=3600.0).contains(&self.time)) {
            anyhow::bail!("--time must be 0..=3600 seconds, got {}", self.time);
        }
        let scene = Scene::load(&self.scene).map_err(|e| anyhow::anyhow!("{e}"))?;
        let saved = super::gallery::read_saved_looks(&self.looks)?;
        if saved.looks.is_empty() {
            anyhow::bail!(
                "{}: no saved looks to export (save some with /vo/look/save)",
                self.looks.display()
            );
        }
        Ok((scene, saved))
    }
}

/// Writes `text` to `out` atomically (a temporary file beside it, synced, renamed over it).
fn write(out: &Path, text: &str) -> anyhow::Result<()> {
    visobjd_files::write_atomic(out, text.as_bytes())
        .with_context(|| format!("{}: cannot write", out.display()))
}
