//! What the page shows (`GET /state.json`), as JSON built section by section from the
//! session and the engine's view of it. The session is held only to build it (no I/O).

use std::hash::{Hash, Hasher};
use std::sync::Arc;

use axum::extract::State;
use axum::response::{IntoResponse, Response};
use serde_json::{Value, json};

use super::Shared;
use crate::engine::Engine;
use crate::engine::rules::Exclude;
use crate::engine::session::Session;
use visobjd_method::constrain::Saturation;
use visobjd_scene::look::Look;
use visobjd_scene::{Palette, Scene};

pub(super) async fn state_json(State(sh): State<Arc<Shared>>) -> Response {
    axum::Json(state(&sh.engine)).into_response()
}

/// A short hash of a look, so the page fetches a picture again only when it changed (a
/// mover's position changes the picture as its intensity does).
pub(super) fn look_key(look: &Look) -> String {
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for l in &look.levels {
        l.intensity.to_bits().hash(&mut hasher);
        l.color.map(f32::to_bits).hash(&mut hasher);
        l.position.hash(&mut hasher);
    }
    format!("{:016x}", hasher.finish())
}

/// The whole page state: the session, the stage, the rig and its rules.
fn state(e: &Engine) -> Value {
    let s = e.session();
    let stage = e.stage();
    let scene = &stage.scene;
    let (undo, redo, _) = s.history();
    let entry = s.entry.unwrap_or((0, 0));
    json!({
        "scene": scene.name,
        "aspect": stage.thumbs.width as f32 / stage.thumbs.height.max(1) as f32,
        "status": e.status_text(&s),
        "output": output(e),
        "console": console(e),
        "generating": e.is_generating(),
        "gallery": s.gallery.as_ref().map(|g| json!({
            "serial": g.serial,
            "seed": g.seed,
            "sizes": g.generation.entries.iter().map(Vec::len).collect::<Vec<_>>(),
        })),
        "entry": entry.0,
        "member": entry.1,
        "live": look_key(&s.live),
        "fade": s.fade_s,
        "master": s.master,
        "blackout": s.blackout,
        "history": {
            "undo": undo.iter().rev().map(look_key).collect::<Vec<_>>(),
            "redo": redo.iter().rev().map(look_key).collect::<Vec<_>>(),
        },
        "looks": s.looks.iter().map(|(n, f)| json!({
            "n": n,
            "label": f.label,
            "key": f.to_look(scene).map(|l| look_key(&l)).unwrap_or_default(),
        })).collect::<Vec<_>>(),
        "lights": lights(scene, &s),
        "groups": groups(scene, &s),
        "pins": pins(scene, &s),
        "objectives": objectives(e, &s),
    })
}

/// Every light: its live level and colour, lock and constraints; a moving light also its
/// focus palettes (in its order) and the one it is in live, so the page offers them and
/// follows a change made elsewhere.
fn lights(scene: &Scene, s: &Session) -> Vec<Value> {
    let rules = &s.rules;
    scene
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let lv = s.live.levels[i];
            let mut light = json!({
                "ch": l.channel,
                "name": l.name,
                "group": scene.groups[l.group].name,
                "colour": scene.profile(i).has_colour(),
                "intensity": lv.intensity,
                "color": lv.color,
                "lock": s.locked_lights[i],
            });
            if let Some(at) = l.position_of(&lv) {
                let offered: Vec<&Palette> = l
                    .positions
                    .iter()
                    .filter_map(|p| scene.palette(p.palette))
                    .collect();
                add_palettes(&mut light, &offered, Some(at.palette));
            }
            add_rules(
                &mut light,
                None,
                rules.light_saturation[i],
                rules.light_exclude[i],
            );
            light
        })
        .collect()
}

/// Every group: its lights, mean live intensity, key, lock and constraints; with moving
/// lights also the palettes they all have (`palettes`) and the one they are all in live
/// (`position`, null when they differ).
fn groups(scene: &Scene, s: &Session) -> Vec<Value> {
    let rules = &s.rules;
    scene
        .groups
        .iter()
        .enumerate()
        .map(|(g, group)| {
            let n = group.lights.len().max(1) as f32;
            let mut row = json!({
                "name": group.name,
                "address": group.address(),
                "lights": group.lights.iter().map(|&l| scene.lights[l].channel).collect::<Vec<_>>(),
                "intensity": group.lights.iter().map(|&l| s.live.levels[l].intensity).sum::<f32>() / n,
                "key": s.key_groups[g],
                "lock": s.locked_groups[g],
                "colour": group.lights.iter().any(|&l| scene.profile(l).has_colour()),
            });
            let shared = scene.shared_palettes(&group.lights);
            if !shared.is_empty() {
                // The palette its movers are all in, if they are in one.
                let mut at = group
                    .lights
                    .iter()
                    .filter_map(|&l| scene.lights[l].position_of(&s.live.levels[l]))
                    .map(|p| p.palette);
                let first = at.next();
                let one = first.filter(|&n| at.all(|m| m == n));
                add_palettes(&mut row, &shared, one);
            }
            let ratio = rules.ratios[g].map(|(a, r)| (scene.groups[a].name.as_str(), r));
            add_rules(
                &mut row,
                ratio,
                rules.group_saturation[g],
                rules.group_exclude[g],
            );
            row
        })
        .collect()
}

/// Every pin: its region and the channels it holds.
fn pins(scene: &Scene, s: &Session) -> Vec<Value> {
    s.rules
        .pins
        .iter()
        .map(|p| {
            let r = p.region;
            json!({
                "id": p.id,
                "region": [r.x0, r.y0, r.x1, r.y1],
                "lights": p.lights.iter().map(|&l| scene.lights[l].channel).collect::<Vec<_>>(),
            })
        })
        .collect()
}

/// Every objective: its image, aspects, region, palette and the channels its region selects.
fn objectives(e: &Engine, s: &Session) -> Vec<Value> {
    let stage = e.stage();
    let scene = &stage.scene;
    s.objectives
        .iter()
        .map(|o| {
            let r = o.objective.region;
            let chosen = stage.footprints.select(r);
            json!({
                "id": o.id,
                "image": o.objective.image,
                "aspects": o.objective.aspects.name(),
                "region": [r.x0, r.y0, r.x1, r.y1],
                "palette": o.objective.analysis.palette.iter().map(|p| {
                    json!([p.color[0], p.color[1], p.color[2], p.weight])
                }).collect::<Vec<_>>(),
                "selected": scene.lights.iter().zip(&chosen)
                    .filter(|(_, on)| **on).map(|(l, _)| l.channel).collect::<Vec<_>>(),
            })
        })
        .collect()
}

/// The DMX output's health (null once it stopped).
fn output(e: &Engine) -> Option<Value> {
    e.output_stats().map(|h| {
        json!({
            "fps": h.tick_rate,
            "late": h.late_ticks,
            "send_errors": h.send_errors,
            "destinations": h.destinations.iter().map(|(name, errors)| json!({
                "name": name,
                "send_errors": errors,
            })).collect::<Vec<_>>(),
        })
    })
}

/// The console's sACN sources (null without `[input.sacn]`).
fn console(e: &Engine) -> Option<Vec<Value>> {
    e.console_sources().map(|sources| {
        sources
            .iter()
            .map(|s| {
                json!({
                    "name": s.name,
                    "priority": s.priority,
                    "universes": s.universes,
                    "age_s": s.age.as_secs_f32(),
                    "sampling": !s.active,
                })
            })
            .collect()
    })
}

/// A setting as the designer typed it: the shortest decimal that reads back as the same
/// f32 (0.2, not 0.20000000298023224), so the page's number fields show it as typed.
fn decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}

/// Adds the focus palettes a light or a group offers (`palettes`: `[number, name or
/// null]`) and the one it is in (`position`) to its row.
fn add_palettes(row: &mut Value, offered: &[&Palette], at: Option<u32>) {
    if let Some(row) = row.as_object_mut() {
        row.insert(
            "palettes".into(),
            offered.iter().map(|p| json!([p.number, p.name])).collect(),
        );
        row.insert("position".into(), json!(at));
    }
}

/// Adds a group's or a light's constraints to its row, each only when set (a scene of
/// hundreds of lights with none set adds nothing): `ratio` `[of, r]`, `saturation`
/// `[min, max]`, `exclude` (`ignore` or `off`).
fn add_rules(
    row: &mut Value,
    ratio: Option<(&str, f32)>,
    saturation: Saturation,
    exclude: Exclude,
) {
    if let Some(row) = row.as_object_mut() {
        if let Some((of, r)) = ratio {
            row.insert("ratio".into(), json!([of, decimal(r)]));
        }
        if !saturation.is_any() {
            row.insert(
                "saturation".into(),
                json!([decimal(saturation.min), decimal(saturation.max)]),
            );
        }
        if exclude != Exclude::None {
            row.insert("exclude".into(), json!(exclude.name()));
        }
    }
}
