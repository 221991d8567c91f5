//! The prototype's constraints beyond locks and keys (docs/method.md, "Designer
//! constraints"): relative brightness between groups, saturation ranges, and the transfer
//! of part of a candidate onto a look. Lights held at 0 ("off") and lights kept as they are
//! (excluded, pinned) reach the sampler as [`crate::sampler::Constraints`] flags.
//!
//! Pure: plain data in and out, no randomness; [`crate::sampler::Plan::sample`] applies
//! ratios and saturation to every candidate after drawing it.

use visobjd_scene::look::Look;

/// Group `follower` is held at `ratio` times group `leader`'s intensity (the mean
/// intensity of each group's lights).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ratio {
    /// The group that follows (B of `/vo/group/<B>/ratio <A> <r>`).
    pub follower: usize,
    /// The group it follows (A).
    pub leader: usize,
    /// r, above 0.
    pub ratio: f32,
}

/// An allowed range of HSV saturation, 0..1, of a light's sRGB colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Saturation {
    /// Lowest allowed.
    pub min: f32,
    /// Highest allowed.
    pub max: f32,
}

impl Saturation {
    /// Any saturation: no constraint.
    pub const ANY: Saturation = Saturation { min: 0.0, max: 1.0 };

    /// Whether it constrains anything.
    pub fn is_any(self) -> bool {
        self.min <= 0.0 && self.max >= 1.0
    }
}

/// HSV saturation of an sRGB colour: (max - min) / max of its components, 0 for black.
pub fn saturation(c: [f32; 3]) -> f32 {
    let max = c[0].max(c[1]).max(c[2]);
    let min = c[0].min(c[1]).min(c[2]);
    if max <= 0.0 { 0.0 } else { (max - min) / max }
}

/// `c` with its HSV saturation clamped into `range`, hue and value kept. In HSV every
/// component is V (1 - S k) with k fixed by the hue, so a new saturation S' scales each
/// component's distance below V by S' / S. A grey has hue 0 (red) by the usual convention;
/// black (V = 0) has no hue or value to keep and stays black.
pub fn clamp_saturation(c: [f32; 3], range: Saturation) -> [f32; 3] {
    let s = saturation(c);
    let target = s.clamp(range.min, range.max);
    let v = c[0].max(c[1]).max(c[2]);
    if target == s || v <= 0.0 {
        return c;
    }
    if s <= 0.0 {
        let low = v * (1.0 - target);
        return [v, low, low];
    }
    c.map(|x| (v - (v - x) * (target / s)).clamp(0.0, 1.0))
}

/// If group `follower` following `leader` would close a loop of ratios, the loop as group
/// indices from `leader` back to `follower` (`[follower]` when they are the same group).
/// `ratios` holds at most one ratio per follower.
pub fn ratio_cycle(ratios: &[Ratio], follower: usize, leader: usize) -> Option<Vec<usize>> {
    let mut path = vec![leader];
    let mut at = leader;
    while at != follower {
        // Each follower has one leader, so the walk up from `leader` is a path; it is at most
        // as long as there are ratios unless the list already loops (then no new loop forms).
        at = ratios.iter().find(|r| r.follower == at)?.leader;
        if path.len() > ratios.len() {
            return None;
        }
        path.push(at);
    }
    Some(path)
}

/// One group as ratios see it.
#[derive(Debug, Clone)]
struct Member {
    /// How many lights it has.
    lights: usize,
    /// Its lights the sampler may change (not locked, excluded, pinned or off).
    free: Vec<usize>,
    /// Its lights whose values are fixed.
    fixed: Vec<usize>,
    /// Its intensity relative to the tree's root.
    scale: f32,
}

/// Groups linked by ratios: a root and its followers, leaders before their followers.
#[derive(Debug, Clone)]
pub(crate) struct RatioTree {
    members: Vec<Member>,
}

/// The trees of `ratios` over `groups`; `held` marks lights whose values are fixed. A
/// group is in one tree at most (it follows one leader); ratios in a loop, which
/// [`ratio_cycle`] keeps out, are ignored.
pub(crate) fn ratio_trees(
    groups: &[Vec<usize>],
    held: &[bool],
    ratios: &[Ratio],
) -> Vec<RatioTree> {
    let follows = |g: usize| ratios.iter().find(|r| r.follower == g);
    let member = |g: usize, scale: f32| {
        let (fixed, free) = groups[g].iter().partition(|&&l| held[l]);
        Member {
            lights: groups[g].len(),
            free,
            fixed,
            scale,
        }
    };
    let mut roots: Vec<usize> = ratios
        .iter()
        .map(|r| r.leader)
        .filter(|&g| follows(g).is_none())
        .collect();
    roots.sort_unstable();
    roots.dedup();
    roots
        .into_iter()
        .map(|root| {
            let mut members = vec![(root, 1.0f32)];
            let mut i = 0;
            while i < members.len() {
                let (g, scale) = members[i];
                for r in ratios.iter().filter(|r| r.leader == g && r.follower != g) {
                    if follows(r.follower) == Some(r) {
                        members.push((r.follower, scale * r.ratio));
                    }
                }
                i += 1;
            }
            RatioTree {
                members: members.into_iter().map(|(g, s)| member(g, s)).collect(),
            }
        })
        .collect()
}

impl RatioTree {
    /// Holds every follower at its ratio to the root in `look`: the root's mean intensity
    /// as sampled is kept unless some group could not reach its share (its fixed lights or
    /// the 0..1 range stop it), then the root moves as little as needed; each follower's
    /// free lights take one value that gives it its share. When fixed lights make the
    /// ratios impossible, they win and the rest come as close as 0..1 allows.
    pub(crate) fn hold(&self, look: &mut Look) {
        let sum = |lights: &[usize], look: &Look| {
            lights
                .iter()
                .map(|&l| look.levels[l].intensity)
                .sum::<f32>()
        };
        let members = || {
            self.members
                .iter()
                .filter(|m| m.lights > 0 && m.scale > 0.0)
        };
        let (mut lo, mut hi) = (0.0f32, f32::INFINITY);
        for m in members() {
            let (n, fixed) = (m.lights as f32, sum(&m.fixed, look));
            lo = lo.max(fixed / n / m.scale);
            hi = hi.min((fixed + m.free.len() as f32) / n / m.scale);
        }
        let Some(root) = self.members.first().filter(|m| m.lights > 0) else {
            return;
        };
        let sampled = (sum(&root.fixed, look) + sum(&root.free, look)) / root.lights as f32;
        let x = if lo <= hi {
            sampled.clamp(lo, hi)
        } else {
            sampled.clamp(hi, lo)
        };
        for (i, m) in members().enumerate() {
            if m.free.is_empty() || (i == 0 && x == sampled) {
                continue;
            }
            let share = m.lights as f32 * m.scale * x - sum(&m.fixed, look);
            let v = (share / m.free.len() as f32).clamp(0.0, 1.0);
            for &l in &m.free {
                look.levels[l].intensity = v;
            }
        }
    }
}

/// `onto` with the lights marked in `lights` taken from `from` (intensity, colour and a
/// mover's position), the
/// rest untouched: a transfer of one area or one group of a candidate onto the live look.
pub fn transfer(onto: &Look, from: &Look, lights: &[bool]) -> Look {
    let mut out = onto.clone();
    for ((o, f), _) in out
        .levels
        .iter_mut()
        .zip(&from.levels)
        .zip(lights)
        .filter(|(_, on)| **on)
    {
        *o = *f;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturation_is_hsv_and_clamping_keeps_hue_and_value() {
        assert_eq!(saturation([1.0, 0.5, 0.0]), 1.0);
        assert_eq!(saturation([0.5, 0.5, 0.5]), 0.0);
        assert_eq!(saturation([0.0; 3]), 0.0);
        let c = clamp_saturation([1.0, 0.5, 0.0], Saturation { min: 0.0, max: 0.4 });
        assert!((saturation(c) - 0.4).abs() < 1e-6, "{c:?}");
        // Hue: the middle component stays at the same fraction between min and max.
        assert!(((c[1] - c[2]) / (c[0] - c[2]) - 0.5).abs() < 1e-6, "{c:?}");
        assert_eq!(c[0], 1.0);
        let grey = clamp_saturation([0.6; 3], Saturation { min: 0.5, max: 1.0 });
        assert_eq!(grey, [0.6, 0.3, 0.3]);
        assert_eq!(
            clamp_saturation([0.0; 3], Saturation { min: 0.5, max: 1.0 }),
            [0.0; 3]
        );
    }

    #[test]
    fn cycles_are_found_and_chains_are_not() {
        let r = |follower, leader| Ratio {
            follower,
            leader,
            ratio: 1.0,
        };
        let ratios = [r(1, 0), r(2, 1)];
        assert_eq!(ratio_cycle(&ratios, 0, 2), Some(vec![2, 1, 0]));
        assert_eq!(ratio_cycle(&ratios, 3, 2), None);
        assert_eq!(ratio_cycle(&ratios, 4, 4), Some(vec![4]));
    }
}
