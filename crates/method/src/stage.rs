//! A scene with its basis images loaded at the sizes in use: what generation and previews
//! run on. Everything here is computed once at load, never per render.

use std::path::Path;

use crate::gallery::{Generation, PROXY_WIDTH, Size};
use crate::objective::Objective;
use crate::sampler::{Constraints, LightGroups, Plan, Spread, Target};
use crate::steer::Steer;
use crate::targeting::{Footprints, WORKING_WIDTH};
use visobjd_compositor::basis::{self, BasisImages, Loaded, Precision, Unseen, UnseenPosition};
use visobjd_compositor::render::{exposure_gain, render_srgb8};
use visobjd_scene::look::Look;
use visobjd_scene::{Scene, SceneError};

/// Default thumbnail width: the paper's gallery thumbnails are 480 px wide.
pub const THUMB_WIDTH: usize = 480;

/// What a candidate asked for costs per proxy pixel, in thumbnail pixels rendered, for a
/// generate's progress: about 1.7 candidates are drawn per candidate kept, and each is
/// rendered, converted to Lab and measured against every representative, where a thumbnail
/// is rendered and encoded. Measured on the demo scene (44 lights, 96 px proxies, 480 px
/// thumbnails): the drawing ends at about 70% of a 100-candidate generate's time and at 97%
/// or more of a 1000-candidate one's; 7 gives 0.70 and 0.96.
const DRAW_COST: usize = 7;

/// A loaded scene.
pub struct Stage {
    /// The scene description.
    pub scene: Scene,
    /// The sampler's view of the rig.
    pub rig: LightGroups,
    /// Region targeting and brightness normalisation data.
    pub footprints: Footprints,
    /// Basis images at proxy size (clustering distances).
    pub proxy: BasisImages,
    /// Basis images at thumbnail size (what people see).
    pub thumbs: BasisImages,
    /// Linear gain of the scene's exposure.
    pub gain: f32,
    /// Lights whose images could not be used: black in every preview and left out of
    /// generation (each keeps its level in the base look, as a locked light does), so a
    /// generate never moves a light it cannot see.
    pub unseen: Vec<Unseen>,
    /// Movers' positions whose images could not be used: never drawn (the light's other
    /// positions are), and named by `visobjd check` and the daemon's log.
    pub unseen_positions: Vec<UnseenPosition>,
}

impl Stage {
    /// Loads `dir/scene.toml` and every one of its basis images, keeping thumbnails
    /// `thumb_width` wide (0: full size): what the offline tools (a gallery, a render)
    /// need, where a light missing from the pictures would mislead. The error is the first
    /// unusable image, with how many more there are. The daemon, which must run without a
    /// bad image's light, uses [`Stage::from_scene`] and its [`Stage::unseen`].
    pub fn load(dir: &Path, thumb_width: usize) -> Result<Stage, SceneError> {
        let scene = Scene::load(dir)?;
        let mut stage = Stage::from_scene(scene, thumb_width)?;
        let more = stage.unseen.len().saturating_sub(1);
        let first = std::mem::take(&mut stage.unseen).into_iter().next();
        match first {
            None => Ok(stage),
            Some(u) if more == 0 => Err(u.error),
            Some(u) => Err(SceneError::Basis {
                path: match &u.error {
                    SceneError::Basis { path, .. } => path.clone(),
                    _ => stage.scene.lights[u.light].basis.clone(),
                },
                message: format!(
                    "{} (and {more} more basis images cannot be used: `visobjd check` lists them)",
                    match u.error {
                        SceneError::Basis { message, .. } => message,
                        other => other.to_string(),
                    }
                ),
            }),
        }
    }

    /// Loads the basis images of an already validated scene.
    pub fn from_scene(scene: Scene, thumb_width: usize) -> Result<Stage, SceneError> {
        // Targeting measures the working size exactly and the small proxy is used in place;
        // thumbnails, most of the bytes, are stored as half floats (half the memory and
        // memory traffic, invisible in 8-bit output).
        let Loaded {
            images: mut sizes,
            unseen,
            unseen_positions,
        } = basis::load(
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
            rig: LightGroups::new(&scene),
            footprints: Footprints::new(&working),
            gain: exposure_gain(scene.exposure),
            scene,
            proxy,
            thumbs,
            unseen,
            unseen_positions,
        })
    }

    /// A stage of `scene` whose images are all black (one pixel each): the patch without
    /// pictures, for a daemon whose scene's images cannot be read, so that its saved look
    /// still goes out through the patch.
    pub fn blank(scene: Scene) -> Stage {
        let lights = scene.lights.len();
        let black = |p| BasisImages::from_planes(1, 1, lights, &vec![0.0; 3 * lights], p);
        Stage {
            rig: LightGroups::new(&scene),
            footprints: Footprints::new(&black(Precision::Single)),
            gain: exposure_gain(scene.exposure),
            proxy: black(Precision::Single),
            thumbs: black(Precision::Half),
            unseen: Vec::new(),
            unseen_positions: Vec::new(),
            scene,
        }
    }

    /// Prepares an objective for this stage: the lights its region selects and their
    /// sensitivities there.
    pub fn target(&self, objective: &Objective) -> Target {
        let stats = objective.analysis.stats;
        let (selected, sensitivity, positions) = self.footprints.reach(objective.region);
        Target {
            aspects: objective.aspects,
            area: objective.region.area(),
            selected,
            sensitivity,
            positions,
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
        self.generate_with_progress(request, rng, |_| {})
    }

    /// [`Stage::generate`], telling `progress` the share of the generate done as it goes,
    /// so a progress bar can follow it: non-decreasing, below 1 (the generate is done when
    /// it returns), at most once a batch of candidates, and the same sequence for the same
    /// seed and inputs (counted in work, not time). The drawing fills the first part (about
    /// 70% of a 100-candidate generate, more of a larger one); the rest is the
    /// representatives' thumbnails, which may still be rendering when the drawing ends.
    pub fn generate_with_progress(
        &self,
        request: &GenerateRequest,
        rng: &mut (impl rand::Rng + Send),
        mut progress: impl FnMut(f32) + Send,
    ) -> Generation {
        let targets: Vec<Target> = request.objectives.iter().map(|o| self.target(o)).collect();
        let mut constraints = request.constraints.clone();
        for u in &self.unseen {
            if let Some(locked) = constraints.locked.get_mut(u.light) {
                *locked = true;
            }
        }
        let plan = Plan::new(
            &self.rig,
            &constraints,
            &targets,
            request.base,
            request.spread,
        );
        let size = Size {
            count: request.count,
            clusters: request.clusters,
        };
        let share = self.drawing_share(size);
        let mut steer = request.steer.cloned();
        let kept: Vec<bool> = (0..self.scene.lights.len())
            .map(|l| constraints.locked[l] || constraints.off[l])
            .collect();
        let (mut generation, thumbnails) = crate::gallery::generate(
            &plan,
            request.base,
            &self.proxy,
            self.gain,
            size,
            rng,
            steer.as_mut().map(|s| (s, kept.as_slice())),
            |reps| self.thumbnails(reps),
            &mut |done| progress(done * share),
        );
        generation.thumbnails = thumbnails.into();
        generation
    }

    /// The share of a generate of `size` that is the drawing, against the representatives'
    /// thumbnails, counted in pixels rendered: a candidate is weighed [`DRAW_COST`] times
    /// its proxy's pixels. At most 0.99, so a progress bar's last step is always the end.
    fn drawing_share(&self, size: Size) -> f32 {
        let drawing = (size.count.max(1) * DRAW_COST * self.proxy.pixels()) as f64;
        let thumbnails = (size.clusters.clamp(1, size.count.max(1)) * self.thumbs.pixels()) as f64;
        (drawing / (drawing + thumbnails).max(1.0)).min(0.99) as f32
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
    /// Steering by the designer's ratings; `None`: the generate it always was.
    pub steer: Option<&'a Steer>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objective::{Aspects, Region, analyze};
    use rand::SeedableRng;

    /// A stage of `lights` colour lights, light l lighting the l-th band of columns, built
    /// in memory (no basis files).
    fn stage(lights: usize) -> Stage {
        let mut toml = String::from("name = \"progress\"\n");
        for l in 0..lights {
            toml += &format!(
                "[[light]]\nchannel = {}\nbasis = \"basis/{l}.exr\"\nprofile = \"irgb\"\nuniverse = 1\naddress = {}\n",
                l + 1,
                4 * l + 1
            );
        }
        let scene = Scene::parse(Path::new("progress"), &toml).expect("a valid scene");
        let (w, h) = (8 * lights, 12);
        let planes: Vec<f32> = (0..3 * lights)
            .flat_map(|i| (0..w * h).map(move |p| f32::from(p % w / 8 == i % lights) * 0.5))
            .collect();
        let at = |precision| BasisImages::from_planes(w, h, lights, &planes, precision);
        Stage {
            rig: LightGroups::new(&scene),
            footprints: Footprints::new(&at(Precision::Single)),
            gain: exposure_gain(scene.exposure),
            scene,
            proxy: at(Precision::Single),
            thumbs: at(Precision::Half),
            unseen: Vec::new(),
            unseen_positions: Vec::new(),
        }
    }

    fn objective() -> Objective {
        let img = image::RgbImage::from_fn(60, 40, |x, y| {
            image::Rgb(match (x < 30, y < 20) {
                (true, _) => [240, 140, 40],
                (false, true) => [30, 50, 160],
                (false, false) => [220, 220, 210],
            })
        });
        Objective {
            image: "test.png".into(),
            aspects: Aspects::Both,
            region: Region::FULL,
            analysis: analyze(&img, Region::FULL, 5),
        }
    }

    /// A generate of `count` with `seed`, and the progress it reported.
    fn run(st: &Stage, count: usize, seed: u64) -> (Generation, Vec<f32>) {
        run_with(st, &Constraints::none(&st.rig), count, seed)
    }

    fn run_with(
        st: &Stage,
        constraints: &Constraints,
        count: usize,
        seed: u64,
    ) -> (Generation, Vec<f32>) {
        let objectives = [objective()];
        let base = Look::off(st.scene.lights.len());
        let request = GenerateRequest {
            objectives: &objectives,
            constraints,
            base: &base,
            spread: Spread::default(),
            count,
            clusters: 12,
            steer: None,
        };
        let mut seen = Vec::new();
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
        let g = st.generate_with_progress(&request, &mut rng, |f| seen.push(f));
        (g, seen)
    }

    #[test]
    fn progress_rises_below_one_the_same_for_the_same_seed() {
        let st = stage(12);
        // Several batches of 64: at least 300 draws.
        let (g, seen) = run(&st, 300, 7);
        assert!(
            seen.windows(2).all(|w| w[0] <= w[1]),
            "not monotone: {seen:?}"
        );
        assert!(seen.iter().all(|f| (0.0..1.0).contains(f)), "{seen:?}");
        let between = seen.iter().filter(|&&f| f > 0.0 && f < 1.0).count();
        assert!(between >= 3, "only {between} values inside: {seen:?}");
        // One report a batch (of at most 64), the first before any work, and the drawing's
        // end last.
        assert!(
            seen.len() > g.draws.div_ceil(64),
            "{} draws: {seen:?}",
            g.draws
        );
        assert_eq!(seen[0], 0.0);
        let share = st.drawing_share(Size {
            count: 300,
            clusters: 12,
        });
        assert_eq!(*seen.last().expect("reports"), share);
        assert!(seen[seen.len() - 2] < share, "{seen:?}");

        let (again, twice) = run(&st, 300, 7);
        assert_eq!(seen, twice);
        assert_eq!(g.candidates, again.candidates);
    }

    #[test]
    fn a_light_whose_image_is_unseen_keeps_its_base_level_in_every_candidate() {
        let mut st = stage(6);
        st.unseen.push(Unseen {
            light: 2,
            error: SceneError::Basis {
                path: "basis/003.exr".into(),
                message: "not found".into(),
            },
        });
        let (g, _) = run(&st, 60, 5);
        assert!(
            g.candidates.iter().all(|c| c.levels[2].intensity == 0.0),
            "the unseen light moved"
        );
        let moved = |l: usize| g.candidates.iter().any(|c| c.levels[l].intensity > 0.0);
        assert!(
            (0..6).filter(|&l| l != 2).any(moved),
            "nothing moved at all"
        );
    }

    #[test]
    fn progress_of_a_generate_that_runs_out_of_draws_follows_the_draws() {
        // Every light locked: every candidate is the base look and all but the first are
        // rejected, so only the draws move the bar, up to their bound.
        let st = stage(4);
        let mut constraints = Constraints::none(&st.rig);
        constraints.locked = vec![true; 4];
        let (g, seen) = run_with(&st, &constraints, 10, 3);
        assert!(g.exhausted);
        assert!(
            seen.windows(2).all(|w| w[0] <= w[1]),
            "not monotone: {seen:?}"
        );
        assert!(seen.iter().all(|f| (0.0..1.0).contains(f)), "{seen:?}");
        let share = st.drawing_share(Size {
            count: 10,
            clusters: 12,
        });
        // Each batch before the last adds its draws' share of the bound.
        let bound = (10 * crate::gallery::DRAWS_PER_CANDIDATE) as f32;
        assert!(
            seen[seen.len() - 2] >= share * (bound - 9.0) / bound,
            "{seen:?}"
        );
        assert_eq!(*seen.last().expect("reports"), share);
    }
}
