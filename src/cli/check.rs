//! `visobjd check`: validates config and scene and prints a one-screen summary a
//! technician can read on a small booth screen.

use std::collections::BTreeMap;
use std::path::PathBuf;

use crate::config::Config;
use visobjd_dmx::Patch;
use visobjd_method::stage::{Stage, THUMB_WIDTH};
use visobjd_scene::Scene;

/// Arguments of `check`.
#[derive(clap::Args)]
pub struct Args {
    /// The config file.
    #[arg(long, default_value = "config/visobjd.toml")]
    config: PathBuf,
}

/// The `refs` line: how many images, and what would keep uploads from working.
fn references(config: &Config) -> String {
    let folder = &config.references;
    let shipped = config.scene.join("refs");
    let mut line = match crate::engine::reference_files(folder) {
        Ok(names) if names.is_empty() => {
            let stocked = crate::engine::reference_files(&shipped).is_ok_and(|n| !n.is_empty());
            if stocked {
                format!(
                    "{} is empty: the daemon copies the scene's {} images there at start",
                    folder.display(),
                    shipped.display()
                )
            } else {
                format!(
                    "{} is empty: objectives need reference images there (copy some in, or upload them on the web page)",
                    folder.display()
                )
            }
        }
        Ok(names) => format!("{} images in {}", names.len(), folder.display()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            format!(
                "{} does not exist yet: the daemon makes it at start",
                folder.display()
            )
        }
        Err(e) => format!("{} is not readable ({e})", folder.display()),
    };
    let probe = folder.join(".visobjd-check");
    if folder.is_dir()
        && let Err(e) = std::fs::write(&probe, b"").and_then(|()| std::fs::remove_file(&probe))
    {
        line += &format!("; not writable ({e}): uploads will fail");
    }
    if !folder.starts_with(&config.state_dir) {
        line += "; outside state_dir: under the booth unit (ProtectSystem=strict) uploads fail \
                 with \"Read-only file system\" (put it under state_dir)";
    }
    line
}

/// Runs `check`: the first problem found is the error; otherwise the summary.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = Config::load(&args.config).map_err(anyhow::Error::msg)?;
    // Every unusable image is listed, not only the first.
    let stage = Stage::from_scene(Scene::load(&config.scene)?, THUMB_WIDTH)?;
    let scene = &stage.scene;
    if !stage.unseen.is_empty() {
        let each: Vec<String> = stage
            .unseen
            .iter()
            .map(|u| {
                let light = &scene.lights[u.light];
                let missing: Vec<String> = light
                    .positions
                    .iter()
                    .filter(|p| !p.basis.is_file())
                    .map(|p| format!("palette {} ({})", p.palette, p.basis.display()))
                    .collect();
                match missing.as_slice() {
                    [] => format!("  light {}: {}", light.channel, u.error),
                    _ => format!(
                        "  light {}: no image for {} (capture shoots them: `visobjd capture`)",
                        light.channel,
                        missing.join(", ")
                    ),
                }
            })
            .collect();
        anyhow::bail!(
            "{} of {} lights have a basis image that cannot be used (the daemon would leave them out of generation):\n{}",
            stage.unseen.len(),
            scene.lights.len(),
            each.join("\n")
        );
    }
    let patch = Patch::new(scene);
    config
        .output
        .validate(patch.universes())
        .map_err(|e| anyhow::anyhow!("{}: {e}", config.path.display()))?;

    let mut profiles: BTreeMap<&str, usize> = BTreeMap::new();
    for l in 0..scene.lights.len() {
        *profiles.entry(scene.profile(l).name.as_str()).or_default() += 1;
    }
    let mut used: BTreeMap<u16, usize> = BTreeMap::new();
    for (l, light) in scene.lights.iter().enumerate() {
        *used.entry(light.universe).or_default() += scene.profile(l).footprint();
    }
    let refs = references(&config);
    let bytes = stage.proxy.bytes() + stage.thumbs.bytes();
    // Colour-mixing lights: previewed from their emitters' own images, or approximated
    // from their white image and their profile's colour model.
    let (mut mixed, mut approximate) = (Vec::new(), Vec::new());
    for (l, light) in scene.lights.iter().enumerate() {
        if !light.emitter_basis.is_empty() {
            mixed.push(light.channel);
        } else if !scene.profile(l).emitters.is_empty() {
            approximate.push(light.channel);
        }
    }
    let out = &config.output;
    let line = |k: &str, v: String| print!("{}", wrap(k, &v));
    line("config", format!("{} ok", config.path.display()));
    line(
        "scene",
        format!("{} ({})", scene.name, config.scene.display()),
    );
    line(
        "lights",
        format!(
            "{} in {} groups, {}",
            scene.lights.len(),
            scene.groups.len(),
            scene.channel_range()
        ),
    );
    line(
        "profiles",
        profiles
            .iter()
            .map(|(p, n)| format!("{p} x{n}"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    line(
        "dmx",
        used.iter()
            .map(|(u, n)| format!("universe {u}: {n}/512 slots"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    line(
        "images",
        format!(
            "{} basis images, all readable; kept at {}x{} and {}x{}",
            stage.thumbs.images - stage.unseen_positions.len(),
            stage.thumbs.width,
            stage.thumbs.height,
            stage.proxy.width,
            stage.proxy.height
        ),
    );
    if !(mixed.is_empty() && approximate.is_empty()) {
        let mut colour = Vec::new();
        if !mixed.is_empty() {
            colour.push(format!(
                "{} previewed from each emitter's image",
                visobjd_rig::channel_list(&mixed)
            ));
        }
        if !approximate.is_empty() {
            colour.push(format!(
                "{} approximate (captured at white only: `capture --emitters` shows their real hues)",
                visobjd_rig::channel_list(&approximate)
            ));
        }
        line("colour", colour.join("; "));
    }
    let movers: Vec<u32> = scene
        .lights
        .iter()
        .filter(|l| l.is_moving())
        .map(|l| l.channel)
        .collect();
    if !movers.is_empty() {
        let palettes: Vec<String> = scene
            .palettes
            .iter()
            .map(|p| {
                format!(
                    "{} on {}",
                    p.describe(),
                    visobjd_rig::channel_list(&channels(scene, &p.lights))
                )
            })
            .collect();
        line(
            "movers",
            format!(
                "{}, {} focus palettes: {}",
                visobjd_rig::channel_list(&movers),
                scene.palettes.len(),
                palettes.join(", ")
            ),
        );
    }
    if !stage.unseen_positions.is_empty() {
        let each: Vec<String> = stage
            .unseen_positions
            .iter()
            .map(|u| {
                let light = &scene.lights[u.light];
                let file = light
                    .positions
                    .iter()
                    .find(|p| p.palette == u.palette)
                    .map_or(String::new(), |p| format!(" ({})", p.basis.display()));
                format!("light {} palette {}{file}", light.channel, u.palette)
            })
            .collect();
        line(
            "missing",
            format!(
                "{} left out of generation until captured (`visobjd capture` shoots them): {}",
                if each.len() == 1 {
                    "a position is"
                } else {
                    "positions are"
                },
                each.join(", ")
            ),
        );
    }
    line(
        "memory",
        format!("about {} MB of basis images", bytes.div_ceil(1 << 20)),
    );
    line("refs", refs);
    line(
        "osc",
        format!(
            "udp {}, tcp {}, allow {}",
            or_off(&config.osc.udp),
            or_off(&config.osc.tcp),
            if config.osc.allow.is_empty() {
                "loopback only".to_string()
            } else {
                config.osc.allow.join(" ")
            }
        ),
    );
    line(
        "http",
        if config.http.listen.is_empty() {
            "off".to_string()
        } else {
            format!(
                "web gallery on http://{}/ (same allow-list)",
                config.http.listen
            )
        },
    );
    line(
        "eos",
        match config.eos.target() {
            Ok(Some(addr)) => format!(
                "presets to {addr} over {} as user {}",
                match config.eos.protocol {
                    crate::eos::Protocol::Udp => "udp",
                    crate::eos::Protocol::Tcp => "tcp (OSC 1.0)",
                    crate::eos::Protocol::TcpSlip => "tcp-slip (OSC 1.1)",
                },
                config.eos.user
            ),
            _ => "off".to_string(),
        },
    );
    line(
        "input",
        match &config.input.sacn {
            Some(sacn) => {
                let missing: Vec<String> = patch
                    .universes()
                    .iter()
                    .filter(|u| !sacn.universes.contains(u))
                    .map(u16::to_string)
                    .collect();
                format!(
                    "console sACN on {}{}, universes {:?}{}",
                    sacn.bind,
                    if sacn.interface.is_empty() {
                        String::new()
                    } else {
                        format!(" (multicast on {})", sacn.interface)
                    },
                    sacn.universes,
                    if missing.is_empty() {
                        String::new()
                    } else {
                        format!(
                            ", scene universes {} not received (they grab dark)",
                            missing.join(" ")
                        )
                    }
                )
            }
            None => "off".to_string(),
        },
    );
    line(
        "output",
        format!(
            "{} sACN and {} Art-Net destinations at {} Hz, fade {} s",
            out.sacn.len(),
            out.artnet.len(),
            out.rate_hz,
            out.fade_s
        ),
    );
    let list = |numbers: Vec<u16>| {
        numbers
            .iter()
            .map(u16::to_string)
            .collect::<Vec<_>>()
            .join(" ")
    };
    let universes = || list(patch.universes().to_vec());
    for d in &out.sacn {
        let to = if d.destination == "multicast" {
            "multicast (239.255.hi.lo per universe)".to_string()
        } else {
            d.destination.clone()
        };
        line(
            "sacn",
            format!(
                "to {to} port {}, universes {}, priority {}, from {}",
                d.port,
                universes(),
                d.priority,
                d.bind
            ),
        );
    }
    for d in &out.artnet {
        line(
            "artnet",
            format!(
                "to {}{} port {}, universes {} as port-addresses {}, from {}",
                d.destination,
                if d.discover {
                    " (nodes that answer its polls)"
                } else {
                    ""
                },
                d.port,
                universes(),
                list(
                    patch
                        .universes()
                        .iter()
                        .filter_map(|&u| d.port_address(u))
                        .collect()
                ),
                d.bind
            ),
        );
    }
    if !config.http.listen.is_empty() && config.http.password.is_empty() {
        let loopback = config
            .http
            .listen
            .parse::<std::net::SocketAddr>()
            .is_ok_and(|a| a.ip().is_loopback());
        if !loopback {
            line(
                "warning",
                format!(
                    "the web page on {} has no password: anyone on the allow-listed networks can change the stage (set [http] password)",
                    config.http.listen
                ),
            );
        }
    }
    Ok(())
}

/// The channels of lights `lights` (indices into the scene's lights).
fn channels(scene: &Scene, lights: &[usize]) -> Vec<u32> {
    lights.iter().map(|&l| scene.lights[l].channel).collect()
}

/// Width of a booth screen's terminal: lines are kept shorter.
const COLUMNS: usize = 80;

/// `key` in a 9-column margin, then `value` wrapped at `, ` (then spaces) so no line
/// reaches [`COLUMNS`]; a single word longer than that (a path) stays whole.
fn wrap(key: &str, value: &str) -> String {
    let width = COLUMNS - 1 - 9;
    let mut lines: Vec<String> = vec![String::new()];
    let pieces = value.split_inclusive(", ").flat_map(|p| {
        if p.len() > width {
            p.split_inclusive(' ').collect::<Vec<_>>()
        } else {
            vec![p]
        }
    });
    for piece in pieces {
        let last = lines.last_mut().expect("one line at least");
        if !last.is_empty() && last.trim_end().len() + piece.trim_end().len() > width {
            lines.push(piece.to_string());
        } else {
            last.push_str(piece);
        }
    }
    let mut out = String::new();
    for (i, l) in lines.iter().enumerate() {
        let k = if i == 0 { key } else { "" };
        out.push_str(&format!("{k:<9}{}\n", l.trim_end()));
    }
    out
}

fn or_off(addr: &str) -> &str {
    if addr.is_empty() { "off" } else { addr }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_values_wrap_under_eighty_columns() {
        let v = (1..=12)
            .map(|u| format!("universe {u}: 120/512 slots"))
            .collect::<Vec<_>>()
            .join(", ");
        let text = wrap("dmx", &v);
        assert!(text.lines().count() > 3, "{text}");
        assert!(text.lines().all(|l| l.len() < COLUMNS), "{text}");
        assert!(
            text.starts_with("dmx      universe 1: 120/512 slots, "),
            "{text}"
        );
        assert!(
            text.lines().skip(1).all(|l| l.starts_with("         u")),
            "{text}"
        );
        // Nothing lost or reordered.
        let joined: String = text.lines().map(|l| &l[9..]).collect::<Vec<_>>().join(" ");
        assert_eq!(joined, v);
        assert_eq!(wrap("osc", "udp off"), "osc      udp off\n");
    }
}
