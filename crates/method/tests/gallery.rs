//! The compositor against its scalar reference, and the gallery's clustering guarantees.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus as Rng;
use visobjd_compositor::color::encode_srgb8;
use visobjd_compositor::render::{composite, render_reference, weights};
use visobjd_method::gallery::{lab_proxies, mean_delta_e};
use visobjd_method::objective::{Aspects, Objective, Region, analyze};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_scene::look::{Level, Look};

fn stage(name: &str, lights: usize) -> Stage {
    let dir = visobjd_testkit::temp_dir(name);
    visobjd_testkit::stripes(&dir, lights, true);
    Stage::load(&dir, 0).unwrap()
}

fn objective() -> Objective {
    let img = image::RgbImage::from_fn(60, 40, |x, y| {
        image::Rgb(if x < 30 {
            [240, 140, 40]
        } else if y < 20 {
            [30, 50, 160]
        } else {
            [220, 220, 210]
        })
    });
    Objective {
        image: "test.png".into(),
        aspects: Aspects::Both,
        region: Region::FULL,
        analysis: analyze(&img, Region::FULL, 5),
    }
}

fn random_look(n: usize, rng: &mut Rng) -> Look {
    use rand::RngExt;
    Look {
        levels: (0..n)
            .map(|_| Level {
                intensity: rng.random(),
                color: [rng.random(), rng.random(), rng.random()],
                position: None,
            })
            .collect(),
    }
}

#[test]
fn batched_compositor_matches_the_scalar_reference() {
    let st = stage("composite", 12);
    let mut rng = Rng::seed_from_u64(11);
    let looks: Vec<Look> = (0..7).map(|_| random_look(12, &mut rng)).collect();
    let refs: Vec<&Look> = looks.iter().collect();
    let gain = 1.7;
    let w = weights(&st.thumbs, &refs, gain);
    let mut outs: Vec<Vec<f32>> = looks
        .iter()
        .map(|_| vec![0.0; st.thumbs.pixels() * 3])
        .collect();
    composite(&st.thumbs, &w, &mut outs, |v| v);
    let bytes = visobjd_compositor::render::render_srgb8(&st.thumbs, &refs, gain);
    for (k, look) in looks.iter().enumerate() {
        let want = render_reference(&st.thumbs, look, gain);
        for (i, (a, b)) in outs[k].iter().zip(&want).enumerate() {
            assert!((a - b).abs() <= 1e-4, "look {k} sample {i}: {a} vs {b}");
        }
        for (a, b) in bytes[k].as_raw().iter().zip(&want) {
            assert_eq!(*a, encode_srgb8(*b));
        }
    }
}

fn generate(
    st: &Stage,
    seed: u64,
    count: usize,
    clusters: usize,
) -> visobjd_method::gallery::Generation {
    let base = Look::off(st.scene.lights.len());
    st.generate(
        &GenerateRequest {
            objectives: &[objective()],
            constraints: &Constraints::none(&st.rig),
            base: &base,
            spread: Spread::default(),
            count,
            clusters,
            steer: None,
        },
        &mut Rng::seed_from_u64(seed),
    )
}

#[test]
fn gallery_respects_its_bounds_and_separates_representatives() {
    let st = stage("gallery", 16);
    for (seed, clusters) in [(1, 12), (2, 5), (3, 1)] {
        let g = generate(&st, seed, 100, clusters);
        assert!(!g.exhausted);
        assert_eq!(g.candidates.len(), 100);
        assert!(g.entries.len() <= clusters, "{} entries", g.entries.len());
        assert!(g.draws >= 100);
        let mut seen: Vec<usize> = g.entries.iter().flatten().copied().collect();
        seen.sort_unstable();
        assert_eq!(
            seen,
            (0..100).collect::<Vec<_>>(),
            "every candidate in one entry"
        );
        let reps: Vec<&Look> = g.entries.iter().map(|e| &g.candidates[e[0]]).collect();
        let labs = lab_proxies(&st.proxy, &reps, st.gain);
        for i in 0..labs.len() {
            for j in 0..i {
                let d = mean_delta_e(&labs[i], &labs[j]);
                assert!(d >= g.threshold, "entries {i},{j}: {d} < {}", g.threshold);
            }
        }
    }
}

#[test]
fn the_same_seed_gives_the_same_gallery() {
    let st = stage("seeded", 10);
    let a = generate(&st, 42, 60, 12);
    let b = generate(&st, 42, 60, 12);
    let c = generate(&st, 43, 60, 12);
    assert_eq!(a.candidates, b.candidates);
    assert_eq!(a.entries, b.entries);
    assert_eq!(a.draws, b.draws);
    assert_ne!(a.candidates, c.candidates);
}

#[test]
fn a_gallery_of_identical_candidates_runs_out_of_draws_and_says_so() {
    // Every light locked: every candidate is the base look, so all but the first are
    // rejected until the draw bound.
    let st = stage("exhausted", 4);
    let mut constraints = Constraints::none(&st.rig);
    constraints.locked = vec![true; 4];
    let base = Look::off(4);
    let g = st.generate(
        &GenerateRequest {
            objectives: &[objective()],
            constraints: &constraints,
            base: &base,
            spread: Spread::default(),
            count: 10,
            clusters: 12,
            steer: None,
        },
        &mut Rng::seed_from_u64(5),
    );
    assert!(g.exhausted);
    assert_eq!(g.candidates.len(), 1);
    assert_eq!(g.draws, 10 * visobjd_method::gallery::DRAWS_PER_CANDIDATE);
    let rejections = (g.draws - 1) as f32;
    assert!((g.threshold - 20.0 / (1.0 + 0.1 * rejections)).abs() < 1e-4);
}

#[test]
fn thumbnails_rendered_beside_the_drawing_are_the_final_representatives() {
    // The representatives' thumbnails start as soon as every entry exists; with more
    // entries allowed than candidates they are rendered at the end, and a gallery asked for
    // no entries has one.
    let st = stage("overlap", 10);
    for (seed, count, clusters) in [(7, 60, 12), (8, 40, 3), (9, 10, 60), (10, 20, 0)] {
        let g = generate(&st, seed, count, clusters);
        let reps: Vec<&Look> = g.entries.iter().map(|e| &g.candidates[e[0]]).collect();
        assert_eq!(g.thumbnails.len(), g.entries.len());
        assert!(*g.thumbnails == *st.thumbnails(&reps), "seed {seed}");
    }
}
