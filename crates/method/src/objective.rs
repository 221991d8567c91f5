//! Visual objectives: what a reference image asks of the stage (paper 4.2.1 and 4.3).
//!
//! An objective is the image's intensity model (mean L*, key L*, fraction of bright pixels)
//! and/or its colour palette, aimed at a region of the stage. Analysis is pure; only
//! [`decode_reference`] touches the file system (its decoding, within a memory bound, is
//! `crate::decode`).

use std::ops::Range;

use rand::{Rng, RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

pub use crate::decode::{DECODE_LIMIT, decode_reference, decode_reference_bytes};
use visobjd_compositor::color::{delta_e, linear_to_lab, srgb8_to_linear_table};
use visobjd_scene::srgb::linear_to_srgb;

/// Longest side the reference is reduced to before statistics (docs/method.md).
pub const ANALYSIS_SIDE: u32 = 256;
/// Largest reference accepted, in pixels (docs/osc.md: images over 64 megapixels are refused).
pub const MAX_REFERENCE_PIXELS: u64 = 64_000_000;
/// Fraction of the brightest pixels assumed lit by key lights (paper 4.2.1).
pub const KEY_FRACTION: f64 = 0.15;

/// Which aspects of the reference an objective takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Aspects {
    /// Mean and key intensity only.
    Intensity,
    /// Palette only.
    Color,
    /// Both.
    Both,
}

impl Aspects {
    /// Parses `intensity`, `color` (or `colour`) or `both`, case-insensitively.
    pub fn parse(s: &str) -> Result<Aspects, String> {
        match s.to_ascii_lowercase().as_str() {
            "intensity" => Ok(Aspects::Intensity),
            "color" | "colour" => Ok(Aspects::Color),
            "both" => Ok(Aspects::Both),
            _ => Err(format!(
                "aspects `{s}` is not one of intensity, color, both"
            )),
        }
    }

    /// The name used on the wire and in files.
    pub fn name(self) -> &'static str {
        match self {
            Aspects::Intensity => "intensity",
            Aspects::Color => "color",
            Aspects::Both => "both",
        }
    }

    /// Whether intensity is taken.
    pub fn intensity(self) -> bool {
        self != Aspects::Color
    }

    /// Whether colour is taken.
    pub fn color(self) -> bool {
        self != Aspects::Intensity
    }
}

/// A rectangle in normalised image coordinates (0..1, y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Left.
    pub x0: f32,
    /// Top.
    pub y0: f32,
    /// Right (exclusive).
    pub x1: f32,
    /// Bottom (exclusive).
    pub y1: f32,
}

impl Region {
    /// The whole stage.
    pub const FULL: Region = Region {
        x0: 0.0,
        y0: 0.0,
        x1: 1.0,
        y1: 1.0,
    };

    /// A validated region: finite, inside 0..1, with x0 < x1 and y0 < y1.
    pub fn new(x0: f32, y0: f32, x1: f32, y1: f32) -> Result<Region, String> {
        let all = [x0, y0, x1, y1];
        if all
            .iter()
            .any(|v| !v.is_finite() || !(0.0..=1.0).contains(v))
        {
            return Err(format!(
                "region {x0},{y0},{x1},{y1} must have every coordinate in 0..1"
            ));
        }
        if x0 >= x1 || y0 >= y1 {
            return Err(format!(
                "region {x0},{y0},{x1},{y1} is empty: it needs x0 < x1 and y0 < y1"
            ));
        }
        Ok(Region { x0, y0, x1, y1 })
    }

    /// Parses `X0,Y0,X1,Y1`.
    pub fn parse(s: &str) -> Result<Region, String> {
        let v: Vec<f32> = s
            .split(',')
            .map(|p| p.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("region `{s}` is not four numbers X0,Y0,X1,Y1"))?;
        match v[..] {
            [x0, y0, x1, y1] => Region::new(x0, y0, x1, y1),
            _ => Err(format!("region `{s}` is not four numbers X0,Y0,X1,Y1")),
        }
    }

    /// Fraction of the image it covers.
    pub fn area(&self) -> f32 {
        (self.x1 - self.x0) * (self.y1 - self.y0)
    }

    /// Whether it is the whole image.
    pub fn is_full(&self) -> bool {
        *self == Region::FULL
    }

    /// The columns and rows of a `w x h` grid whose pixels have their centres inside: the
    /// pixels a region covers for targeting, as a rectangle to sum over.
    pub fn pixel_spans(&self, w: usize, h: usize) -> (Range<usize>, Range<usize>) {
        let span = |n: usize, v0: f32, v1: f32| {
            let within = |i: usize| {
                let c = (i as f32 + 0.5) / n as f32;
                c >= v0 && c < v1
            };
            let first = (0..n).find(|&i| within(i)).unwrap_or(n);
            first..(first..n).find(|&i| !within(i)).unwrap_or(n)
        };
        (span(w, self.x0, self.x1), span(h, self.y0, self.y1))
    }

    /// The pixel rectangle `[x0, x1) x [y0, y1)` it covers on a `w x h` grid (at least 1x1).
    fn pixel_bounds(&self, w: u32, h: u32) -> (u32, u32, u32, u32) {
        let px = |v: f32, n: u32| ((v * n as f32).round() as u32).min(n);
        let (x0, x1) = (px(self.x0, w), px(self.x1, w));
        let (y0, y1) = (px(self.y0, h), px(self.y1, h));
        let x0 = x0.min(w.saturating_sub(1));
        let y0 = y0.min(h.saturating_sub(1));
        (x0, y0, x1.max(x0 + 1), y1.max(y0 + 1))
    }
}

/// The intensity model of a reference (paper 4.2.1), L* as 0..100.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntensityStats {
    /// Mean L* (mu_a x 100).
    pub mean_l: f32,
    /// Mean L* of the brightest 15% of pixels (mu_k x 100).
    pub key_l: f32,
    /// Fraction of pixels strictly brighter than the mean (b).
    pub bright: f32,
}

/// One palette colour: sRGB 0..1 and the fraction of the image nearest to it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaletteColor {
    /// sRGB 0..1 (the cluster's mean colour).
    pub color: [f32; 3],
    /// Share of pixels; a palette's weights sum to 1.
    pub weight: f32,
}

/// A reference image reduced to what the sampler needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Analysis {
    /// Intensity model.
    pub stats: IntensityStats,
    /// Palette, heaviest colour first.
    pub palette: Vec<PaletteColor>,
}

/// A visual objective: a reference image's analysis, which aspects to take, and where.
#[derive(Debug, Clone, PartialEq)]
pub struct Objective {
    /// The reference's file name, as the user gave it.
    pub image: String,
    /// Aspects taken.
    pub aspects: Aspects,
    /// Stage region aimed at.
    pub region: Region,
    /// The reference's statistics and palette.
    pub analysis: Analysis,
}

/// Crops to `crop`, then shrinks so the longest side is at most [`ANALYSIS_SIDE`], and
/// returns the pixels in linear RGB. The crop is a view: a big reference is read where it
/// lies, never copied whole.
fn analysis_pixels(img: &image::RgbImage, crop: Region) -> Vec<[f32; 3]> {
    let (x0, y0, x1, y1) = crop.pixel_bounds(img.width(), img.height());
    let view = image::imageops::crop_imm(img, x0, y0, x1 - x0, y1 - y0);
    let (w, h) = (x1 - x0, y1 - y0);
    let small = if w.max(h) > ANALYSIS_SIDE {
        let scale = f64::from(ANALYSIS_SIDE) / f64::from(w.max(h));
        let nw = ((f64::from(w) * scale).round() as u32).max(1);
        let nh = ((f64::from(h) * scale).round() as u32).max(1);
        image::imageops::resize(&*view, nw, nh, image::imageops::FilterType::Triangle)
    } else {
        view.to_image()
    };
    let lut = srgb8_to_linear_table();
    small
        .pixels()
        .map(|p| [lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]])
        .collect()
}

/// Analyses a decoded reference: intensity statistics and a `palette_size`-colour palette.
///
/// The palette's k-means is seeded from the pixels themselves, so the same image always
/// gives the same palette.
pub fn analyze(img: &image::RgbImage, crop: Region, palette_size: usize) -> Analysis {
    let pixels = analysis_pixels(img, crop);
    let labs: Vec<[f32; 3]> = pixels.iter().map(|&p| linear_to_lab(p)).collect();
    let lightness: Vec<f32> = labs.iter().map(|l| l[0]).collect();
    Analysis {
        stats: intensity_stats(&lightness),
        palette: palette(&pixels, &labs, palette_size),
    }
}

/// Mean L*, key L* (exact mean of the top 15%) and the fraction above the mean.
pub fn intensity_stats(lightness: &[f32]) -> IntensityStats {
    let n = lightness.len().max(1);
    let mean = lightness.iter().map(|&v| f64::from(v)).sum::<f64>() / n as f64;
    let k = ((KEY_FRACTION * lightness.len() as f64).round() as usize).clamp(1, n);
    let mut sorted = lightness.to_vec();
    let key = if sorted.is_empty() {
        0.0
    } else {
        // Everything after position n - k is at least as bright: the exact top k.
        sorted.select_nth_unstable_by(n - k, |a, b| a.total_cmp(b));
        sorted[n - k..].iter().map(|&v| f64::from(v)).sum::<f64>() / k as f64
    };
    let bright = lightness
        .iter()
        .filter(|&&v| f64::from(v) > mean + 1e-4)
        .count() as f64
        / n as f64;
    IntensityStats {
        mean_l: mean as f32,
        key_l: key as f32,
        bright: bright as f32,
    }
}

/// Largest number of k-means iterations; palettes settle well before.
const KMEANS_ITERATIONS: usize = 30;

/// K-means in CIELAB with k-means++ seeding; colours are the members' mean linear RGB,
/// sRGB-encoded; weights the share of pixels nearest each centre.
fn palette(pixels: &[[f32; 3]], labs: &[[f32; 3]], k: usize) -> Vec<PaletteColor> {
    if labs.is_empty() || k == 0 {
        return Vec::new();
    }
    // The seed depends only on the pixels, so one image always gives one palette.
    let seed = labs.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, l| {
        (h ^ u64::from(l[0].to_bits())).wrapping_mul(0x100_0000_01b3)
    });
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut centres = kmeans_pp(labs, k, &mut rng);
    let mut assign = vec![0usize; labs.len()];
    for _ in 0..KMEANS_ITERATIONS {
        let mut changed = false;
        for (a, l) in assign.iter_mut().zip(labs) {
            let best = nearest(&centres, *l);
            changed |= *a != best;
            *a = best;
        }
        let mut sums = vec![[0.0f64; 4]; centres.len()];
        for (a, l) in assign.iter().zip(labs) {
            for c in 0..3 {
                sums[*a][c] += f64::from(l[c]);
            }
            sums[*a][3] += 1.0;
        }
        for (centre, s) in centres.iter_mut().zip(&sums) {
            if s[3] > 0.0 {
                *centre = [0, 1, 2].map(|c| (s[c] / s[3]) as f32);
            }
        }
        if !changed {
            break;
        }
    }
    let mut sums = vec![[0.0f64; 4]; centres.len()];
    for (a, p) in assign.iter().zip(pixels) {
        for c in 0..3 {
            sums[*a][c] += f64::from(p[c]);
        }
        sums[*a][3] += 1.0;
    }
    let total = labs.len() as f64;
    let mut out: Vec<PaletteColor> = sums
        .iter()
        .filter(|s| s[3] > 0.0)
        .map(|s| PaletteColor {
            color: [0, 1, 2].map(|c| linear_to_srgb((s[c] / s[3]) as f32)),
            weight: (s[3] / total) as f32,
        })
        .collect();
    out.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    out
}

/// k-means++ seeding; stops early when every pixel coincides with a centre (an image with
/// fewer distinct colours than `k` gets fewer palette colours).
fn kmeans_pp(labs: &[[f32; 3]], k: usize, rng: &mut impl Rng) -> Vec<[f32; 3]> {
    let mut centres = vec![labs[rng.random_range(0..labs.len())]];
    let mut d2: Vec<f64> = labs
        .iter()
        .map(|l| f64::from(delta_e(*l, centres[0])).powi(2))
        .collect();
    while centres.len() < k {
        let total: f64 = d2.iter().sum();
        if total <= 1e-9 {
            break;
        }
        let mut target = rng.random::<f64>() * total;
        let mut pick = d2.len() - 1;
        for (i, &d) in d2.iter().enumerate() {
            if target < d {
                pick = i;
                break;
            }
            target -= d;
        }
        let c = labs[pick];
        centres.push(c);
        for (d, l) in d2.iter_mut().zip(labs) {
            *d = d.min(f64::from(delta_e(*l, c)).powi(2));
        }
    }
    centres
}

/// Index of the centre nearest to `lab`.
pub fn nearest(centres: &[[f32; 3]], lab: [f32; 3]) -> usize {
    let mut best = (0, f32::INFINITY);
    for (i, c) in centres.iter().enumerate() {
        let d = delta_e(*c, lab);
        if d < best.1 {
            best = (i, d);
        }
    }
    best.0
}

/// An objective as files record it (the gallery's JSON, the daemon's session file): its
/// analysis is kept, so it stands on its own without the image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectiveRecord {
    /// The reference's file name.
    pub image: String,
    /// `intensity`, `color` or `both`.
    pub aspects: String,
    /// x0, y0, x1, y1.
    pub region: [f32; 4],
    /// Mean L*.
    pub mean_l: f32,
    /// Key L*.
    pub key_l: f32,
    /// Fraction of pixels above the mean.
    pub bright: f32,
    /// Palette, heaviest first.
    pub palette: Vec<PaletteRecord>,
}

/// One palette colour as files record it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PaletteRecord {
    /// sRGB 0..1.
    pub color: [f32; 3],
    /// Share of pixels.
    pub weight: f32,
}

impl From<&Objective> for ObjectiveRecord {
    fn from(o: &Objective) -> ObjectiveRecord {
        let st = o.analysis.stats;
        ObjectiveRecord {
            image: o.image.clone(),
            aspects: o.aspects.name().to_string(),
            region: [o.region.x0, o.region.y0, o.region.x1, o.region.y1],
            mean_l: st.mean_l,
            key_l: st.key_l,
            bright: st.bright,
            palette: o
                .analysis
                .palette
                .iter()
                .map(|p| PaletteRecord {
                    color: p.color,
                    weight: p.weight,
                })
                .collect(),
        }
    }
}

impl ObjectiveRecord {
    /// The objective again; Err names what was edited into something invalid: aspects or
    /// a region that do not parse, or an analysis number that is not finite (a palette
    /// weight outside 0..1), which would put NaN into every generate.
    pub fn to_objective(&self) -> Result<Objective, String> {
        let [x0, y0, x1, y1] = self.region;
        let finite = |name: &str, v: f32| {
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("{name} {v} is not a finite number"))
            }
        };
        let palette = self
            .palette
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if p.color.iter().any(|c| !c.is_finite()) {
                    return Err(format!(
                        "palette colour {} {:?} is not finite",
                        i + 1,
                        p.color
                    ));
                }
                let weight = finite(&format!("palette weight {}", i + 1), p.weight)?;
                if !(0.0..=1.0).contains(&weight) {
                    return Err(format!("palette weight {} {weight} is outside 0..1", i + 1));
                }
                Ok(PaletteColor {
                    color: p.color,
                    weight,
                })
            })
            .collect::<Result<_, String>>()?;
        Ok(Objective {
            image: self.image.clone(),
            aspects: Aspects::parse(&self.aspects)?,
            region: Region::new(x0, y0, x1, y1)?,
            analysis: Analysis {
                stats: IntensityStats {
                    mean_l: finite("mean_l", self.mean_l)?,
                    key_l: finite("key_l", self.key_l)?,
                    bright: finite("bright", self.bright)?,
                },
                palette,
            },
        })
    }
}
