//! A scene with its basis images loaded at the sizes in use: what generation and previews
//! run on. Everything here is computed once at load, never per render.

use std::path::Path;

use crate::gallery::{Generation, PROXY_WIDTH, Size};
use crate::objective::Objective;
use crate::sampler::{Constraints, Plan, Rig, Spread, Target};
use crate::targeting::{Footprints, WORKING_WIDTH};
use visobjd_compositor::basis::{self, BasisImages, Precision};
use visobjd_compositor::render::{exposure_gain, render_srgb8};
use visobjd_scene::look::Look;
use visobjd_scene::{Scene, SceneError};

/// Default thumbnail width: the paper's gallery thumbnails are 480 px wide.
pub const THUMB_WIDTH: usize = 480;

/// A loaded scene.
pub struct Stage {
    /// The scene description.
    pub scene: Scene,
    /// The sampler's view of the rig.
    pub rig: Rig,
    /// Region targeting and brightness normalisation data.
    pub footprints: Footprints,
    /// Basis images at proxy size (clustering distances).
    pub proxy: BasisImages,
    /// Basis images at thumbnail size (what people see).
    pub thumbs: BasisImages,
    /// Linear gain of the scene's exposure.
    pub gain: f32,
}

impl Stage {
    /// Loads `dir/scene.toml` and its basis images, keeping thumbnails `thumb_width` wide
    /// (0: full size).
    pub fn load(dir: &Path, thumb_width: usize) -> Result<Stage, SceneError> {
        let scene = Scene::load(dir)?;
        Stage::from_scene(scene, thumb_width)
    }

    /// Loads the basis images of an already validated scene.
    pub fn from_scene(scene: Scene, thumb_width: usize) -> Result<Stage, SceneError> {
        // Targeting measures the working size exactly and the small proxy is used in place;
        // thumbnails, most of the bytes, are stored as half floats (half the memory and
        // memory traffic, invisible in 8-bit output).
        let mut sizes = basis::load(
            &scene,
            &[
                (WORKING_WIDTH, Precision::Single),
                (PROXY_WIDTH, Precision::Single),
                (thumb_width, Precision::Half),
            ],
        )?;
        let thumbs = sizes.pop().expect("three sizes asked");
        let proxy = sizes.pop().expect("three sizes asked");
        let working = sizes.pop().expect("three sizes asked");
        Ok(Stage {
            rig: Rig::new(&scene),
            footprints: Footprints::new(&working),
            gain: exposure_gain(scene.exposure),
            scene,
            proxy,
            thumbs,
        })
    }

    /// Prepares an objective for this stage: the lights its region selects and their
    /// sensitivities there.
    pub fn target(&self, objective: &Objective) -> Target {
        let stats = objective.analysis.stats;
        Target {
            aspects: objective.aspects,
            area: objective.region.area(),
            selected: self.footprints.select(objective.region),
            sensitivity: self.footprints.sensitivity(objective.region),
            mean: stats.mean_l / 100.0,
            key: stats.key_l / 100.0,
            bright: stats.bright,
            palette: objective.analysis.palette.clone(),
        }
    }

    /// Samples and clusters candidates for the objectives from `base`, and renders the
    /// representatives' thumbnails (what a user sees first), while the last candidates are
    /// still being decided.
    pub fn generate(
        &self,
        request: &GenerateRequest,
        rng: &mut (impl rand::Rng + Send),
    ) -> Generation {
        let targets: Vec<Target> = request.objectives.iter().map(|o| self.target(o)).collect();
        let plan = Plan::new(
            &self.rig,
            request.constraints,
            &targets,
            request.base,
            request.spread,
        );
        let size = Size {
            count: request.count,
            clusters: request.clusters,
        };
        let (mut generation, thumbnails) = crate::gallery::generate(
            &plan,
            request.base,
            &self.proxy,
            self.gain,
            size,
            rng,
            |reps| self.thumbnails(reps),
        );
        generation.thumbnails = thumbnails.into();
        generation
    }

    /// Thumbnails of looks, in order.
    pub fn thumbnails(&self, looks: &[&Look]) -> Vec<image::RgbImage> {
        render_srgb8(&self.thumbs, looks, self.gain)
    }
}

/// Everything a generate depends on besides the stage and the random seed.
pub struct GenerateRequest<'a> {
    /// Objectives in the order they were added.
    pub objectives: &'a [Objective],
    /// Locks, keys and granularity.
    pub constraints: &'a Constraints,
    /// The look generation starts from.
    pub base: &'a Look,
    /// Key and fill spreads.
    pub spread: Spread,
    /// Candidates to accept (N).
    pub count: usize,
    /// Entries at most (c).
    pub clusters: usize,
}
