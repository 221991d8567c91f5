//! Moving lights through the method (docs/method.md, "Moving lights"): an objective aimed
//! at one side puts the movers on the palettes that light it, the side is brighter for it
//! than with the movers locked elsewhere, and a candidate's picture is the sum of the
//! images of the positions it chose, read from the files.

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus as Rng;
use visobjd_compositor::basis::read_exr;
use visobjd_compositor::color::encode_srgb8;
use visobjd_method::objective::{Aspects, Objective, Region, analyze};
use visobjd_method::sampler::{Constraints, Spread};
use visobjd_method::stage::{GenerateRequest, Stage};
use visobjd_scene::look::{Level, Look};

const W: usize = 64;
const H: usize = 32;
/// Where each palette's spot lands (x, of W).
const SPOTS: [usize; 4] = [8, 24, 40, 56];

/// Two washes (left and right halves, dim) and three movers of four palettes each, every
/// spot a disc of its own size around its palette's x.
fn write_stage(dir: &Path) {
    std::fs::create_dir_all(dir.join("basis")).expect("mkdir");
    let mut toml = String::from(
        "[[group]]\nname = \"movers\"\n[[profile]]\nname = \"spot\"\nchannels = [\"intensity\", \"pan16\", \"tilt16\"]\n",
    );
    for (ch, left) in [(1u32, true), (2, false)] {
        let basis = format!("basis/{ch}.exr");
        visobjd_testkit::write_exr(&dir.join(&basis), W, H, |x, _| {
            if (x < W / 2) == left {
                [0.1; 3]
            } else {
                [0.0; 3]
            }
        });
        toml += &format!(
            "[[light]]\nchannel = {ch}\nbasis = \"{basis}\"\nprofile = \"dimmer\"\nuniverse = 1\naddress = {ch}\n"
        );
    }
    for m in 0..3u32 {
        let ch = 11 + m;
        toml += &format!(
            "[[light]]\nchannel = {ch}\ngroup = \"movers\"\nprofile = \"spot\"\nuniverse = 1\naddress = {}\n",
            10 + 5 * m
        );
        for (n, &cx) in SPOTS.iter().enumerate() {
            let basis = format!("basis/{ch}-{n}.exr");
            let r2 = (5.0 + m as f32) * (5.0 + m as f32);
            let level = 0.5 + 0.1 * m as f32;
            visobjd_testkit::write_exr(&dir.join(&basis), W, H, |x, y| {
                let d2 = (x as f32 - cx as f32).powi(2) + (y as f32 - 16.0).powi(2);
                if d2 < r2 {
                    [level, level * 0.9, level * 0.8]
                } else {
                    [0.0; 3]
                }
            });
            toml += &format!(
                "[[light.position]]\npalette = {}\npan = {}\ntilt = 20.0\nbasis = \"{basis}\"\n",
                n + 1,
                -60.0 + 40.0 * n as f64
            );
        }
    }
    std::fs::write(dir.join("scene.toml"), toml).expect("write scene.toml");
}

fn objective(region: Region) -> Objective {
    let img = image::RgbImage::from_fn(40, 20, |x, _| image::Rgb([(60 + 4 * x) as u8; 3]));
    Objective {
        image: "grey.png".into(),
        aspects: Aspects::Intensity,
        region,
        analysis: analyze(&img, Region::FULL, 5),
    }
}

/// The mean luminance of `img` over columns `xs`.
fn mean_luma(img: &image::RgbImage, xs: std::ops::Range<u32>) -> f64 {
    let mut sum = 0.0;
    let mut n = 0.0;
    for y in 0..img.height() {
        for x in xs.clone() {
            let p = img.get_pixel(x, y).0;
            sum += 0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2]);
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn an_objective_aimed_at_one_side_aims_the_movers_there() {
    let dir = visobjd_testkit::temp_dir("method-movers");
    write_stage(&dir);
    let stage = Stage::load(&dir, 0).expect("the stage loads");
    let right = Region::new(0.75, 0.0, 1.0, 1.0).expect("region");
    let obj = objective(right);
    let movers: Vec<usize> = (2..5).collect();
    let mut base = Look::off(stage.scene.lights.len());
    for &l in &movers {
        base.levels[l] = Level {
            intensity: 1.0,
            color: [1.0; 3],
            position: Some(1),
        };
    }
    let generate = |constraints: &Constraints, seed| {
        stage.generate(
            &GenerateRequest {
                objectives: std::slice::from_ref(&obj),
                constraints,
                base: &base,
                spread: Spread::default(),
                count: 60,
                clusters: 6,
                steer: None,
            },
            &mut Rng::seed_from_u64(seed),
        )
    };
    let free = Constraints::none(&stage.rig);
    let g = generate(&free, 5);
    let aimed = g
        .candidates
        .iter()
        .flat_map(|c| movers.iter().map(move |&l| c.levels[l].position))
        .filter(|&p| p == Some(4))
        .count();
    let all = g.candidates.len() * movers.len();
    // Chance is a quarter; the right-hand palette is the only one the region selects.
    assert!(
        aimed * 10 >= all * 9,
        "{aimed} of {all} mover positions on palette 4"
    );

    // Locked on the left, the movers leave the right side darker.
    let mut locked = free.clone();
    for &l in &movers {
        locked.locked[l] = true;
    }
    let held = generate(&locked, 5);
    assert!(
        held.candidates
            .iter()
            .all(|c| movers.iter().all(|&l| c.levels[l].position == Some(1)))
    );
    let side = |g: &visobjd_method::gallery::Generation| {
        let thumbs = stage.thumbnails(
            &g.entries
                .iter()
                .map(|e| &g.candidates[e[0]])
                .collect::<Vec<_>>(),
        );
        thumbs.iter().map(|t| mean_luma(t, 48..64)).sum::<f64>() / thumbs.len() as f64
    };
    let (free_side, held_side) = (side(&g), side(&held));
    assert!(
        free_side > held_side + 5.0,
        "right side {free_side:.1} free vs {held_side:.1} locked left"
    );

    // A candidate's thumbnail is the sum of its lights' chosen images, read from the files.
    for e in &g.entries {
        let look = &g.candidates[e[0]];
        let got = &stage.thumbnails(&[look])[0];
        let mut want = vec![[0.0f32; 3]; W * H];
        for (l, light) in stage.scene.lights.iter().enumerate() {
            let path = light
                .position_of(&look.levels[l])
                .map_or(light.basis.clone(), |p| p.basis.clone());
            let img = read_exr(&path).expect("the image reads");
            for (w, p) in want.iter_mut().zip(&img.pixels) {
                for (w, v) in w.iter_mut().zip(p) {
                    *w += look.levels[l].intensity * v;
                }
            }
        }
        for (i, (w, g)) in want.iter().zip(got.pixels()).enumerate() {
            for (c, (&w, &got)) in w.iter().zip(&g.0).enumerate() {
                let code = encode_srgb8(w * stage.gain);
                assert!(
                    code.abs_diff(got) <= 1,
                    "pixel {i} channel {c}: {got} vs {code}"
                );
            }
        }
    }
}

#[test]
fn a_position_without_an_image_is_never_drawn_and_the_rest_are() {
    let dir = visobjd_testkit::temp_dir("method-movers-unseen");
    write_stage(&dir);
    std::fs::remove_file(dir.join("basis/11-3.exr")).expect("palette 4 of light 11");
    let stage = Stage::from_scene(visobjd_scene::Scene::load(&dir).expect("scene"), 0)
        .expect("the stage loads");
    assert!(stage.unseen.is_empty(), "{:?}", stage.unseen);
    let unseen: Vec<(usize, u32)> = stage
        .unseen_positions
        .iter()
        .map(|u| (u.light, u.palette))
        .collect();
    assert_eq!(unseen, [(2, 4)]);
    let obj = objective(Region::new(0.75, 0.0, 1.0, 1.0).expect("region"));
    let g = stage.generate(
        &GenerateRequest {
            objectives: std::slice::from_ref(&obj),
            constraints: &Constraints::none(&stage.rig),
            base: &Look::off(stage.scene.lights.len()),
            spread: Spread::default(),
            count: 40,
            clusters: 4,
            steer: None,
        },
        &mut Rng::seed_from_u64(9),
    );
    let on = |l: usize, n: u32| {
        g.candidates
            .iter()
            .filter(|c| c.levels[l].position == Some(n))
            .count()
    };
    assert_eq!(
        on(2, 4),
        0,
        "light 11 never on the palette it has no image for"
    );
    assert_eq!(on(3, 4), g.candidates.len(), "light 12 still goes there");
}
