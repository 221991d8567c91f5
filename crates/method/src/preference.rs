//! A preference model over looks: Gaussian-process regression of the designer's ratings
//! (0..1) over a look's features, as in *Design Adjectives* (Shimizu, Fisher, Paris,
//! McCann, Fatahalian, UIST 2020), so a sampler can ask how a candidate would be rated
//! before anyone sees it.
//!
//! Pure: plain data in, numbers out, no randomness and no I/O. The kernel is a squared
//! exponential with one length scale per kind of feature (group intensities, light
//! intensities, colours, positions), its hyperparameters fitted to the ratings by the log
//! marginal likelihood; with few ratings the fit is held near the defaults.

use visobjd_compositor::color::srgb_to_lab;
use visobjd_scene::Scene;
use visobjd_scene::look::Look;

use crate::sampler::full_value;

/// The kinds of feature, each with its own length scale.
const KINDS: usize = 4;

/// What a look is described by: per group its mean intensity, per light its intensity,
/// the CIELAB of its colour (lights that have colour, scaled to about 0..1) and a mover's
/// pan and tilt (as fractions of its profile's travel).
#[derive(Debug, Clone)]
pub struct Features {
    groups: Vec<Vec<usize>>,
    coloured: Vec<bool>,
    /// Per light, its positions' (palette, pan, tilt) as fractions of the travel.
    aims: Vec<Vec<(u32, f64, f64)>>,
}

impl Features {
    /// The features of `scene`'s rig.
    pub fn new(scene: &Scene) -> Features {
        Features {
            groups: scene.groups.iter().map(|g| g.lights.clone()).collect(),
            coloured: (0..scene.lights.len())
                .map(|l| scene.profile(l).has_colour())
                .collect(),
            aims: scene
                .lights
                .iter()
                .enumerate()
                .map(|(l, light)| {
                    let p = scene.profile(l);
                    light
                        .positions
                        .iter()
                        .map(|q| (q.palette, q.pan / p.pan_range, q.tilt / p.tilt_range))
                        .collect()
                })
                .collect(),
        }
    }

    /// The feature vector of `look` and each entry's kind.
    pub fn of(&self, look: &Look) -> Point {
        let mut values = Vec::new();
        let mut kinds = Vec::new();
        let mut push = |v: f64, kind: usize| {
            values.push(v);
            kinds.push(kind as u8);
        };
        for g in &self.groups {
            let sum: f32 = g.iter().map(|&l| look.levels[l].intensity).sum();
            push(f64::from(sum) / g.len().max(1) as f64, 0);
        }
        for (l, lv) in look.levels.iter().enumerate() {
            push(f64::from(lv.intensity), 1);
            if self.coloured[l] {
                let lab = srgb_to_lab(full_value(lv.color));
                push(f64::from(lab[0]) / 100.0, 2);
                push(f64::from(lab[1]) / 100.0, 2);
                push(f64::from(lab[2]) / 100.0, 2);
            }
            let aims = &self.aims[l];
            if let Some(&(_, pan, tilt)) = lv.position_in(aims, |a| a.0) {
                push(pan, 3);
                push(tilt, 3);
            }
        }
        Point { values, kinds }
    }
}

/// A look's features ([`Features::of`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    values: Vec<f64>,
    kinds: Vec<u8>,
}

impl Point {
    /// The feature values, in order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Each feature's kind (0 group intensity, 1 light intensity, 2 colour, 3 position):
    /// which length scale it is measured by.
    pub fn kinds(&self) -> &[u8] {
        &self.kinds
    }

    /// Per kind, the squared distance to `other` (a point of the same rig).
    fn sq_distances(&self, other: &Point) -> [f64; KINDS] {
        let mut d = [0.0; KINDS];
        for ((a, b), &k) in self.values.iter().zip(&other.values).zip(&self.kinds) {
            d[usize::from(k)] += (a - b) * (a - b);
        }
        d
    }

    /// How many features of each kind.
    fn counts(&self) -> [f64; KINDS] {
        let mut n = [0.0; KINDS];
        for &k in &self.kinds {
            n[usize::from(k)] += 1.0;
        }
        n
    }
}

/// The kernel's hyperparameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hyper {
    /// Squared length scale per kind, divided by that kind's feature count: a look's
    /// distance is measured per feature, so one scale suits rigs of any size.
    pub length2: [f64; KINDS],
    /// Signal variance.
    pub signal2: f64,
    /// Noise variance: how far two ratings of one look may differ.
    pub noise2: f64,
}

impl Hyper {
    /// Where the fit starts and what it stays near with a few ratings: a look differs by
    /// its features' mean square difference against 0.05 (a fifth of the range, squared,
    /// about), ratings vary by about a quarter of their range, and a tenth is noise.
    pub const DEFAULT: Hyper = Hyper {
        length2: [0.05; KINDS],
        signal2: 0.0625,
        noise2: 0.01,
    };
}

/// A fitted preference model: predicts the rating of a look from the rated ones.
#[derive(Debug, Clone)]
pub struct Model {
    points: Vec<Point>,
    /// `(K + noise I)^-1 (y - mean)`.
    alpha: Vec<f64>,
    mean: f64,
    hyper: Hyper,
    counts: [f64; KINDS],
}

/// Ratings needed before the hyperparameters are fitted rather than left at the defaults.
const FIT_FROM: usize = 4;

impl Model {
    /// The model of `ratings` (a look's point and its score in 0..1) with `hyper`; `None`
    /// without ratings, or when the kernel matrix cannot be factored.
    pub fn with(ratings: &[(Point, f64)], hyper: Hyper) -> Option<Model> {
        let f = factor(ratings, hyper)?;
        Some(Model {
            points: ratings.iter().map(|(p, _)| p.clone()).collect(),
            alpha: f.alpha,
            mean: f.mean,
            hyper,
            counts: f.counts,
        })
    }

    /// The model of `ratings` with its hyperparameters fitted ([`fit`]).
    pub fn fitted(ratings: &[(Point, f64)]) -> Option<Model> {
        Model::with(ratings, fit(ratings))
    }

    /// The predicted rating of `x` (the posterior mean).
    pub fn predict(&self, x: &Point) -> f64 {
        self.mean
            + self
                .points
                .iter()
                .zip(&self.alpha)
                .map(|(p, a)| a * kernel(&self.hyper, &self.counts, x, p))
                .sum::<f64>()
    }

    /// The hyperparameters in use.
    pub fn hyper(&self) -> Hyper {
        self.hyper
    }
}

/// The squared-exponential kernel between two points.
fn kernel(h: &Hyper, counts: &[f64; KINDS], a: &Point, b: &Point) -> f64 {
    let d = a.sq_distances(b);
    let mut e = 0.0;
    for k in 0..KINDS {
        if counts[k] > 0.0 {
            e += d[k] / (h.length2[k] * counts[k]);
        }
    }
    h.signal2 * (-0.5 * e).exp()
}

/// The kernel matrix of some ratings factored, and what the model keeps of it.
struct Factored {
    /// Lower Cholesky factor of `K + noise I`.
    chol: Vec<f64>,
    alpha: Vec<f64>,
    mean: f64,
    counts: [f64; KINDS],
}

/// `ratings`' kernel matrix under `hyper`, factored; `None` without ratings or when it is
/// not positive definite.
fn factor(ratings: &[(Point, f64)], hyper: Hyper) -> Option<Factored> {
    let (first, _) = ratings.first()?;
    let counts = first.counts();
    let n = ratings.len();
    let mean = ratings.iter().map(|(_, y)| y).sum::<f64>() / n as f64;
    let mut k = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let v = kernel(&hyper, &counts, &ratings[i].0, &ratings[j].0);
            k[i * n + j] = v;
            k[j * n + i] = v;
        }
        k[i * n + i] += hyper.noise2;
    }
    let chol = cholesky(&k, n)?;
    let y: Vec<f64> = ratings.iter().map(|(_, y)| y - mean).collect();
    let alpha = solve(&chol, n, &y);
    Some(Factored {
        chol,
        alpha,
        mean,
        counts,
    })
}

/// The log marginal likelihood of `ratings` (centred on their mean) under `hyper`: the
/// fit's objective. `None` when the kernel matrix cannot be factored.
pub fn log_likelihood(ratings: &[(Point, f64)], hyper: Hyper) -> Option<f64> {
    let f = factor(ratings, hyper)?;
    let n = ratings.len();
    let fit: f64 = ratings
        .iter()
        .zip(&f.alpha)
        .map(|((_, y), a)| (y - f.mean) * a)
        .sum();
    let log_det: f64 = (0..n).map(|i| f.chol[i * n + i].ln()).sum::<f64>() * 2.0;
    Some(-0.5 * fit - 0.5 * log_det - 0.5 * n as f64 * (2.0 * std::f64::consts::PI).ln())
}

/// Hyperparameters for `ratings`: the defaults below [`FIT_FROM`] ratings, else the best
/// log marginal likelihood found by a deterministic coordinate search over each
/// parameter's logarithm (steps of a factor 2, then 1.41, 1.19, ...), each held within a
/// factor 100 of its default so a handful of ratings cannot fit a degenerate kernel.
pub fn fit(ratings: &[(Point, f64)]) -> Hyper {
    let mut best = Hyper::DEFAULT;
    if ratings.len() < FIT_FROM {
        return best;
    }
    let mut score = log_likelihood(ratings, best).unwrap_or(f64::NEG_INFINITY);
    let mut step = 2.0f64;
    while step > 1.05 {
        let mut improved = false;
        for p in 0..KINDS + 2 {
            for factor in [step, 1.0 / step] {
                let mut h = best;
                let (value, default) = match p {
                    k if k < KINDS => (&mut h.length2[k], Hyper::DEFAULT.length2[k]),
                    k if k == KINDS => (&mut h.signal2, Hyper::DEFAULT.signal2),
                    _ => (&mut h.noise2, Hyper::DEFAULT.noise2),
                };
                *value *= factor;
                if !(default / 100.0..=default * 100.0).contains(value) {
                    continue;
                }
                if let Some(s) = log_likelihood(ratings, h)
                    && s > score + 1e-12
                {
                    (best, score, improved) = (h, s, true);
                }
            }
        }
        if !improved {
            step = step.sqrt();
        }
    }
    best
}

/// The lower Cholesky factor of the `n x n` row-major matrix `a`, `None` if it is not
/// positive definite.
fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            if i == j {
                let d = a[i * n + i] - s;
                if !(d > 0.0 && d.is_finite()) {
                    return None;
                }
                l[i * n + i] = d.sqrt();
            } else {
                l[i * n + j] = (a[i * n + j] - s) / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// `x` with `L L^T x = b`, `l` a lower Cholesky factor.
fn solve(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; n];
    for i in 0..n {
        let s: f64 = (0..i).map(|k| l[i * n + k] * y[k]).sum();
        y[i] = (b[i] - s) / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| l[k * n + i] * x[k]).sum();
        x[i] = (y[i] - s) / l[i * n + i];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_refuses_what_is_not_positive_definite() {
        let a = [4.0, 2.0, 0.6, 2.0, 5.0, 1.5, 0.6, 1.5, 3.0];
        let l = cholesky(&a, 3).expect("positive definite");
        let x = solve(&l, 3, &[1.0, 2.0, 3.0]);
        for i in 0..3 {
            let ax: f64 = (0..3).map(|j| a[i * 3 + j] * x[j]).sum();
            assert!((ax - [1.0, 2.0, 3.0][i]).abs() < 1e-12, "{ax}");
        }
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
        assert!(cholesky(&[f64::NAN], 1).is_none());
    }
}
