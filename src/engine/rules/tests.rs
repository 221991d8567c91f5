//! The rules as the sampler takes them: what `Rules::apply` gives a real stage's sampler.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus as Rng;
use visobjd_method::objective::{Aspects, PaletteColor};
use visobjd_method::sampler::{Plan, Spread, Target};
use visobjd_method::stage::Stage;
use visobjd_scene::look::{Level, Look};
use visobjd_testkit::{TestLight, temp_dir, write_scene};

use super::*;

#[test]
fn excluded_and_pinned_lights_keep_the_base_bit_for_bit_on_a_real_stage() {
    let dir = temp_dir("rules-pins");
    // Eight lights in two groups, each lighting its own 5-pixel column of a 40x20 stage.
    let lights: Vec<TestLight> = (0..8)
        .map(|i| {
            TestLight::rect(
                i + 1,
                Some(if i < 4 { "left" } else { "right" }),
                "rgb",
                1 + 3 * i as u16,
                (5 * i as usize, 0, 5 * i as usize + 5, 20),
                0.8,
            )
        })
        .collect();
    write_scene(&dir, 40, 20, &["left", "right"], &lights);
    let stage = Stage::load(&dir, 40).unwrap();
    let scene = &stage.scene;
    let mut rules = Rules::new(scene);
    // The pin covers columns 0..10 of 40: lights 1 and 2.
    let region = Region::new(0.0, 0.0, 0.25, 1.0).unwrap();
    let pinned: Vec<usize> = (0..8)
        .filter(|&l| stage.footprints.select(region)[l])
        .collect();
    assert_eq!(pinned, vec![0, 1]);
    rules.pins.push(Pin {
        id: 1,
        region,
        lights: pinned,
    });
    let right = scene.group_index("right").unwrap();
    rules.group_exclude[right] = Exclude::Ignore;
    // A light's own exclusion wins over its group's.
    rules.light_exclude[7] = Exclude::Off;
    let mut c = Constraints::none(&stage.rig);
    rules.apply(scene, &mut c);
    // Every light at a different level and colour.
    let base = Look {
        levels: (0..8)
            .map(|i| Level {
                intensity: 0.05 + 0.9 * ((i * 37 % 8) as f32 / 8.0),
                color: [0.9, 0.2 + 0.5 * (i % 3) as f32 / 2.0, 0.1],
                position: None,
            })
            .collect(),
    };
    let t = Target {
        aspects: Aspects::Both,
        area: 1.0,
        selected: vec![true; 8],
        sensitivity: vec![1.0; 8],
        positions: vec![Vec::new(); 8],
        mean: 0.5,
        key: 0.9,
        bright: 0.5,
        palette: vec![PaletteColor {
            color: [0.0, 1.0, 0.0],
            weight: 1.0,
        }],
    };
    let plan = Plan::new(&stage.rig, &c, &[t], &base, Spread::default());
    let mut rng = Rng::seed_from_u64(15);
    let mut changed = [false; 8];
    for _ in 0..300 {
        let look = plan.sample(&base, &mut rng);
        for l in [0, 1, 4, 5, 6] {
            assert_eq!(
                look.levels[l].intensity.to_bits(),
                base.levels[l].intensity.to_bits()
            );
            assert_eq!(
                look.levels[l].color.map(f32::to_bits),
                base.levels[l].color.map(f32::to_bits)
            );
        }
        assert_eq!(look.levels[7].intensity, 0.0);
        for ((c, got), want) in changed.iter_mut().zip(&look.levels).zip(&base.levels) {
            *c |= got != want;
        }
    }
    assert_eq!(
        changed,
        [false, false, true, true, false, false, false, true]
    );
}
