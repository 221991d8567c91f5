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
    /// The scene folder whose groups get the constraints and transfer rows (and, with
    /// moving lights, the positions page's).
    #[arg(long, default_value = "scenes/demo")]
    scene: PathBuf,
    /// The .tosc file to write.
    #[arg(long)]
    out: PathBuf,
}

/// Writes the layout and says what it holds.
pub fn run(args: Args) -> anyhow::Result<()> {
    let refs = crate::touchosc::reference_images(&args.refs)
        .with_context(|| format!("--refs {}: cannot list it", args.refs.display()))?;
    let scene = visobjd_scene::Scene::load(&args.scene)
        .with_context(|| format!("--scene {}: cannot load it", args.scene.display()))?;
    let groups: Vec<String> = scene.groups.iter().map(|g| g.name.clone()).collect();
    let palettes = crate::touchosc::palette_rows(&scene);
    let bytes = crate::touchosc::layout_tosc(&refs, &groups, &palettes)
        .context("cannot compress the layout")?;
    std::fs::write(&args.out, bytes)
        .with_context(|| format!("--out {}: cannot write it", args.out.display()))?;
    let shown = refs.len().min(crate::touchosc::MAX_REFERENCES);
    println!(
        "touchosc: {} reference buttons, {} groups, {} entries, {} look slots, {} groups of moving lights -> {}",
        shown,
        groups.len().min(crate::touchosc::MAX_GROUPS),
        crate::touchosc::ENTRY_BUTTONS,
        crate::touchosc::LOOK_SLOTS,
        palettes.len().min(crate::touchosc::MAX_GROUPS),
        args.out.display()
    );
    left_off(
        "references",
        "objectives",
        &refs,
        crate::touchosc::MAX_REFERENCES,
    );
    left_off(
        "groups",
        "constraints and transfer",
        &groups,
        crate::touchosc::MAX_GROUPS,
    );
    let moving: Vec<String> = palettes.iter().map(|r| r.group.clone()).collect();
    left_off(
        "groups of moving lights",
        "positions",
        &moving,
        crate::touchosc::MAX_GROUPS,
    );
    for row in &palettes {
        let numbers: Vec<String> = row.palettes.iter().map(|p| p.0.to_string()).collect();
        left_off(
            &format!("palettes of group `{}`", row.group),
            "positions",
            &numbers,
            crate::touchosc::MAX_PALETTES,
        );
    }
    Ok(())
}

/// Names what a page has no room for (the first `room` of `all` get a control), so a
/// technician knows which ones the tablet cannot reach: a console macro or `visobjd send`
/// still can.
fn left_off(what: &str, page: &str, all: &[String], room: usize) {
    if let Some(rest) = all.get(room..).filter(|r| !r.is_empty()) {
        tracing::warn!(
            "touchosc: the {page} page has room for {room} {what}; left off: {} (reach them with /vo/... from a console or visobjd send, or keep fewer)",
            rest.join(", ")
        );
    }
}
