//! Which lights reach a region of the stage, and how strongly (paper 4.4.1 and 4.2.5).
//!
//! Both are read straight off the basis images (the composite is linear), at a small
//! working resolution, once per light at load; a region query is then a pixel count.

use std::ops::Range;

use rayon::prelude::*;

use crate::objective::Region;
use visobjd_compositor::basis::BasisImages;

/// Width the footprints are analysed at (docs/method.md, "Region targeting").
pub const WORKING_WIDTH: usize = 128;
/// A light's bright pixels: its top 15% by luminance among the pixels it lights.
const BRIGHT_FRACTION: f64 = 0.15;
/// A light's highlight pixels: its top 5%.
const HIGHLIGHT_FRACTION: f64 = 0.05;

/// Per-image luminance at the working resolution, and where each image's bright and
/// highlight pixels are: every light's white image, then each moving light's other
/// positions, so a region selects a mover by the positions it can take.
#[derive(Debug, Clone)]
pub struct Footprints {
    width: usize,
    height: usize,
    /// `luma[i * pixels + p]` for footprint image `i`: lights first, then positions.
    luma: Vec<f32>,
    /// Per light, its positions as (focus palette, footprint image); empty for a fixed
    /// light. The first is the light's own image.
    positions: Vec<Vec<(u32, usize)>>,
    /// Per light, summed-area tables of its bright and highlight pixels: at each corner of
    /// the pixel grid (`(width + 1) * (height + 1)` per light, row by row) how many lie above
    /// and left of it. A region's counts are then four lookups per light whatever its
    /// size: a drag asks for a selection 60 times a second.
    counts: Vec<[u32; 2]>,
}

impl Footprints {
    /// Analyses basis images (ideally already at [`WORKING_WIDTH`]).
    pub fn new(basis: &BasisImages) -> Footprints {
        let mut luma = Vec::with_capacity(basis.lights * basis.pixels());
        for l in 0..basis.lights {
            luma.extend(basis.luminance(l));
        }
        let mut spots = basis.lights;
        let positions = basis
            .positions
            .iter()
            .enumerate()
            .map(|(l, held)| {
                held.iter()
                    .map(|&(palette, image)| {
                        if image == l {
                            (palette, l)
                        } else {
                            luma.extend(basis.luminance(image));
                            spots += 1;
                            (palette, spots - 1)
                        }
                    })
                    .collect()
            })
            .collect();
        Footprints {
            positions,
            ..Footprints::of_luma(basis.width, basis.height, luma)
        }
    }

    /// The footprints of luminance images `luma` (`width x height` each, one after the
    /// other), each a fixed light's.
    fn of_luma(width: usize, height: usize, luma: Vec<f32>) -> Footprints {
        let pixels = width * height;
        let lights = luma.len().checked_div(pixels).unwrap_or(0);
        let stride = width + 1;
        let corners = stride * (height + 1);
        let mut counts = vec![[0u32; 2]; lights * corners];
        for l in 0..lights {
            let lum = &luma[l * pixels..(l + 1) * pixels];
            let [b, h] = thresholds(lum);
            let table = &mut counts[l * corners..(l + 1) * corners];
            for y in 0..height {
                let mut row = [0u32; 2];
                for x in 0..width {
                    let v = lum[y * width + x];
                    row[0] += u32::from(v > 0.0 && v >= b);
                    row[1] += u32::from(v > 0.0 && v >= h);
                    let above = table[y * stride + x + 1];
                    table[(y + 1) * stride + x + 1] = [above[0] + row[0], above[1] + row[1]];
                }
            }
        }
        Footprints {
            width,
            height,
            positions: vec![Vec::new(); lights],
            luma,
            counts,
        }
    }

    fn images(&self) -> usize {
        self.luma
            .len()
            .checked_div(self.width * self.height)
            .unwrap_or(0)
    }

    /// Per light, a value of each of its images (`per_image`): a fixed light's one, and
    /// for a mover `fold` over its positions'.
    fn per_light<T: Copy>(&self, per_image: &[T], fold: impl Fn(&[T]) -> T) -> Vec<T> {
        self.positions
            .iter()
            .enumerate()
            .map(|(l, held)| match held.as_slice() {
                [] => per_image[l],
                held => fold(&held.iter().map(|&(_, i)| per_image[i]).collect::<Vec<T>>()),
            })
            .collect()
    }

    /// What `region` reaches, each image measured once: per light whether it is selected
    /// and its sensitivity (as [`Footprints::select`] and [`Footprints::sensitivity`]),
    /// and per light, per position (the scene's order; empty for a fixed light), its focus
    /// palette, whether the region selects the light there and its sensitivity there.
    pub fn reach(&self, region: Region) -> (Vec<bool>, Vec<f32>, Vec<Vec<Reach>>) {
        let selected = self.select_images(region);
        let sensitivity = self.sensitivity_images(region);
        let positions = self
            .positions
            .iter()
            .map(|held| {
                held.iter()
                    .map(|&(palette, i)| Reach {
                        palette,
                        selected: selected[i],
                        sensitivity: sensitivity[i],
                    })
                    .collect()
            })
            .collect();
        (
            self.per_light(&selected, |v| v.contains(&true)),
            self.per_light(&sensitivity, |v| v[0]),
            positions,
        )
    }

    fn light(&self, l: usize) -> &[f32] {
        let n = self.width * self.height;
        &self.luma[l * n..(l + 1) * n]
    }

    /// Light `l`'s bright and highlight pixels inside the pixel rectangle `xs x ys`.
    fn count(&self, l: usize, xs: &Range<usize>, ys: &Range<usize>) -> [u32; 2] {
        let stride = self.width + 1;
        let corners = stride * (self.height + 1);
        let table = &self.counts[l * corners..(l + 1) * corners];
        let at = |x: usize, y: usize| table[y * stride + x];
        let (a, b) = (at(xs.start, ys.start), at(xs.end, ys.start));
        let (c, d) = (at(xs.start, ys.end), at(xs.end, ys.end));
        [0, 1].map(|k| d[k] + a[k] - b[k] - c[k])
    }

    /// The lights a region selects: any of the paper's three heuristics holds (for a
    /// moving light, in any of its positions). The whole stage selects every light.
    pub fn select(&self, region: Region) -> Vec<bool> {
        self.per_light(&self.select_images(region), |v| v.contains(&true))
    }

    /// [`Footprints::select`] per footprint image.
    fn select_images(&self, region: Region) -> Vec<bool> {
        if region.is_full() {
            return vec![true; self.images()];
        }
        let (xs, ys) = region.pixel_spans(self.width, self.height);
        let area = (xs.len() * ys.len()).max(1) as f64;
        let all = (0..self.width, 0..self.height);
        (0..self.images())
            .map(|l| {
                let [bright_in, high_in] = self.count(l, &xs, &ys).map(f64::from);
                let [bright_all, high_all] = self.count(l, &all.0, &all.1).map(f64::from);
                let covers = bright_in / area > 0.25;
                let contained = bright_all > 0.0 && bright_in / bright_all > 0.5;
                let highlights = high_all > 0.0 && high_in / high_all > 0.05;
                covers || contained || highlights
            })
            .collect()
    }

    /// Per light, the mean luminance it adds inside the region per unit of intensity: the
    /// "sensitivity" brightness normalisation divides by (a moving light's in its first
    /// position). Runs on every generate, so it sums the region's row spans (a rectangle)
    /// in parallel instead of testing every pixel.
    pub fn sensitivity(&self, region: Region) -> Vec<f32> {
        self.per_light(&self.sensitivity_images(region), |v| v[0])
    }

    /// [`Footprints::sensitivity`] per footprint image.
    fn sensitivity_images(&self, region: Region) -> Vec<f32> {
        let w = self.width;
        let (xs, ys) = region.pixel_spans(w, self.height);
        let area = (xs.len() * ys.len()).max(1) as f64;
        (0..self.images())
            .into_par_iter()
            .map(|l| {
                let light = self.light(l);
                let sum: f64 = ys
                    .clone()
                    .map(|y| f64::from(lane_sum(&light[y * w..][xs.clone()])))
                    .sum();
                (sum / area) as f32
            })
            .collect()
    }
}

/// One position of a moving light as a region sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// Its focus palette.
    pub palette: u32,
    /// The region selects the light in this position.
    pub selected: bool,
    /// Mean luminance it adds in the region per unit of intensity, in this position.
    pub sensitivity: f32,
}

/// Sum in eight independent lanes, so it vectorises (a single running f32 sum cannot).
fn lane_sum(v: &[f32]) -> f32 {
    let (chunks, rest) = v.as_chunks::<8>();
    let mut lanes = [0.0f32; 8];
    for c in chunks {
        for (l, x) in lanes.iter_mut().zip(c) {
            *l += x;
        }
    }
    lanes.iter().sum::<f32>() + rest.iter().sum::<f32>()
}

/// The luminance at or above which a pixel of a light's image `lum` is bright, and a
/// highlight: its top [`BRIGHT_FRACTION`] and [`HIGHLIGHT_FRACTION`] among the pixels it
/// lights (`INFINITY` for a light that lights nothing).
fn thresholds(lum: &[f32]) -> [f32; 2] {
    let mut lit: Vec<f32> = lum.iter().copied().filter(|&v| v > 0.0).collect();
    [BRIGHT_FRACTION, HIGHLIGHT_FRACTION].map(|f| top_threshold(&mut lit, f))
}

/// The value at or above which the top `fraction` of `values` lie (`INFINITY` if empty).
fn top_threshold(values: &mut [f32], fraction: f64) -> f32 {
    if values.is_empty() {
        return f32::INFINITY;
    }
    let n = values.len();
    let k = ((fraction * n as f64).ceil() as usize).clamp(1, n);
    let (_, kth, _) = values.select_nth_unstable_by(n - k, |a, b| a.total_cmp(b));
    *kth
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The selection as the paper states it, pixel by pixel.
    fn select_by_pixels(f: &Footprints, region: Region) -> Vec<bool> {
        let (w, h) = (f.width, f.height);
        let (xs, ys) = region.pixel_spans(w, h);
        let inside: Vec<bool> = (0..w * h)
            .map(|p| xs.contains(&(p % w)) && ys.contains(&(p / w)))
            .collect();
        let area = inside.iter().filter(|&&v| v).count().max(1) as f64;
        (0..f.positions.len())
            .map(|l| {
                let [bright, highlight] = thresholds(f.light(l));
                let (mut bright_in, mut bright_all, mut high_in, mut high_all) = (0, 0, 0, 0);
                for (&v, &ins) in f.light(l).iter().zip(&inside) {
                    if v > 0.0 && v >= bright {
                        bright_all += 1;
                        bright_in += usize::from(ins);
                    }
                    if v > 0.0 && v >= highlight {
                        high_all += 1;
                        high_in += usize::from(ins);
                    }
                }
                let covers = bright_in as f64 / area > 0.25;
                let contained = bright_all > 0 && bright_in as f64 / bright_all as f64 > 0.5;
                let highlights = high_all > 0 && high_in as f64 / high_all as f64 > 0.05;
                covers || contained || highlights
            })
            .collect()
    }

    #[test]
    fn the_tables_select_what_the_pixels_do() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        let (w, h, lights) = (37, 23, 40);
        // Each light a soft spot somewhere (some off stage, one dark), as basis images are.
        let mut luma = Vec::new();
        for l in 0..lights {
            let (cx, cy) = (
                rng.random_range(-5.0..42.0f32),
                rng.random_range(-5.0..28.0f32),
            );
            let r = rng.random_range(2.0..15.0f32);
            for y in 0..h {
                for x in 0..w {
                    let d2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2);
                    luma.push(if l == 3 {
                        0.0
                    } else {
                        (1.0 - d2 / (r * r)).max(0.0)
                    });
                }
            }
        }
        let f = Footprints::of_luma(w, h, luma);
        let mut picked = 0;
        for _ in 0..500 {
            let (x0, y0) = (rng.random_range(0.0..1.0f32), rng.random_range(0.0..1.0f32));
            let (x1, y1) = (rng.random_range(x0..=1.0f32), rng.random_range(y0..=1.0f32));
            let Ok(region) = Region::new(x0, y0, x1, y1) else {
                continue;
            };
            let want = select_by_pixels(&f, region);
            assert_eq!(f.select(region), want, "{region:?}");
            picked += want.iter().filter(|&&on| on).count();
        }
        // Regions select some lights and leave others: the comparison is not all-false.
        assert!(picked > 500 && picked < 500 * lights, "{picked}");
    }
}
