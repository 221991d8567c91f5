//! The rig file: what `synth` reads, and the checks that turn a typo into one clear line.

use serde::Deserialize;
use visobjd_scene::profile::{Profile, ProfileFile};
use visobjd_scene::{MAX_PALETTE, MAX_POSITIONS};

use super::SynthError;

/// A virtual stage: image size, room, props, camera and lights (see the module docs for the
/// file format). Fields are public so tests and tools can move things around after parsing.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VirtualStage {
    /// Scene name, copied to `scene.toml`.
    pub name: String,
    /// Basis image width in pixels.
    pub width: u32,
    /// Basis image height in pixels.
    pub height: u32,
    /// Camera exposure in stops (default 0): every basis image is scaled by `2^exposure`, so
    /// intensities can be given in realistic candela and still land near display white.
    #[serde(default)]
    pub exposure: f32,
    /// The room.
    pub stage: Room,
    /// The viewpoint every basis image shares.
    pub camera: Viewpoint,
    /// Box props (platforms, steps, tables).
    #[serde(default, rename = "box")]
    pub boxes: Vec<BoxProp>,
    /// Upright cylinder props (bodies, columns).
    #[serde(default, rename = "cylinder")]
    pub cylinders: Vec<CylinderProp>,
    /// Sphere props (heads, globes).
    #[serde(default, rename = "sphere")]
    pub spheres: Vec<SphereProp>,
    /// The lights, in the order their basis images are numbered.
    #[serde(default, rename = "light")]
    pub lights: Vec<Spotlight>,
    /// Fixture types beside the built-ins, as scene.toml's `[[profile]]` tables (a moving
    /// light needs one: no built-in pans or tilts); copied to `scene.toml`.
    #[serde(default, rename = "profile")]
    pub profiles: Vec<ProfileFile>,
}

/// The stage floor (y = 0, x centred on 0, z from 0 at the downstage edge to `depth`), with
/// an optional cyclorama or back wall and optional side masking.
#[derive(Debug, Clone, Deserialize)]
// A type error names the `[stage]` table as it always has: "expected struct Stage".
#[serde(deny_unknown_fields, expecting = "struct Stage")]
pub struct Room {
    /// Floor width in metres (x from -width/2 to width/2).
    pub width: f32,
    /// Floor depth in metres (z from 0 to depth).
    pub depth: f32,
    /// Floor reflectance, linear RGB 0..1.
    pub albedo: [f32; 3],
    /// A cyclorama (or, with `cove = 0`, a flat back wall) at z = depth.
    pub cyc: Option<Cyc>,
    /// Pairs of black legs masking the sides.
    pub legs: Option<Legs>,
}

/// The upstage surface that cyc lights wash.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cyc {
    /// Height in metres.
    pub height: f32,
    /// Radius of the curved join to the floor in metres; 0 gives a flat back wall.
    #[serde(default)]
    pub cove: f32,
    /// Reflectance, linear RGB 0..1.
    pub albedo: [f32; 3],
}

/// Side masking: `pairs` pairs of legs spaced evenly from downstage to upstage, each a thin
/// box standing at the edge of the floor and reaching `width` onstage.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Legs {
    /// Number of pairs.
    pub pairs: u32,
    /// How far each leg reaches onstage, in metres.
    pub width: f32,
    /// Height in metres.
    pub height: f32,
    /// Reflectance, linear RGB 0..1 (black serge is about 0.02).
    pub albedo: [f32; 3],
}

/// A pinhole camera; up is +y.
#[derive(Debug, Clone, Deserialize)]
// A type error names the `[camera]` table as it always has: "expected struct Camera".
#[serde(deny_unknown_fields, expecting = "struct Camera")]
pub struct Viewpoint {
    /// Eye position in metres.
    pub position: [f32; 3],
    /// Point the camera looks at.
    pub look_at: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov: f32,
}

/// A box standing on `position` (centre of its bottom face), turned by `yaw` degrees about
/// the vertical axis.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxProp {
    /// Label used in error messages.
    pub name: Option<String>,
    /// Centre of the bottom face in metres.
    pub position: [f32; 3],
    /// Width (x), height (y) and depth (z) in metres before turning.
    pub size: [f32; 3],
    /// Turn about the vertical axis in degrees.
    #[serde(default)]
    pub yaw: f32,
    /// Reflectance, linear RGB 0..1.
    pub albedo: [f32; 3],
}

/// An upright capped cylinder standing on `position`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CylinderProp {
    /// Label used in error messages.
    pub name: Option<String>,
    /// Centre of the bottom cap in metres.
    pub position: [f32; 3],
    /// Radius in metres.
    pub radius: f32,
    /// Height in metres.
    pub height: f32,
    /// Reflectance, linear RGB 0..1.
    pub albedo: [f32; 3],
}

/// A sphere centred on `position`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereProp {
    /// Label used in error messages.
    pub name: Option<String>,
    /// Centre in metres.
    pub position: [f32; 3],
    /// Radius in metres.
    pub radius: f32,
    /// Reflectance, linear RGB 0..1.
    pub albedo: [f32; 3],
}

/// A spotlight with a soft-edged cone, patched like a real fixture.
#[derive(Debug, Clone, Deserialize)]
// A type error names the `[[light]]` table as it always has: "expected struct Light".
#[serde(deny_unknown_fields, expecting = "struct Light")]
pub struct Spotlight {
    /// Console channel number, unique, copied to `scene.toml`.
    pub channel: u32,
    /// Label, copied to `scene.toml`.
    pub name: Option<String>,
    /// Light group ("system"), copied to `scene.toml`.
    pub group: Option<String>,
    /// Fixture profile: a built-in (`dimmer`, `dimmer16`, `rgb`, `irgb`, `rgbw`, `irgbw`,
    /// `rgba`) or a `[[profile]]` of the rig.
    pub profile: String,
    /// DMX universe, 1..=63999.
    pub universe: u32,
    /// DMX start address, 1..=512; the whole footprint must fit.
    pub address: u32,
    /// Lamp position in metres.
    pub position: [f32; 3],
    /// Point the beam centre passes through (a fixed light; a moving light has `focus`).
    pub aim: Option<[f32; 3]>,
    /// A moving light's focus palettes (`[[light.focus]]`), one basis image each.
    #[serde(default)]
    pub focus: Vec<Focus>,
    /// Full angle in degrees inside which the beam is at full intensity.
    pub beam: f32,
    /// Full angle in degrees at which the beam has faded to zero (>= beam).
    pub field: f32,
    /// Luminous intensity on the axis (candela-like; see `VirtualStage::exposure`).
    pub intensity: f32,
    /// Gel colour, sRGB 0..1, for conventional (`dimmer`, `dimmer16`) fixtures only: colour
    /// mixing fixtures are captured white and coloured at render time.
    pub gel: Option<[f32; 3]>,
}

/// One focus palette of a moving light: the stage point it aims at there.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Focus {
    /// Focus palette number (1..=9999), shared by the lights that have it.
    pub palette: u32,
    /// Its label, the same on every light that names it.
    pub name: Option<String>,
    /// The point the beam centre passes through in this position.
    pub aim: [f32; 3],
}

impl Spotlight {
    /// Unit beam directions, one per basis image: towards `aim` for a fixed light, and for
    /// a moving light the direction its pan and tilt for each focus give ([`pan_tilt`],
    /// [`beam_direction`]), so the image shows what those DMX values would.
    pub fn directions(&self) -> Vec<[f32; 3]> {
        match self.aim {
            Some(aim) => vec![sub(aim, self.position)],
            None => self
                .focus
                .iter()
                .map(|f| {
                    let (pan, tilt) = pan_tilt(self.position, f.aim);
                    beam_direction(pan, tilt)
                })
                .collect(),
        }
    }
}

/// The pan and tilt in degrees, rounded to 0.01, that point a moving light at
/// `position` at `aim`. A mover hangs pointing straight down: tilt is the angle away
/// from straight down (0..=180), pan the turn about the vertical, 0 tilting the beam
/// downstage (-z) and 90 towards +x ([`beam_direction`] is the inverse). Straight down
/// has pan 0.
pub fn pan_tilt(position: [f32; 3], aim: [f32; 3]) -> (f64, f64) {
    let d = sub(aim, position).map(f64::from);
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let tilt = (-d[1] / len).clamp(-1.0, 1.0).acos().to_degrees();
    let pan = if d[0].hypot(d[2]) < 1e-9 * len {
        0.0
    } else {
        d[0].atan2(-d[2]).to_degrees()
    };
    // `+ 0.0` turns -0.0 into 0.0, which scene.toml would otherwise spell `-0.0`.
    let round = |v: f64| (v * 100.0).round() / 100.0 + 0.0;
    (round(pan), round(tilt))
}

/// The unit beam direction of a moving light hung pointing down at `pan` and `tilt`
/// degrees: `(sin tilt sin pan, -cos tilt, -sin tilt cos pan)` (see [`pan_tilt`]).
pub fn beam_direction(pan: f64, tilt: f64) -> [f32; 3] {
    let (sp, cp) = pan.to_radians().sin_cos();
    let (st, ct) = tilt.to_radians().sin_cos();
    [(st * sp) as f32, (-ct) as f32, (-st * cp) as f32]
}

/// Largest image accepted (UHD): the camera's view takes about 160 bytes a pixel, so this
/// keeps a typo from allocating gigabytes.
const MAX_SIDE: u32 = 8192;
const MAX_PIXELS: u64 = 3840 * 2160;

impl VirtualStage {
    /// Parses and checks a rig file's text, so that rendering never meets a degenerate value.
    pub fn parse(text: &str) -> Result<VirtualStage, SynthError> {
        let rig: VirtualStage = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(1, |s| {
                text[..s.start.min(text.len())].matches('\n').count() + 1
            });
            SynthError::Syntax {
                line,
                message: e.message().trim().replace('\n', "; "),
            }
        })?;
        rig.validate()?;
        Ok(rig)
    }

    fn validate(&self) -> Result<(), SynthError> {
        let bad = |m: String| Err(SynthError::Invalid(m));
        let (w, h) = (self.width, self.height);
        if w == 0
            || h == 0
            || w > MAX_SIDE
            || h > MAX_SIDE
            || u64::from(w) * u64::from(h) > MAX_PIXELS
        {
            return bad(format!(
                "image size {w}x{h}: sides must be 1..={MAX_SIDE} and the area at most 3840x2160"
            ));
        }
        finite("exposure", &[self.exposure])?;
        let s = &self.stage;
        positive("stage width", s.width)?;
        positive("stage depth", s.depth)?;
        albedo("stage", s.albedo)?;
        if let Some(c) = &s.cyc {
            positive("cyc height", c.height)?;
            albedo("cyc", c.albedo)?;
            finite("cyc cove", &[c.cove])?;
            if c.cove < 0.0 || c.cove > c.height.min(s.depth) {
                return bad(format!(
                    "cyc cove {} must be between 0 and the cyc height and stage depth",
                    c.cove
                ));
            }
        }
        if let Some(l) = &s.legs {
            positive("leg width", l.width)?;
            positive("leg height", l.height)?;
            albedo("legs", l.albedo)?;
        }
        let c = &self.camera;
        finite("camera position", &c.position)?;
        finite("camera look_at", &c.look_at)?;
        if !(c.fov > 0.0 && c.fov < 179.0) {
            return bad(format!(
                "camera fov {} must be between 0 and 179 degrees",
                c.fov
            ));
        }
        let d = sub(c.look_at, c.position);
        let len = dot(d, d).sqrt();
        if len < 1e-4 {
            return bad("camera looks at its own position".into());
        }
        if d[1].abs() > 0.9999 * len {
            return bad("camera looks straight up or down (up is +y)".into());
        }
        for (i, b) in self.boxes.iter().enumerate() {
            let what = label("box", i, &b.name);
            finite(&what, &b.position)?;
            finite(&what, &[b.yaw])?;
            for v in b.size {
                positive(&format!("{what} size"), v)?;
            }
            albedo(&what, b.albedo)?;
        }
        for (i, c) in self.cylinders.iter().enumerate() {
            let what = label("cylinder", i, &c.name);
            finite(&what, &c.position)?;
            positive(&format!("{what} radius"), c.radius)?;
            positive(&format!("{what} height"), c.height)?;
            albedo(&what, c.albedo)?;
        }
        for (i, sp) in self.spheres.iter().enumerate() {
            let what = label("sphere", i, &sp.name);
            finite(&what, &sp.position)?;
            positive(&format!("{what} radius"), sp.radius)?;
            albedo(&what, sp.albedo)?;
        }
        if self.lights.is_empty() {
            return bad("the rig has no [[light]]".into());
        }
        for (i, p) in self.profiles.iter().enumerate() {
            if Profile::built_in(&p.name).is_some()
                || self.profiles[..i].iter().any(|o| o.name == p.name)
            {
                return bad(format!("profile `{}` is defined twice", p.name));
            }
            Profile::from_file(p).map_err(SynthError::Invalid)?;
        }
        // Focus palette number -> (its name, the light that named it).
        let mut palettes: std::collections::HashMap<u32, (String, String)> = Default::default();
        // (universe, slot) -> light index, to report overlaps by name.
        let mut slots = std::collections::HashMap::new();
        let mut channels = std::collections::HashMap::new();
        for (i, l) in self.lights.iter().enumerate() {
            let what = label("light", i, &l.name);
            if l.channel == 0 {
                return bad(format!("{what}: channel must be 1 or more"));
            }
            if let Some(j) = channels.insert(l.channel, i) {
                return bad(format!(
                    "{what}: channel {} is already used by {}",
                    l.channel,
                    label("light", j, &self.lights[j].name)
                ));
            }
            let Some(profile) = self.profile(&l.profile) else {
                return bad(format!(
                    "{what}: unknown profile `{}` ({}, or a [[profile]] of the rig)",
                    l.profile,
                    Profile::built_in_names().collect::<Vec<_>>().join(", ")
                ));
            };
            let fp = profile.footprint() as u32;
            if !(1..=63999).contains(&l.universe) {
                return bad(format!(
                    "{what}: universe {} is outside 1..=63999",
                    l.universe
                ));
            }
            if l.address == 0 || l.address > 513 - fp {
                return bad(format!(
                    "{what}: address {} with a {fp}-slot footprint does not fit in 1..=512",
                    l.address
                ));
            }
            for slot in l.address..l.address + fp {
                if let Some(j) = slots.insert((l.universe, slot), i) {
                    return bad(format!(
                        "{what}: universe {} slot {slot} is already used by {}",
                        l.universe,
                        label("light", j, &self.lights[j].name)
                    ));
                }
            }
            finite(&format!("{what} position"), &l.position)?;
            match (l.aim, profile.is_moving()) {
                (Some(aim), false) => {
                    finite(&format!("{what} aim"), &aim)?;
                    if !l.focus.is_empty() {
                        return bad(format!(
                            "{what}: [[light.focus]] is for a moving light, and profile `{}` has no pan and tilt slots",
                            l.profile
                        ));
                    }
                }
                (None, false) => return bad(format!("{what}: no `aim`")),
                (Some(_), true) => {
                    return bad(format!(
                        "{what}: a moving light (profile `{}`) is aimed by its [[light.focus]] tables, not `aim`",
                        l.profile
                    ));
                }
                (None, true) => self.check_focus(&what, l, &profile, &mut palettes)?,
            }
            for d in l.directions() {
                if dot(d, d) < 1e-8 {
                    return bad(format!("{what} aims at its own position"));
                }
            }
            if !(l.beam > 0.0 && l.beam < 180.0) {
                return bad(format!(
                    "{what}: beam angle {} must be between 0 and 180 degrees",
                    l.beam
                ));
            }
            if !(l.field >= l.beam && l.field < 180.0) {
                return bad(format!(
                    "{what}: field angle {} must be at least the beam angle {} and below 180",
                    l.field, l.beam
                ));
            }
            if !(l.intensity >= 0.0 && l.intensity.is_finite()) {
                return bad(format!(
                    "{what}: intensity {} must be 0 or more",
                    l.intensity
                ));
            }
            if let Some(g) = l.gel {
                if profile.has_colour() {
                    return bad(format!(
                        "{what}: a gel only suits a conventional fixture (dimmer, dimmer16), not `{}`",
                        l.profile
                    ));
                }
                if g.iter().any(|v| !(0.0..=1.0).contains(v)) {
                    return bad(format!("{what}: gel components must be within 0..1"));
                }
            }
        }
        Ok(())
    }

    /// The profile called `name`: a built-in or one of the rig's (checked) `[[profile]]`s.
    pub fn profile(&self, name: &str) -> Option<Profile> {
        Profile::built_in(name).or_else(|| {
            let file = self.profiles.iter().find(|p| p.name == name)?;
            Profile::from_file(file).ok()
        })
    }

    /// A moving light's focus palettes: at least one, numbered 1..=9999 once each, aimed
    /// at finite points its pan and tilt reach, and named as other lights name them
    /// (`palettes` holds the names so far).
    fn check_focus(
        &self,
        what: &str,
        l: &Spotlight,
        profile: &Profile,
        palettes: &mut std::collections::HashMap<u32, (String, String)>,
    ) -> Result<(), SynthError> {
        let bad = |m: String| Err(SynthError::Invalid(m));
        if l.focus.is_empty() {
            return bad(format!(
                "{what}: a moving light needs at least one [[light.focus]] (palette, aim)"
            ));
        }
        if l.focus.len() > MAX_POSITIONS {
            return bad(format!(
                "{what}: {} focus palettes; a light holds at most {MAX_POSITIONS}",
                l.focus.len()
            ));
        }
        for (k, f) in l.focus.iter().enumerate() {
            let n = f.palette;
            if !(1..=MAX_PALETTE).contains(&n) {
                return bad(format!(
                    "{what}: focus palette {n} is not a palette number (1-{MAX_PALETTE})"
                ));
            }
            if l.focus[..k].iter().any(|o| o.palette == n) {
                return bad(format!("{what}: focus palette {n} is listed twice"));
            }
            finite(&format!("{what} focus palette {n} aim"), &f.aim)?;
            let d = sub(f.aim, l.position);
            if dot(d, d) < 1e-8 {
                return bad(format!(
                    "{what}: focus palette {n} aims at its own position"
                ));
            }
            let (pan, tilt) = pan_tilt(l.position, f.aim);
            for (axis, v, range) in [
                ("pan", pan, profile.pan_range),
                ("tilt", tilt, profile.tilt_range),
            ] {
                if v.abs() > range / 2.0 {
                    return bad(format!(
                        "{what}: focus palette {n} needs {axis} {v} degrees, outside profile `{}`'s {axis}_range {range} (-{h}..={h})",
                        l.profile,
                        h = range / 2.0
                    ));
                }
            }
            if let Some(name) = f.name.as_deref().map(str::trim).filter(|n| !n.is_empty()) {
                let (had, by) = palettes
                    .entry(n)
                    .or_insert_with(|| (name.to_string(), what.to_string()));
                if had != name {
                    return bad(format!(
                        "{what}: focus palette {n} is `{name}` here but `{had}` on {by}: a palette has one name"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// "light 3 (`FOH L1`)": 1-based position in the file, plus the name when there is one.
pub(crate) fn label(kind: &str, index: usize, name: &Option<String>) -> String {
    match name {
        Some(n) => format!("{kind} {} (`{n}`)", index + 1),
        None => format!("{kind} {}", index + 1),
    }
}

fn finite(what: &str, v: &[f32]) -> Result<(), SynthError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(SynthError::Invalid(format!(
            "{what}: numbers must be finite"
        )))
    }
}

fn positive(what: &str, v: f32) -> Result<(), SynthError> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(SynthError::Invalid(format!("{what} {v} must be above 0")))
    }
}

fn albedo(what: &str, a: [f32; 3]) -> Result<(), SynthError> {
    if a.iter().all(|v| (0.0..=1.0).contains(v)) {
        Ok(())
    } else {
        Err(SynthError::Invalid(format!(
            "{what}: albedo components must be within 0..1"
        )))
    }
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
