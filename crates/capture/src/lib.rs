//! `visobjd capture`: a real rig's basis images, light by light. Each light goes to full
//! (white through its profile, as the daemon drives it) with every other light at 0; the
//! camera shoots a metering frame, then a bracket chosen from it; the bracket is merged
//! to linear radiance ([`visobjd_hdr`]), the ambient light (measured with everything at
//! 0, at the start and the end) is taken off, and the result is written as the light's
//! basis image as soon as it is merged. `capture.json` beside `scene.toml` records the
//! camera, the exposures, the fitted camera response and every light done, so a capture
//! that stopped resumes at the next light on the same scale.
//!
//! The DMX side is the daemon's own output (`visobjd_dmx::Output`), run by the caller at
//! the capture's sACN priority; the camera is anything implementing
//! [`visobjd_camera::Camera`] (gphoto2, a command, or [`sim::SimCamera`]).

pub mod decode;
pub mod sim;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use visobjd_camera::{Camera, Shutter};
use visobjd_compositor::basis::Precision;
use visobjd_dmx::{Output, Patch, SlotLevels};
use visobjd_hdr::{BracketSettings, ExposureFit, MergeSettings, Radiance, Response};
use visobjd_scene::emitter::colour::{ciede2000, linear_srgb_to_xyz, xyz_to_lab};
use visobjd_scene::look::{Level, Look};
use visobjd_scene::{MeasuredEmitter, Scene, SceneFile};

/// What the camera is asked to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Format {
    /// 8-bit JPEG: the camera's response is recovered once per session.
    Jpeg,
    /// Linear raw (a 16-bit TIFF with black and white levels).
    Raw,
}

impl Format {
    /// `--format` values.
    pub fn parse(s: &str) -> Result<Format, String> {
        match s {
            "jpeg" | "jpg" => Ok(Format::Jpeg),
            "raw" => Ok(Format::Raw),
            other => Err(format!("--format {other}: expected raw or jpeg")),
        }
    }

    /// The camera's name for it (`imageformat`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Jpeg => "JPEG",
            Format::Raw => "RAW",
        }
    }

    /// The file extension the sim writes.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Jpeg => "jpg",
            Format::Raw => "dng",
        }
    }
}

/// How to capture.
#[derive(Debug, Clone)]
pub struct CaptureOptions {
    /// Channels to shoot (`--lights`); `None`: every light.
    pub lights: Option<Vec<u32>>,
    /// How long a light is given to reach its level before the first frame (lamps warm up).
    pub settle: Duration,
    /// How long a moving light is given, dark, to reach a new position before it is lit
    /// (`[capture] move_settle_s`): a shot taken while it still moves shows it elsewhere.
    pub move_settle: Duration,
    /// Basis width in pixels (height from the camera's aspect).
    pub width: usize,
    /// Raw or JPEG.
    pub format: Format,
    /// Seed of the validation look.
    pub seed: u64,
    /// Also shoot each additive emitter of a colour-mixing light alone (`--emitters`).
    pub emitters: bool,
}

/// What a person watching the capture is told.
pub trait Progress {
    /// The capture starts: this many lights to shoot.
    fn begin(&mut self, lights: usize);
    /// What is being done now ("light 7 (front 3): bracket of 5").
    fn step(&mut self, what: &str);
    /// One light is done (written, or found to show no light).
    fn light_done(&mut self);
    /// Something the user should know, shown without stopping.
    fn warn(&mut self, what: &str);
}

/// Why a capture stopped.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The camera failed (after its retry).
    #[error("camera: {0}")]
    Camera(#[from] visobjd_camera::Error),
    /// A merge failed.
    #[error("merge: {0}")]
    Merge(#[from] visobjd_hdr::HdrError),
    /// A shot or a record could not be read or written.
    #[error("{0}")]
    Files(String),
    /// Ctrl-C (or a stop request): what was written stays; run the same command to resume.
    #[error("stopped; the lights written so far are kept: run the same command to resume")]
    Stopped,
}

/// How a capture ended.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    /// Channels written in this run.
    pub captured: Vec<u32>,
    /// Channels already written by an earlier run (resumed past).
    pub resumed: Vec<u32>,
    /// Channels that show no light, with the sentence saying so (a moving light once per
    /// position that shows none).
    pub no_light: Vec<(u32, String)>,
    /// Moving lights' positions written in this run, as (channel, palette).
    pub positions_captured: Vec<(u32, u32)>,
    /// Moving lights' positions already written by an earlier run, as (channel, palette).
    pub positions_resumed: Vec<(u32, u32)>,
    /// Relative change of the ambient light between start and end.
    pub ambient_drift: Option<f64>,
    /// Median relative error of the validation shot against the composite.
    pub validation: Option<f64>,
    /// With `--emitters`: a saturated look of the lights captured per emitter, shot and
    /// compared with its previews.
    pub colour_validation: Option<ColourValidation>,
    /// Emitter images written in this run (`--emitters`).
    pub emitter_images: usize,
    /// Like `overhead_per_light`, per emitter image written.
    pub overhead_per_emitter: Option<f64>,
    /// Seconds per light written that capture itself took: the light's time less the
    /// camera's calls and the wait for the lamps and the DMX (decoding, merging,
    /// writing, metering decisions).
    pub overhead_per_light: Option<f64>,
}

/// How far a shot of a saturated look is from its previews: the median CIEDE2000 over the
/// pixels the shot lights, in CIELAB relative to the shot's brightest pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourValidation {
    /// The preview from the per-emitter images (each weighed by its solved level).
    pub per_emitter: f64,
    /// The preview from the white images and the profiles' colour models alone.
    pub white_only: f64,
}

/// `capture.json`: what a resumed capture needs, and what a person wants to know later.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Record {
    /// The camera's model.
    pub camera: String,
    /// Raw or JPEG.
    pub format: Option<Format>,
    /// The fitted camera response (JPEG), reused when resuming.
    pub response: Option<Response>,
    /// Lights written, by channel.
    pub lights: BTreeMap<u32, LightRecord>,
    /// Lights that showed no light, by channel.
    pub no_light: BTreeMap<u32, String>,
    /// Per-emitter images written (`--emitters`), by channel and emitter name.
    #[serde(default)]
    pub emitters: BTreeMap<u32, BTreeMap<String, LightRecord>>,
    /// Moving lights' position images written, by channel and focus palette: a moving
    /// light's images are its positions', so it has no entry in `lights`.
    #[serde(default)]
    pub positions: BTreeMap<u32, BTreeMap<u32, LightRecord>>,
    /// Moving lights' positions that showed no light, by channel and focus palette.
    #[serde(default)]
    pub no_light_positions: BTreeMap<u32, BTreeMap<u32, String>>,
    /// Relative ambient change between start and end.
    pub ambient_drift: Option<f64>,
    /// Median relative error of the validation shot.
    pub validation: Option<f64>,
}

/// One light as captured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LightRecord {
    /// The basis image written (relative to the scene folder).
    pub basis: String,
    /// DMX universe, start address and the bytes its slots were sent.
    pub dmx: (u16, u16, Vec<u8>),
    /// The bracket's frames: EXIF exposure and the ratio fitted from the pixels.
    pub exposures: Vec<ExposureFit>,
    /// Pixels clipped in every frame (0 unless the light is too bright for the camera).
    pub clipped: usize,
    /// When it was written (Unix seconds).
    pub time: u64,
}

/// Where the capture keeps its working files inside the scene folder.
fn work_dir(scene_dir: &Path) -> PathBuf {
    scene_dir.join("capture")
}

fn record_path(scene_dir: &Path) -> PathBuf {
    scene_dir.join("capture.json")
}

/// Reads `capture.json`; none is an empty record.
pub fn load_record(scene_dir: &Path) -> Result<Record, CaptureError> {
    match visobjd_files::load_json::<Record>(&record_path(scene_dir)) {
        visobjd_files::Loaded::Ok(r) => Ok(r),
        visobjd_files::Loaded::Missing => Ok(Record::default()),
        visobjd_files::Loaded::MovedAside(at, why) => Err(CaptureError::Files(format!(
            "capture.json {why}; it was kept as {} and the capture starts over",
            at.display()
        ))),
    }
}

fn save_record(scene_dir: &Path, record: &Record) -> Result<(), CaptureError> {
    visobjd_files::save_json(&record_path(scene_dir), record)
        .map_err(|e| CaptureError::Files(format!("capture.json cannot be written: {e}")))
}

fn now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// The session: the rig, the camera and what is known so far.
struct Session<'a> {
    scene: &'a Scene,
    scene_dir: &'a Path,
    output: &'a Output,
    camera: &'a mut dyn Camera,
    opts: &'a CaptureOptions,
    progress: &'a mut dyn Progress,
    stop: &'a AtomicBool,
    shutters: Vec<Shutter>,
    iso: f64,
    f_number: f64,
    record: Record,
    shots: u64,
    /// The scene's patch, for the DMX bytes each light is recorded with.
    patch: Patch,
    /// Time spent in the camera's calls and waiting for the rig, so far: what capture's
    /// own overhead is measured without.
    waited: Duration,
    /// The look last put on the rig: where each moving light points now, so [`Session::show`]
    /// moves one dark before it is lit somewhere else.
    shown: Look,
}

/// Captures the scene's basis images (see the crate's documentation). `output` must be
/// running with the scene's patch; the caller stops it (terminating its streams) however
/// this returns.
pub fn capture(
    scene: &Scene,
    scene_dir: &Path,
    output: &Output,
    camera: &mut dyn Camera,
    opts: &CaptureOptions,
    progress: &mut dyn Progress,
    stop: &AtomicBool,
) -> Result<Summary, CaptureError> {
    let description = camera.describe()?;
    let settings = camera.settings()?;
    if let Some(f) = &settings.image_format {
        // Bodies name their formats their own way (`Large Fine JPEG`, `RAW`, `RAW + JPEG`):
        // JPEG alone, or RAW alone; keep the current one when none fits.
        let fits = |c: &&String| {
            let c = c.to_uppercase();
            match opts.format {
                Format::Jpeg => c.contains("JPEG") && !c.contains("RAW"),
                Format::Raw => c.contains("RAW") && !c.contains("JPEG"),
            }
        };
        if let Some(choice) = f.choices.iter().find(fits) {
            camera.set_config(&f.key, choice)?;
        }
    }
    let number = |s: Option<&visobjd_camera::CameraSetting>, default: f64| {
        s.and_then(|s| s.current.trim_start_matches("f/").parse::<f64>().ok())
            .unwrap_or(default)
    };
    let mut record = load_record(scene_dir)?;
    if record.format.is_some_and(|f| f != opts.format) {
        return Err(CaptureError::Files(format!(
            "capture.json was made in {:?}; resume with the same --format, or move it aside to start over",
            record.format
        )));
    }
    record.camera = description.model;
    record.format = Some(opts.format);
    std::fs::create_dir_all(work_dir(scene_dir))
        .map_err(|e| CaptureError::Files(format!("cannot make the capture folder: {e}")))?;
    let mut s = Session {
        scene,
        scene_dir,
        output,
        opts,
        progress,
        stop,
        shutters: settings.shutter.shutters(),
        iso: number(settings.iso.as_ref(), 100.0),
        f_number: number(settings.aperture.as_ref(), 8.0),
        camera,
        record,
        shots: 0,
        patch: Patch::new(scene),
        waited: Duration::ZERO,
        // What the caller starts the output with.
        shown: Look::off(scene.lights.len()),
    };
    if s.shutters.is_empty() {
        return Err(CaptureError::Files(
            "the camera lists no shutter times: set its mode dial to M".into(),
        ));
    }
    s.run()
}

impl Session<'_> {
    fn run(&mut self) -> Result<Summary, CaptureError> {
        let todo: Vec<usize> = (0..self.scene.lights.len())
            .filter(|&l| {
                let ch = self.scene.lights[l].channel;
                self.opts.lights.as_ref().is_none_or(|w| w.contains(&ch))
            })
            .collect();
        let mut summary = Summary::default();
        let (mut own, mut own_emitters) = (Duration::ZERO, Duration::ZERO);
        self.progress.begin(todo.len());
        if self.opts.format == Format::Jpeg && self.record.response.is_none() {
            self.progress
                .step("camera response: a bracket of every light at full");
            let all = Look {
                levels: vec![WHITE; self.scene.lights.len()],
            };
            self.show(&all, self.patch.unmastered(&all))?;
            let shots = self.response_bracket()?;
            let frames: Vec<_> = shots.iter().map(decode::DecodedShot::frame).collect();
            let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(self.opts.seed);
            self.record.response = Some(Response::recover(&frames, &mut rng)?);
            save_record(self.scene_dir, &self.record)?;
        }
        let ambient = self.ambient("ambient-start.exr")?;
        // A second look at the same dark stage: how much two merges of the same light
        // differ, the measure a light must clearly exceed to show light.
        let again = self.ambient("ambient-again.exr")?;
        for l in todo {
            let light = &self.scene.lights[l];
            let ch = light.channel;
            if light.is_moving() {
                // Each position with no image yet; a moving light has no emitter images
                // (scene.toml keeps `emitter_basis` for fixed lights: they would hold
                // for one position only).
                let (before, mut resumed) = (summary.positions_captured.len(), 0);
                for p in 0..light.positions.len() {
                    let palette = light.positions[p].palette;
                    let done = self
                        .record
                        .positions
                        .get(&ch)
                        .is_some_and(|m| m.contains_key(&palette));
                    if done && light.positions[p].basis.is_file() {
                        summary.positions_resumed.push((ch, palette));
                        resumed += 1;
                    } else {
                        self.alone(l, Some(p), (&ambient, &again), &mut summary, &mut own)?;
                    }
                }
                if summary.positions_captured.len() > before {
                    summary.captured.push(ch);
                } else if resumed == light.positions.len() {
                    summary.resumed.push(ch);
                }
                self.progress.light_done();
                continue;
            }
            if self.record.lights.contains_key(&ch) && light.basis.is_file() {
                summary.resumed.push(ch);
            } else if !self.alone(l, None, (&ambient, &again), &mut summary, &mut own)? {
                self.progress.light_done();
                continue;
            }
            if self.opts.emitters {
                let (started, waited) = (Instant::now(), self.waited);
                let n = self.emitters(l, &ambient)?;
                summary.emitter_images += n;
                own_emitters += started.elapsed().saturating_sub(self.waited - waited);
            }
            self.progress.light_done();
        }
        self.progress.step("ambient light again: everything at 0");
        let off = Look::off(self.scene.lights.len());
        let end = self
            .shoot_look(&off, self.patch.unmastered(&off), true)?
            .radiance;
        let drift = visobjd_hdr::ambient_drift(&ambient, &again, &end)?;
        if drift.relative > 0.05 {
            self.progress.warn(&format!(
                "the ambient light changed by {:.0}% between the start and the end (work lights, a door, daylight?): the basis images carry the difference",
                drift.relative * 100.0
            ));
        }
        summary.ambient_drift = Some(drift.relative);
        self.record.ambient_drift = summary.ambient_drift;
        // Per image: a moving light's positions each count as one.
        let images = summary.positions_captured.len()
            + summary
                .captured
                .iter()
                .filter(|&&ch| self.record.lights.contains_key(&ch))
                .count();
        summary.overhead_per_light = (images > 0).then(|| own.as_secs_f64() / images as f64);
        summary.overhead_per_emitter = (summary.emitter_images > 0)
            .then(|| own_emitters.as_secs_f64() / summary.emitter_images as f64);
        summary.validation = self.validate(&ambient)?;
        self.record.validation = summary.validation;
        if self.opts.emitters {
            summary.colour_validation = self.validate_colour(&ambient)?;
        }
        save_record(self.scene_dir, &self.record)?;
        Ok(summary)
    }

    /// Light `l` at full white alone (a moving light in its position `position`, an index
    /// into its [`visobjd_scene::Light::positions`]: moved there dark first by
    /// [`Session::show`]), merged, the ambient (`ambient`, and `again` for the noise test)
    /// taken off and written as its basis image (the position's); false (recorded and
    /// reported) when it shows no light.
    fn alone(
        &mut self,
        l: usize,
        position: Option<usize>,
        (ambient, again): (&Radiance, &Radiance),
        summary: &mut Summary,
        own: &mut Duration,
    ) -> Result<bool, CaptureError> {
        let light = &self.scene.lights[l];
        let (ch, name) = (light.channel, light.name.clone());
        let aim = position.map(|p| &light.positions[p]);
        let palette = aim.map(|p| p.palette);
        let basis = aim.map_or(&light.basis, |p| &p.basis).clone();
        let what = match palette {
            Some(n) => format!("light {ch} ({name}) in palette {}", self.palette_name(n)),
            None => format!("light {ch} ({name})"),
        };
        if self.stop.load(Ordering::SeqCst) {
            return Err(CaptureError::Stopped);
        }
        self.progress.step(&what);
        let (started, waited) = (Instant::now(), self.waited);
        let mut look = Look::off(self.scene.lights.len());
        look.levels[l] = Level {
            position: palette,
            ..WHITE
        };
        let merged = self.shoot_look(&look, self.patch.unmastered(&look), false)?;
        let mut test = visobjd_hdr::light_test(&merged.radiance, ambient)?;
        let above = above_null(&merged.radiance, ambient, again);
        test.shows_light &= above >= test.min_lit_pixels;
        tracing::debug!("{what}: {test:?}, {above} samples above the ambient's own spread");
        if !test.shows_light {
            let why = format!("{what} shows no light: unpatched, lamp out, or aimed out of frame?");
            self.progress.warn(&why);
            match palette {
                Some(n) => {
                    self.record
                        .no_light_positions
                        .entry(ch)
                        .or_default()
                        .insert(n, why.clone());
                }
                None => {
                    self.record.no_light.insert(ch, why.clone());
                }
            }
            summary.no_light.push((ch, why));
            save_record(self.scene_dir, &self.record)?;
            return Ok(false);
        }
        if merged.clipped_everywhere > 0 {
            self.progress.warn(&format!(
                "{what}: {} pixels are clipped even at the shortest exposure: close the aperture or lower the ISO",
                merged.clipped_everywhere
            ));
        }
        let image = visobjd_hdr::subtract_ambient(&merged.radiance, ambient)?;
        visobjd_hdr::write_exr(&basis, &image)?;
        let done = LightRecord {
            basis: basis
                .strip_prefix(self.scene_dir)
                .unwrap_or(&basis)
                .display()
                .to_string(),
            dmx: self.dmx_of(l, &self.patch.unmastered(&look)),
            exposures: merged.exposures,
            clipped: merged.clipped_everywhere,
            time: now(),
        };
        match palette {
            Some(n) => {
                if let Some(m) = self.record.no_light_positions.get_mut(&ch) {
                    m.remove(&n);
                }
                self.record.positions.entry(ch).or_default().insert(n, done);
                summary.positions_captured.push((ch, n));
            }
            None => {
                self.record.no_light.remove(&ch);
                self.record.lights.insert(ch, done);
                summary.captured.push(ch);
            }
        }
        self.record.no_light_positions.retain(|_, m| !m.is_empty());
        save_record(self.scene_dir, &self.record)?;
        *own += started.elapsed().saturating_sub(self.waited - waited);
        Ok(true)
    }

    /// Focus palette `number` as messages name it: `3 "DS centre"`, or `3`.
    fn palette_name(&self, number: u32) -> String {
        self.scene
            .palettes
            .iter()
            .find(|p| p.number == number)
            .map_or_else(|| number.to_string(), visobjd_scene::Palette::describe)
    }

    /// Light `l`'s additive emitters, each alone at full with its dimmer at full and every
    /// other light at 0 (`--emitters`), written beside its basis image as
    /// `NNN-EMITTER.exr` and, once all are, named in scene.toml's `emitter_basis`. Emitters
    /// already in `capture.json` whose image exists are skipped. Returns how many images
    /// it wrote (0 for a light without emitters).
    fn emitters(&mut self, l: usize, ambient: &Radiance) -> Result<usize, CaptureError> {
        let light = &self.scene.lights[l];
        let (ch, light_name, basis) = (light.channel, light.name.clone(), light.basis.clone());
        let names: Vec<String> = self
            .scene
            .profile(l)
            .mixed_emitters()
            .into_iter()
            .map(str::to_string)
            .collect();
        let mut images = BTreeMap::new();
        let mut sums = Vec::with_capacity(names.len());
        let mut written = 0;
        for (k, name) in names.iter().enumerate() {
            let path = emitter_path(&basis, name);
            let relative = path
                .strip_prefix(self.scene_dir)
                .unwrap_or(&path)
                .display()
                .to_string();
            let done = self
                .record
                .emitters
                .get(&ch)
                .is_some_and(|m| m.contains_key(name));
            let kept = done
                .then(|| visobjd_compositor::basis::read_exr(&path).ok())
                .flatten();
            if let Some(image) = kept {
                sums.push((name.clone(), radiance_sum(&image.pixels)));
            } else {
                if self.stop.load(Ordering::SeqCst) {
                    return Err(CaptureError::Stopped);
                }
                self.progress
                    .step(&format!("light {ch} ({light_name}): {name} alone"));
                let mut look = Look::off(self.scene.lights.len());
                look.levels[l] = WHITE;
                let frame = self.patch.emitter_alone(&look, l, k);
                let dmx = self.dmx_of(l, &frame);
                let merged = self.shoot_look(&look, frame, false)?;
                if merged.clipped_everywhere > 0 {
                    self.progress.warn(&format!(
                        "light {ch} ({light_name}) {name}: {} pixels are clipped even at the shortest exposure: close the aperture or lower the ISO",
                        merged.clipped_everywhere
                    ));
                }
                let image = visobjd_hdr::subtract_ambient(&merged.radiance, ambient)?;
                visobjd_hdr::write_exr(&path, &image)?;
                sums.push((name.clone(), radiance_sum(&image.pixels)));
                self.record.emitters.entry(ch).or_default().insert(
                    name.clone(),
                    LightRecord {
                        basis: relative.clone(),
                        dmx,
                        exposures: merged.exposures,
                        clipped: merged.clipped_everywhere,
                        time: now(),
                    },
                );
                save_record(self.scene_dir, &self.record)?;
                written += 1;
            }
            images.insert(name.clone(), relative);
        }
        if !images.is_empty() {
            let measured = measure_emitters(&sums);
            if measured.is_empty() {
                self.progress.warn(&format!(
                    "light {ch} ({light_name}): an emitter's image holds no measurable light, so its colour is solved with the profile's emitters"
                ));
            }
            set_emitter_basis(self.scene_dir, ch, images, measured)?;
        }
        Ok(written)
    }

    /// The ambient light (everything at 0) merged once per capture and kept in the
    /// capture folder as `name`, so a resumed capture subtracts the same one.
    fn ambient(&mut self, name: &str) -> Result<Radiance, CaptureError> {
        let path = work_dir(self.scene_dir).join(name);
        if let Ok(img) = visobjd_compositor::basis::read_exr(&path) {
            return Ok(Radiance {
                width: img.width,
                height: img.height,
                pixels: img.pixels,
            });
        }
        self.progress.step("ambient light: everything at 0");
        let off = Look::off(self.scene.lights.len());
        let a = self
            .shoot_look(&off, self.patch.unmastered(&off), true)?
            .radiance;
        visobjd_hdr::write_exr(&path, &a)?;
        Ok(a)
    }

    /// Puts `look` on the rig as the slot levels `frame` (its [`Patch::unmastered`], or a
    /// light's emitter alone: [`Patch::emitter_alone`]) and waits for the lamps and for
    /// frames that carry it. A moving light lit in `look` at another position than the
    /// rig shows goes there dark first (`look` with its intensity 0) and is given
    /// `move_settle` to arrive: a light is never photographed, nor swept across the stage
    /// lit, on its way.
    fn show(&mut self, look: &Look, frame: SlotLevels) -> Result<(), CaptureError> {
        let started = Instant::now();
        let level = |look: &Look, l: usize| look.levels.get(l).copied().unwrap_or(Level::OFF);
        let mut dark = look.clone();
        let mut moves = false;
        for (l, light) in self.scene.lights.iter().enumerate() {
            let (to, from) = (level(look, l), level(&self.shown, l));
            let palette = |lv: &Level| light.position_of(lv).map(|p| p.palette);
            if to.intensity > 0.0 && palette(&to) != palette(&from) {
                moves = true;
                if let Some(d) = dark.levels.get_mut(l) {
                    d.intensity = 0.0;
                }
            }
        }
        if moves {
            let frame = self.patch.unmastered(&dark);
            self.send(dark, frame, self.opts.move_settle)?;
        }
        self.send(look.clone(), frame, self.opts.settle)?;
        self.shown = look.clone();
        self.waited += started.elapsed();
        Ok(())
    }

    /// Sends `frame` (standing for `look`), waits `settle`, then for two DMX frames that
    /// carry it.
    fn send(&self, look: Look, frame: SlotLevels, settle: Duration) -> Result<(), CaptureError> {
        self.output.set_frame(look, frame);
        let ticks = self.output.stats().ticks;
        std::thread::sleep(settle);
        let deadline = Instant::now() + Duration::from_secs(5);
        while self.output.stats().ticks < ticks + 2 {
            if Instant::now() > deadline {
                return Err(CaptureError::Files(
                    "the DMX output is not sending: check the [output] destinations".into(),
                ));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        Ok(())
    }

    /// One frame at `shutter`, decoded; its file is removed once read.
    fn shoot(&mut self, shutter: &Shutter) -> Result<decode::DecodedShot, CaptureError> {
        if self.stop.load(Ordering::SeqCst) {
            return Err(CaptureError::Stopped);
        }
        self.shots += 1;
        let out = work_dir(self.scene_dir).join(format!("shot-{}", self.shots));
        let started = Instant::now();
        let frame = self.camera.capture(shutter, &out);
        self.waited += started.elapsed();
        let frame = frame?;
        let path = frame
            .paths
            .iter()
            .find(|p| {
                let ext = p.extension().map(|e| e.to_string_lossy().to_lowercase());
                match self.opts.format {
                    Format::Jpeg => matches!(ext.as_deref(), Some("jpg" | "jpeg")),
                    Format::Raw => !matches!(ext.as_deref(), Some("jpg" | "jpeg")),
                }
            })
            .or(frame.paths.first())
            .cloned()
            .ok_or_else(|| CaptureError::Files("the camera wrote no file".into()))?;
        let exposure = visobjd_hdr::Exposure {
            seconds: frame.exposure.seconds,
            iso: frame.exposure.iso.unwrap_or(self.iso),
            f_number: frame.exposure.f_number.unwrap_or(self.f_number),
        };
        let shot = decode::load(&path, exposure).map_err(CaptureError::Files);
        for p in &frame.paths {
            let _ = std::fs::remove_file(p);
        }
        shot
    }

    /// The shutter choice nearest to `seconds` (in stops).
    fn nearest(&self, seconds: f64) -> Shutter {
        self.shutters
            .iter()
            .min_by(|a, b| {
                let d = |s: &Shutter| (s.seconds() / seconds).log2().abs();
                d(a).total_cmp(&d(b))
            })
            .cloned()
            .unwrap_or_else(|| self.shutters[0].clone())
    }

    /// Seven frames a stop apart around the metered exposure, for the camera response.
    fn response_bracket(&mut self) -> Result<Vec<decode::DecodedShot>, CaptureError> {
        let (_, t) = self.meter()?;
        let mut shots = Vec::new();
        for k in -3..=3 {
            let s = self.nearest(t * 2f64.powi(k));
            shots.push(self.shoot(&s)?);
        }
        Ok(shots)
    }

    fn choices(&self) -> Vec<f64> {
        self.shutters.iter().map(Shutter::seconds).collect()
    }

    /// A metering frame whose brightest pixels (the 99.9th percentile) sit high but
    /// unclipped, found from 1/60 s by trial (the camera's response may not be known
    /// yet, so the frame's own values are read); with its exposure time.
    fn meter(&mut self) -> Result<(decode::DecodedShot, f64), CaptureError> {
        let (shortest, longest) = self.shutters_range();
        let longest = longest.min(LONGEST);
        let mut t = 1.0 / 60.0;
        let mut shot = self.shoot(&self.nearest(t))?;
        for _ in 0..10 {
            let high = shot.high();
            let factor = if high >= 0.97 {
                0.25
            } else if high < METERED {
                (0.6 / high.max(1e-3)).min(16.0)
            } else {
                break;
            };
            let next = (t * factor).clamp(shortest, longest);
            if self.nearest(next).seconds() == self.nearest(t).seconds() {
                break;
            }
            t = next;
            shot = self.shoot(&self.nearest(t))?;
        }
        Ok((shot, self.nearest(t).seconds()))
    }

    /// The shortest and longest shutter times the camera offers.
    fn shutters_range(&self) -> (f64, f64) {
        self.choices()
            .into_iter()
            .fold((f64::MAX, 0.0f64), |(a, b), t| (a.min(t), b.max(t)))
    }

    /// Shows `look`, meters, shoots the bracket the metering frame proposes and merges
    /// it with the metering frame. For the ambient light (`dark`: everything at 0, where a proposal from noise
    /// means nothing), and for a light whose metering frame stays dark at the longest
    /// exposure, the bracket is the metered exposure and two and four stops below it, so
    /// a light that adds nothing is merged exactly as the ambient was and compares with it
    /// on noise alone.
    fn shoot_look(
        &mut self,
        look: &Look,
        frame: SlotLevels,
        dark: bool,
    ) -> Result<visobjd_hdr::Merged, CaptureError> {
        self.show(look, frame)?;
        let response = self.record.response.clone();
        let (meter, t) = self.meter()?;
        let mut times = if dark || meter.high() < METERED {
            [t / 16.0, t / 4.0, t]
                .map(|x| self.nearest(x).seconds())
                .to_vec()
        } else {
            let mut times = visobjd_hdr::propose_bracket(
                &meter.frame(),
                response.as_ref(),
                &self.choices(),
                &BracketSettings::default(),
            )?
            .times;
            times.retain(|&x| x <= LONGEST);
            times
        };
        if times.is_empty() {
            times.push(t);
        }
        times.dedup();
        self.progress
            .step(&format!("bracket of {} frames", times.len()));
        let mut shots = Vec::with_capacity(times.len() + 1);
        for t in times {
            shots.push(self.shoot(&self.nearest(t))?);
        }
        // The metering frame shows the same look: merged too, it adds its noise and its
        // EXIF error to the merge's averages (a light's scale rests on the mean of its
        // frames' EXIF times) at no cost.
        shots.push(meter);
        let frames: Vec<_> = shots.iter().map(decode::DecodedShot::frame).collect();
        let settings = MergeSettings {
            width: Some(self.opts.width),
            ..MergeSettings::default()
        };
        let mut merged = visobjd_hdr::merge(&frames, response.as_ref(), &settings)?;
        if let Some(m) = shots.first().and_then(decode::DecodedShot::to_srgb) {
            merged.radiance.transform(m);
        }
        Ok(merged)
    }

    /// The bytes light `l`'s slots are sent in `frame` (unmastered levels).
    fn dmx_of(&self, l: usize, frame: &SlotLevels) -> (u16, u16, Vec<u8>) {
        let patch = &self.patch;
        let bytes = patch.quantise(frame);
        let light = &self.scene.lights[l];
        let u = patch
            .universes()
            .binary_search(&light.universe)
            .unwrap_or_default();
        let start = usize::from(light.address.max(1)) - 1;
        let end = (start + self.scene.profile(l).footprint()).min(bytes[u].len());
        (light.universe, light.address, bytes[u][start..end].to_vec())
    }

    /// The focus palettes of moving light `l` captured (recorded, their image on disk),
    /// in its order; empty for a fixed light.
    fn captured_palettes(&self, l: usize) -> Vec<u32> {
        let light = &self.scene.lights[l];
        let recorded = self.record.positions.get(&light.channel);
        light
            .positions
            .iter()
            .filter(|p| recorded.is_some_and(|m| m.contains_key(&p.palette)) && p.basis.is_file())
            .map(|p| p.palette)
            .collect()
    }

    /// A random look of a few captured lights, shot and compared with the composite of
    /// their basis images: the median relative error over the pixels the look lights. A
    /// moving light in it takes a random captured position other than its first when it
    /// has one (its first is what a look naming none shows), and the look holds one when
    /// any is captured, so the positions' images and the moves to them are checked too.
    fn validate(&mut self, ambient: &Radiance) -> Result<Option<f64>, CaptureError> {
        let palettes: Vec<Vec<u32>> = (0..self.scene.lights.len())
            .map(|l| self.captured_palettes(l))
            .collect();
        let captured: Vec<usize> = (0..self.scene.lights.len())
            .filter(|&l| {
                !palettes[l].is_empty()
                    || self
                        .record
                        .lights
                        .contains_key(&self.scene.lights[l].channel)
            })
            .collect();
        if captured.is_empty() {
            return Ok(None);
        }
        self.progress
            .step("validation: a random look of several lights");
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(self.opts.seed ^ 0x5eed);
        let mut look = Look::off(self.scene.lights.len());
        let mut composite: Option<Radiance> = None;
        let movers: Vec<usize> = captured
            .iter()
            .copied()
            .filter(|&l| !palettes[l].is_empty())
            .collect();
        let mut chosen: Vec<usize> = (0..captured.len().min(4))
            .map(|_| captured[rng.random_range(0..captured.len())])
            .collect();
        if !movers.is_empty() && !chosen.iter().any(|l| movers.contains(l)) {
            chosen.push(movers[rng.random_range(0..movers.len())]);
        }
        for l in chosen {
            let level = rng.random_range(0.3f32..1.0);
            let first = self.scene.lights[l].positions.first().map(|p| p.palette);
            let others: Vec<u32> = palettes[l]
                .iter()
                .copied()
                .filter(|&n| Some(n) != first)
                .collect();
            let choices = if others.is_empty() {
                &palettes[l]
            } else {
                &others
            };
            look.levels[l] = Level {
                intensity: level,
                color: [1.0; 3],
                position: (!choices.is_empty())
                    .then(|| choices[rng.random_range(0..choices.len())]),
            };
        }
        for (l, lv) in look.levels.iter().enumerate() {
            if lv.intensity == 0.0 {
                continue;
            }
            let light = &self.scene.lights[l];
            let basis = light.position_of(lv).map_or(&light.basis, |p| &p.basis);
            let img = visobjd_compositor::basis::read_exr(basis).map_err(CaptureError::Files)?;
            let c = composite.get_or_insert_with(|| Radiance {
                width: img.width,
                height: img.height,
                pixels: vec![[0.0; 3]; img.pixels.len()],
            });
            if c.pixels.len() != img.pixels.len() {
                return Err(CaptureError::Files(
                    "the basis images differ in size: capture them again together".into(),
                ));
            }
            let m = self.scene.colour_model(l).multiplier(lv);
            for (o, p) in c.pixels.iter_mut().zip(&img.pixels) {
                for k in 0..3 {
                    o[k] += m[k] * p[k];
                }
            }
        }
        let Some(composite) = composite else {
            return Ok(None);
        };
        let shot = self
            .shoot_look(&look, self.patch.unmastered(&look), false)?
            .radiance;
        let shot = visobjd_hdr::subtract_ambient(&shot, ambient)?;
        Ok(relative_error(&shot, &composite))
    }
}

impl Session<'_> {
    /// A saturated look of up to four lights captured per emitter (the scene as the
    /// capture left it), shot and compared with its preview from the per-emitter images
    /// and with its preview from the white images alone ([`colour_difference`]). None when
    /// no light has its emitter images.
    fn validate_colour(
        &mut self,
        ambient: &Radiance,
    ) -> Result<Option<ColourValidation>, CaptureError> {
        let mut scene =
            Scene::load(self.scene_dir).map_err(|e| CaptureError::Files(e.to_string()))?;
        // Levels solved with the profiles' emitters, sent and previewed alike: this checks
        // the images, whatever the measured emitters make of a colour
        // (tests/capture/capture.rs checks those against the sim's true emitters).
        for light in &mut scene.lights {
            light.emitter_measured.clear();
        }
        let lit: Vec<usize> = (0..scene.lights.len())
            .filter(|&l| {
                !scene.lights[l].emitter_basis.is_empty()
                    && self.record.lights.contains_key(&scene.lights[l].channel)
            })
            .take(4)
            .collect();
        if lit.is_empty() {
            return Ok(None);
        }
        self.progress
            .step("colour validation: a saturated look of the lights captured per emitter");
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(self.opts.seed ^ 0xc01);
        let mut look = Look::off(scene.lights.len());
        for &l in &lit {
            look.levels[l] = Level {
                intensity: rng.random_range(0.6f32..1.0),
                color: SATURATED[rng.random_range(0..SATURATED.len())],
                position: None,
            };
        }
        // The previews of the lit lights alone: the others' images may not exist yet.
        let mut part = scene.clone();
        part.lights = lit.iter().map(|&l| scene.lights[l].clone()).collect();
        let part_look = Look {
            levels: lit.iter().map(|&l| look.levels[l]).collect(),
        };
        let mut basis = visobjd_compositor::basis::load(&part, &[(0, Precision::Single)])
            .and_then(visobjd_compositor::basis::Loaded::all)
            .map_err(|e| CaptureError::Files(e.to_string()))?
            .pop()
            .ok_or_else(|| CaptureError::Files("no basis images".into()))?;
        let per_emitter = visobjd_compositor::render::render_reference(&basis, &part_look, 1.0);
        // The same images without their emitters': each light from its white image.
        basis.emitter_images.fill(None);
        let white_only = visobjd_compositor::render::render_reference(&basis, &part_look, 1.0);
        // Solved through the profiles' emitters, as previewed.
        let frame = Patch::new(&scene).unmastered(&look);
        let shot = self.shoot_look(&look, frame, false)?;
        let shot = visobjd_hdr::subtract_ambient(&shot.radiance, ambient)?;
        Ok(colour_difference(&shot, &per_emitter)
            .zip(colour_difference(&shot, &white_only))
            .map(|(per_emitter, white_only)| ColourValidation {
                per_emitter,
                white_only,
            }))
    }
}

/// The colours of the colour validation: saturated, each mixing two or three emitters.
const SATURATED: &[[f32; 3]] = &[
    [1.0, 0.25, 0.0],
    [1.0, 0.0, 0.6],
    [0.0, 1.0, 0.35],
    [0.2, 0.35, 1.0],
    [0.6, 0.0, 1.0],
    [0.0, 0.8, 1.0],
];

/// Median CIEDE2000 between a shot and a preview (interleaved linear RGB of the same
/// size) over the pixels the shot lights (luminance above 5% of its brightest), both in
/// CIELAB with the shot's brightest pixels (99.9th percentile of luminance) as white.
pub fn colour_difference(shot: &Radiance, preview: &[f32]) -> Option<f64> {
    if preview.len() != shot.pixels.len() * 3 {
        return None;
    }
    let lum = |p: [f64; 3]| linear_srgb_to_xyz(p)[1];
    let mut lums: Vec<f64> = shot.pixels.iter().map(|p| lum(p.map(f64::from))).collect();
    lums.sort_by(f64::total_cmp);
    let white = *lums.get(lums.len() * 999 / 1000)?;
    if white.is_nan() || white <= 0.0 {
        return None;
    }
    let lab = |p: [f64; 3]| xyz_to_lab(linear_srgb_to_xyz(p.map(|v| v.max(0.0) / white)));
    let mut de: Vec<f64> = shot
        .pixels
        .iter()
        .zip(preview.chunks_exact(3))
        .map(|(s, p)| (s.map(f64::from), [0, 1, 2].map(|k| f64::from(p[k]))))
        .filter(|(s, _)| lum(*s) > 0.05 * white)
        .map(|(s, p)| ciede2000(lab(s), lab(p)))
        .collect();
    if de.is_empty() {
        return None;
    }
    de.sort_by(f64::total_cmp);
    Some(de[de.len() / 2])
}

/// Where emitter `name`'s image of a light goes: beside its basis image, `NNN-NAME.exr`.
fn emitter_path(basis: &Path, name: &str) -> PathBuf {
    let stem = basis
        .file_stem()
        .map_or_else(|| "light".into(), |s| s.to_string_lossy());
    basis.with_file_name(format!("{stem}-{name}.exr"))
}

/// The linear sRGB radiance of an image summed over its pixels: the light the camera
/// received from it.
fn radiance_sum(pixels: &[[f32; 3]]) -> [f64; 3] {
    pixels.iter().fold([0.0; 3], |mut s, p| {
        for (s, v) in s.iter_mut().zip(p) {
            *s += f64::from(*v);
        }
        s
    })
}

/// Each emitter's CIE xy and flux from its image's radiance sum (`sums`: emitter name and
/// linear sRGB sum), the flux relative to the sum of the light's emitters' Y: the emitters
/// as the camera sees them, on one scale, which is all the colour solve needs. Empty when
/// an emitter's light is not a colour (nothing measurable, or noise below zero), so the
/// profile's emitters stand.
fn measure_emitters(sums: &[(String, [f64; 3])]) -> BTreeMap<String, MeasuredEmitter> {
    let xyz: Vec<[f64; 3]> = sums.iter().map(|(_, s)| linear_srgb_to_xyz(*s)).collect();
    let total: f64 = xyz.iter().map(|v| v[1]).sum();
    let measured: Option<BTreeMap<String, MeasuredEmitter>> = sums
        .iter()
        .zip(&xyz)
        .map(|((name, _), v)| {
            let all = v[0] + v[1] + v[2];
            let m = MeasuredEmitter {
                xy: [v[0] / all, v[1] / all],
                flux: v[1] / total,
            };
            m.fault().is_none().then(|| (name.clone(), m))
        })
        .collect();
    measured.unwrap_or_default()
}

/// Names light `channel`'s per-emitter images in `scene_dir/scene.toml`
/// (`emitter_basis`) with the emitters measured from them (`emitter_measured`), checked as a scene before the atomic write; unchanged, nothing is
/// written.
fn set_emitter_basis(
    scene_dir: &Path,
    channel: u32,
    images: BTreeMap<String, String>,
    measured: BTreeMap<String, MeasuredEmitter>,
) -> Result<(), CaptureError> {
    let path = scene_dir.join("scene.toml");
    let fail = |e: String| CaptureError::Files(format!("{}: {e}", path.display()));
    let text = std::fs::read_to_string(&path).map_err(|e| fail(e.to_string()))?;
    let mut file = SceneFile::parse(&path, &text).map_err(|e| fail(e.to_string()))?;
    let Some(light) = file.light.iter_mut().find(|l| l.channel == channel) else {
        return Err(fail(format!("light {channel} is no longer in the scene")));
    };
    if light.emitter_basis == images && light.emitter_measured == measured {
        return Ok(());
    }
    light.emitter_basis = images;
    light.emitter_measured = measured;
    let text = file.to_toml().map_err(fail)?;
    Scene::parse(scene_dir, &text).map_err(|e| fail(e.to_string()))?;
    visobjd_files::write_atomic(&path, text.as_bytes()).map_err(|e| fail(e.to_string()))
}

/// The longest exposure capture uses, in seconds: long enough for a dim light at a
/// stopped-down aperture, short enough that a light takes seconds, not minutes.
const LONGEST: f64 = 8.0;

/// A metering frame is good when its brightest pixels reach this fraction of full scale.
const METERED: f64 = 0.3;

/// Every light at full white: how capture asks a light for its basis.
const WHITE: Level = Level {
    intensity: 1.0,
    color: [1.0; 3],
    position: None,
};

/// How many samples of `light - ambient` exceed one and a half times the largest
/// difference between two merges of the ambient light (`ambient`, `again`): an empirical
/// noise level that holds whatever the noise looks like (JPEG's near-black codes are
/// quantised and blocky, where a local estimate from the pixels is fooled).
fn above_null(light: &Radiance, ambient: &Radiance, again: &Radiance) -> usize {
    let null = ambient
        .pixels
        .iter()
        .zip(&again.pixels)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    light
        .pixels
        .iter()
        .zip(&ambient.pixels)
        .filter(|(l, a)| (0..3).any(|c| l[c] - a[c] > 1.5 * null))
        .count()
}

/// Median relative error of `got` against `want` over the pixels `want` lights (above 5%
/// of its brightest luminance).
pub fn relative_error(got: &Radiance, want: &Radiance) -> Option<f64> {
    if got.pixels.len() != want.pixels.len() {
        return None;
    }
    let lum = |p: &[f32; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let peak = want.pixels.iter().map(lum).fold(0.0f32, f32::max);
    let mut errors: Vec<f32> = got
        .pixels
        .iter()
        .zip(&want.pixels)
        .filter(|(_, w)| lum(w) > 0.05 * peak)
        .map(|(g, w)| ((lum(g) - lum(w)) / lum(w)).abs())
        .collect();
    if errors.is_empty() {
        return None;
    }
    errors.sort_by(f32::total_cmp);
    Some(f64::from(errors[errors.len() / 2]))
}
