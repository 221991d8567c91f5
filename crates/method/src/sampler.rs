//! Candidate looks from objectives: the paper's sequential key/fill sampler (4.2), colour
//! assignment by weight (4.3), and its refinements (4.4): groups, regions, keys, locks.
//!
//! Pure: plain data in, a [`Look`] out, randomness only from the caller's generator, so a
//! seed reproduces a gallery. A [`Plan`] does the per-generate work once (which lights
//! each objective reaches, normalisation factors, locked sums); [`Plan::sample`] is then
//! cheap enough to call thousands of times.

use rand::Rng;
use rand::seq::{IndexedRandom, SliceRandom};
use rand_distr::{Distribution, Normal};

use crate::constrain::{Ratio, RatioTree, Saturation, clamp_saturation, ratio_trees};
use crate::objective::{Aspects, PaletteColor, nearest};
use crate::targeting::Reach;
use visobjd_compositor::color::srgb_to_lab;
use visobjd_scene::look::Look;
use visobjd_scene::srgb::{linear_to_srgb, srgb_to_linear};

/// The lights as the sampler sees them: each group's lights, and which can change colour.
#[derive(Debug, Clone)]
pub struct LightGroups {
    /// Light indices per group.
    pub groups: Vec<Vec<usize>>,
    /// Per light: whether its profile can change colour.
    pub colored: Vec<bool>,
}

impl LightGroups {
    /// The sampler's view of a scene.
    pub fn new(scene: &visobjd_scene::Scene) -> LightGroups {
        LightGroups {
            groups: scene.groups.iter().map(|g| g.lights.clone()).collect(),
            colored: (0..scene.lights.len())
                .map(|l| scene.profile(l).has_colour())
                .collect(),
        }
    }

    fn group_of(&self) -> Vec<usize> {
        let mut of = vec![0; self.colored.len()];
        for (g, lights) in self.groups.iter().enumerate() {
            for &l in lights {
                of[l] = g;
            }
        }
        of
    }
}

/// The designer's partial specification (paper 4.4.3).
#[derive(Debug, Clone, Default)]
pub struct Constraints {
    /// Per light: keeps its base value exactly (locked lights and lights of locked groups).
    pub locked: Vec<bool>,
    /// Per group: designated key group. If any is set, these are the keys.
    pub keys: Vec<bool>,
    /// Sample each light on its own instead of one value per group.
    pub per_light: bool,
    /// Per light: held at intensity 0 in every candidate (excluded `off`), its colour kept.
    /// A locked light keeps its base instead.
    pub off: Vec<bool>,
    /// Per light: its allowed HSV saturation (colour-capable lights only).
    pub saturation: Vec<Saturation>,
    /// Groups held at a ratio of another group's intensity; one per follower, no loops.
    pub ratios: Vec<Ratio>,
}

impl Constraints {
    /// No locks, no designated keys, group granularity.
    pub fn none(rig: &LightGroups) -> Constraints {
        Constraints {
            locked: vec![false; rig.colored.len()],
            keys: vec![false; rig.groups.len()],
            per_light: false,
            off: vec![false; rig.colored.len()],
            saturation: vec![Saturation::ANY; rig.colored.len()],
            ratios: Vec::new(),
        }
    }
}

/// An objective prepared for the stage: what it asks and which lights it reaches.
#[derive(Debug, Clone)]
pub struct Target {
    /// Aspects taken.
    pub aspects: Aspects,
    /// Area of its region (0..1): larger regions run first, so smaller ones win.
    pub area: f32,
    /// Per light: selected by the region.
    pub selected: Vec<bool>,
    /// Per light: mean luminance added in the region per unit of intensity.
    pub sensitivity: Vec<f32>,
    /// Per light, per position (empty for a fixed light): whether the region selects it
    /// there, and its sensitivity there.
    pub positions: Vec<Vec<Reach>>,
    /// mu_a, 0..1.
    pub mean: f32,
    /// mu_k, 0..1.
    pub key: f32,
    /// b: fraction of reference pixels brighter than the mean.
    pub bright: f32,
    /// Palette (colours sRGB, weights summing to 1).
    pub palette: Vec<PaletteColor>,
}

/// Spreads of the key and fill draws (fractions of full).
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    /// sigma_k (paper: 5%, the just-noticeable difference).
    pub key: f32,
    /// sigma_a (paper: 10%).
    pub fill: f32,
}

impl Default for Spread {
    fn default() -> Spread {
        Spread {
            key: 0.05,
            fill: 0.10,
        }
    }
}

/// One sampling unit: the unlocked lights of a group (or one light) that an objective
/// reaches; they all take the same value.
#[derive(Debug, Clone)]
struct Unit {
    lights: Vec<usize>,
    /// Belongs to a designated key group.
    designated: bool,
    /// Its moving lights and how the region sees each of their positions: their share of
    /// the unit's sensitivity follows the position drawn ([`IntensityStep::factor`]).
    movers: Vec<(usize, Vec<Reach>)>,
    /// The sensitivity of its fixed lights.
    fixed: f32,
}

/// The moving lights of one sampling unit of one objective, and the focus palettes they
/// may take: one is drawn per candidate, uniformly, and every mover of the unit goes to
/// it (each with its own pan and tilt).
#[derive(Debug, Clone)]
struct PositionUnit {
    movers: Vec<usize>,
    choices: Vec<u32>,
}

#[derive(Debug, Clone)]
struct IntensityStep {
    units: Vec<Unit>,
    /// The mean of 1/sensitivity over the units that light the region (0: none does),
    /// what a factor is relative to.
    mean_inv: f32,
    /// Fully locked units count as already set (their base values).
    locked_units: usize,
    locked_sum: f32,
    designated_keys: bool,
    mean: f32,
    key: f32,
    bright: f32,
}

#[derive(Debug, Clone)]
struct ColorStep {
    /// Per unit, its unlocked colour-capable lights.
    units: Vec<Vec<usize>>,
    /// Locked colour-capable lights the objective reaches: they count toward the
    /// nearest palette colour's share.
    locked: Vec<usize>,
    /// Palette colours at full value (hue and saturation only), their weights and Lab.
    colors: Vec<([f32; 3], f32, [f32; 3])>,
}

/// The per-generate preparation of objectives against a rig, constraints and base look.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Per objective (larger regions first), its moving lights' choices.
    positions: Vec<Vec<PositionUnit>>,
    intensity: Vec<IntensityStep>,
    color: Vec<ColorStep>,
    spread: Spread,
    /// Lights held at 0.
    off: Vec<usize>,
    ratios: Vec<RatioTree>,
    /// Free colour-capable lights with a saturation range.
    saturation: Vec<(usize, Saturation)>,
    /// Targets (indices in the order given) that ask for colour only over lights the base
    /// leaves dark and no intensity target reaches: they take their reference's intensity
    /// too, as a colour on a dark light shows nothing.
    lit_for_color: Vec<usize>,
}

impl Plan {
    /// Prepares the objectives: intensity aspects first, then colour; within each, larger
    /// regions first so that a region inside another wins the lights both select. Lights
    /// held off count as locked at 0; ratios and saturation ranges apply after sampling. A
    /// colour-only target whose free colour lights are all dark in the base and outside
    /// every intensity target is sampled for intensity too ([`Plan::lit_for_color`]).
    pub fn new(
        rig: &LightGroups,
        constraints: &Constraints,
        targets: &[Target],
        base: &Look,
        spread: Spread,
    ) -> Plan {
        let off: Vec<usize> = (0..rig.colored.len())
            .filter(|&l| constraints.off[l] && !constraints.locked[l])
            .collect();
        let mut held = constraints.clone();
        let mut start = base.clone();
        for &l in &off {
            held.locked[l] = true;
            start.levels[l].intensity = 0.0;
        }
        let (constraints, base) = (&held, &start);
        let lit_for_color = dark_color_targets(rig, constraints, targets, base);
        let mut order: Vec<(usize, &Target)> = targets.iter().enumerate().collect();
        order.sort_by(|a, b| b.1.area.total_cmp(&a.1.area));
        let group_of = rig.group_of();
        let mut intensity = Vec::new();
        let mut color = Vec::new();
        let mut positions = Vec::new();
        for (i, t) in order {
            let units = units(rig, constraints, t);
            positions.push(position_units(constraints, t, &units));
            if t.aspects.intensity() || lit_for_color.contains(&i) {
                intensity.push(intensity_step(constraints, &group_of, t, &units, base));
            }
            if t.aspects.color() && !t.palette.is_empty() {
                color.push(color_step(rig, constraints, t, &units));
            }
        }
        Plan {
            positions,
            intensity,
            color,
            spread,
            ratios: ratio_trees(&rig.groups, &constraints.locked, &constraints.ratios),
            saturation: (0..rig.colored.len())
                .filter(|&l| rig.colored[l] && !constraints.locked[l])
                .map(|l| (l, constraints.saturation[l]))
                .filter(|(_, s)| !s.is_any())
                .collect(),
            off,
            lit_for_color,
        }
    }

    /// Colour-only targets (indices in the order given to [`Plan::new`]) that take their
    /// reference's intensity as well, because the base leaves their lights dark.
    pub fn lit_for_color(&self) -> &[usize] {
        &self.lit_for_color
    }

    /// One candidate: the base look with every reached, unlocked light resampled, lights
    /// held off at 0, then ratios and saturation ranges applied.
    pub fn sample(&self, base: &Look, rng: &mut impl Rng) -> Look {
        let mut look = base.clone();
        for &l in &self.off {
            look.levels[l].intensity = 0.0;
        }
        for unit in self.positions.iter().flatten() {
            if let Some(&palette) = unit.choices.choose(rng) {
                for &l in &unit.movers {
                    look.levels[l].position = Some(palette);
                }
            }
        }
        for step in &self.intensity {
            let keys = if step.designated_keys {
                Keys::Designated(step.units.iter().map(|u| u.designated).collect())
            } else {
                Keys::Count(key_count(step.bright, step.units.len()))
            };
            let values = gibbs(
                step.units.len(),
                step.locked_units,
                step.locked_sum,
                &keys,
                step.mean,
                step.key,
                self.spread,
                rng,
            );
            for (unit, x) in step.units.iter().zip(values) {
                let v = (x * step.factor(unit, &look)).min(1.0);
                for &l in &unit.lights {
                    look.levels[l].intensity = v;
                }
            }
        }
        for tree in &self.ratios {
            tree.hold(&mut look);
        }
        for step in &self.color {
            assign_colors(step, &mut look, rng);
        }
        for &(l, range) in &self.saturation {
            look.levels[l].color = clamp_saturation(look.levels[l].color, range);
        }
        look
    }
}

/// The colour-only targets with a palette whose free colour-capable lights are all at 0 in
/// `base` and selected by no intensity target: their colours would fall on dark lights.
fn dark_color_targets(
    rig: &LightGroups,
    constraints: &Constraints,
    targets: &[Target],
    base: &Look,
) -> Vec<usize> {
    let reached = |l: usize| {
        targets
            .iter()
            .any(|t| t.aspects.intensity() && t.selected[l])
    };
    targets
        .iter()
        .enumerate()
        .filter(|(_, t)| t.aspects.color() && !t.aspects.intensity() && !t.palette.is_empty())
        .filter(|(_, t)| {
            let mut free = (0..rig.colored.len())
                .filter(|&l| t.selected[l] && rig.colored[l] && !constraints.locked[l])
                .peekable();
            free.peek().is_some() && free.all(|l| base.levels[l].intensity <= 0.0 && !reached(l))
        })
        .map(|(i, _)| i)
        .collect()
}

impl IntensityStep {
    /// `unit`'s brightness normalisation factor (4.2.5) in `look`: 1/s over the step's
    /// mean of 1/s, s its fixed lights' sensitivity and its movers' in the positions
    /// `look` gives them; 1 for a unit that does not light the region.
    fn factor(&self, unit: &Unit, look: &Look) -> f32 {
        let s = unit.fixed
            + unit
                .movers
                .iter()
                .map(|(l, reach)| {
                    look.levels[*l]
                        .position_in(reach, |r| r.palette)
                        .map_or(0.0, |r| r.sensitivity)
                })
                .sum::<f32>();
        if s > 0.0 && self.mean_inv > 0.0 {
            (1.0 / s) / self.mean_inv
        } else {
            1.0
        }
    }
}

/// The moving lights of each of `t`'s sampling units that the sampler may aim, and the
/// palettes it draws from: those every free mover of the unit has, narrowed to the ones
/// where the region selects at least one of them (all of them when it selects none).
/// Movers without a palette in common are drawn one by one.
fn position_units(
    constraints: &Constraints,
    t: &Target,
    all_units: &[Vec<usize>],
) -> Vec<PositionUnit> {
    let free =
        |l: &usize| !t.positions[*l].is_empty() && !constraints.locked[*l] && !constraints.off[*l];
    let mut out = Vec::new();
    for members in all_units {
        let movers: Vec<usize> = members.iter().copied().filter(free).collect();
        let Some(&first) = movers.first() else {
            continue;
        };
        let common: Vec<u32> = t.positions[first]
            .iter()
            .map(|r| r.palette)
            .filter(|&n| {
                movers
                    .iter()
                    .all(|&l| t.positions[l].iter().any(|r| r.palette == n))
            })
            .collect();
        let narrowed = |lights: &[usize], palettes: &[u32]| -> Vec<u32> {
            let aimed: Vec<u32> = palettes
                .iter()
                .copied()
                .filter(|&n| {
                    lights
                        .iter()
                        .any(|&l| t.positions[l].iter().any(|r| r.palette == n && r.selected))
                })
                .collect();
            if aimed.is_empty() {
                palettes.to_vec()
            } else {
                aimed
            }
        };
        if common.is_empty() {
            for l in movers {
                let own: Vec<u32> = t.positions[l].iter().map(|r| r.palette).collect();
                out.push(PositionUnit {
                    choices: narrowed(&[l], &own),
                    movers: vec![l],
                });
            }
        } else {
            out.push(PositionUnit {
                choices: narrowed(&movers, &common),
                movers,
            });
        }
    }
    out
}

/// Number of keys over `units` sampled units: round(b L / 2) (paper 4.2.4).
pub fn key_count(bright: f32, units: usize) -> usize {
    ((bright * units as f32 / 2.0).round() as usize).min(units)
}

fn units(rig: &LightGroups, constraints: &Constraints, t: &Target) -> Vec<Vec<usize>> {
    let selected = |l: &usize| t.selected[*l];
    if constraints.per_light {
        (0..rig.colored.len())
            .filter(selected)
            .map(|l| vec![l])
            .collect()
    } else {
        rig.groups
            .iter()
            .map(|g| g.iter().copied().filter(selected).collect::<Vec<_>>())
            .filter(|u| !u.is_empty())
            .collect()
    }
}

fn intensity_step(
    constraints: &Constraints,
    group_of: &[usize],
    t: &Target,
    all_units: &[Vec<usize>],
    base: &Look,
) -> IntensityStep {
    let mut units = Vec::new();
    let (mut locked_units, mut locked_sum) = (0, 0.0);
    for members in all_units {
        let free: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&l| !constraints.locked[l])
            .collect();
        if free.is_empty() {
            locked_units += 1;
            locked_sum += members
                .iter()
                .map(|&l| base.levels[l].intensity)
                .sum::<f32>()
                / members.len() as f32;
        } else {
            let designated = constraints.keys[group_of[free[0]]];
            let movers: Vec<(usize, Vec<Reach>)> = free
                .iter()
                .filter(|&&l| !t.positions[l].is_empty())
                .map(|&l| (l, t.positions[l].clone()))
                .collect();
            let fixed = free
                .iter()
                .filter(|&&l| t.positions[l].is_empty())
                .map(|&l| t.sensitivity[l])
                .sum();
            units.push(Unit {
                lights: free,
                designated,
                movers,
                fixed,
            });
        }
    }
    // Brightness normalisation: 1/s rescaled to mean 1 over the units that light the
    // region; units that do not light it keep factor 1. A moving light counts with its
    // mean sensitivity over the positions where the region selects it (all, if none).
    let s: Vec<f32> = units
        .iter()
        .map(|u| {
            let movers: f32 = u
                .movers
                .iter()
                .map(|(_, reach)| {
                    let aimed = || reach.iter().filter(|r| r.selected);
                    let (sum, n) = if aimed().next().is_some() {
                        (aimed().map(|r| r.sensitivity).sum::<f32>(), aimed().count())
                    } else {
                        (reach.iter().map(|r| r.sensitivity).sum(), reach.len())
                    };
                    sum / n.max(1) as f32
                })
                .sum();
            u.fixed + movers
        })
        .collect();
    let inv: Vec<f32> = s.iter().filter(|&&v| v > 0.0).map(|v| 1.0 / v).collect();
    let mean_inv = if inv.is_empty() {
        0.0
    } else {
        inv.iter().sum::<f32>() / inv.len() as f32
    };
    IntensityStep {
        mean_inv,
        designated_keys: constraints.keys.iter().any(|&k| k),
        units,
        locked_units,
        locked_sum,
        mean: t.mean,
        key: t.key,
        bright: t.bright,
    }
}

fn color_step(
    rig: &LightGroups,
    constraints: &Constraints,
    t: &Target,
    all_units: &[Vec<usize>],
) -> ColorStep {
    let free = |l: &usize| rig.colored[*l] && !constraints.locked[*l];
    let units = all_units
        .iter()
        .map(|u| u.iter().copied().filter(free).collect::<Vec<_>>())
        .filter(|u| !u.is_empty())
        .collect();
    let locked = (0..rig.colored.len())
        .filter(|&l| t.selected[l] && rig.colored[l] && constraints.locked[l])
        .collect();
    let colors = t
        .palette
        .iter()
        .map(|p| {
            let c = full_value(p.color);
            (c, p.weight, srgb_to_lab(c))
        })
        .collect();
    ColorStep {
        units,
        locked,
        colors,
    }
}

/// A palette colour's hue and saturation at full value: the light's brightness comes from
/// its intensity (docs/method.md). Black has no hue and becomes white.
pub fn full_value(srgb: [f32; 3]) -> [f32; 3] {
    let lin = srgb.map(srgb_to_linear);
    let max = lin[0].max(lin[1]).max(lin[2]);
    if max <= 1e-6 {
        return [1.0, 1.0, 1.0];
    }
    lin.map(|v| linear_to_srgb(v / max))
}

/// How the keys of a pass are chosen.
#[derive(Debug, Clone)]
pub enum Keys {
    /// This many, chosen uniformly at random.
    Count(usize),
    /// Exactly these units (designer-chosen key groups).
    Designated(Vec<bool>),
}

/// The sequential key/fill pass over `n` free units (paper 4.2.2, equation 4).
///
/// `locked_units` units already hold values summing to `locked_sum`; they count as set.
/// Keys are drawn from N(key, sigma_k); then each fill, in random order, from
/// N(mu_j, sigma_a) with mu_j = (L mu_a - sum so far) / (units still unset). Every draw is
/// clamped to 0..1. Returns one value per free unit.
#[allow(clippy::too_many_arguments)]
pub fn gibbs(
    n: usize,
    locked_units: usize,
    locked_sum: f32,
    keys: &Keys,
    mean: f32,
    key: f32,
    spread: Spread,
    rng: &mut impl Rng,
) -> Vec<f32> {
    let mut values = vec![0.0f32; n];
    let mut order: Vec<usize> = (0..n).collect();
    let key_units: Vec<usize> = match keys {
        Keys::Count(k) => {
            order.shuffle(rng);
            order[..(*k).min(n)].to_vec()
        }
        Keys::Designated(flags) => {
            let ks: Vec<usize> = (0..n).filter(|&i| flags[i]).collect();
            order.retain(|i| !flags[*i]);
            order.shuffle(rng);
            let mut all = ks.clone();
            all.extend_from_slice(&order);
            order = all;
            ks
        }
    };
    let total = (n + locked_units) as f32;
    let mut sum = locked_sum;
    let mut set = locked_units;
    for &u in &key_units {
        let x = draw(key, spread.key, rng);
        values[u] = x;
        sum += x;
        set += 1;
    }
    for &u in &order[key_units.len()..] {
        let mu = (total * mean - sum) / (total - set as f32);
        let x = draw(mu, spread.fill, rng);
        values[u] = x;
        sum += x;
        set += 1;
    }
    values
}

/// One clamped normal draw.
fn draw(mean: f32, sigma: f32, rng: &mut impl Rng) -> f32 {
    let x = match Normal::new(mean, sigma.max(0.0)) {
        Ok(n) => n.sample(rng),
        Err(_) => mean,
    };
    x.clamp(0.0, 1.0)
}

/// Colour assignment by weight (paper 4.3): units in random order take the palette's
/// colours in a random order, each colour until its share of the total intensity reaches
/// its weight.
fn assign_colors(step: &ColorStep, look: &mut Look, rng: &mut impl Rng) {
    let k = step.colors.len();
    let share_of = |lights: &[usize], look: &Look| -> f32 {
        lights.iter().map(|&l| look.levels[l].intensity).sum()
    };
    let unit_shares: Vec<f32> = step.units.iter().map(|u| share_of(u, look)).collect();
    let labs: Vec<[f32; 3]> = step.colors.iter().map(|c| c.2).collect();
    let mut share = vec![0.0f32; k];
    let mut locked_total = 0.0;
    for &l in &step.locked {
        let lv = look.levels[l];
        share[nearest(&labs, srgb_to_lab(full_value(lv.color)))] += lv.intensity;
        locked_total += lv.intensity;
    }
    let mut total = locked_total + unit_shares.iter().sum::<f32>();
    // All dark: share by count instead, so colours still follow the weights.
    let by_count = total <= 1e-6;
    if by_count {
        share = vec![0.0; k];
        for &l in &step.locked {
            share[nearest(&labs, srgb_to_lab(full_value(look.levels[l].color)))] += 1.0;
        }
        total = (step.locked.len() + step.units.iter().map(Vec::len).sum::<usize>()) as f32;
    }
    let mut colors: Vec<usize> = (0..k).collect();
    colors.shuffle(rng);
    let mut units: Vec<usize> = (0..step.units.len()).collect();
    units.shuffle(rng);
    let full = |c: usize, share: &[f32]| share[c] >= step.colors[c].1 * total;
    let mut at = 0;
    for u in units {
        while at + 1 < k && full(colors[at], &share) {
            at += 1;
        }
        let c = colors[at];
        for &l in &step.units[u] {
            look.levels[l].color = step.colors[c].0;
        }
        share[c] += if by_count {
            step.units[u].len() as f32
        } else {
            unit_shares[u]
        };
    }
}
