//! `visobjd export usitt`: the saved looks as a USITT ASCII show file ("ASCII Text
//! Representation for Lighting Console Data", version 3.0, 1992), which Eos, Ion,
//! Element, Strand and many other consoles import:
//!
//! ```text
//! Ident 3:0
//! Manufacturer visobjd
//! Console visobjd
//! Cue 1
//! Text Act 2 dusk
//! Up 3
//! Down 3
//! Chan 1/62 2/FL 5/9 12/40
//! EndData
//! ```
//!
//! One cue per saved look in look-number order, numbered from `--first`, with the look's
//! label as its text, `--time` as its up and down time, and each lit channel's intensity
//! in whole percent (`FL` at full). The format carries intensities only: colour,
//! position and the rest have no standard record (docs/export.md).

use std::path::PathBuf;

use visobjd_scene::Scene;
use visobjd_scene::look::Look;

/// The longest line the standard allows.
const LINE: usize = 80;

/// Arguments of `export usitt`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    saved: super::Saved,
    /// The file to write.
    #[arg(long)]
    out: PathBuf,
    /// The first cue's number; the next looks take the next whole numbers.
    #[arg(long, default_value_t = 1)]
    first: u32,
}

/// Runs `export usitt`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.first == 0 || args.first > 9999 {
        anyhow::bail!("--first must be a cue number 1..=9999, got {}", args.first);
    }
    let (scene, saved) = args.saved.load()?;
    let mut cues = Vec::with_capacity(saved.looks.len());
    for (i, (n, file)) in saved.looks.iter().enumerate() {
        let (look, refused) = file.fit(&scene);
        for why in refused {
            eprintln!("warning: saved look {n}: {why}; left out of its cue");
        }
        cues.push((args.first + i as u32, file.label.clone(), look));
    }
    let text = show(&scene, &cues, args.saved.time);
    super::write(&args.out, &text)?;
    println!(
        "{}: {} cues ({} to {}) of scene `{}`, intensities only",
        args.out.display(),
        cues.len(),
        args.first,
        args.first as usize + cues.len() - 1,
        scene.name
    );
    Ok(())
}

/// The show file: one cue per `(number, label, look)`.
fn show(scene: &Scene, cues: &[(u32, String, Look)], time_s: f32) -> String {
    let mut out = format!(
        "! Written by visobjd: {} saved looks as cues, intensities only\n! Scene: {}\n\
         Ident 3:0\nManufacturer visobjd\nConsole visobjd\n",
        cues.len(),
        text(&scene.name, LINE - "! Scene: ".len())
    );
    let time = seconds(time_s);
    for (number, label, look) in cues {
        out += &format!("Cue {number}\n");
        let label = text(label, LINE - "Text ".len());
        if !label.is_empty() {
            out += &format!("Text {label}\n");
        }
        out += &format!("Up {time}\nDown {time}\n");
        let levels: Vec<String> = scene
            .lights
            .iter()
            .zip(&look.levels)
            .filter_map(|(light, level)| {
                let percent = (level.intensity.clamp(0.0, 1.0) * 100.0).round() as u32;
                (percent > 0).then(|| match percent {
                    100 => format!("{}/FL", light.channel),
                    p => format!("{}/{p}", light.channel),
                })
            })
            .collect();
        let mut line = String::from("Chan");
        for pair in levels {
            if line.len() + 1 + pair.len() > LINE {
                out += &line;
                out.push('\n');
                line = String::from("Chan");
            }
            line.push(' ');
            line += &pair;
        }
        if line.len() > "Chan".len() {
            out += &line;
            out.push('\n');
        }
    }
    out += "EndData\n";
    out
}

/// Text as the format takes it: printable ASCII (others become `?`), no `!` (it starts
/// a comment), at most `max` characters.
fn text(s: &str, max: usize) -> String {
    s.chars()
        .map(|c| match c {
            '!' => '.',
            c if c.is_ascii_graphic() || c == ' ' => c,
            _ => '?',
        })
        .take(max)
        .collect::<String>()
        .trim()
        .to_string()
}

/// Seconds with at most one decimal, no trailing zeros.
fn seconds(t: f32) -> String {
    let s = format!("{t:.1}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_printable_ascii_without_comments() {
        assert_eq!(text("Dusk! über", 80), "Dusk. ?ber");
        assert_eq!(text(&"x".repeat(100), 75).len(), 75);
        assert_eq!(seconds(2.5), "2.5");
        assert_eq!(seconds(3.0), "3");
    }
}
