//! `visobjd render`: one look file to a PNG.

use std::path::PathBuf;

use anyhow::Context;

use visobjd_method::stage::Stage;

/// Arguments of `render`.
#[derive(clap::Args)]
pub struct Args {
    /// The scene folder.
    #[arg(long)]
    scene: PathBuf,
    /// The look file (JSON, as the daemon saves looks), or `STATE/looks.json#N` for the
    /// daemon's saved look N.
    #[arg(long)]
    look: PathBuf,
    /// The PNG to write.
    #[arg(long)]
    out: PathBuf,
    /// Width in pixels (default: the basis images' full width; never upscaled).
    #[arg(long, default_value_t = 0)]
    width: usize,
}

/// Runs `render`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let stage = Stage::load(&args.scene, args.width)?;
    let look = super::gallery::read_look(&args.look, &stage)?;
    let img = stage
        .thumbnails(&[&look])
        .pop()
        .context("nothing was rendered")?;
    img.save_with_format(&args.out, image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot write", args.out.display()))?;
    println!(
        "render: {}x{} -> {}",
        img.width(),
        img.height(),
        args.out.display()
    );
    Ok(())
}
