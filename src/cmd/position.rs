//! Focus palettes of the scene: `/vo/position/learn n [name]` records palette n from
//! where the console aims the moving lights (`[input.sacn]`), written into scene.toml and
//! running once the scene reloads; `/vo/positions` lists the palettes (docs/osc.md).

use std::path::Path;
use std::sync::Mutex;

use rosc::OscMessage;

use super::{Context, int, int_arg, text};
use crate::engine::session::MAX_LABEL;
use crate::engine::{Refusal, msg};
use crate::osc::args::{self, Request};
use visobjd_scene::{MAX_PALETTE, PositionFile, Scene, SceneFile};

pub enum Cmd {
    /// Palette `palette` of every moving light the console aims, named `name` (else its
    /// existing name).
    Learn {
        palette: u32,
        name: Option<String>,
    },
    List,
}

/// One learn's read, change and write of scene.toml at a time: two at once would each
/// write the file without the other's palette.
static WRITING: Mutex<()> = Mutex::new(());

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        Ok(Some(if req.matches("/vo/position/learn").is_some() {
            let palette = int_arg(req, 0, "focus palette", 1, i64::from(MAX_PALETTE))? as u32;
            let name = match req.arg(1) {
                Some(a) => Some(palette_name(args::string(a, "palette name")?)?),
                None => None,
            };
            Cmd::Learn { palette, name }
        } else if req.matches("/vo/positions").is_some() {
            Cmd::List
        } else {
            return Ok(None);
        }))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        match self {
            Cmd::List => Ok(list(&cx.engine.stage().scene)),
            Cmd::Learn { palette, name } => {
                cx.engine.scene_loaded()?;
                let aims = cx.engine.console_aims()?;
                let stage = cx.engine.stage();
                let scene = &stage.scene;
                let learned: Vec<(u32, [f64; 2])> = scene
                    .lights
                    .iter()
                    .zip(&aims)
                    .filter(|(l, _)| l.is_moving())
                    .filter_map(|(l, aim)| Some((l.channel, (*aim)?)))
                    .collect();
                if learned.is_empty() {
                    return Err(Refusal::conflict(format!(
                        "no moving light is patched on a universe a console source is sending \
                         now: palette {palette} was not learned"
                    )));
                }
                let name = name.or_else(|| scene.palette(palette).and_then(|p| p.name.clone()));
                {
                    let _one = WRITING.lock().unwrap_or_else(|p| p.into_inner());
                    learn(
                        &cx.engine.config().scene,
                        palette,
                        name.as_deref(),
                        &learned,
                    )?;
                }
                let lights = learned.len();
                // Answered once the scene with the new palette runs.
                cx.engine.reload_then(cx.later(), move |_| {
                    vec![msg(
                        "/vo/position/learned",
                        vec![
                            int(palette as usize),
                            int(lights),
                            text(name.as_deref().unwrap_or("")),
                        ],
                    )]
                })?;
                Ok(Vec::new())
            }
        }
    }
}

/// A palette's name, refused past [`MAX_LABEL`] characters or blank.
fn palette_name(text: &str) -> Result<String, String> {
    let n = text.chars().count();
    if n > MAX_LABEL {
        return Err(format!(
            "a palette name is at most {MAX_LABEL} characters, got {n}"
        ));
    }
    if text.trim().is_empty() {
        return Err("a palette name is not blank (leave it out to keep the palette's name)".into());
    }
    Ok(text.trim().to_string())
}

/// The image a learned position is captured into, relative to the scene folder: named as
/// `visobjd synth` names a position's (`basis/045-fp03.exr`).
fn basis_of(channel: u32, palette: u32) -> String {
    format!("basis/{channel:03}-fp{palette:02}.exr")
}

/// Writes palette `palette` (`name`) into `dir/scene.toml`: for each learned light
/// (channel, [pan, tilt] in degrees) its position replaced or added, its basis
/// [`basis_of`]; a name given renames the palette on every light that has it (a palette
/// has one name). Checked as a scene before the atomic write.
fn learn(
    dir: &Path,
    palette: u32,
    name: Option<&str>,
    learned: &[(u32, [f64; 2])],
) -> Result<(), Refusal> {
    let path = dir.join("scene.toml");
    let fail = |e: String| {
        Refusal::conflict(format!(
            "{}: {e}: palette {palette} was not learned",
            path.display()
        ))
    };
    let read = std::fs::read_to_string(&path).map_err(|e| fail(e.to_string()))?;
    let mut file = SceneFile::parse(&path, &read).map_err(|e| fail(e.to_string()))?;
    for &(channel, [pan, tilt]) in learned {
        let Some(light) = file.light.iter_mut().find(|l| l.channel == channel) else {
            return Err(fail(format!("light {channel} is no longer in it")));
        };
        let position = PositionFile {
            palette,
            name: name.map(str::to_string),
            pan: thousandths(pan),
            tilt: thousandths(tilt),
            basis: basis_of(channel, palette),
        };
        match light.positions.iter_mut().find(|p| p.palette == palette) {
            Some(p) => *p = position,
            None => light.positions.push(position),
        }
    }
    if let Some(name) = name {
        file.name_palette(palette, name);
    }
    let written = file.to_toml().map_err(fail)?;
    Scene::parse(dir, &written).map_err(|e| fail(e.to_string()))?;
    visobjd_files::write_atomic(&path, written.as_bytes()).map_err(|e| fail(e.to_string()))
}

/// Degrees to a thousandth, as scene.toml reads best: a 16-bit step of a 540-degree pan
/// is 0.008 degrees, so nothing the wire can tell apart is lost.
fn thousandths(degrees: f64) -> f64 {
    (degrees * 1000.0).round() / 1000.0
}

/// One `/vo/position n:i name:s ch:i ...` per palette (name `""` when it has none; the
/// channels of the lights that have it), then `/vo/positions/end count:i`.
fn list(scene: &Scene) -> Vec<OscMessage> {
    let mut out: Vec<OscMessage> = scene
        .palettes
        .iter()
        .map(|p| {
            let mut a = vec![
                int(p.number as usize),
                text(p.name.as_deref().unwrap_or("")),
            ];
            a.extend(
                p.lights
                    .iter()
                    .map(|&l| int(scene.lights[l].channel as usize)),
            );
            msg("/vo/position", a)
        })
        .collect();
    out.push(msg("/vo/positions/end", vec![int(scene.palettes.len())]));
    out
}
