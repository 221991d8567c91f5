//! `visobjd touchosc`: writes the booth tablet's TouchOSC layout (src/touchosc.rs), so the
//! shipped `touchosc/visobjd.tosc` is regenerated, not hand-edited, when addresses change.

use std::path::PathBuf;

use anyhow::Context;

/// Arguments of `touchosc`.
#[derive(clap::Args)]
pub struct Args {
    /// The references folder whose images get a button on the objectives page.
    #[arg(long, default_value = "scenes/demo/refs")]
    refs: PathBuf,
    /// The .tosc file to write.
    #[arg(long)]
    out: PathBuf,
}

/// Writes the layout and says what it holds.
pub fn run(args: Args) -> anyhow::Result<()> {
    let refs = crate::touchosc::reference_images(&args.refs)
        .with_context(|| format!("--refs {}: cannot list it", args.refs.display()))?;
    let bytes = crate::touchosc::layout_tosc(&refs).context("cannot compress the layout")?;
    std::fs::write(&args.out, bytes)
        .with_context(|| format!("--out {}: cannot write it", args.out.display()))?;
    let shown = refs.len().min(crate::touchosc::MAX_REFERENCES);
    println!(
        "touchosc: {} reference buttons, {} entries, {} look slots -> {}",
        shown,
        crate::touchosc::ENTRY_BUTTONS,
        crate::touchosc::LOOK_SLOTS,
        args.out.display()
    );
    Ok(())
}
