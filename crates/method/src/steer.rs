//! Steering a generate by the designer's ratings (issue 33): a candidate drawn from the
//! objectives is kept only when the preference model ([`crate::preference`]) predicts it
//! passes the mode's test against the base look, and the draws adapt as *Design
//! Adjectives*' rejection sampler does so the gallery still fills.
//!
//! Pure and seeded: the same ratings, mode and seed give the same gallery.

use rand::Rng;
use rand::seq::{IndexedRandom, SliceRandom};
use visobjd_scene::look::Look;

use crate::preference::{Features, Model};

/// Which way a steered generate goes from the base look's predicted rating.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Predicted higher than the base look.
    Towards,
    /// Predicted lower.
    Away,
    /// Predicted within a tenth of the ratings' range of it.
    Similar,
}

/// Rejections in a row before a draw keeps more of a liked look (Design Adjectives'
/// released sampler: 20).
const PATIENCE: usize = 20;
/// Sampling units a draw takes from the objectives at least (their floor: 3).
const FLOOR: usize = 3;
/// Tries for one candidate before the sampler gives up on the model and keeps a draw
/// (their bound: 10,000), so a generate always ends.
const TRIES: usize = 10_000;

/// A generate's steering: the model, the test, and the adaptation's state.
#[derive(Debug, Clone)]
pub struct Steer {
    model: Model,
    features: Features,
    mode: Mode,
    /// The base look's predicted rating.
    base: f64,
    /// A tenth of the ratings' range (at least 0.01): the `similar` band.
    band: f64,
    /// The rated looks a draw keeps part of: those in the upper half of the ratings'
    /// range (towards, similar), or the lower half (away).
    liked: Vec<Look>,
    /// The rig's groups: the parameters a draw takes from the objectives or a liked look.
    groups: Vec<Vec<usize>>,
    /// Groups a draw currently takes from the objectives.
    k: usize,
    in_row: usize,
    /// Candidates the model turned down.
    turned_down: usize,
}

impl Steer {
    /// Steering by `model` over `features`, from `base`; `rated` are the rated looks and
    /// their scores (the liked ones, or for `away` the disliked, are kept), `groups` the
    /// rig's groups.
    pub fn new(
        model: Model,
        features: Features,
        mode: Mode,
        base: &Look,
        rated: &[(Look, f64)],
        groups: Vec<Vec<usize>>,
    ) -> Steer {
        let (lo, hi) = rated
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, s)| {
                (lo.min(*s), hi.max(*s))
            });
        let mid = (lo + hi) / 2.0;
        Steer {
            base: model.predict(&features.of(base)),
            band: ((hi - lo) / 10.0).max(0.01),
            liked: rated
                .iter()
                .filter(|(_, s)| match mode {
                    Mode::Away => *s < mid || hi == lo,
                    Mode::Towards | Mode::Similar => *s > mid || hi == lo,
                })
                .map(|(l, _)| l.clone())
                .collect(),
            k: groups.len(),
            groups,
            model,
            features,
            mode,
            in_row: 0,
            turned_down: 0,
        }
    }

    /// Whether the model's prediction for `look` passes the mode's test: beyond the base
    /// look's by a tenth of the ratings' range (towards, away), or within it (similar).
    pub fn accepts(&self, look: &Look) -> bool {
        let s = self.model.predict(&self.features.of(look));
        match self.mode {
            Mode::Towards => s > self.base + self.band,
            Mode::Away => s < self.base - self.band,
            Mode::Similar => (s - self.base).abs() <= self.band,
        }
    }

    /// How many candidates the model turned down so far.
    pub fn turned_down(&self) -> usize {
        self.turned_down
    }

    /// The next candidate: drawn by `sample` (from the objectives), and while `k` is below
    /// the group count, a liked look with `k` random groups taken from that draw (lights
    /// `kept` by the constraints always from the draw); kept when the model accepts it.
    /// After [`PATIENCE`] rejections in a row `k` falls by one (not below [`FLOOR`]), after
    /// each accept it rises by one; after [`TRIES`] the last draw is kept.
    pub fn draw<R: Rng>(
        &mut self,
        rng: &mut R,
        kept: &[bool],
        sample: impl Fn(&mut R) -> Look,
    ) -> Look {
        let groups = self.groups.len();
        let mut look = sample(rng);
        for _ in 0..TRIES {
            if self.k < groups
                && let Some(liked) = self.liked.choose(rng)
            {
                let mut mixed = liked.clone();
                let mut order: Vec<usize> = (0..groups).collect();
                order.shuffle(rng);
                for &g in &order[..self.k] {
                    for &l in &self.groups[g] {
                        mixed.levels[l] = look.levels[l];
                    }
                }
                for (l, _) in kept.iter().enumerate().filter(|(_, k)| **k) {
                    mixed.levels[l] = look.levels[l];
                }
                look = mixed;
            }
            if self.accepts(&look) {
                self.in_row = 0;
                self.k = (self.k + 1).min(groups);
                return look;
            }
            self.turned_down += 1;
            self.in_row += 1;
            if self.in_row >= PATIENCE {
                self.in_row = 0;
                self.k = self.k.saturating_sub(1).max(FLOOR.min(groups));
            }
            look = sample(rng);
        }
        look
    }
}
