//! The preference model (crates/method/src/preference.rs) against an independent
//! Gaussian-process regression in numpy (tests/peers/gp_reference.py), and what it learns
//! from ratings made by a rule it is never told.

use std::io::Write;
use std::process::{Command, Stdio};

use rand::rngs::Xoshiro256PlusPlus as Rng;
use rand::{RngExt, SeedableRng};
use visobjd_method::preference::{Features, Hyper, Model, Point, fit, log_likelihood};
use visobjd_scene::Scene;
use visobjd_scene::look::{Level, Look};

/// Six lights in three groups (left dimmers, right rgb, two movers of three palettes).
fn scene() -> Scene {
    let mut toml = String::from(
        "[[group]]\nname = \"left\"\n[[group]]\nname = \"right\"\n[[group]]\nname = \"movers\"\n\
         [[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n",
    );
    for (ch, group, profile) in [
        (1, "left", "dimmer"),
        (2, "left", "dimmer"),
        (3, "right", "rgb"),
        (4, "right", "rgb"),
    ] {
        toml += &format!(
            "[[light]]\nchannel = {ch}\ngroup = \"{group}\"\nbasis = \"b.exr\"\nprofile = \"{profile}\"\nuniverse = 1\naddress = {}\n",
            ch * 4
        );
    }
    for ch in [5, 6] {
        toml += &format!(
            "[[light]]\nchannel = {ch}\ngroup = \"movers\"\nprofile = \"spot\"\nuniverse = 2\naddress = {}\n",
            ch * 10
        );
        for (n, pan) in [(1, -90.0), (2, 0.0), (3, 90.0)] {
            toml += &format!(
                "[[light.position]]\npalette = {n}\npan = {pan}\ntilt = 30.0\nbasis = \"m{ch}-{n}.exr\"\n"
            );
        }
    }
    Scene::parse(std::path::Path::new("/pref"), &toml).expect("the scene parses")
}

fn random_look(rng: &mut Rng) -> Look {
    Look {
        levels: (0..6)
            .map(|l| Level {
                intensity: rng.random(),
                color: [rng.random(), rng.random(), rng.random()],
                position: (l >= 4).then(|| rng.random_range(1..=3)),
            })
            .collect(),
    }
}

/// The rule the model is never told: stage left (lights 1, 2) brighter than right (3, 4).
fn rule(look: &Look) -> f64 {
    let side = |a: usize, b: usize| look.levels[a].intensity + look.levels[b].intensity;
    if side(0, 1) > side(2, 3) { 1.0 } else { 0.0 }
}

/// numpy's posterior mean at `queries` and log marginal likelihood.
fn numpy(ratings: &[(Point, f64)], hyper: Hyper, queries: &[Point]) -> Option<(Vec<f64>, f64)> {
    if !visobjd_testkit::tools::python(
        "numpy",
        "python3 with numpy",
        "python3 -m pip install numpy",
    ) {
        return None;
    }
    let input = serde_json::json!({
        "x": ratings.iter().map(|(p, _)| p.values()).collect::<Vec<_>>(),
        "kinds": ratings[0].0.kinds(),
        "y": ratings.iter().map(|(_, y)| y).collect::<Vec<_>>(),
        "length2": hyper.length2,
        "signal2": hyper.signal2,
        "noise2": hyper.noise2,
        "queries": queries.iter().map(Point::values).collect::<Vec<_>>(),
    });
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/peers/gp_reference.py"
    );
    let mut child = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(input.to_string().as_bytes())
        .expect("write the input");
    let out = child.wait_with_output().expect("the reference answers");
    assert!(out.status.success(), "gp_reference.py failed");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let mean = v["mean"]
        .as_array()
        .expect("mean")
        .iter()
        .map(|m| m.as_f64().expect("a number"))
        .collect();
    Some((mean, v["lml"].as_f64().expect("lml")))
}

#[test]
fn predictions_and_likelihood_match_an_independent_gaussian_process() {
    let scene = scene();
    let features = Features::new(&scene);
    let mut rng = Rng::seed_from_u64(33);
    let ratings: Vec<(Point, f64)> = (0..20)
        .map(|_| {
            let look = random_look(&mut rng);
            (features.of(&look), rule(&look))
        })
        .collect();
    let queries: Vec<Point> = (0..10)
        .map(|_| features.of(&random_look(&mut rng)))
        .collect();
    // 2 group + 6 light intensities, 2 x 3 Lab, 2 x 2 pan/tilt.
    assert_eq!(ratings[0].0.values().len(), 3 + 6 + 6 + 4);
    let fitted = fit(&ratings);
    for hyper in [Hyper::DEFAULT, fitted] {
        let model = Model::with(&ratings, hyper).expect("a model");
        let Some((mean, lml)) = numpy(&ratings, hyper, &queries) else {
            return;
        };
        for (q, want) in queries.iter().zip(&mean) {
            let got = model.predict(q);
            assert!(
                (got - want).abs() < 1e-9,
                "{hyper:?}: {got} vs numpy {want}"
            );
        }
        let got = log_likelihood(&ratings, hyper).expect("a likelihood");
        assert!(
            (got - lml).abs() < 1e-8 * lml.abs().max(1.0),
            "{got} vs numpy {lml}"
        );
    }
    // The fit finds a better likelihood than the defaults; three ratings keep them.
    assert!(log_likelihood(&ratings, fitted) > log_likelihood(&ratings, Hyper::DEFAULT));
    assert_eq!(fit(&ratings[..3]), Hyper::DEFAULT);
}

#[test]
fn ratings_by_an_untold_rule_predict_it_on_new_looks() {
    let scene = scene();
    let features = Features::new(&scene);
    let mut rng = Rng::seed_from_u64(7);
    let ratings: Vec<(Point, f64)> = (0..30)
        .map(|_| {
            let look = random_look(&mut rng);
            (features.of(&look), rule(&look))
        })
        .collect();
    let model = Model::fitted(&ratings).expect("a model");
    let (mut agree, mut n) = (0, 0);
    for _ in 0..400 {
        let look = random_look(&mut rng);
        let predicted = model.predict(&features.of(&look)) > 0.5;
        agree += usize::from(predicted == (rule(&look) > 0.5));
        n += 1;
    }
    // Chance is a half.
    println!(
        "{agree} of {n} new looks predicted as the rule says ({:?})",
        model.hyper()
    );
    assert!(
        agree * 100 >= n * 75,
        "{agree} of {n} predicted as the rule says"
    );
    // The same ratings give the same model.
    let again = Model::fitted(&ratings).expect("a model");
    assert_eq!(again.hyper(), model.hyper());
    assert!(Model::fitted(&[]).is_none());
}
