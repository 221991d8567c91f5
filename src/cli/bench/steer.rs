//! The steering row (issue 33): a generate steered by 20 ratings against the same generate
//! unsteered, in one run.

use rand::SeedableRng;

use super::{Rng, Row, median};
use visobjd_method::objective::Objective;
use visobjd_method::preference::{Features, Model, Point};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_method::steer::{Mode, Steer};
use visobjd_scene::look::Look;

/// Ratings the row's model learns from.
const RATINGS: usize = 20;

/// The row: the median of `runs` steered generates (100 candidates into 12 entries,
/// thumbnails; `towards` 20 ratings of candidates by "the first half of the lights brighter
/// than the second") over the median unsteered, taken in turns.
pub(super) fn row(stage: &Stage, objective: &Objective, runs: usize) -> Row {
    let lights = stage.scene.lights.len();
    let base = Look::off(lights);
    let constraints = Constraints::none(&stage.rig);
    let timed = |steer: Option<&Steer>, seed: u64| {
        let started = std::time::Instant::now();
        let g = stage.generate(
            &GenerateRequest {
                objectives: std::slice::from_ref(objective),
                constraints: &constraints,
                base: &base,
                spread: Spread::default(),
                count: 100,
                clusters: 12,
                steer,
            },
            &mut Rng::seed_from_u64(seed),
        );
        (started.elapsed().as_secs_f64() * 1000.0, g)
    };
    let rule = |look: &Look| {
        let half = lights / 2;
        let sum = |r: std::ops::Range<usize>| r.map(|l| look.levels[l].intensity).sum::<f32>();
        if sum(0..half) > sum(half..lights) {
            1.0
        } else {
            0.0
        }
    };
    let (_, first) = timed(None, 7);
    let rated: Vec<(Look, f64)> = first
        .candidates
        .iter()
        .take(RATINGS)
        .map(|c| (c.clone(), rule(c)))
        .collect();
    let features = Features::new(&stage.scene);
    let points: Vec<(Point, f64)> = rated.iter().map(|(l, s)| (features.of(l), *s)).collect();
    let groups = stage
        .scene
        .groups
        .iter()
        .map(|g| g.lights.clone())
        .collect();
    let steer = Model::fitted(&points)
        .map(|model| Steer::new(model, features, Mode::Towards, &base, &rated, groups));
    let (mut steered, mut plain, mut turned_down) = (Vec::new(), Vec::new(), 0);
    for seed in 1..=runs as u64 {
        let (ms, g) = timed(steer.as_ref(), seed);
        steered.push(ms);
        turned_down += g.turned_down;
        plain.push(timed(None, seed).0);
    }
    let (a, b) = (median(&mut steered), median(&mut plain));
    Row {
        name: format!(
            "/vo/generate steered by {RATINGS} ratings over not ({b:.1} ms, {} turned down)",
            turned_down / runs.max(1)
        ),
        value: a,
        unit: "ms",
        ratio: a / b,
        target: Some(1.5),
        more: false,
        note: String::new(),
    }
}
