//! `visobjd capture`: a real rig's basis images, shot light by light with a tethered
//! camera (docs/capture.md). Capture drives the rig over the config's `[output]`
//! destinations at its own sACN priority (`[capture] priority`, default 200, so the
//! console can stay connected), and terminates its streams at the end, on Ctrl-C or on an
//! error, so the console takes the rig back.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::Context;
use visobjd_capture::{CaptureOptions, Format, Progress};
use visobjd_dmx::{Output, Patch, SacnDest};
use visobjd_scene::Scene;
use visobjd_scene::look::Look;

use crate::config::Config;

/// Arguments of `capture`.
#[derive(clap::Args)]
pub struct Args {
    /// The config file: its scene (basis images may be missing) and `[output]`.
    #[arg(long)]
    config: PathBuf,
    /// `gphoto2`, `sim` (a simulated camera photographing the scene's own basis images),
    /// or `command:TEMPLATE` with `{exposure}` and `{out}`.
    #[arg(long, default_value = "gphoto2")]
    camera: String,
    /// Channels to shoot, as `1-44,50` (default: every light).
    #[arg(long)]
    lights: Option<String>,
    /// Seconds a light is given to reach its level (default `[capture] settle_s`).
    #[arg(long)]
    settle: Option<f64>,
    /// What the camera writes: `jpeg` (its response is recovered once per session), or
    /// `raw` (DNG or the camera's own raw format, read as linear sensor values).
    #[arg(long, default_value = "jpeg")]
    format: String,
    /// Basis width in pixels (the height follows the camera's aspect).
    #[arg(long, default_value_t = 480)]
    width: usize,
    /// Seed of the validation look (and of the sim camera's noise).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also shoot each emitter of a colour-mixing light alone, so previews mix what the
    /// camera saw of each emitter (scene.toml's `emitter_basis`).
    #[arg(long)]
    emitters: bool,
}

/// `1-44,50` as channels.
fn channels(spec: &str) -> Result<Vec<u32>, String> {
    visobjd_rig::parse_channels(spec)
        .map_err(|part| format!("--lights {spec}: `{part}` is not a channel or a range like 1-44"))
}

/// A progress bar with the light being shot and the time left.
struct Bar(indicatif::ProgressBar);

impl Progress for Bar {
    fn begin(&mut self, lights: usize) {
        self.0.set_length(lights as u64);
        self.0.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} lights, {eta} left: {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
    }
    fn step(&mut self, what: &str) {
        self.0.set_message(what.to_string());
    }
    fn light_done(&mut self) {
        self.0.inc(1);
    }
    fn warn(&mut self, what: &str) {
        self.0.suspend(|| eprintln!("warning: {what}"));
        tracing::warn!("{what}");
    }
}

/// Runs a capture; an error, a stop, or a light that shows no light exits non-zero.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = Config::load(&args.config).map_err(anyhow::Error::msg)?;
    let scene = Scene::load(&config.scene)?;
    let format = Format::parse(&args.format).map_err(anyhow::Error::msg)?;
    let lights = args
        .lights
        .as_deref()
        .map(channels)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    if let Some(missing) = lights
        .iter()
        .flatten()
        .find(|ch| scene.light_index(**ch).is_none())
    {
        anyhow::bail!(
            "--lights: light {missing} is not in the scene ({})",
            scene.channel_range()
        );
    }
    let settle = args.settle.unwrap_or(config.capture.settle_s);
    anyhow::ensure!(
        settle.is_finite() && (0.0..=60.0).contains(&settle),
        "--settle must be 0..=60 seconds"
    );
    let mut output_config = config.output.clone();
    for d in &mut output_config.sacn {
        d.priority = config.capture.priority;
    }
    let mut camera: Box<dyn visobjd_camera::Camera + Send> = if args.camera == "sim" {
        let sim = visobjd_capture::sim::SimCamera::new(&scene, &config.scene, format, args.seed)
            .map_err(anyhow::Error::msg)?;
        let at = sim.listens_on().context("the sim camera's address")?;
        output_config.sacn.push(SacnDest {
            destination: at.ip().to_string(),
            port: at.port(),
            priority: config.capture.priority,
            source_name: "visobjd capture".into(),
            ..SacnDest::default()
        });
        Box::new(sim)
    } else {
        visobjd_camera::open(
            &args.camera,
            visobjd_camera::CameraOptions {
                timeout: Duration::from_secs_f64(config.capture.camera_timeout_s),
                ..visobjd_camera::CameraOptions::default()
            },
        )?
    };
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, Arc::clone(&stop)).context("cannot watch Ctrl-C")?;
    }
    // Capture's own CID (kept beside its records), never the daemon's: both may run.
    let output = Output::start(
        &output_config,
        Patch::new(&scene),
        &config.scene.join("capture"),
        Look::off(scene.lights.len()),
    )?;
    let options = CaptureOptions {
        lights,
        settle: Duration::from_secs_f64(settle),
        move_settle: Duration::from_secs_f64(config.capture.move_settle_s),
        width: args.width.max(1),
        format,
        seed: args.seed,
        emitters: args.emitters,
    };
    let mut bar = Bar(indicatif::ProgressBar::new(0));
    let result = visobjd_capture::capture(
        &scene,
        &config.scene,
        &output,
        camera.as_mut(),
        &options,
        &mut bar,
        &stop,
    );
    bar.0.finish_and_clear();
    // Stream_Terminated on every universe: the console takes the rig back at once.
    output.shutdown();
    let summary = result?;
    println!(
        "capture: {} lights written, {} already done, {} showing no light",
        summary.captured.len(),
        summary.resumed.len(),
        summary.no_light.len()
    );
    if !summary.positions_captured.is_empty() || !summary.positions_resumed.is_empty() {
        println!(
            "moving lights: {} positions written, {} already done",
            summary.positions_captured.len(),
            summary.positions_resumed.len()
        );
    }
    if let Some(d) = summary.ambient_drift {
        println!("ambient drift between start and end: {:.1}%", d * 100.0);
    }
    if let Some(o) = summary.overhead_per_light {
        println!(
            "capture's own time per image (camera and settling aside): {:.2} s",
            o
        );
    }
    if summary.emitter_images > 0 {
        println!("emitters: {} images written", summary.emitter_images);
    }
    if let Some(o) = summary.overhead_per_emitter {
        println!("capture's own time per emitter image (camera and settling aside): {o:.2} s");
    }
    if let Some(v) = summary.validation {
        println!(
            "validation: a random look shot and composited from the basis differ by {:.1}% (median over the lit pixels)",
            v * 100.0
        );
    }
    if let Some(c) = summary.colour_validation {
        println!(
            "colour validation: a saturated look shot and previewed differ by Delta E2000 {:.2} per emitter, {:.2} from white only (median over the lit pixels)",
            c.per_emitter, c.white_only
        );
    }
    if !summary.no_light.is_empty() {
        for (_, why) in &summary.no_light {
            eprintln!("{why}");
        }
        // A moving light is named once, however many of its positions show no light.
        let channels: std::collections::BTreeSet<u32> =
            summary.no_light.iter().map(|(ch, _)| *ch).collect();
        let list: Vec<String> = channels.iter().map(u32::to_string).collect();
        anyhow::bail!("lights {} show no light", list.join(", "));
    }
    Ok(())
}
