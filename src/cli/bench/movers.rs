//! The moving-light row: a generate on a rig whose movers hold many focus palettes against
//! the same rig with each mover holding one, in one run (issue 31: the compositor's cost
//! follows the lights lit, not the palettes held).

use std::path::Path;

use anyhow::Context;
use rayon::prelude::*;

use super::{Row, generate_once, median, spot_image};
use visobjd_method::objective::Objective;
use visobjd_method::stage::{Stage, THUMB_WIDTH};

/// Fixed lights, movers, palettes per mover, and the image size of the row's rigs.
const RIG: (usize, usize, u32, usize, usize) = (44, 12, 8, 480, 270);

/// The row: the median of `runs` generates (100 candidates into 12 entries, thumbnails)
/// with every mover holding [`RIG`]'s palettes, over the median with each holding one,
/// taken in turns so a busy spell of the host slows both alike. The rigs are written
/// under `dir` and removed.
pub(super) fn row(dir: &Path, objective: &Objective, runs: usize) -> anyhow::Result<Row> {
    let (fixed, movers, palettes, ..) = RIG;
    let many = dir.join("movers-many");
    let one = dir.join("movers-one");
    write_rig(&many, palettes)?;
    write_rig(&one, 1)?;
    let stages = [&many, &one].map(|d| {
        Stage::load(d, THUMB_WIDTH).with_context(|| format!("{}: cannot load", d.display()))
    });
    let [many_stage, one_stage] = stages;
    let (many_stage, one_stage) = (many_stage?, one_stage?);
    generate_once(&many_stage, objective, 999); // warm-up
    generate_once(&one_stage, objective, 999);
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for seed in 1..=runs as u64 {
        a.push(generate_once(&many_stage, objective, seed));
        b.push(generate_once(&one_stage, objective, seed));
    }
    let (a, b) = (median(&mut a), median(&mut b));
    let _ = std::fs::remove_dir_all(&many);
    let _ = std::fs::remove_dir_all(&one);
    Ok(Row {
        name: format!(
            "/vo/generate, {movers} movers x {palettes} palettes over x 1 (+{fixed} fixed, {b:.0} ms)"
        ),
        value: a,
        unit: "ms",
        ratio: a / b,
        target: Some(1.25),
        more: false,
        note: String::new(),
    })
}

/// Writes a rig of [`RIG`]'s fixed lights and movers, each mover holding `palettes`
/// positions (the first `palettes` of the same images whatever the count).
fn write_rig(dir: &Path, palettes: u32) -> anyhow::Result<()> {
    let (fixed, movers, _, w, h) = RIG;
    std::fs::create_dir_all(dir.join("basis"))?;
    let mut toml = String::from(
        "name = \"bench, movers\"\n[[profile]]\nname = \"spot\"\n\
         channels = [\"intensity\", \"red\", \"green\", \"blue\", \"pan16\", \"tilt16\"]\n",
    );
    let mut images = Vec::new();
    for i in 0..fixed {
        let basis = format!("basis/{:03}.exr", i + 1);
        toml += &format!(
            "[[light]]\nchannel = {}\nbasis = \"{basis}\"\nprofile = \"irgb\"\nuniverse = 1\naddress = {}\n",
            i + 1,
            i * 4 + 1
        );
        images.push((basis, i as u64));
    }
    for m in 0..movers {
        let ch = 101 + m;
        toml += &format!(
            "[[light]]\nchannel = {ch}\nprofile = \"spot\"\nuniverse = 2\naddress = {}\n",
            m * 8 + 1
        );
        for n in 1..=palettes {
            let basis = format!("basis/{ch}-fp{n}.exr");
            toml += &format!(
                "[[light.position]]\npalette = {n}\npan = {}\ntilt = 30.0\nbasis = \"{basis}\"\n",
                f64::from(n) * 20.0 - 90.0
            );
            images.push((basis, 1000 + (m as u64) * 100 + u64::from(n)));
        }
    }
    std::fs::write(dir.join("scene.toml"), toml)?;
    images
        .par_iter()
        .try_for_each(|(basis, seed)| spot_image(&dir.join(basis), w, h, *seed))
}
