//! `/vo/objective/...` and `/vo/objectives`: reference images and what to take from them.

use rosc::{OscMessage, OscType};

use super::{Context, int, int_arg, num_arg, rgb_args, text};
use crate::engine::session::{Entry, MAX_IMAGE_NAME, MAX_OBJECTIVES, Session};
use crate::engine::{Outcome, Refusal, msg};
use crate::osc::args::{self, Request};
use visobjd_method::objective::{Aspects, Objective, Region};
use visobjd_method::targeting::Footprints;

pub enum Cmd {
    /// Reads the image first (slow, outside the session), then adds the objective.
    Add {
        image: String,
        aspects: Aspects,
    },
    Edit(Edit),
}

/// The objective commands that only change (or read) the session.
pub enum Edit {
    Aspects { id: Which, aspects: Aspects },
    Region { id: Which, region: Region },
    Palette { id: Which },
    Color { id: Which, k: usize, rgb: [f32; 3] },
    Weight { id: Which, k: usize, w: f32 },
    Remove { id: Which },
    Clear,
    List,
}

/// The objective an address names: by number, or `last`, the newest one (a tablet button
/// cannot know the number the daemon gave the objective it just added).
#[derive(Clone, Copy)]
pub enum Which {
    Id(u32),
    Last,
}

fn id(segment: &str) -> Result<Which, String> {
    if segment == "last" {
        return Ok(Which::Last);
    }
    segment
        .parse::<u32>()
        .map(Which::Id)
        .map_err(|_| format!("objective `{segment}` is not an objective number (or `last`)"))
}

fn aspects(req: &Request, i: usize) -> Result<Aspects, String> {
    match req.arg(i) {
        None => Ok(Aspects::Both),
        Some(a) => Aspects::parse(args::string(a, "aspects")?),
    }
}

impl Cmd {
    pub fn parse(req: &Request) -> Result<Option<Cmd>, String> {
        if req.matches("/vo/objective/add").is_some() {
            let image = args::string(req.required(0, "image")?, "image")?;
            let n = image.chars().count();
            if n > MAX_IMAGE_NAME {
                return Err(format!(
                    "an objective's image name is at most {MAX_IMAGE_NAME} characters, got {n}"
                ));
            }
            return Ok(Some(Cmd::Add {
                image: image.to_string(),
                aspects: aspects(req, 1)?,
            }));
        }
        if req.matches("/vo/objective/clear").is_some() {
            return Ok(Some(Cmd::Edit(Edit::Clear)));
        }
        if req.matches("/vo/objectives").is_some() {
            return Ok(Some(Cmd::Edit(Edit::List)));
        }
        let Some(captures) = req.matches("/vo/objective/*/*") else {
            return Ok(None);
        };
        let (seg, what) = (captures[0], captures[1]);
        Ok(Some(Cmd::Edit(match what {
            "aspects" => Edit::Aspects {
                id: id(seg)?,
                aspects: Aspects::parse(args::string(req.required(0, "aspects")?, "aspects")?)?,
            },
            "region" => Edit::Region {
                id: id(seg)?,
                region: if req.arg(0).is_none() {
                    Region::FULL
                } else {
                    Region::new(
                        num_arg(req, 0, "x0", 0.0, 1.0)?,
                        num_arg(req, 1, "y0", 0.0, 1.0)?,
                        num_arg(req, 2, "x1", 0.0, 1.0)?,
                        num_arg(req, 3, "y1", 0.0, 1.0)?,
                    )?
                },
            },
            "palette" => Edit::Palette { id: id(seg)? },
            "color" | "colour" => Edit::Color {
                id: id(seg)?,
                k: int_arg(req, 0, "palette colour number", 1, 64)? as usize,
                rgb: rgb_args(req, 1)?,
            },
            "weight" => Edit::Weight {
                id: id(seg)?,
                k: int_arg(req, 0, "palette colour number", 1, 64)? as usize,
                w: num_arg(req, 1, "weight", 0.0, 1.0)?,
            },
            "remove" => Edit::Remove { id: id(seg)? },
            _ => return Ok(None),
        })))
    }

    pub fn apply(self, cx: &Context) -> Result<Vec<OscMessage>, Refusal> {
        let e = cx.engine;
        let edit = match self {
            Cmd::Add { image, aspects } => return add(cx, &image, aspects),
            Cmd::Edit(edit) => edit,
        };
        let stage = e.stage();
        let footprints = &stage.footprints;
        if let Edit::Region { id, region } = edit
            && e.exploring()
        {
            // While exploring, the region goes to the explore slot: no disk, no generate
            // waited for, not forwarded as itself; the session takes it with the gallery
            // drawn from it.
            let id = find(&e.session(), id)?.1;
            if e.explore_region(id, region) {
                return Ok(vec![region_reply(id, region, footprints)]);
            }
        }
        cx.commit(|s| {
            Ok(match edit {
                Edit::Aspects { id, aspects } => {
                    let (i, id) = find(s, id)?;
                    s.objectives[i].objective.aspects = aspects;
                    Outcome::reply(msg(
                        "/vo/objective/aspects",
                        vec![int(id as usize), text(aspects.name())],
                    ))
                    .saved()
                }
                Edit::Region { id, region } => {
                    let (i, id) = find(s, id)?;
                    if !footprints.select(region).contains(&true) {
                        return Err(Refusal::input(format!(
                            "region {} {} {} {} selects no light (none lights that part of the \
                             stage): objective {id} keeps its region; draw it where a light falls",
                            region.x0, region.y0, region.x1, region.y1
                        )));
                    }
                    s.objectives[i].objective.region = region;
                    Outcome::reply(region_reply(id, region, footprints)).saved()
                }
                Edit::Palette { id } => {
                    let (i, id) = find(s, id)?;
                    Outcome::reply(palette(id, &s.objectives[i].objective))
                }
                Edit::Color { id, k, rgb } => {
                    let (i, id) = find(s, id)?;
                    let colors = &mut s.objectives[i].objective.analysis.palette;
                    let c = colour_index(colors, id, k)?;
                    colors[c].color = rgb;
                    Outcome::reply(palette(id, &s.objectives[i].objective)).saved()
                }
                Edit::Weight { id, k, w } => {
                    let (i, id) = find(s, id)?;
                    let colors = &mut s.objectives[i].objective.analysis.palette;
                    let c = colour_index(colors, id, k)?;
                    reweigh(colors, c, w).map_err(Refusal::conflict)?;
                    Outcome::reply(palette(id, &s.objectives[i].objective)).saved()
                }
                Edit::Remove { id } => {
                    let (i, id) = find(s, id)?;
                    s.objectives.remove(i);
                    Outcome::reply(msg("/vo/objective/removed", vec![int(id as usize)]))
                        .saved()
                        .pushed()
                }
                Edit::Clear => {
                    let n = s.objectives.len();
                    s.objectives.clear();
                    Outcome::reply(msg("/vo/objective/cleared", vec![int(n)]))
                        .saved()
                        .pushed()
                }
                Edit::List => Outcome::replies(list(s)),
            })
        })
    }
}

/// `/vo/objective/add`: the reference is read with the session unlocked, then added.
fn add(cx: &Context, image: &str, aspects: Aspects) -> Result<Vec<OscMessage>, Refusal> {
    // Checked before the slow read too, so a full session refuses at once.
    room(&cx.engine.session())?;
    let objective = cx.engine.read_objective(image, aspects)?;
    cx.commit(|s| {
        room(s)?;
        let id = s.next_id;
        s.next_id += 1;
        let st = objective.analysis.stats;
        s.objectives.push(Entry { id, objective });
        let added = msg(
            "/vo/objective/added",
            vec![
                int(id as usize),
                text(aspects.name()),
                OscType::Float(st.mean_l),
                OscType::Float(st.key_l),
                OscType::Float(st.bright),
            ],
        );
        Ok(Outcome::reply(added).saved().pushed())
    })
}

/// Refuses a new objective when the session has [`MAX_OBJECTIVES`].
fn room(s: &Session) -> Result<(), Refusal> {
    if s.objectives.len() >= MAX_OBJECTIVES {
        return Err(Refusal::conflict(format!(
            "there are already {MAX_OBJECTIVES} objectives, the most a session keeps: remove \
             one first (/vo/objective/<id>/remove)"
        )));
    }
    Ok(())
}

pub fn list(s: &Session) -> Vec<OscMessage> {
    let mut out: Vec<OscMessage> = s
        .objectives
        .iter()
        .map(|en| {
            let o = &en.objective;
            msg(
                "/vo/objective",
                vec![
                    int(en.id as usize),
                    text(&o.image),
                    text(o.aspects.name()),
                    OscType::Float(o.region.x0),
                    OscType::Float(o.region.y0),
                    OscType::Float(o.region.x1),
                    OscType::Float(o.region.y1),
                ],
            )
        })
        .collect();
    out.push(msg("/vo/objectives/end", vec![int(s.objectives.len())]));
    out
}

/// The index and number of the objective `which` names.
fn find(s: &Session, which: Which) -> Result<(usize, u32), Refusal> {
    let id = match which {
        Which::Id(id) => id,
        Which::Last => s.objectives.last().map(|e| e.id).ok_or_else(|| {
            Refusal::conflict("there are no objectives: add one with /vo/objective/add first")
        })?,
    };
    s.objective_index(id).map(|i| (i, id)).ok_or_else(|| {
        let ids: Vec<String> = s.objectives.iter().map(|e| e.id.to_string()).collect();
        Refusal::conflict(if ids.is_empty() {
            format!("objective {id} does not exist: there are no objectives")
        } else {
            format!(
                "objective {id} does not exist (objectives: {})",
                ids.join(", ")
            )
        })
    })
}

/// `/vo/objective/region id x0 y0 x1 y1 lights`: with how many lights the region selects.
fn region_reply(id: u32, region: Region, footprints: &Footprints) -> OscMessage {
    let lights = footprints.select(region).iter().filter(|&&on| on).count();
    msg(
        "/vo/objective/region",
        vec![
            int(id as usize),
            OscType::Float(region.x0),
            OscType::Float(region.y0),
            OscType::Float(region.x1),
            OscType::Float(region.y1),
            int(lights),
        ],
    )
}

/// Palette colour `k` (1-based, as OSC numbers them) of objective `id`, as an index.
fn colour_index(
    colors: &[visobjd_method::objective::PaletteColor],
    id: u32,
    k: usize,
) -> Result<usize, Refusal> {
    let n = colors.len();
    (1..=n).contains(&k).then(|| k - 1).ok_or_else(|| {
        Refusal::conflict(format!(
            "objective {id} has no palette colour {k} (colours 1-{n})"
        ))
    })
}

fn palette(id: u32, o: &Objective) -> OscMessage {
    let mut a = vec![int(id as usize)];
    for p in &o.analysis.palette {
        a.extend(p.color.map(OscType::Float));
        a.push(OscType::Float(p.weight));
    }
    msg("/vo/objective/palette", a)
}

/// Gives palette colour `k` the weight `w` and the others `1 - w` in their old proportions
/// (equal shares if they had none), so the weights still sum to 1; the order is kept.
fn reweigh(
    colors: &mut [visobjd_method::objective::PaletteColor],
    k: usize,
    w: f32,
) -> Result<(), String> {
    let others = colors.len() - 1;
    if others == 0 && w < 1.0 {
        return Err("a palette of one colour has weight 1".into());
    }
    let rest: f32 = colors
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != k)
        .map(|(_, c)| c.weight)
        .sum();
    for (j, c) in colors.iter_mut().enumerate() {
        c.weight = if j == k {
            w
        } else if rest > 0.0 {
            c.weight / rest * (1.0 - w)
        } else {
            (1.0 - w) / others as f32
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use visobjd_method::objective::PaletteColor;

    fn palette(weights: &[f32]) -> Vec<PaletteColor> {
        weights
            .iter()
            .map(|&weight| PaletteColor {
                color: [0.5; 3],
                weight,
            })
            .collect()
    }

    #[test]
    fn a_new_weight_keeps_the_sum_and_the_others_proportions() {
        let mut p = palette(&[0.5, 0.3, 0.2]);
        reweigh(&mut p, 2, 0.6).unwrap();
        let w: Vec<f32> = p.iter().map(|c| c.weight).collect();
        assert!((w[2] - 0.6).abs() < 1e-6);
        assert!(
            (w[0] - 0.25).abs() < 1e-6 && (w[1] - 0.15).abs() < 1e-6,
            "{w:?}"
        );
        let mut p = palette(&[1.0, 0.0, 0.0]);
        reweigh(&mut p, 0, 0.5).unwrap();
        assert_eq!(p[1].weight, 0.25);
        let mut one = palette(&[1.0]);
        assert!(reweigh(&mut one, 0, 0.5).is_err());
        reweigh(&mut one, 0, 1.0).unwrap();
    }
}
