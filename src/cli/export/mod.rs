//! `visobjd export`: the daemon's saved looks written as files a console imports, for a
//! console without a network link to visobjd: USITT ASCII (docs/export.md), a grandMA3
//! plugin (docs/ma3.md).

mod ma3;
mod usitt;

use std::path::Path;

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
    Ascii(usitt::Args),
    /// A grandMA3 plugin (XML and Lua) that stores every saved look as a preset or a cue
    /// when run on the desk.
    Ma3(ma3::Args),
}

/// Runs `export`.
pub fn run(args: Args) -> anyhow::Result<()> {
    match args.format {
        Format::Ascii(a) => usitt::run(a),
        Format::Ma3(a) => ma3::run(a),
    }
}

/// The saved looks of a daemon's `looks.json` (its state folder's) and the scene they are
/// played on.
fn saved_looks(scene: &Path, looks: &Path) -> anyhow::Result<(Scene, LooksFile)> {
    let scene = Scene::load(scene).map_err(|e| anyhow::anyhow!("{e}"))?;
    let saved = super::gallery::read_saved_looks(looks)?;
    if saved.looks.is_empty() {
        anyhow::bail!(
            "{}: no saved looks to export (save some with /vo/look/save)",
            looks.display()
        );
    }
    Ok((scene, saved))
}

/// Writes `text` to `out` atomically (a temporary file beside it, synced, renamed over it).
fn write(out: &Path, text: &str) -> anyhow::Result<()> {
    visobjd_files::write_atomic(out, text.as_bytes())
        .with_context(|| format!("{}: cannot write", out.display()))
}
