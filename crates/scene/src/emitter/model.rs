//! One light's colour model: how a look's level (an sRGB colour and an intensity) becomes
//! emitter levels by [`solve`], and what those levels show relative to the light's basis
//! image, so that the DMX output, the preview, the capture simulation and the Eos export
//! all mix the same light (docs/dmx.md, "Look to slots" and "Slots back to light").
//!
//! A colour's brightness is its largest linear component: sRGB (1, 0.5, 0) is its
//! chromaticity at the most light the emitters give, (0.5, 0.25, 0) half of that. A basis
//! image is the light captured at white, so the preview multiplier is the reached linear
//! sRGB divided, per channel, by the reached linear sRGB of white (D65 at its most light).
//! With the sRGB primaries (the `rgb` profiles) that is the decoded colour itself; with a
//! white emitter, white is the sum of every emitter at full and a saturated colour a
//! fraction of it.

use super::colour::{D65, linear_srgb_to_xyz, xyz_to_linear_srgb};
use super::{MAX_EMITTERS, Solution, solve};
use crate::look::Level;
use crate::profile::Profile;
use crate::srgb::srgb_to_linear;

/// A light's emitters and its white, computed once per profile.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourModel {
    /// Each additive emitter's CIE XYZ at full, in slot order; empty for a light without
    /// (a dimmer, a CMY fixture), which keeps the plain linear colour.
    emitters: Vec<[f64; 3]>,
    /// The linear sRGB the light makes at white: what its basis image shows.
    white: [f64; 3],
}

impl ColourModel {
    /// The model of a light with `profile`.
    pub fn new(profile: &Profile) -> ColourModel {
        ColourModel::from_emitters(profile.emitters_xyz())
    }

    /// The model of a light whose additive emitters make `emitters` (CIE XYZ at full, slot
    /// order): a profile's, or those capture measured.
    pub fn from_emitters(mut emitters: Vec<[f64; 3]>) -> ColourModel {
        emitters.truncate(MAX_EMITTERS);
        let mut model = ColourModel {
            emitters,
            white: [1.0; 3],
        };
        if !model.emitters.is_empty() {
            model.white = model.most_light(D65).reached_linear_srgb();
        }
        model
    }

    /// [`solve`] for `target`, with a level within [`FULL`] of 1 taken as 1: emitter data
    /// carry about seven digits (the sRGB primaries' luminances), so white on `rgb` would
    /// otherwise ask one emitter for 0.9999995, a byte less at half intensity.
    fn most_light(&self, target: [f64; 3]) -> Solution {
        let mut s = solve(&self.emitters, target);
        if s.levels[..s.len]
            .iter()
            .any(|l| (1.0 - l).abs() < FULL && *l != 1.0)
        {
            for l in &mut s.levels[..s.len] {
                if (1.0 - *l).abs() < FULL {
                    *l = 1.0;
                }
            }
            s.reached = self.reached(s.levels());
        }
        s
    }

    /// A light without additive emitters: its colour is the plain linear multiplier (the
    /// model of basis images that come without a scene, as in tests).
    pub fn plain() -> ColourModel {
        ColourModel {
            emitters: Vec::new(),
            white: [1.0; 3],
        }
    }

    /// How many additive emitters the light has (the length of every solution's levels).
    pub fn emitters(&self) -> usize {
        self.emitters.len()
    }

    /// The emitter levels (slot order) for the sRGB `color` (clamped to 0..1): its
    /// chromaticity at the most light, times its brightness. A light with a dimmer sends
    /// these; one without sends `Solution::at(intensity)` of them.
    pub fn solve(&self, color: [f32; 3]) -> Solution {
        let linear = color.map(|c| f64::from(srgb_to_linear(unit(c))));
        let brightness = linear.iter().copied().fold(0.0, f64::max);
        self.most_light(linear_srgb_to_xyz(linear)).at(brightness)
    }

    /// The linear RGB multiplier `level` applies to the light's basis image: the reached
    /// colour relative to the light's white, times the intensity, never below 0 (a wide
    /// gamut's colour outside sRGB shows as its nearest sRGB colour, not as negative light).
    /// A light without emitters keeps [`Level::multiplier`].
    pub fn multiplier(&self, level: &Level) -> [f32; 3] {
        if self.emitters.is_empty() {
            return level.multiplier();
        }
        // Dark needs no solve, and white is the light's white by definition: the two
        // levels a sampled look holds most often, at no cost.
        if level.intensity == 0.0 {
            return [0.0; 3];
        }
        if level.color == [1.0; 3] {
            return [level.intensity; 3];
        }
        let relative = self.relative(self.solve(level.color).reached);
        relative.map(|v| v as f32 * level.intensity)
    }

    /// The CIE XYZ that emitter `levels` (slot order) make.
    pub fn reached(&self, levels: &[f64]) -> [f64; 3] {
        let mut xyz = [0.0; 3];
        for (l, e) in levels.iter().zip(&self.emitters) {
            for (s, v) in xyz.iter_mut().zip(e) {
                *s += l * v;
            }
        }
        xyz
    }

    /// The linear multiplier of the light's basis image that makes `xyz`: its linear sRGB
    /// relative to the light's white, per channel, at least 0. A channel the white does
    /// not light (a single-colour fixture's) stays 0.
    pub fn relative(&self, xyz: [f64; 3]) -> [f64; 3] {
        let rgb = xyz_to_linear_srgb(xyz);
        let top = self.white.iter().fold(0.0f64, |a, w| a.max(w.abs()));
        std::array::from_fn(|k| {
            if self.white[k].abs() > 1e-9 * top {
                (rgb[k] / self.white[k]).max(0.0)
            } else {
                0.0
            }
        })
    }

    /// The inverse of [`ColourModel::solve`]: the brightness (0..1) and the linear colour
    /// (largest component 1, white when dark) that give emitter `levels` back, to within
    /// what the emitters can tell apart. Levels that are not the most light of their colour
    /// (an RGBW fixture with white left in R, G and B) come back as the colour they make.
    pub fn read(&self, levels: &[f64]) -> (f64, [f64; 3]) {
        let xyz = self.reached(levels);
        let most = solve(&self.emitters, xyz).reached;
        if !(xyz[1] > 0.0 && most[1] > 0.0) {
            return (0.0, [1.0; 3]);
        }
        let rgb = xyz_to_linear_srgb(xyz).map(|v| v.max(0.0));
        let peak = rgb.iter().copied().fold(0.0, f64::max);
        if peak <= 0.0 {
            return (0.0, [1.0; 3]);
        }
        ((xyz[1] / most[1]).clamp(0.0, 1.0), rgb.map(|v| v / peak))
    }
}

/// How close to 1 a solved level is taken as full (far below a 16-bit DMX step, 1.5e-5).
const FULL: f64 = 1e-6;

/// `v` clamped to 0..1, NaN as 0.
fn unit(v: f32) -> f32 {
    if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(name: &str) -> ColourModel {
        ColourModel::new(&Profile::built_in(name).expect("built in"))
    }

    #[test]
    fn rgb_previews_as_the_plain_multiplier() {
        let mut state = 0x1234_5678_9abc_def1u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for name in ["rgb", "irgb"] {
            let m = model(name);
            for round in 0..5000 {
                let mut color = [next(), next(), next()];
                if round % 2 == 0 {
                    color[round % 3] = 1.0;
                }
                let level = Level {
                    intensity: next(),
                    color,
                    position: None,
                };
                let (got, want) = (m.multiplier(&level), level.multiplier());
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() <= 2e-6,
                        "{name} {level:?}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn white_previews_as_white_for_every_profile() {
        for name in Profile::built_in_names() {
            let m = model(name);
            for intensity in [0.0, 0.3, 1.0] {
                let got = m.multiplier(&Level {
                    intensity,
                    color: [1.0; 3],
                    position: None,
                });
                for v in got {
                    assert!((v - intensity).abs() <= 1e-6, "{name}: {got:?}");
                }
            }
        }
    }

    #[test]
    fn white_is_every_emitter_exactly_full_where_they_add_up_to_white() {
        for name in ["rgb", "irgb", "rgbw", "irgbw"] {
            let s = model(name).solve([1.0; 3]);
            assert!(s.levels().iter().all(|&l| l == 1.0), "{name}: {s:?}");
        }
    }

    #[test]
    fn plain_lights_keep_the_linear_colour() {
        let level = Level {
            intensity: 0.4,
            color: [1.0, 0.5, 0.2],
            position: None,
        };
        assert_eq!(ColourModel::plain().multiplier(&level), level.multiplier());
        assert_eq!(model("dimmer").multiplier(&level), level.multiplier());
        assert_eq!(model("dimmer").emitters(), 0);
    }

    #[test]
    fn read_inverts_solve() {
        for name in ["rgb", "rgbw", "rgba"] {
            let m = model(name);
            for color in [[1.0, 0.5, 0.0], [0.2, 1.0, 0.7], [1.0; 3], [0.5, 0.5, 0.5]] {
                let s = m.solve(color);
                let (t, linear) = m.read(s.levels());
                let again = m.solve(linear.map(|v| crate::srgb::linear_to_srgb(v as f32)));
                for (a, b) in s.levels().iter().zip(again.at(t).levels()) {
                    assert!((a - b).abs() < 1e-4, "{name} {color:?}: {s:?} vs {again:?}");
                }
            }
        }
    }

    #[test]
    fn a_trace_inside_the_gamut_edge_still_solves() {
        // A red read back from DMX carries a trace of blue from rounding: it lies a hair
        // inside the red-blue edge, where the programme is ill-conditioned.
        for name in ["rgb", "rgbw", "rgba"] {
            for trace in [1e-12f32, 1e-9, 9.585_502e-8, 4.553_116_4e-7, 1e-6] {
                let s = model(name).solve([1.0, 0.0, trace]);
                assert!((s.levels()[0] - 1.0).abs() < 1e-5, "{name} {trace}: {s:?}");
                let s = model(name).solve([0.0, 1.0, trace]);
                assert!((s.levels()[1] - 1.0).abs() < 1e-5, "{name} {trace}: {s:?}");
                let s = model(name).solve([trace, 1.0, 1.0]);
                assert!(
                    s.levels().iter().any(|&l| l > 0.99),
                    "{name} {trace}: {s:?}"
                );
            }
        }
    }

    /// A seven-colour fixture: the named six without white, and cyan and indigo.
    fn seven() -> ColourModel {
        let file = crate::profile::ProfileFile {
            name: "seven".into(),
            channels: [
                "intensity",
                "red",
                "green",
                "blue",
                "amber",
                "lime",
                "emitter:cyan",
                "emitter:indigo",
            ]
            .map(String::from)
            .to_vec(),
            emitters: Vec::new(),
            pan_range: None,
            tilt_range: None,
        };
        ColourModel::new(&Profile::from_file(&file).expect("parses"))
    }

    #[test]
    fn white_previews_as_white_on_seven_colours_too() {
        let m = seven();
        assert_eq!(m.emitters(), 7);
        let s = m.solve([1.0; 3]);
        assert!(s.levels().iter().all(|l| (0.0..=1.0).contains(l)), "{s:?}");
        for intensity in [0.25f32, 1.0] {
            let got = m.multiplier(&Level {
                intensity,
                color: [1.0; 3],
                position: None,
            });
            assert!(got.iter().all(|v| (v - intensity).abs() < 1e-6), "{got:?}");
        }
    }

    #[test]
    fn a_saturated_colour_on_rgbw_previews_at_its_share_of_white() {
        // By hand: the default white emitter is R + G + B at full, so white on rgbw (every
        // emitter at full) is twice R + G + B; a pure red is the red emitter alone, half
        // the red of white. A pure green likewise, and yellow (R + G) too.
        let m = model("rgbw");
        for (color, want) in [
            ([1.0, 0.0, 0.0], [0.5, 0.0, 0.0]),
            ([0.0, 1.0, 0.0], [0.0, 0.5, 0.0]),
            ([1.0, 1.0, 0.0], [0.5, 0.5, 0.0]),
        ] {
            let got = m.multiplier(&Level {
                intensity: 0.8,
                color,
                position: None,
            });
            for k in 0..3 {
                assert!((got[k] - 0.8 * want[k]).abs() < 1e-5, "{color:?}: {got:?}");
            }
        }
    }

    #[test]
    fn out_of_gamut_colours_preview_as_the_colour_reached() {
        // An RGB fixture whose red is an orange (x 0.55, y 0.40): sRGB's red is beyond it,
        // and the closest it comes is its own red emitter alone, at full.
        let file = crate::profile::ProfileFile {
            name: "orange-red".into(),
            channels: ["red", "green", "blue"].map(String::from).to_vec(),
            emitters: vec![crate::profile::EmitterFile {
                name: "red".into(),
                xy: Some([0.55, 0.40]),
                flux: None,
            }],
            pan_range: None,
            tilt_range: None,
        };
        let profile = Profile::from_file(&file).expect("parses");
        let m = ColourModel::new(&profile);
        let s = m.solve([1.0, 0.0, 0.0]);
        assert!(!s.in_gamut());
        let red = profile.emitters_xyz()[0];
        let got = m.multiplier(&Level {
            intensity: 1.0,
            color: [1.0, 0.0, 0.0],
            position: None,
        });
        // What the red emitter alone shows relative to white, computed here from its XYZ.
        let want = m.relative(red);
        assert!(want[1] > 0.1, "the orange has green in it: {want:?}");
        for k in 0..3 {
            assert!(
                (f64::from(got[k]) - want[k]).abs() < 1e-4,
                "{got:?} vs {want:?}"
            );
        }
    }
}
