//! Which lights reach a region of the stage, and how strongly (paper 4.4.1 and 4.2.5).
//!
//! Both are read straight off the basis images (the composite is linear), at a small
//! working resolution, once per light at load; a region query is then a pixel count.

use rayon::prelude::*;

use crate::objective::Region;
use visobjd_compositor::basis::BasisImages;

/// Width the footprints are analysed at (docs/method.md, "Region targeting").
pub const WORKING_WIDTH: usize = 128;
/// A light's bright pixels: its top 15% by luminance among the pixels it lights.
const BRIGHT_FRACTION: f64 = 0.15;
/// A light's highlight pixels: its top 5%.
const HIGHLIGHT_FRACTION: f64 = 0.05;

/// Per-light luminance at the working resolution, with its bright/highlight thresholds.
#[derive(Debug, Clone)]
pub struct Footprints {
    width: usize,
    height: usize,
    /// `luma[l * pixels + p]`.
    luma: Vec<f32>,
    /// Per light: luminance at or above which a pixel is bright / a highlight; `INFINITY`
    /// for a light that lights nothing.
    bright: Vec<f32>,
    highlight: Vec<f32>,
}

impl Footprints {
    /// Analyses basis images (ideally already at [`WORKING_WIDTH`]).
    pub fn new(basis: &BasisImages) -> Footprints {
        let mut luma = Vec::with_capacity(basis.lights * basis.pixels());
        let mut bright = Vec::with_capacity(basis.lights);
        let mut highlight = Vec::with_capacity(basis.lights);
        for l in 0..basis.lights {
            let lum = basis.luminance(l);
            let mut lit: Vec<f32> = lum.iter().copied().filter(|&v| v > 0.0).collect();
            bright.push(top_threshold(&mut lit, BRIGHT_FRACTION));
            highlight.push(top_threshold(&mut lit, HIGHLIGHT_FRACTION));
            luma.extend(lum);
        }
        Footprints {
            width: basis.width,
            height: basis.height,
            luma,
            bright,
            highlight,
        }
    }

    fn lights(&self) -> usize {
        self.bright.len()
    }

    fn light(&self, l: usize) -> &[f32] {
        let n = self.width * self.height;
        &self.luma[l * n..(l + 1) * n]
    }

    fn inside(&self, region: Region) -> Vec<bool> {
        let (w, h) = (self.width, self.height);
        let (xs, ys) = region.pixel_spans(w, h);
        (0..w * h)
            .map(|p| xs.contains(&(p % w)) && ys.contains(&(p / w)))
            .collect()
    }

    /// The lights a region selects: any of the paper's three heuristics holds. The whole
    /// stage selects every light.
    pub fn select(&self, region: Region) -> Vec<bool> {
        if region.is_full() {
            return vec![true; self.lights()];
        }
        let inside = self.inside(region);
        let area = inside.iter().filter(|&&v| v).count().max(1) as f64;
        (0..self.lights())
            .map(|l| {
                let (mut bright_in, mut bright_all, mut high_in, mut high_all) = (0, 0, 0, 0);
                for (&v, &ins) in self.light(l).iter().zip(&inside) {
                    if v > 0.0 && v >= self.bright[l] {
                        bright_all += 1;
                        bright_in += usize::from(ins);
                    }
                    if v > 0.0 && v >= self.highlight[l] {
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

    /// Per light, the mean luminance it adds inside the region per unit of intensity: the
    /// "sensitivity" brightness normalisation divides by. Runs on every generate, so it sums
    /// the region's row spans (a rectangle) in parallel instead of testing every pixel.
    pub fn sensitivity(&self, region: Region) -> Vec<f32> {
        let w = self.width;
        let (xs, ys) = region.pixel_spans(w, self.height);
        let area = (xs.len() * ys.len()).max(1) as f64;
        (0..self.lights())
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
