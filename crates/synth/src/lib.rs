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
//! profile = "dimmer"          # dimmer, dimmer16, rgb, irgb, rgbw, irgbw, rgba
//! universe = 1
//! address = 1                 # the footprint must fit in 1..=512 and not overlap
//! position = [-4.0, 7.0, -8.0]
//! aim = [-1.5, 1.2, 3.0]
//! beam = 19.0                 # full angle at full intensity, degrees
//! field = 30.0                # full angle where it has faded to zero (>= beam)
//! intensity = 40000.0         # on-axis candela
//! gel = [1.0, 0.8, 0.6]       # optional, dimmer profiles only
//! ```
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

use serde::Serialize;

pub use rig::{
    BoxProp, Cyc, CylinderProp, Legs, Room, SphereProp, Spotlight, Viewpoint, VirtualStage,
};

/// What `synth` produced, for the command line to print.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthReport {
    /// Number of basis images written.
    pub lights: usize,
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
    for (i, light) in parsed.lights.iter().enumerate() {
        let basis = basis_name(i);
        let path = out.join(&basis);
        write_exr(&path, parsed.width, parsed.height, &renderer.render(light))
            .map_err(|source| SynthError::Exr { path, source })?;
        entries.push(LightEntry {
            channel: light.channel,
            name: light.name.clone(),
            group: light.group.clone(),
            basis,
            profile: light.profile.clone(),
            universe: light.universe,
            address: light.address,
        });
    }
    write_scene(out, &parsed, entries)?;
    Ok(SynthReport {
        lights: parsed.lights.len(),
        width: parsed.width,
        height: parsed.height,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Renders one light (index into `rig.lights`) alone at full: linear RGB, row-major,
/// `width * height` pixels, exactly what `synth` writes for it before half-float rounding.
///
/// # Panics
/// If `light` is out of range.
pub fn render_light(rig: &VirtualStage, light: usize) -> Vec<[f32; 3]> {
    render::Renderer::new(rig).render(&rig.lights[light])
}

/// `basis/001.exr` for the first light: numbered by position in the rig, so names stay short
/// and sorted whatever the channel numbers are.
fn basis_name(index: usize) -> String {
    format!("basis/{:03}.exr", index + 1)
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

#[derive(Serialize)]
struct SceneFile<'a> {
    name: &'a str,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    group: Vec<GroupEntry>,
    light: Vec<LightEntry>,
}

#[derive(Serialize)]
struct GroupEntry {
    name: String,
}

#[derive(Serialize)]
struct LightEntry {
    channel: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    name: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    group: Option<String>,
    basis: String,
    profile: String,
    universe: u32,
    address: u32,
}

/// Writes `scene.toml` with the groups in order of first use.
fn write_scene(out: &Path, rig: &VirtualStage, light: Vec<LightEntry>) -> Result<(), SynthError> {
    let mut group: Vec<GroupEntry> = Vec::new();
    for g in rig.lights.iter().filter_map(|l| l.group.as_ref()) {
        if !group.iter().any(|e| &e.name == g) {
            group.push(GroupEntry { name: g.clone() });
        }
    }
    let scene = SceneFile {
        name: &rig.name,
        group,
        light,
    };
    let path = out.join("scene.toml");
    let text =
        toml::to_string(&scene).map_err(|e| SynthError::Invalid(format!("scene.toml: {e}")))?;
    std::fs::write(&path, text).map_err(|source| SynthError::Write { path, source })
}
