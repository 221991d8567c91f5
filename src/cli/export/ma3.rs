//! `visobjd export ma3`: the saved looks as a grandMA3 plugin (the XML and Lua pair MA3
//! imports into its plugin pool) that stores them as presets or cues when run on the desk,
//! with or without a network link (docs/ma3.md). The Lua calls MA3's `Cmd` once per
//! command, the same commands `/vo/ma3/preset` and `/vo/ma3/cue` send over OSC.

use std::path::PathBuf;

use crate::ma3::commands::{Target, store_commands};

/// Arguments of `export ma3`.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    saved: super::Saved,
    /// The folder to write the plugin's two files into.
    #[arg(long)]
    out: PathBuf,
    /// Store the looks as presets from this one on (POOL.NUMBER, e.g. 21.1).
    #[arg(long, conflicts_with = "sequence")]
    preset: Option<String>,
    /// Store the looks as cues of this sequence (from --first on).
    #[arg(long)]
    sequence: Option<u32>,
    /// The first cue's number, with --sequence.
    #[arg(long, default_value_t = 1)]
    first: u32,
    /// The plugin's name and its files' (NAME.xml, NAME.lua).
    #[arg(long, default_value = "visobjd_looks")]
    name: String,
}

/// Runs `export ma3`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.name.is_empty()
        || !args
            .name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        anyhow::bail!(
            "--name must be letters, digits, '_' or '-' (it names the plugin's files), got `{}`",
            args.name
        );
    }
    let first = match (&args.preset, args.sequence) {
        (Some(p), None) => Target::preset(p).map_err(anyhow::Error::msg)?,
        (None, Some(sequence)) if (1..=9999).contains(&sequence) && args.first >= 1 => {
            Target::Cue {
                sequence,
                cue: args.first,
            }
        }
        (None, Some(_)) => anyhow::bail!("--sequence and --first must be 1..=9999"),
        _ => anyhow::bail!("say where the looks go: --preset POOL.NUMBER or --sequence N"),
    };
    let (scene, saved) = args.saved.load()?;
    let mut commands = Vec::new();
    for (i, (n, file)) in saved.looks.iter().enumerate() {
        let (look, refused) = file.fit(&scene);
        for why in refused {
            eprintln!("warning: saved look {n}: {why}; left out");
        }
        let target = first.next(i as u32);
        commands.push(format!("-- saved look {n}: {target}"));
        commands.extend(
            store_commands(&scene, &look, target, Some(&file.label), args.saved.time)
                .into_iter()
                .map(|c| format!("Cmd({})", lua_string(&c))),
        );
    }
    std::fs::create_dir_all(&args.out)
        .map_err(|e| anyhow::anyhow!("{}: cannot create it: {e}", args.out.display()))?;
    let lua = format!(
        "-- Written by visobjd: {} saved looks of scene `{}`, stored from {first} on.\n\
         -- Import {name}.xml into the desk's plugin pool and run it.\n\
         local function main()\n{}\nend\n\nreturn main\n",
        saved.looks.len(),
        scene.name.replace('\n', " "),
        commands
            .iter()
            .map(|c| format!("  {c}"))
            .collect::<Vec<_>>()
            .join("\n"),
        name = args.name
    );
    let xml = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n\
         <GMA3 DataVersion=\"2.0.0.0\">\n\
         \t<UserPlugin Name=\"{name}\" Version=\"1.0.0.0\">\n\
         \t\t<ComponentLua Name=\"{name}\" FileName=\"{name}.lua\"/>\n\
         \t</UserPlugin>\n\
         </GMA3>\n",
        name = args.name
    );
    let lua_path = args.out.join(format!("{}.lua", args.name));
    let xml_path = args.out.join(format!("{}.xml", args.name));
    super::write(&lua_path, &lua)?;
    super::write(&xml_path, &xml)?;
    println!(
        "{}, {}: {} looks stored from {first} on when run on the desk",
        xml_path.display(),
        lua_path.display(),
        saved.looks.len()
    );
    Ok(())
}

/// `s` as a Lua string literal.
fn lua_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('\'');
    for c in s.chars() {
        match c {
            '\\' => out += "\\\\",
            '\'' => out += "\\'",
            '\n' => out += "\\n",
            c => out.push(c),
        }
    }
    out.push('\'');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lua_strings_are_escaped() {
        assert_eq!(lua_string(r#"Label "It's""#), r#"'Label "It\'s"'"#);
        assert_eq!(lua_string("a\\b"), "'a\\\\b'");
    }
}
