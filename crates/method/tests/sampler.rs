//! The sampler's statistical properties (paper 4.2.3) and the designer's constraints,
//! with fixed seeds and enough samples.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus as Rng;
use rand_distr::{Distribution, Normal};
use visobjd_method::objective::{Aspects, PaletteColor, Region};
use visobjd_method::sampler::{
    Constraints, Keys, LightGroups, Plan, Spread, Target, gibbs, key_count,
};
use visobjd_scene::look::{Level, Look};
use visobjd_testkit::{TestLight, temp_dir, write_scene};

fn mean(v: &[f32]) -> f32 {
    v.iter().sum::<f32>() / v.len() as f32
}

fn variance(v: &[f32]) -> f32 {
    let m = mean(v);
    v.iter().map(|x| (x - m).powi(2)).sum::<f32>() / (v.len() - 1) as f32
}

/// A rig of `n` lights, each its own group, all colour-capable.
fn rig(n: usize) -> LightGroups {
    LightGroups {
        groups: (0..n).map(|l| vec![l]).collect(),
        colored: vec![true; n],
    }
}

fn target(n: usize, mean: f32, key: f32, bright: f32) -> Target {
    Target {
        aspects: Aspects::Intensity,
        area: 1.0,
        selected: vec![true; n],
        sensitivity: vec![1.0; n],
        positions: vec![Vec::new(); n],
        mean,
        key,
        bright,
        palette: Vec::new(),
    }
}

#[test]
fn mean_intensity_sits_on_target_and_keys_on_key_level() {
    let n = 24;
    let (mu_a, mu_k, b) = (0.35, 0.8, 0.5);
    let mut rng = Rng::seed_from_u64(1);
    let keys = key_count(b, n);
    assert_eq!(keys, 6);
    let mut means = Vec::new();
    let mut key_values = Vec::new();
    for _ in 0..1000 {
        let designated = Keys::Designated((0..n).map(|i| i < keys).collect());
        let v = gibbs(
            n,
            0,
            0.0,
            &designated,
            mu_a,
            mu_k,
            Spread::default(),
            &mut rng,
        );
        means.push(mean(&v));
        key_values.extend_from_slice(&v[..keys]);
    }
    assert!((mean(&means) - mu_a).abs() < 0.01, "mean {}", mean(&means));
    assert!(
        (mean(&key_values) - mu_k).abs() < 0.02,
        "keys {}",
        mean(&key_values)
    );
}

/// The direct bimodal draw of paper 4.2.3: keys from N(mu_k, sigma_k), every fill from one
/// N(mu_x, sigma_a) with mu_x from equation 2 evaluated once.
fn bimodal(n: usize, keys: usize, mu_a: f32, mu_k: f32, rng: &mut Rng) -> Vec<f32> {
    let s = Spread::default();
    let key = Normal::new(mu_k, s.key).unwrap();
    let mut v: Vec<f32> = (0..keys).map(|_| key.sample(rng).clamp(0.0, 1.0)).collect();
    let sum: f32 = v.iter().sum();
    let mu_x = (n as f32 * mu_a - sum) / (n - keys) as f32;
    let fill = Normal::new(mu_x, s.fill).unwrap();
    v.extend((keys..n).map(|_| fill.sample(rng).clamp(0.0, 1.0)));
    v
}

#[test]
fn sequential_sampling_is_tighter_overall_and_wider_per_light_than_bimodal() {
    let n = 20;
    let (mu_a, mu_k) = (0.4, 0.85);
    let keys = 5;
    let designated = Keys::Designated((0..n).map(|i| i < keys).collect());
    let mut rng = Rng::seed_from_u64(2);
    let mut g_means = Vec::new();
    let mut b_means = Vec::new();
    let mut g_fill = vec![Vec::new(); n];
    let mut b_fill = vec![Vec::new(); n];
    for _ in 0..2000 {
        let g = gibbs(
            n,
            0,
            0.0,
            &designated,
            mu_a,
            mu_k,
            Spread::default(),
            &mut rng,
        );
        let b = bimodal(n, keys, mu_a, mu_k, &mut rng);
        g_means.push(mean(&g));
        b_means.push(mean(&b));
        for i in keys..n {
            g_fill[i].push(g[i]);
            b_fill[i].push(b[i]);
        }
    }
    let (g_sd, b_sd) = (variance(&g_means).sqrt(), variance(&b_means).sqrt());
    assert!(
        g_sd * 3.0 <= b_sd,
        "spread of the mean: sequential {g_sd}, bimodal {b_sd}"
    );
    let g_var = mean(&(keys..n).map(|i| variance(&g_fill[i])).collect::<Vec<_>>());
    let b_var = mean(&(keys..n).map(|i| variance(&b_fill[i])).collect::<Vec<_>>());
    assert!(
        g_var > b_var,
        "per-light variance: sequential {g_var}, bimodal {b_var}"
    );
}

#[test]
fn full_sampler_hits_the_mean_over_a_thousand_candidates() {
    let n = 16;
    let r = rig(n);
    let t = target(n, 0.45, 0.9, 0.4);
    let base = Look::off(n);
    let plan = Plan::new(&r, &Constraints::none(&r), &[t], &base, Spread::default());
    let mut rng = Rng::seed_from_u64(3);
    let means: Vec<f32> = (0..1000)
        .map(|_| {
            let look = plan.sample(&base, &mut rng);
            mean(&look.levels.iter().map(|l| l.intensity).collect::<Vec<_>>())
        })
        .collect();
    assert!((mean(&means) - 0.45).abs() < 0.01, "{}", mean(&means));
}

#[test]
fn a_flat_reference_gives_no_keys() {
    assert_eq!(key_count(0.0, 40), 0);
    assert_eq!(key_count(1.0, 40), 20);
    assert_eq!(key_count(0.5, 40), 10);
}

#[test]
fn brightness_normalisation_evens_out_lights_of_different_strength() {
    // Light 0 is four times as strong in the region as light 1: it gets a quarter of the
    // factor, and the factors' mean over the two is one.
    let r = rig(2);
    let mut t = target(2, 0.5, 0.5, 0.0);
    t.sensitivity = vec![4.0, 1.0];
    let base = Look::off(2);
    let plan = Plan::new(
        &r,
        &Constraints::none(&r),
        &[t],
        &base,
        Spread {
            key: 0.0,
            fill: 0.0,
        },
    );
    let look = plan.sample(&base, &mut Rng::seed_from_u64(4));
    // Raw draws are both 0.5; factors (1/4)/(5/8) = 0.4 and 1/(5/8) = 1.6 (capped at 1).
    assert!((look.levels[0].intensity - 0.2).abs() < 1e-6, "{:?}", look);
    assert!((look.levels[1].intensity - 0.8).abs() < 1e-6, "{:?}", look);
}

#[test]
fn groups_share_one_value_and_locked_lights_keep_the_base_exactly() {
    let n = 9;
    let r = LightGroups {
        groups: vec![vec![0, 1, 2], vec![3, 4, 5], vec![6, 7, 8]],
        colored: vec![true; n],
    };
    let mut base = Look::off(n);
    for (i, l) in base.levels.iter_mut().enumerate() {
        *l = Level {
            intensity: 0.1 + 0.07 * i as f32,
            color: [0.3, 0.6, 0.9],
            position: None,
        };
    }
    let mut c = Constraints::none(&r);
    c.locked[4] = true; // one light of group 2
    for l in [6, 7, 8] {
        c.locked[l] = true; // all of group 3
    }
    let mut t = target(n, 0.6, 0.9, 0.5);
    t.aspects = Aspects::Both;
    t.palette = vec![PaletteColor {
        color: [1.0, 0.0, 0.0],
        weight: 1.0,
    }];
    let plan = Plan::new(&r, &c, &[t], &base, Spread::default());
    let mut rng = Rng::seed_from_u64(5);
    for _ in 0..200 {
        let look = plan.sample(&base, &mut rng);
        for l in [4, 6, 7, 8] {
            assert_eq!(
                look.levels[l].intensity.to_bits(),
                base.levels[l].intensity.to_bits()
            );
            assert_eq!(look.levels[l].color, base.levels[l].color);
        }
        assert_eq!(look.levels[0].intensity, look.levels[1].intensity);
        assert_eq!(look.levels[1].intensity, look.levels[2].intensity);
        assert_eq!(look.levels[3].intensity, look.levels[5].intensity);
        assert_eq!(look.levels[0].color, [1.0, 0.0, 0.0]);
    }
}

#[test]
fn colours_follow_their_weights_and_dimmers_stay_white() {
    let n = 40;
    let mut r = rig(n);
    for l in (0..n).step_by(4) {
        r.colored[l] = false;
    }
    let mut base = Look::off(n);
    for l in &mut base.levels {
        l.intensity = 0.5;
    }
    let mut t = target(n, 0.5, 0.5, 0.0);
    t.aspects = Aspects::Color;
    let red = [1.0, 0.0, 0.0];
    let blue = [0.0, 0.0, 1.0];
    t.palette = vec![
        PaletteColor {
            color: red,
            weight: 0.7,
        },
        PaletteColor {
            color: blue,
            weight: 0.3,
        },
    ];
    let plan = Plan::new(&r, &Constraints::none(&r), &[t], &base, Spread::default());
    let mut rng = Rng::seed_from_u64(6);
    let mut red_share = Vec::new();
    for _ in 0..500 {
        let look = plan.sample(&base, &mut rng);
        let coloured: Vec<&Level> = (0..n)
            .filter(|&l| r.colored[l])
            .map(|l| &look.levels[l])
            .collect();
        red_share.push(
            coloured.iter().filter(|l| l.color == red).count() as f32 / coloured.len() as f32,
        );
        for l in (0..n).step_by(4) {
            assert_eq!(look.levels[l].color, [1.0; 3], "dimmer {l} was coloured");
        }
        assert_eq!(
            look.levels[1].intensity, 0.5,
            "colour-only changes no intensity"
        );
    }
    assert!(
        (mean(&red_share) - 0.7).abs() < 0.05,
        "{}",
        mean(&red_share)
    );
}

#[test]
fn a_colour_only_objective_over_dark_lights_takes_the_references_intensity_too() {
    let n = 12;
    let r = rig(n);
    let colour_only = |mean| {
        let mut t = target(n, mean, 0.8, 0.3);
        t.aspects = Aspects::Color;
        t.palette = vec![PaletteColor {
            color: [1.0, 0.0, 0.0],
            weight: 1.0,
        }];
        t
    };
    let none = Constraints::none(&r);
    // A dark base: without intensity the colours would fall on lights at 0.
    let dark = Look::off(n);
    let plan = Plan::new(&r, &none, &[colour_only(0.4)], &dark, Spread::default());
    assert_eq!(plan.lit_for_color(), &[0]);
    let mut rng = Rng::seed_from_u64(8);
    let means: Vec<f32> = (0..300)
        .map(|_| {
            let look = plan.sample(&dark, &mut rng);
            mean(&look.levels.iter().map(|l| l.intensity).collect::<Vec<_>>())
        })
        .collect();
    assert!((mean(&means) - 0.4).abs() < 0.03, "{}", mean(&means));
    // One lit light in its region: the base's intensities are the designer's, kept.
    let mut lit = Look::off(n);
    lit.levels[5].intensity = 0.3;
    let plan = Plan::new(&r, &none, &[colour_only(0.4)], &lit, Spread::default());
    assert!(plan.lit_for_color().is_empty());
    assert_eq!(plan.sample(&lit, &mut rng).levels, {
        let mut want = lit.levels.clone();
        for l in &mut want {
            l.color = [1.0, 0.0, 0.0];
        }
        want
    });
    // An intensity objective over the same lights sets them: colour stays colour only.
    let intensity = target(n, 0.5, 0.8, 0.3);
    let plan = Plan::new(
        &r,
        &none,
        &[intensity, colour_only(0.4)],
        &dark,
        Spread::default(),
    );
    assert!(plan.lit_for_color().is_empty());
    // Every light locked: nothing to light, nothing claimed.
    let mut locked = Constraints::none(&r);
    locked.locked = vec![true; n];
    let plan = Plan::new(&r, &locked, &[colour_only(0.4)], &dark, Spread::default());
    assert!(plan.lit_for_color().is_empty());
}

#[test]
fn palette_colours_take_full_value() {
    let c = visobjd_method::sampler::full_value([0.2, 0.1, 0.05]);
    assert!((c[0] - 1.0).abs() < 1e-6, "{c:?}");
    assert!(c[1] < 1.0 && c[2] < c[1]);
    assert_eq!(visobjd_method::sampler::full_value([0.0; 3]), [1.0; 3]);
}

#[test]
fn the_smaller_region_wins_the_lights_both_select() {
    let n = 10;
    let r = rig(n);
    let base = Look::off(n);
    let palette = |c: [f32; 3]| {
        vec![PaletteColor {
            color: c,
            weight: 1.0,
        }]
    };
    let mut small = target(n, 0.5, 0.5, 0.0);
    small.aspects = Aspects::Color;
    small.area = 0.3;
    small.selected = (0..n).map(|l| l < 3).collect();
    small.palette = palette([0.0, 0.0, 1.0]);
    let mut whole = target(n, 0.5, 0.5, 0.0);
    whole.aspects = Aspects::Color;
    whole.palette = palette([1.0, 0.0, 0.0]);
    // Given small first: the order of objectives must not matter, the area does.
    let plan = Plan::new(
        &r,
        &Constraints::none(&r),
        &[small, whole],
        &base,
        Spread::default(),
    );
    let look = plan.sample(&base, &mut Rng::seed_from_u64(7));
    for l in 0..n {
        let want = if l < 3 {
            [0.0, 0.0, 1.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        assert_eq!(look.levels[l].color, want, "light {l}");
    }
}

#[test]
fn region_targeting_selects_exactly_the_expected_lights() {
    let dir = temp_dir("region");
    // 40x20 stage; the region is the left quarter (x < 10).
    let lights = vec![
        // 1: lights everything evenly: its bright pixels cover the region (> 25%).
        TestLight::rect(1, None, "dimmer", 1, (0, 0, 40, 20), 0.3),
        // 2: lights only the right half: not selected.
        TestLight::rect(2, None, "dimmer", 2, (20, 0, 40, 20), 0.8),
        // 3: a small spot inside the region: its light is contained there (> 50%).
        TestLight::rect(3, None, "dimmer", 3, (2, 2, 6, 6), 1.0),
        // 4: mostly the right half, dim, plus a hot spot in the region: highlights (> 5%).
        TestLight {
            channel: 4,
            group: None,
            profile: "dimmer",
            universe: 1,
            address: 4,
            pixel: Box::new(|x, y| {
                if (4..8).contains(&x) && (8..12).contains(&y) {
                    [2.0; 3]
                } else if x >= 20 {
                    [0.1 + 0.001 * (x + 40 * y) as f32; 3]
                } else {
                    [0.0; 3]
                }
            }),
        },
        // 5: right side with a bright stripe just outside the region: not selected.
        TestLight {
            channel: 5,
            group: None,
            profile: "dimmer",
            universe: 1,
            address: 5,
            pixel: Box::new(|x, _| {
                if (10..12).contains(&x) {
                    [1.0; 3]
                } else if x >= 12 {
                    [0.2; 3]
                } else {
                    [0.0; 3]
                }
            }),
        },
    ];
    write_scene(&dir, 40, 20, &[], &lights);
    let stage = visobjd_method::stage::Stage::load(&dir, 40).unwrap();
    let selected = stage
        .footprints
        .select(Region::new(0.0, 0.0, 0.25, 1.0).unwrap());
    assert_eq!(selected, vec![true, false, true, true, false]);
    assert_eq!(stage.footprints.select(Region::FULL), vec![true; 5]);
    let s = stage
        .footprints
        .sensitivity(Region::new(0.0, 0.0, 0.25, 1.0).unwrap());
    assert!(s[1] == 0.0 && s[0] > 0.0 && s[2] > 0.0);
}

// ---- the prototype's constraints (docs/method.md, "Designer constraints") ----------------

use visobjd_method::constrain::{Ratio, Saturation, clamp_saturation, saturation, transfer};

/// A rig of `groups` groups of `size` lights each, all colour-capable.
fn grouped(groups: usize, size: usize) -> LightGroups {
    LightGroups {
        groups: (0..groups)
            .map(|g| (g * size..(g + 1) * size).collect())
            .collect(),
        colored: vec![true; groups * size],
    }
}

fn group_mean(look: &Look, lights: &[usize]) -> f32 {
    lights
        .iter()
        .map(|&l| look.levels[l].intensity)
        .sum::<f32>()
        / lights.len() as f32
}

/// A base look with every light at a different level and colour.
fn varied_base(n: usize) -> Look {
    Look {
        levels: (0..n)
            .map(|i| Level {
                intensity: 0.05 + 0.9 * ((i * 37 % n) as f32 / n as f32),
                color: [0.9, 0.2 + 0.5 * (i % 3) as f32 / 2.0, 0.1],
                position: None,
            })
            .collect(),
    }
}

/// Ratios are held to this, as a fraction of full, in every candidate.
const RATIO_TOLERANCE: f32 = 1e-4;

#[test]
fn ratios_hold_in_every_candidate_through_chains_keys_locks_and_the_range() {
    // Groups 0..6 of three lights. 1 follows 0 at 0.5, 2 follows 1 at 1.5 (a chain), 3
    // follows 0 at 1.8 (out of range unless 0 is held below 1/1.8), 5 follows 4 at 0.5
    // with 4 locked at its base (the locked leader is fixed, the follower follows).
    let r = grouped(6, 3);
    let n = 18;
    let base = varied_base(n);
    let ratio = |follower, leader, ratio| Ratio {
        follower,
        leader,
        ratio,
    };
    for designated in [false, true] {
        let mut c = Constraints::none(&r);
        c.ratios = vec![
            ratio(1, 0, 0.5),
            ratio(2, 1, 1.5),
            ratio(3, 0, 1.8),
            ratio(5, 4, 0.5),
        ];
        for l in &r.groups[4] {
            c.locked[*l] = true;
        }
        // One light of the follower locked too: the other two make up its share.
        c.locked[r.groups[2][0]] = true;
        if designated {
            // Both ends of a ratio designated keys: the follower still follows.
            c.keys[0] = true;
            c.keys[1] = true;
        }
        let t = target(n, 0.45, 0.9, 0.5);
        let plan = Plan::new(&r, &c, &[t], &base, Spread::default());
        let mut rng = Rng::seed_from_u64(11);
        let mut leaders = Vec::new();
        for _ in 0..500 {
            let look = plan.sample(&base, &mut rng);
            let m: Vec<f32> = r.groups.iter().map(|g| group_mean(&look, g)).collect();
            for (b, a, k) in [(1, 0, 0.5), (2, 1, 1.5), (3, 0, 1.8), (5, 4, 0.5)] {
                assert!(
                    (m[b] - k * m[a]).abs() <= RATIO_TOLERANCE,
                    "group {b} at {} is not {k} x group {a} at {} (keys {designated})",
                    m[b],
                    m[a]
                );
            }
            for &l in r.groups[4].iter().chain([&r.groups[2][0]]) {
                assert_eq!(
                    look.levels[l].intensity.to_bits(),
                    base.levels[l].intensity.to_bits()
                );
            }
            assert!(
                look.levels
                    .iter()
                    .all(|l| (0.0..=1.0).contains(&l.intensity))
            );
            leaders.push(m[0]);
        }
        // The leader still varies: ratios do not freeze the look (as a designated key it is
        // drawn near 0.9, above what group 3 allows, and held at 1/1.8 every time).
        if designated {
            assert!(
                leaders
                    .iter()
                    .all(|&m| (m - 1.0 / 1.8).abs() < RATIO_TOLERANCE)
            );
        } else {
            assert!(
                variance(&leaders) > 1e-3,
                "leader variance {}",
                variance(&leaders)
            );
        }
    }
}

#[test]
fn a_locked_follower_makes_its_leader_follow() {
    let r = grouped(2, 2);
    let base = varied_base(4);
    let mut c = Constraints::none(&r);
    c.ratios = vec![Ratio {
        follower: 1,
        leader: 0,
        ratio: 2.0,
    }];
    c.locked[2] = true;
    c.locked[3] = true;
    let want = group_mean(&base, &r.groups[1]) / 2.0;
    let plan = Plan::new(
        &r,
        &c,
        &[target(4, 0.5, 0.9, 0.5)],
        &base,
        Spread::default(),
    );
    let mut rng = Rng::seed_from_u64(12);
    for _ in 0..200 {
        let look = plan.sample(&base, &mut rng);
        assert!((group_mean(&look, &r.groups[0]) - want).abs() <= RATIO_TOLERANCE);
    }
}

/// HSV hue in degrees (None for a grey).
fn hue(c: [f32; 3]) -> Option<f32> {
    let max = c[0].max(c[1]).max(c[2]);
    let min = c[0].min(c[1]).min(c[2]);
    let d = max - min;
    if d <= 1e-6 {
        return None;
    }
    let h = if max == c[0] {
        ((c[1] - c[2]) / d).rem_euclid(6.0)
    } else if max == c[1] {
        (c[2] - c[0]) / d + 2.0
    } else {
        (c[0] - c[1]) / d + 4.0
    };
    Some(h * 60.0)
}

#[test]
fn saturation_stays_in_its_range_with_the_sampler_s_hue_and_value() {
    let n = 30;
    let mut r = rig(n);
    r.colored[0] = false;
    let base = varied_base(n);
    let mut t = target(n, 0.5, 0.9, 0.4);
    t.aspects = Aspects::Both;
    t.palette = [
        ([1.0, 0.0, 0.0], 0.3),
        ([0.2, 0.4, 1.0], 0.3),
        ([1.0, 0.9, 0.8], 0.2),
        ([0.5, 1.0, 0.6], 0.2),
    ]
    .map(|(color, weight)| PaletteColor { color, weight })
    .to_vec();
    let range = Saturation { min: 0.3, max: 0.6 };
    let mut c = Constraints::none(&r);
    for l in 1..20 {
        c.saturation[l] = range;
    }
    let free = Plan::new(
        &r,
        &Constraints::none(&r),
        &[t.clone()],
        &base,
        Spread::default(),
    );
    let held = Plan::new(&r, &c, &[t], &base, Spread::default());
    let (mut a, mut b) = (Rng::seed_from_u64(13), Rng::seed_from_u64(13));
    let mut clamped = 0;
    for _ in 0..500 {
        let (x, y) = (free.sample(&base, &mut a), held.sample(&base, &mut b));
        for l in 0..n {
            let (cx, cy) = (x.levels[l].color, y.levels[l].color);
            assert_eq!(
                x.levels[l].intensity.to_bits(),
                y.levels[l].intensity.to_bits()
            );
            if !(1..20).contains(&l) {
                assert_eq!(cx, cy, "light {l} has no range");
                continue;
            }
            let s = saturation(cy);
            assert!(
                (range.min - 1e-5..=range.max + 1e-5).contains(&s),
                "light {l}: saturation {s} of {cy:?}"
            );
            let vmax = |c: [f32; 3]| c[0].max(c[1]).max(c[2]);
            assert!(
                (vmax(cx) - vmax(cy)).abs() < 1e-6,
                "value kept: {cx:?} {cy:?}"
            );
            if let (Some(hx), Some(hy)) = (hue(cx), hue(cy)) {
                assert!((hx - hy).abs() < 0.05, "hue kept: {cx:?} -> {cy:?}");
            }
            clamped += usize::from(cx != cy);
        }
    }
    assert!(
        clamped > 1000,
        "the range mattered: {clamped} colours clamped"
    );
    assert_eq!(
        clamp_saturation([0.3, 0.2, 0.1], Saturation::ANY),
        [0.3, 0.2, 0.1]
    );
}

#[test]
fn off_lights_are_exactly_zero_and_count_as_zero_in_the_mean() {
    let n = 20;
    let r = rig(n);
    let base = varied_base(n);
    let mut c = Constraints::none(&r);
    for l in 0..5 {
        c.off[l] = true;
    }
    // A locked light that is also off keeps its base: what is fixed stays fixed.
    c.locked[4] = true;
    let mut t = target(n, 0.4, 0.8, 0.3);
    t.aspects = Aspects::Both;
    t.palette = vec![PaletteColor {
        color: [0.0, 0.0, 1.0],
        weight: 1.0,
    }];
    let plan = Plan::new(&r, &c, &[t], &base, Spread::default());
    let mut rng = Rng::seed_from_u64(14);
    let mut means = Vec::new();
    for _ in 0..1000 {
        let look = plan.sample(&base, &mut rng);
        for l in 0..4 {
            assert_eq!(look.levels[l].intensity.to_bits(), 0.0f32.to_bits());
            assert_eq!(look.levels[l].color, base.levels[l].color, "colour kept");
        }
        assert_eq!(look.levels[4], base.levels[4]);
        means.push(mean(
            &look.levels.iter().map(|l| l.intensity).collect::<Vec<_>>(),
        ));
    }
    // The other lights make up the mean around the held ones (4 at 0, one at its base).
    assert!((mean(&means) - 0.4).abs() < 0.01, "{}", mean(&means));
}

#[test]
fn a_transfer_touches_exactly_the_named_lights() {
    let n = 50;
    let onto = varied_base(n);
    let mut rng = Rng::seed_from_u64(16);
    let r = rig(n);
    let plan = Plan::new(
        &r,
        &Constraints::none(&r),
        &[target(n, 0.5, 0.9, 0.5)],
        &onto,
        Spread::default(),
    );
    for i in 0..100 {
        let from = plan.sample(&onto, &mut rng);
        let mask: Vec<bool> = (0..n).map(|l| (l * 7 + i * 13) % 10 < 3).collect();
        let out = transfer(&onto, &from, &mask);
        for (l, &taken) in mask.iter().enumerate() {
            let want = if taken {
                from.levels[l]
            } else {
                onto.levels[l]
            };
            assert_eq!(
                out.levels[l].intensity.to_bits(),
                want.intensity.to_bits(),
                "light {l}"
            );
            assert_eq!(out.levels[l].color, want.color, "light {l}");
        }
    }
}
