//! `--camera sim`: a simulated camera for tests and for trying the whole capture workflow
//! on the demo stage without hardware. It listens for sACN on a loopback port the capture
//! sends to, reads back what each light is asked to do ([`Patch::multipliers`]), lights
//! the scene's own basis images with it (for the demo: the images `visobjd synth` rendered
//! from its rig), and photographs the result through a camera model: exposure, shot and
//! read noise, black level, clipping; an 8-bit JPEG through an sRGB-like tone curve, or a
//! linear 14-bit raw (an uncompressed Bayer DNG with its black and white levels and
//! colour matrix, read back through `rawler` like a camera's). Each file
//! carries its exposure in EXIF, read back like a real camera's.
//!
//! A moving light is photographed at the position its pan and tilt on the wire point it
//! at: the scene's image of the position whose pan and tilt bytes (as the patch sends
//! them) they are, or nothing (aimed out of frame) when they are none of its positions.
//! The sim's movers arrive at once; the fake gphoto2 of the tests is the one that takes
//! time (docs/capture.md).
//!
//! The fixtures may be other than their profiles say: `capture/sim/emitters.json` gives,
//! per channel, the emitters as they really are (`{"3": [{"name": "red", "xy": [0.6, 0.35],
//! "flux": 0.3}]}`, keys as in `[[profile.emitter]]`; emitters not listed stay as the
//! profile has them), and the sim lights those lights by
//! each emitter's true colour ([`Patch::multipliers_as`]): what a per-emitter capture is
//! for, tested against a preview made without that knowledge.

use std::io::Cursor;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, Normal};
use visobjd_camera::{
    Camera, CameraSetting, Description, Error, ExposureSource, Settings, Shot, Shutter,
};
use visobjd_dmx::Patch;
use visobjd_dmx::patch::SLOTS;
use visobjd_scene::Scene;
use visobjd_scene::emitter::ColourModel;
use visobjd_scene::profile::{EmitterFile, Profile};

use crate::Format;

/// Raw black level and white level (14-bit), as the DNG's `BlackLevel`/`WhiteLevel`.
pub const RAW_BLACK: u16 = 512;
/// See [`RAW_BLACK`].
pub const RAW_WHITE: u16 = 16383;
/// Electrons at full scale: sets the shot noise.
const FULL_WELL: f32 = 20_000.0;
/// Read noise, as a fraction of full scale.
const READ_NOISE: f32 = 2.0 / 16383.0;
/// The sim's fixed ISO and aperture (a real capture keeps both fixed too).
const ISO: f64 = 100.0;
const F_NUMBER: f64 = 8.0;
/// The sensor is at least this wide: the basis is enlarged by a whole factor so the
/// capture's downsample to the working width has something to do.
const SENSOR_WIDTH: usize = 1920;
/// Shutter choices, 1/4000 s to 30 s in third stops, as a camera lists them.
const SHUTTERS: &[&str] = &[
    "1/4000", "1/3200", "1/2500", "1/2000", "1/1600", "1/1250", "1/1000", "1/800", "1/640",
    "1/500", "1/400", "1/320", "1/250", "1/200", "1/160", "1/125", "1/100", "1/80", "1/60", "1/50",
    "1/40", "1/30", "1/25", "1/20", "1/15", "1/13", "1/10", "1/8", "1/6", "1/5", "1/4", "0.3",
    "0.4", "0.5", "0.6", "0.8", "1", "1.3", "1.6", "2", "2.5", "3.2", "4", "5", "6", "8", "10",
    "13", "15", "20", "25", "30",
];

/// The simulated camera.
pub struct SimCamera {
    socket: UdpSocket,
    patch: Patch,
    /// The latest DMX received, per patched universe.
    dmx: Vec<[u8; SLOTS]>,
    /// Per light: its basis image at sensor resolution, linear RGB; a moving light's, one
    /// per position in its scene order.
    truth: Vec<Vec<Vec<[f32; 3]>>>,
    /// Per light: for a moving light, where its pan and tilt bytes are (universe index,
    /// slot) and, per position, the bytes the patch sends for it; empty for a fixed light.
    aims: Vec<Aims>,
    /// Per light: its emitters as they really are (`capture/sim/emitters.json`), or `None`
    /// where the profile is right.
    real: Vec<Option<ColourModel>>,
    width: usize,
    height: usize,
    format: Format,
    shutter: String,
    rng: Xoshiro256PlusPlus,
}

impl SimCamera {
    /// A camera that photographs `scene`'s basis images lit by the DMX it receives on a
    /// fresh loopback port ([`SimCamera::listens_on`]). It photographs a copy of them made
    /// in `scene_dir/capture/sim/` on its first run, so a capture that replaces them, and
    /// a resumed one, see the same stage.
    pub fn new(
        scene: &Scene,
        scene_dir: &Path,
        format: Format,
        seed: u64,
    ) -> Result<SimCamera, String> {
        let socket = UdpSocket::bind("127.0.0.1:0")
            .map_err(|e| format!("the sim camera cannot listen on loopback: {e}"))?;
        let mut truth = Vec::with_capacity(scene.lights.len());
        let mut size = None;
        let stage = scene_dir.join("capture").join("sim");
        std::fs::create_dir_all(&stage)
            .map_err(|e| format!("{}: cannot make it: {e}", stage.display()))?;
        for (i, light) in scene.lights.iter().enumerate() {
            let images: Vec<(String, &Path)> = if light.is_moving() {
                light
                    .positions
                    .iter()
                    .map(|p| (format!("{i:04}-{}.exr", p.palette), p.basis.as_path()))
                    .collect()
            } else {
                vec![(format!("{i:04}.exr"), light.basis.as_path())]
            };
            let mut imgs = Vec::with_capacity(images.len());
            for (name, basis) in images {
                let copy = stage.join(name);
                if !copy.is_file() {
                    std::fs::copy(basis, &copy).map_err(|e| {
                        format!(
                            "the sim camera photographs the scene's own basis images (render them with `visobjd synth`): {}: {e}",
                            basis.display()
                        )
                    })?;
                }
                let img = visobjd_compositor::basis::read_exr(&copy).map_err(|e| {
                    format!(
                        "the sim camera photographs the scene's own basis images (render them with `visobjd synth`): {e}"
                    )
                })?;
                if *size.get_or_insert((img.width, img.height)) != (img.width, img.height) {
                    return Err(format!(
                        "{}: the basis images differ in size",
                        basis.display()
                    ));
                }
                imgs.push(img);
            }
            truth.push(imgs);
        }
        let (w, h) = size.ok_or("the scene has no lights")?;
        let k = SENSOR_WIDTH.div_ceil(w).max(1);
        let (width, height) = (w * k, h * k);
        let truth = truth
            .into_iter()
            .map(|imgs| {
                imgs.into_iter()
                    .map(|img| {
                        (0..width * height)
                            .map(|i| img.pixels[(i / width / k) * w + (i % width) / k])
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let patch = Patch::new(scene);
        let aims = (0..scene.lights.len())
            .map(|l| Aims::of(scene, &patch, l))
            .collect();
        let real = real_emitters(scene, &stage.join("emitters.json"))?;
        Ok(SimCamera {
            aims,
            real,
            socket,
            dmx: vec![[0; SLOTS]; patch.universes().len()],
            patch,
            truth,
            width,
            height,
            format,
            shutter: "1/60".into(),
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
        })
    }

    /// Where the capture must send sACN for this camera to see the rig.
    pub fn listens_on(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Takes in every sACN packet waiting; waits (bounded) for one if none is.
    fn receive(&mut self) -> Result<(), Error> {
        let mut buf = [0u8; 1144];
        let mut got = false;
        let deadline = Instant::now() + Duration::from_secs(3);
        loop {
            let wait = if got {
                Duration::from_millis(1)
            } else {
                deadline.saturating_duration_since(Instant::now())
            };
            if wait.is_zero() {
                break;
            }
            self.socket
                .set_read_timeout(Some(wait))
                .map_err(|source| io("sim", source))?;
            let Ok(n) = self.socket.recv(&mut buf) else {
                break;
            };
            got = true;
            self.take(&buf[..n]);
        }
        if got {
            Ok(())
        } else {
            Err(Error::Tool {
                call: "sim capture".into(),
                message: "no DMX arrived within 3 s: is the capture sending sACN to the sim?"
                    .into(),
                code: None,
                hint: String::new(),
            })
        }
    }

    /// One sACN packet: level data (start code 0) of a patched universe replaces it.
    fn take(&mut self, packet: &[u8]) {
        use sacn::packet::{AcnRootLayerProtocol, E131RootLayerData};
        let Ok(p) = AcnRootLayerProtocol::parse(packet) else {
            return;
        };
        let E131RootLayerData::DataPacket(data) = p.pdu.data else {
            return;
        };
        let values = &data.data.property_values;
        if values.first() != Some(&0) || data.stream_terminated {
            return;
        }
        if let Ok(u) = self.patch.universes().binary_search(&data.universe) {
            let slots = &values[1..];
            self.dmx[u] = [0; SLOTS];
            self.dmx[u][..slots.len().min(SLOTS)].copy_from_slice(&slots[..slots.len().min(SLOTS)]);
        }
    }

    /// The sensor's reading, 0..1 of full scale, before clipping.
    fn expose(&mut self, seconds: f64) -> Vec<[f32; 3]> {
        let m = self.patch.multipliers_as(&self.dmx, &self.real);
        let relative = (seconds * ISO / (F_NUMBER * F_NUMBER)) as f32;
        let mut out = vec![[0.0f32; 3]; self.width * self.height];
        for ((light, images), aims) in m.iter().zip(&self.truth).zip(&self.aims) {
            if *light == [0.0; 3] {
                continue;
            }
            let Some(basis) = images.get(aims.position(&self.dmx)) else {
                continue; // aimed at none of its positions: out of frame
            };
            for (o, b) in out.iter_mut().zip(basis) {
                for c in 0..3 {
                    o[c] += light[c] * b[c] * relative;
                }
            }
        }
        let read = Normal::new(0.0f32, READ_NOISE).ok();
        for o in &mut out {
            for v in o.iter_mut() {
                let shot = (v.max(0.0) / FULL_WELL).sqrt();
                let noise: f32 = Normal::new(0.0f32, shot)
                    .map(|n| n.sample(&mut self.rng))
                    .unwrap_or(0.0)
                    + read.map_or(0.0, |n| n.sample(&mut self.rng));
                *v += noise;
            }
        }
        out
    }
}

/// Where a moving light's pan and tilt bytes are and what the patch sends in them for each
/// of its positions: how the sim tells which of its images a light shows.
struct Aims {
    /// (universe index, slot) of each pan and tilt byte.
    slots: Vec<(usize, usize)>,
    /// Per position, in the light's order, the bytes of `slots`.
    bytes: Vec<Vec<u8>>,
}

impl Aims {
    /// Light `l`'s (no slots for a fixed light).
    fn of(scene: &Scene, patch: &Patch, l: usize) -> Aims {
        let light = &scene.lights[l];
        let universe = patch
            .universes()
            .binary_search(&light.universe)
            .unwrap_or_default();
        let mut at = usize::from(light.address.max(1)) - 1;
        let mut slots = Vec::new();
        for slot in &scene.profile(l).slots {
            if slot.is_position() {
                slots.extend((at..at + slot.width()).map(|s| (universe, s)));
            }
            at += slot.width();
        }
        slots.retain(|&(_, s)| s < SLOTS);
        let bytes = light
            .positions
            .iter()
            .map(|p| {
                let mut look = visobjd_scene::look::Look::off(scene.lights.len());
                look.levels[l].position = Some(p.palette);
                let sent = patch.quantise(&patch.unmastered(&look));
                slots.iter().map(|&(u, s)| sent[u][s]).collect()
            })
            .collect();
        Aims { slots, bytes }
    }

    /// The index of the image the light shows with `dmx` on the wire: 0 for a fixed light,
    /// the position its pan and tilt bytes are for a moving one, and past the end (nothing)
    /// when they are none of its positions.
    fn position(&self, dmx: &[[u8; SLOTS]]) -> usize {
        if self.bytes.is_empty() {
            return 0;
        }
        let got: Vec<u8> = self.slots.iter().map(|&(u, s)| dmx[u][s]).collect();
        self.bytes
            .iter()
            .position(|b| *b == got)
            .unwrap_or(self.bytes.len())
    }
}

/// The colour models of the fixtures as `path` says they really are (none without the
/// file): each listed light's profile with its emitters' xy and flux replaced.
fn real_emitters(scene: &Scene, path: &Path) -> Result<Vec<Option<ColourModel>>, String> {
    let mut real = vec![None; scene.lights.len()];
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(real);
    };
    let given: std::collections::BTreeMap<u32, Vec<EmitterFile>> =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    for (channel, emitters) in given {
        let l = scene
            .light_index(channel)
            .ok_or_else(|| format!("{}: channel {channel} is not in the scene", path.display()))?;
        let mut file = scene.profile(l).to_file();
        for e in emitters {
            file.emitters.retain(|x| x.name != e.name);
            file.emitters.push(e);
        }
        let profile = Profile::from_file(&file)
            .map_err(|e| format!("{}: channel {channel}: {e}", path.display()))?;
        real[l] = Some(ColourModel::new(&profile));
    }
    Ok(real)
}

fn io(call: &str, source: std::io::Error) -> Error {
    Error::Tool {
        call: call.into(),
        message: source.to_string(),
        code: None,
        hint: String::new(),
    }
}

/// sRGB-like tone curve of the sim's JPEGs (the capture recovers it from a bracket).
fn tone(v: f32) -> u8 {
    let v = v.clamp(0.0, 1.0);
    let e = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

/// The EXIF fields a camera records about an exposure.
fn exif_fields(seconds: f64) -> Vec<exif::Field> {
    use exif::{Field, In, Rational, Tag, Value};
    // Shutters are fractions (1/60) or decimals (0.3): a denominator of 10000 holds both.
    let t = Rational::from(((seconds * 10_000.0).round() as u32, 10_000));
    vec![
        Field {
            tag: Tag::ExposureTime,
            ifd_num: In::PRIMARY,
            value: Value::Rational(vec![t]),
        },
        Field {
            tag: Tag::FNumber,
            ifd_num: In::PRIMARY,
            value: Value::Rational(vec![Rational::from(((F_NUMBER * 10.0) as u32, 10))]),
        },
        Field {
            tag: Tag::PhotographicSensitivity,
            ifd_num: In::PRIMARY,
            value: Value::Short(vec![ISO as u16]),
        },
    ]
}

/// A JPEG with an EXIF APP1 segment right after its SOI. Public for the decode benchmark.
pub fn write_jpeg(
    path: &Path,
    width: usize,
    height: usize,
    rgb: &[u8],
    seconds: f64,
) -> Result<(), Error> {
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 95)
        .encode(
            rgb,
            width as u32,
            height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| io("sim jpeg", std::io::Error::other(e)))?;
    let fields = exif_fields(seconds);
    let mut writer = exif::experimental::Writer::new();
    for f in &fields {
        writer.push_field(f);
    }
    let mut tiff = Cursor::new(Vec::new());
    writer
        .write(&mut tiff, false)
        .map_err(|e| io("sim exif", std::io::Error::other(e.to_string())))?;
    let tiff = tiff.into_inner();
    let len = u16::try_from(2 + 6 + tiff.len())
        .map_err(|_| io("sim exif", std::io::Error::other("EXIF too long")))?;
    let mut out = Vec::with_capacity(jpeg.len() + tiff.len() + 10);
    out.extend_from_slice(&jpeg[..2]);
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(b"Exif\0\0");
    out.extend_from_slice(&tiff);
    out.extend_from_slice(&jpeg[2..]);
    std::fs::write(path, out).map_err(|source| io("sim write", source))
}

/// The sim sensor's colour: its red, green and blue filters each pass some of the
/// others' light (rows: camera R, G, B from linear sRGB), as real filters do, so the raw
/// path must apply the file's colour matrix to get the scene's colours back.
const CAMERA_RGB: [[f64; 3]; 3] = [[0.80, 0.15, 0.05], [0.10, 0.80, 0.10], [0.02, 0.18, 0.80]];

/// An uncompressed 16-bit colour-filter (RGGB Bayer) DNG, as a DNG-writing camera makes
/// one: 14-bit samples over a black level, `ColorMatrix1` (XYZ to camera RGB, for D65)
/// and the exposure in EXIF tags of the main IFD. Public for the decode benchmark.
pub fn write_raw(
    path: &Path,
    width: usize,
    height: usize,
    sensor: &[[f32; 3]],
    seconds: f64,
) -> Result<(), Error> {
    use tiff::encoder::{Rational, SRational, TiffEncoder, colortype};
    use tiff::tags::Tag;
    let fail = |e: tiff::TiffError| io("sim raw", std::io::Error::other(e.to_string()));
    let span = f32::from(RAW_WHITE - RAW_BLACK);
    let values: Vec<u16> = (0..height)
        .flat_map(|y| (0..width).map(move |x| (y, x)))
        .map(|(y, x)| {
            // R G / G B
            let c = (y % 2) + (x % 2);
            let rgb = sensor[y * width + x];
            let v: f32 = (0..3).map(|k| CAMERA_RGB[c][k] as f32 * rgb[k]).sum();
            (f32::from(RAW_BLACK) + v * span)
                .round()
                .clamp(0.0, f32::from(RAW_WHITE)) as u16
        })
        .collect();
    // XYZ -> camera = CAMERA_RGB * (sRGB -> XYZ)^-1.
    let xyz_to_srgb = crate::decode::invert(crate::decode::SRGB_TO_XYZ)
        .ok_or_else(|| io("sim raw", std::io::Error::other("singular sRGB matrix")))?;
    let matrix: Vec<SRational> = (0..9)
        .map(|i| {
            let v: f64 = (0..3)
                .map(|k| CAMERA_RGB[i / 3][k] * xyz_to_srgb[k][i % 3])
                .sum();
            SRational {
                n: (v * 1_000_000.0).round() as i32,
                d: 1_000_000,
            }
        })
        .collect();
    let file = std::fs::File::create(path).map_err(|source| io("sim raw", source))?;
    let mut encoder = TiffEncoder::new(std::io::BufWriter::new(file)).map_err(fail)?;
    let mut image = encoder
        .new_image::<colortype::Gray16>(width as u32, height as u32)
        .map_err(fail)?;
    let dir = image.encoder();
    let tag = |t: u16| Tag::Unknown(t);
    dir.write_tag(Tag::PhotometricInterpretation, 32803u16) // colour filter array
        .map_err(fail)?;
    dir.write_tag(Tag::Make, "visobjd").map_err(fail)?;
    dir.write_tag(Tag::Model, "simulated camera")
        .map_err(fail)?;
    dir.write_tag(tag(50706), &[1u8, 4, 0, 0][..])
        .map_err(fail)?; // DNGVersion
    dir.write_tag(tag(50708), "visobjd simulated camera") // UniqueCameraModel
        .map_err(fail)?;
    dir.write_tag(tag(33421), &[2u16, 2][..]).map_err(fail)?; // CFARepeatPatternDim
    dir.write_tag(tag(33422), &[0u8, 1, 1, 2][..])
        .map_err(fail)?; // CFAPattern: RGGB
    dir.write_tag(tag(50714), RAW_BLACK).map_err(fail)?; // BlackLevel
    dir.write_tag(tag(50717), RAW_WHITE).map_err(fail)?; // WhiteLevel
    dir.write_tag(tag(50721), &matrix[..]).map_err(fail)?; // ColorMatrix1
    dir.write_tag(tag(50778), 21u16).map_err(fail)?; // CalibrationIlluminant1: D65
    let t = Rational {
        n: (seconds * 10_000.0).round() as u32,
        d: 10_000,
    };
    dir.write_tag(tag(0x829A), t).map_err(fail)?; // ExposureTime
    dir.write_tag(
        tag(0x829D),
        Rational {
            n: (F_NUMBER * 10.0) as u32,
            d: 10,
        },
    )
    .map_err(fail)?; // FNumber
    dir.write_tag(tag(0x8827), ISO as u16).map_err(fail)?; // ISOSpeedRatings
    image.write_data(&values).map_err(fail)
}

impl Camera for SimCamera {
    fn describe(&mut self) -> Result<Description, Error> {
        Ok(Description {
            model: "visobjd simulated camera".into(),
            port: format!("sim:{}", self.listens_on().map_or(0, |a| a.port())),
        })
    }

    fn config(&mut self, key: &str) -> Result<CameraSetting, Error> {
        let (label, current, choices): (&str, String, Vec<String>) = match key {
            "shutterspeed" => (
                "Shutter Speed",
                self.shutter.clone(),
                SHUTTERS.iter().map(|s| s.to_string()).collect(),
            ),
            "iso" => ("ISO Speed", "100".into(), vec!["100".into()]),
            "aperture" => ("Aperture", "8".into(), vec!["8".into()]),
            "imageformat" => (
                "Image Format",
                self.format.name().into(),
                vec!["JPEG".into(), "RAW".into()],
            ),
            other => {
                return Err(Error::Unsupported(format!(
                    "the sim camera has no setting `{other}`"
                )));
            }
        };
        Ok(CameraSetting {
            key: key.into(),
            label: label.into(),
            readonly: false,
            kind: "RADIO".into(),
            current,
            choices,
        })
    }

    fn settings(&mut self) -> Result<Settings, Error> {
        Ok(Settings {
            shutter: self.config("shutterspeed")?,
            iso: Some(self.config("iso")?),
            aperture: Some(self.config("aperture")?),
            image_format: Some(self.config("imageformat")?),
        })
    }

    fn set_config(&mut self, key: &str, value: &str) -> Result<(), Error> {
        let setting = self.config(key)?;
        if !setting.accepts(value) {
            return Err(Error::NotAChoice {
                key: key.into(),
                value: value.into(),
                choices: setting.choices.join(", "),
            });
        }
        match key {
            "shutterspeed" => self.shutter = value.into(),
            "imageformat" => {
                self.format = if value == "RAW" {
                    Format::Raw
                } else {
                    Format::Jpeg
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn capture(&mut self, shutter: &Shutter, out: &Path) -> Result<Shot, Error> {
        self.receive()?;
        self.shutter = shutter.text().to_string();
        let seconds = shutter.seconds();
        let sensor = self.expose(seconds);
        let path: PathBuf = out.with_extension(self.format.extension());
        match self.format {
            Format::Jpeg => {
                let rgb: Vec<u8> = sensor.iter().flat_map(|p| p.map(tone)).collect();
                write_jpeg(&path, self.width, self.height, &rgb, seconds)?;
            }
            Format::Raw => write_raw(&path, self.width, self.height, &sensor, seconds)?,
        }
        let exposure = visobjd_camera::read_exposure(&path)?.ok_or_else(|| Error::Exif {
            path: path.clone(),
            problem: "the sim wrote no exposure".into(),
        })?;
        Ok(Shot {
            paths: vec![path],
            exposure,
            source: ExposureSource::Exif,
        })
    }
}
