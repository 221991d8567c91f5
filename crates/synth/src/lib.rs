//! Renders a virtual stage's basis images, for rooms that have not been captured and for
//! the demo scene: one linear HDR image per light, at full, from one camera (paper 5.1: the
//! composite does not care whether the basis images were photographed or rendered).
//!
//! # Rig file (TOML, unknown keys are errors)
//!
//! Coordinates in metres: x to the audience's right, y up, z upstage; the floor's downstage
//! edge is z = 0 and its centre line x = 0. Colours are RGB 0..1: albedos are linear
//! reflectances, gels are sRGB as picked.
//!
//! ```toml
//! name = "Black box"          # copied to scene.toml
//! width = 480                 # basis image size
//! height = 270
//! exposure = -8.0             # optional, stops applied to every image (default 0)
//!
//! [stage]
//! width = 12.0                # floor x from -6 to 6
//! depth = 8.0                 # floor z from 0 to 8
//! albedo = [0.1, 0.1, 0.1]
//! [stage.cyc]                 # optional: cyclorama at z = depth
//! height = 6.0
//! cove = 1.0                  # radius of the curved join to the floor; 0 = flat back wall
//! albedo = [0.8, 0.8, 0.8]
//! [stage.legs]                # optional side masking, spaced evenly up the sides
//! pairs = 3
//! width = 1.2
//! height = 6.0
//! albedo = [0.02, 0.02, 0.02]
//!
//! [camera]
//! position = [0.0, 2.5, -10.0]
//! look_at = [0.0, 1.2, 4.0]
//! fov = 32.0                  # vertical, degrees
//!
//! [[box]]                     # also [[cylinder]] (radius, height) and [[sphere]] (radius)
//! name = "platform"           # optional, for error messages
//! position = [0.0, 0.0, 5.0]  # centre of the bottom (sphere: centre)
//! size = [4.0, 0.6, 2.0]      # x, y, z before turning
//! yaw = 0.0                   # optional, degrees about y
//! albedo = [0.3, 0.3, 0.3]
//!
//! [[light]]
//! channel = 1                 # unique console channel
//! name = "FOH L1"             # optional
//! group = "front warm"        # optional
//! profile = "dimmer"          # a built-in (dimmer, rgb, irgb, ...) or a [[profile]]
//! universe = 1
//! address = 1                 # the footprint must fit in 1..=512 and not overlap
//! position = [-4.0, 7.0, -8.0]
//! aim = [-1.5, 1.2, 3.0]
//! beam = 19.0                 # full angle at full intensity, degrees
//! field = 30.0                # full angle where it has faded to zero (>= beam)
//! intensity = 40000.0         # on-axis candela
//! gel = [1.0, 0.8, 0.6]       # optional, profiles without colour only
//!
//! [[profile]]                 # as in scene.toml, copied to it
//! name = "mover"
//! channels = ["intensity", "pan16", "tilt16", "red", "green", "blue", "white"]
//! pan_range = 540.0           # optional, degrees of full travel
//! tilt_range = 270.0
//!
//! [[light]]                   # a moving light: a profile with pan and tilt, no `aim`
//! channel = 45
//! profile = "mover"
//! universe = 3
//! address = 1
//! position = [-3.0, 7.5, 2.0] # hung pointing straight down
//! beam = 14.0
//! field = 22.0
//! intensity = 60000.0
//! [[light.focus]]             # one focus palette: one basis image, one [[light.position]]
//! palette = 1                 # shared by the lights that have it, 1..=9999
//! name = "DS left"            # optional, the same on every light
//! aim = [3.0, 0.0, 1.5]       # the point the beam centre passes through
//! ```
//!
//! A moving light hangs pointing straight down: tilt is the angle from straight down,
//! pan the turn about the vertical, pan 0 tilting downstage (-z) and pan 90 towards +x
//! ([`pan_tilt`]). Each focus's pan and tilt must be inside the profile's ranges (DMX
//! centre = 0 degrees); its image is `basis/NNN-fpPP.exr` (light NNN, palette PP).
//!
//! # Light transport
//!
//! Direct light falls off with distance squared and the cosine at the surface, inside a
//! soft-edged cone, with hard shadows; one diffuse bounce is gathered from virtual point
//! lights placed where the beam lands, so a light aimed at nothing contributes exactly zero.
//! Everything is deterministic: the same rig gives the same bytes.

mod render;
mod rig;
mod trace;

use std::path::{Path, PathBuf};
use std::time::Instant;

pub use rig::{
    BoxProp, Cyc, CylinderProp, Focus, Legs, Room, SphereProp, Spotlight, Viewpoint, VirtualStage,
    beam_direction, pan_tilt,
};
use visobjd_scene::{GroupFile, LightFile, PositionFile, SceneFile};

/// What `synth` produced, for the command line to print.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthReport {
    /// Number of lights.
    pub lights: usize,
    /// Number of basis images written (one per fixed light, one per focus of a mover).
    pub images: usize,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Wall time of the whole run.
    pub seconds: f64,
}

/// Why a rig could not be rendered; every message is one line naming the file or the item.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The rig text is not valid TOML or does not match the format.
    #[error("line {line}: {message}")]
    Syntax {
        /// 1-based line of the offending text.
        line: usize,
        /// What is wrong there.
        message: String,
    },
    /// The rig parses but describes something impossible (e.g. a light aimed at itself).
    #[error("{0}")]
    Invalid(String),
    /// A `Syntax` or `Invalid` error, with the rig file it came from.
    #[error("{}: {source}", path.display())]
    Rig {
        /// The rig file.
        path: PathBuf,
        /// The problem in it.
        source: Box<SynthError>,
    },
    /// The rig file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        /// The rig file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// An output file or folder could not be written.
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        /// The output path.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The EXR encoder failed.
    #[error("{}: cannot write EXR: {source}", path.display())]
    Exr {
        /// The basis image path.
        path: PathBuf,
        /// The encoder's error.
        source: exr::error::Error,
    },
}

/// Renders a rig file into a scene folder: `out/scene.toml` plus `out/basis/NNN.exr`, one per light.
pub fn synth(rig: &Path, out: &Path) -> Result<SynthReport, SynthError> {
    let start = Instant::now();
    let text = std::fs::read_to_string(rig).map_err(|source| SynthError::Read {
        path: rig.to_path_buf(),
        source,
    })?;
    let parsed = VirtualStage::parse(&text).map_err(|e| SynthError::Rig {
        path: rig.to_path_buf(),
        source: Box::new(e),
    })?;
    let basis_dir = out.join("basis");
    std::fs::create_dir_all(&basis_dir).map_err(|source| SynthError::Write {
        path: basis_dir.clone(),
        source,
    })?;
    let renderer = render::Renderer::new(&parsed);
    let mut entries = Vec::with_capacity(parsed.lights.len());
    let mut images = 0;
    for (i, light) in parsed.lights.iter().enumerate() {
        let mut names = Vec::new();
        for (k, direction) in light.directions().into_iter().enumerate() {
            let basis = basis_name(i, light.focus.get(k).map(|f| f.palette));
            let path = out.join(&basis);
            write_exr(
                &path,
                parsed.width,
                parsed.height,
                &renderer.render(light, direction),
            )
            .map_err(|source| SynthError::Exr { path, source })?;
            names.push(basis);
        }
        images += names.len();
        let positions: Vec<PositionFile> = light
            .focus
            .iter()
            .zip(&names)
            .map(|(f, basis)| {
                let (pan, tilt) = pan_tilt(light.position, f.aim);
                PositionFile {
                    palette: f.palette,
                    name: f.name.clone(),
                    pan,
                    tilt,
                    basis: basis.clone(),
                }
            })
            .collect();
        entries.push(LightFile {
            channel: light.channel,
            name: light.name.clone(),
            group: light.group.clone(),
            basis: positions.is_empty().then(|| names.remove(0)),
            profile: light.profile.clone(),
            // Checked: universe 1..=63999, address 1..=512.
            universe: light.universe as u16,
            address: light.address as u16,
            emitter_basis: Default::default(),
            emitter_measured: Default::default(),
            ma3_id: None,
            positions,
        });
    }
    write_scene(out, &parsed, entries)?;
    Ok(SynthReport {
        lights: parsed.lights.len(),
        images,
        width: parsed.width,
        height: parsed.height,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Renders one light (index into `rig.lights`) alone at full: linear RGB, row-major,
/// `width * height` pixels, exactly what `synth` writes for it before half-float rounding
/// (a moving light in its first focus palette: see [`render_focus`]).
///
/// # Panics
/// If `light` is out of range.
pub fn render_light(rig: &VirtualStage, light: usize) -> Vec<[f32; 3]> {
    render_focus(rig, light, 0)
}

/// Renders light `light` alone at full in its `k`-th direction ([`Spotlight::directions`]:
/// a moving light's `k`-th `[[light.focus]]`; 0 for a fixed light).
///
/// # Panics
/// If `light` or `k` is out of range.
pub fn render_focus(rig: &VirtualStage, light: usize, k: usize) -> Vec<[f32; 3]> {
    let l = &rig.lights[light];
    render::Renderer::new(rig).render(l, l.directions()[k])
}

/// `basis/001.exr` for the first light, `basis/045-fp03.exr` for the 45th in focus
/// palette 3: numbered by position in the rig, so names stay short and sorted whatever the
/// channel numbers are.
fn basis_name(index: usize, palette: Option<u32>) -> String {
    match palette {
        None => format!("basis/{:03}.exr", index + 1),
        Some(p) => format!("basis/{:03}-fp{p:02}.exr", index + 1),
    }
}

/// Half-float RGB, ZIP-compressed: half the size of float and far more precision than a
/// composite needs.
fn write_exr(path: &Path, width: u32, height: u32, px: &[[f32; 3]]) -> exr::error::Result<()> {
    use exr::prelude::*;
    let w = width as usize;
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let v = px[p.y() * w + p.x()];
        (
            f16::from_f32(v[0]),
            f16::from_f32(v[1]),
            f16::from_f32(v[2]),
        )
    });
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        (w, height as usize),
        LayerAttributes::default(),
        encoding,
        channels,
    );
    Image::from_layer(layer).write().to_file(path)
}

/// Writes `scene.toml` with the groups in order of first use and the rig's profiles.
fn write_scene(out: &Path, rig: &VirtualStage, light: Vec<LightFile>) -> Result<(), SynthError> {
    let mut group: Vec<GroupFile> = Vec::new();
    for g in rig.lights.iter().filter_map(|l| l.group.as_ref()) {
        if !group.iter().any(|e| &e.name == g) {
            group.push(GroupFile { name: g.clone() });
        }
    }
    let scene = SceneFile {
        name: Some(rig.name.clone()),
        exposure: 0.0,
        group,
        light,
        profile: rig.profiles.clone(),
    };
    let path = out.join("scene.toml");
    let text = scene
        .to_toml()
        .map_err(|e| SynthError::Invalid(format!("scene.toml: {e}")))?;
    std::fs::write(&path, text).map_err(|source| SynthError::Write { path, source })
}
