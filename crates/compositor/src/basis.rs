//! Basis images: one linear HDR image per light, read once at load and kept at the
//! resolutions in use, in the planar layout the compositor wants.

use std::path::{Path, PathBuf};

use half::f16;
use rayon::prelude::*;

use crate::render::STRIP;

use visobjd_scene::emitter::ColourModel;
use visobjd_scene::look::Level;
use visobjd_scene::{Scene, SceneError};

/// How basis samples are stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// IEEE half floats: half the memory and memory traffic; relative error <= 2^-11 per
    /// sample, far below what 8-bit output or Delta-E distances resolve.
    Half,
    /// 32-bit floats: exact, for what measures basis images (targeting) and for HDR values
    /// beyond half-float range.
    Single,
}

#[derive(Debug, Clone)]
enum Samples {
    Half(Vec<f16>),
    Single(Vec<f32>),
}

/// All lights' basis images at one resolution, packed for the compositor: the image is cut
/// into strips of [`STRIP`] pixels, and each strip holds, per channel and image, that
/// image's [`STRIP`] samples (zero past the last pixel). Images `0..lights` are the lights'
/// white images, in light order; a light captured per emitter has one more image per
/// emitter after them ([`BasisImages::emitter_images`]).
///
/// A render is a matrix product (candidates x lights) x (lights x pixels) per channel; this
/// layout makes every strip's (lights x pixels) panel one contiguous block, so the
/// compositor streams the basis from memory once, sequentially, with no gather.
#[derive(Debug, Clone)]
pub struct BasisImages {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Number of lights.
    pub lights: usize,
    /// Number of images: the lights' white images, then the per-emitter ones.
    pub images: usize,
    /// Per light, the first of its per-emitter images (one per emitter of its colour model,
    /// in slot order), or `None` when it was captured at white only.
    pub emitter_images: Vec<Option<usize>>,
    /// Per light, its positions' images as (focus palette, image), in the scene's order,
    /// the first being its white image; empty for a fixed light. A look's level picks one
    /// ([`BasisImages::image_of`]).
    pub positions: Vec<Vec<(u32, usize)>>,
    /// Per light, how a look's level becomes the multiplier of its image (each image is
    /// its light at white through its profile): from the scene at [`load`], plain linear
    /// colour for images made by [`BasisImages::from_planes`].
    pub colours: Vec<ColourModel>,
    samples: Samples,
}

/// One strip's panel as stored: `[channel][image][STRIP]`.
pub enum Panel<'a> {
    /// Half floats (converted by the compositor).
    Half(&'a [f16]),
    /// 32-bit floats (used in place).
    Single(&'a [f32]),
}

/// One light's rows of one image, in strip then channel order, to be filled at load.
enum Rows<'a> {
    Half(Vec<&'a mut [f16]>),
    Single(Vec<&'a mut [f32]>),
}

impl Rows<'_> {
    /// Fills the rows from planar `[R, G, B]` images; true if a sample exceeded the storage
    /// range (half floats: 65504).
    fn fill(self, planes: &[Vec<f32>; 3]) -> bool {
        fn put<T: Copy>(rows: Vec<&mut [T]>, planes: &[Vec<f32>; 3], conv: impl Fn(f32) -> T) {
            for (j, row) in rows.into_iter().enumerate() {
                let (s, ch) = (j / 3, j % 3);
                let src = planes[ch].get(s * STRIP..).unwrap_or(&[]);
                for (d, &v) in row.iter_mut().zip(src) {
                    *d = conv(v);
                }
            }
        }
        match self {
            Rows::Half(rows) => {
                let max = f16::MAX.to_f32();
                put(rows, planes, f16::from_f32);
                planes.iter().flatten().any(|&v| v > max)
            }
            Rows::Single(rows) => {
                put(rows, planes, |v| v);
                false
            }
        }
    }
}

impl BasisImages {
    /// All-black images, ready to be filled: the lights' white images, then `emitter_images`.
    fn zeroed(
        width: usize,
        height: usize,
        lights: usize,
        emitter_images: Vec<Option<usize>>,
        images: usize,
        precision: Precision,
    ) -> BasisImages {
        let n = (width * height).div_ceil(STRIP) * 3 * images * STRIP;
        BasisImages {
            width,
            height,
            lights,
            images,
            emitter_images,
            positions: vec![Vec::new(); lights],
            colours: vec![ColourModel::plain(); lights],
            samples: match precision {
                Precision::Half => Samples::Half(in_huge_pages(n, f16::ZERO)),
                Precision::Single => Samples::Single(in_huge_pages(n, 0.0)),
            },
        }
    }

    /// Images from planar samples (`planes[(ch * lights + l) * pixels + p]`), stored at
    /// `precision` (saturating half floats at 65504). For tests and tools; scenes load
    /// with [`load`].
    pub fn from_planes(
        width: usize,
        height: usize,
        lights: usize,
        planes: &[f32],
        precision: Precision,
    ) -> BasisImages {
        let pixels = width * height;
        assert_eq!(planes.len(), 3 * lights * pixels);
        let mut img =
            BasisImages::zeroed(width, height, lights, vec![None; lights], lights, precision);
        let lim = match precision {
            Precision::Half => f16::MAX.to_f32(),
            Precision::Single => f32::MAX,
        };
        for (l, rows) in img.rows_by_image().into_iter().enumerate() {
            rows.fill(&std::array::from_fn(|ch| {
                let start = (ch * lights + l) * pixels;
                planes[start..start + pixels]
                    .iter()
                    .map(|&v| v.clamp(-lim, lim))
                    .collect()
            }));
        }
        img
    }

    /// Every image's rows (strip then channel order), so images can be filled in parallel.
    fn rows_by_image(&mut self) -> Vec<Rows<'_>> {
        fn split<T>(data: &mut [T], images: usize) -> Vec<Vec<&mut [T]>> {
            let mut out: Vec<Vec<&mut [T]>> = (0..images)
                .map(|_| Vec::with_capacity(data.len() / STRIP / images.max(1)))
                .collect();
            for (r, row) in data.chunks_mut(STRIP).enumerate() {
                out[r % images].push(row);
            }
            out
        }
        match &mut self.samples {
            Samples::Half(d) => split(d, self.images).into_iter().map(Rows::Half).collect(),
            Samples::Single(d) => split(d, self.images)
                .into_iter()
                .map(Rows::Single)
                .collect(),
        }
    }

    /// The image light `light` lights at `level` (a fixed light: its white image; a mover:
    /// its position's, [`Level::position_in`]): what the compositor weighs.
    pub fn image_of(&self, light: usize, level: &Level) -> usize {
        level
            .position_in(&self.positions[light], |&(p, _)| p)
            .map_or(light, |&(_, image)| image)
    }

    /// Pixels per image.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// Number of [`STRIP`]-pixel strips.
    pub fn strips(&self) -> usize {
        self.pixels().div_ceil(STRIP)
    }

    /// How the samples are stored.
    pub fn precision(&self) -> Precision {
        match self.samples {
            Samples::Half(_) => Precision::Half,
            Samples::Single(_) => Precision::Single,
        }
    }

    /// Strip `s`'s panel, `3 * images * STRIP` samples.
    pub fn panel(&self, s: usize) -> Panel<'_> {
        let n = 3 * self.images * STRIP;
        match &self.samples {
            Samples::Half(d) => Panel::Half(&d[s * n..(s + 1) * n]),
            Samples::Single(d) => Panel::Single(&d[s * n..(s + 1) * n]),
        }
    }

    /// One sample of image `l`, channel `ch` (0 = R, 1 = G, 2 = B), at pixel `p`, as stored.
    fn sample(&self, ch: usize, l: usize, p: usize) -> f32 {
        let i = ((p / STRIP * 3 + ch) * self.images + l) * STRIP + p % STRIP;
        match &self.samples {
            Samples::Half(d) => d[i].to_f32(),
            Samples::Single(d) => d[i],
        }
    }

    /// One image's plane for one channel (0 = R, 1 = G, 2 = B), as stored: for the scalar
    /// reference and for measuring lights (image `l` < `lights` is light `l` at white), not
    /// for the compositor.
    pub fn plane(&self, channel: usize, light: usize) -> Vec<f32> {
        (0..self.pixels())
            .map(|p| self.sample(channel, light, p))
            .collect()
    }

    /// One light's luminance image (Rec. 709 weights on linear RGB).
    pub fn luminance(&self, light: usize) -> Vec<f32> {
        (0..self.pixels())
            .map(|p| crate::color::luminance(std::array::from_fn(|ch| self.sample(ch, light, p))))
            .collect()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match &self.samples {
            Samples::Half(d) => d.len() * std::mem::size_of::<f16>(),
            Samples::Single(d) => d.len() * std::mem::size_of::<f32>(),
        }
    }
}

/// `n` copies of `zero` in memory the kernel is asked to back with 2 MiB pages, before any
/// of it is touched. The compositor streams the whole basis every render; with 4 KiB pages
/// that is a TLB miss every 4 KiB, each a two-level walk in a virtual machine. Renders from
/// a basis in huge pages took 0.98-0.99 of the time in same-process pairs (44 lights). The
/// advice is only a hint: where the kernel declines, the pages are ordinary ones.
fn in_huge_pages<T: Copy>(n: usize, zero: T) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let spare = v.spare_capacity_mut();
        let start = spare.as_ptr() as usize;
        let (lo, hi) = (
            start.next_multiple_of(HUGE),
            (start + size_of_val(spare)) / HUGE * HUGE,
        );
        // SAFETY: the range is inside this allocation; MADV_HUGEPAGE changes how the kernel
        // backs it, never its contents or validity.
        if hi > lo && unsafe { libc::madvise(lo as *mut _, hi - lo, libc::MADV_HUGEPAGE) } != 0 {
            tracing::debug!(
                "huge pages declined for the basis images: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    v.resize(n, zero);
    v
}

/// A decoded linear RGB image, interleaved.
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width * height` pixels, row-major.
    pub pixels: Vec<[f32; 3]>,
}

/// The most pixels a side of an image [`read_exr`] reads: far past any camera or render a
/// basis is made from, and what a header must not exceed before a pixel is read.
pub const MAX_SIDE: usize = 16384;

/// The most pixels in all an image [`read_exr`] reads (64 megapixels, 768 MB as it is
/// decoded), so a header cannot ask for more memory than the machine has.
pub const MAX_PIXELS: usize = 64 << 20;

/// Reads an OpenEXR file's first RGB(A) layer (half or float, scanline or tiled).
///
/// The headers are read first, and a layer of more than [`MAX_SIDE`] pixels a side or
/// [`MAX_PIXELS`] in all is refused before anything is allocated for it. Decoding runs
/// under `catch_unwind`: a hostile file must produce an error, never take the daemon down.
pub fn read_exr(path: &Path) -> Result<RgbImage, String> {
    read_exr_on(path, Threads::Pool)
}

/// How [`read_exr_on`] decompresses a file's blocks.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Threads {
    /// On a thread pool of the decoder's own, made for the file: what one large image
    /// read alone wants.
    Pool,
    /// On the thread that reads the file: what many files read in parallel want (the
    /// decoder would otherwise make a pool per file, 16,000 of them for 16,000 lights).
    Reader,
}

/// [`read_exr`], decompressing on `threads`.
fn read_exr_on(path: &Path, threads: Threads) -> Result<RgbImage, String> {
    use exr::prelude::traits::{ReadChannels, ReadLayers};
    use std::io::{BufReader, Seek};
    let mut file = std::fs::File::open(path).map_err(|e| describe_exr_error(e.into()))?;
    let meta = exr::meta::MetaData::read_from_buffered(BufReader::new(&file), false)
        .map_err(describe_exr_error)?;
    for header in &meta.headers {
        let (w, h) = (header.layer_size.0, header.layer_size.1);
        if w > MAX_SIDE || h > MAX_SIDE || w.saturating_mul(h) > MAX_PIXELS {
            return Err(format!(
                "is {w}x{h} pixels; a basis image may have at most {MAX_SIDE} a side and {} megapixels",
                MAX_PIXELS >> 20
            ));
        }
    }
    file.rewind().map_err(|e| describe_exr_error(e.into()))?;
    let result = std::panic::catch_unwind(move || {
        let read = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |size, _| RgbImage {
                    width: size.0,
                    height: size.1,
                    pixels: vec![[0.0; 3]; size.0 * size.1],
                },
                |img: &mut RgbImage, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    let i = pos.1 * img.width + pos.0;
                    img.pixels[i] = [r, g, b];
                },
            )
            .first_valid_layer()
            .all_attributes();
        match threads {
            Threads::Pool => read.from_buffered(BufReader::new(file)),
            Threads::Reader => read.non_parallel().from_buffered(BufReader::new(file)),
        }
    });
    match result {
        Ok(Ok(image)) => {
            let img = image.layer_data.channel_data.pixels;
            if img.width == 0 || img.height == 0 {
                return Err("the image is empty".into());
            }
            Ok(img)
        }
        Ok(Err(e)) => Err(describe_exr_error(e)),
        Err(_) => Err("the file is corrupt (the EXR decoder gave up)".into()),
    }
}

fn describe_exr_error(e: exr::error::Error) -> String {
    use exr::error::Error;
    match e {
        Error::Io(io) if io.kind() == std::io::ErrorKind::NotFound => "file not found".into(),
        Error::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            "the file is truncated".into()
        }
        Error::Io(io) => format!("cannot read it: {io}"),
        Error::NotSupported(what) => format!("not a supported OpenEXR file ({what})"),
        Error::Invalid(what) => format!("not a valid OpenEXR file ({what})"),
        Error::Aborted => "reading was aborted".into(),
    }
}

/// Size of a `width`-wide version of a `w x h` image (never upscaled, at least 1x1).
pub fn scaled_size(w: usize, h: usize, width: usize) -> (usize, usize) {
    if width >= w || width == 0 {
        return (w, h);
    }
    let height = ((h as f64 * width as f64 / w as f64).round() as usize).max(1);
    (width, height)
}

/// Area-averaging resample of one plane: every source pixel contributes by the fraction of
/// it that falls inside each destination pixel, so energy (mean value) is preserved.
pub fn resample(src: &[f32], w: usize, h: usize, nw: usize, nh: usize) -> Vec<f32> {
    if (nw, nh) == (w, h) {
        return src.to_vec();
    }
    let xs = weights_1d(w, nw);
    let ys = weights_1d(h, nh);
    // Horizontal pass into h x nw, then vertical into nh x nw.
    let mut tmp = vec![0.0f32; h * nw];
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        for (x, taps) in xs.iter().enumerate() {
            tmp[y * nw + x] = taps.iter().map(|&(i, wt)| row[i] * wt).sum();
        }
    }
    let mut out = vec![0.0f32; nh * nw];
    for (y, taps) in ys.iter().enumerate() {
        for &(i, wt) in taps {
            let src_row = &tmp[i * nw..(i + 1) * nw];
            for (o, &s) in out[y * nw..(y + 1) * nw].iter_mut().zip(src_row) {
                *o += s * wt;
            }
        }
    }
    out
}

/// For each destination index, the source indices and weights (summing to 1) it averages.
fn weights_1d(n: usize, nn: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = n as f64 / nn as f64;
    (0..nn)
        .map(|d| {
            let (a, b) = (d as f64 * scale, (d + 1) as f64 * scale);
            let mut taps = Vec::new();
            let mut i = a.floor() as usize;
            while (i as f64) < b && i < n {
                let overlap = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                if overlap > 0.0 {
                    taps.push((i, (overlap / scale) as f32));
                }
                i += 1;
            }
            taps
        })
        .collect()
}

/// One basis image, validated, as planar `[R, G, B]` (negatives clamped to 0).
fn decode(path: &Path) -> Result<(usize, usize, [Vec<f32>; 3]), SceneError> {
    let fail = |message: String| SceneError::Basis {
        path: path.to_path_buf(),
        message,
    };
    // The scene's images are read in parallel, each decoded where it is read.
    let img = read_exr_on(path, Threads::Reader).map_err(fail)?;
    if img.pixels.iter().flatten().any(|v| !v.is_finite()) {
        return Err(fail(
            "contains NaN or infinite samples; re-export it with finite values".into(),
        ));
    }
    let planes = std::array::from_fn(|c| img.pixels.iter().map(|p| p[c].max(0.0)).collect());
    Ok((img.width, img.height, planes))
}

/// A light whose basis image (or one of its per-emitter images) cannot be used: missing,
/// corrupt, not finite or of another size. Its images are left black, so it adds nothing
/// to a preview; the stage leaves it out of generation and names it.
#[derive(Debug)]
pub struct Unseen {
    /// The light (index into the scene's lights).
    pub light: usize,
    /// Why, naming the file.
    pub error: SceneError,
}

/// A moving light's position (not its first) whose image cannot be used: the position is
/// left out of [`BasisImages::positions`], so generation never draws it, while the light's
/// other positions work (a palette learned from the console has no image until captured).
#[derive(Debug)]
pub struct UnseenPosition {
    /// The light (index into the scene's lights).
    pub light: usize,
    /// The focus palette.
    pub palette: u32,
    /// Why, naming the file.
    pub error: SceneError,
}

/// What [`load`] made of a scene's images.
#[derive(Debug)]
pub struct Loaded {
    /// One set of images per requested width.
    pub images: Vec<BasisImages>,
    /// The lights whose images could not be used, in light order.
    pub unseen: Vec<Unseen>,
    /// Movers' positions whose images could not be used, in light order.
    pub unseen_positions: Vec<UnseenPosition>,
}

impl Loaded {
    /// The images if every light's could be used, else the first unseen light's error
    /// (a check that compares against every image needs them all).
    pub fn all(self) -> Result<Vec<BasisImages>, SceneError> {
        match self.unseen.into_iter().next() {
            Some(u) => Err(u.error),
            None => Ok(self.images),
        }
    }
}

/// Loads every light's basis image and keeps it at each requested width (0 = full size)
/// and precision.
///
/// Each EXR is decoded once and written straight into the final packed images (no second
/// copy of the basis ever exists, so resident memory stays close to what is kept). The
/// first white image that reads sets the size; a light whose image is missing, corrupt or
/// of another size is left black and listed in [`Loaded::unseen`], so one bad file never
/// keeps the rest of the rig from loading. Only a scene none of whose white images reads is
/// an error. If a sample exceeds half-float range, the scene is loaded again in single
/// precision.
pub fn load(scene: &Scene, widths: &[(usize, Precision)]) -> Result<Loaded, SceneError> {
    let mut unseen = Vec::new();
    let mut first = None;
    for (l, light) in scene.lights.iter().enumerate() {
        match decode(&light.basis) {
            Ok(d) => {
                first = Some((l, d));
                break;
            }
            Err(error) => unseen.push(Unseen { light: l, error }),
        }
    }
    let Some((first_light, first)) = first else {
        return Err(match unseen.into_iter().next() {
            Some(u) => SceneError::Basis {
                path: scene.lights[0].basis.clone(),
                message: format!(
                    "no basis image of the scene can be read; the first: {}",
                    u.error
                ),
            },
            None => SceneError::Invalid {
                path: scene.dir.join("scene.toml"),
                message: "has no lights".into(),
            },
        });
    };
    let (w, h) = (first.0, first.1);
    let reference = scene.lights[first_light].basis.clone();
    let lights = scene.lights.len();
    // Every image in panel order: the lights' white images, then the per-emitter ones,
    // each with the light it belongs to.
    let mut files: Vec<&Path> = scene.lights.iter().map(|l| l.basis.as_path()).collect();
    let mut owner: Vec<usize> = (0..lights).collect();
    let emitter_images: Vec<Option<usize>> = scene
        .lights
        .iter()
        .enumerate()
        .map(|(l, light)| {
            (!light.emitter_basis.is_empty()).then(|| {
                let first = files.len();
                files.extend(light.emitter_basis.iter().map(PathBuf::as_path));
                owner.resize(files.len(), l);
                first
            })
        })
        .collect();
    // Then a moving light's other positions (its first is its white image).
    let mut palette_of: Vec<Option<u32>> = vec![None; files.len()];
    let mut positions: Vec<Vec<(u32, usize)>> = scene
        .lights
        .iter()
        .enumerate()
        .map(|(l, light)| {
            let mut held = Vec::with_capacity(light.positions.len());
            for (k, p) in light.positions.iter().enumerate() {
                if k == 0 {
                    held.push((p.palette, l));
                } else {
                    held.push((p.palette, files.len()));
                    files.push(p.basis.as_path());
                    owner.push(l);
                    palette_of.push(Some(p.palette));
                }
            }
            held
        })
        .collect();
    let mut images: Vec<BasisImages> = widths
        .iter()
        .map(|&(width, precision)| {
            let (nw, nh) = scaled_size(w, h, width);
            BasisImages::zeroed(
                nw,
                nh,
                lights,
                emitter_images.clone(),
                files.len(),
                precision,
            )
        })
        .collect();
    let mut slots: Vec<Vec<Rows>> = (0..files.len()).map(|_| Vec::new()).collect();
    for img in &mut images {
        for (slot, rows) in slots.iter_mut().zip(img.rows_by_image()) {
            slot.push(rows);
        }
    }
    let skip: Vec<bool> = {
        let mut skip = vec![false; files.len()];
        for u in &unseen {
            skip[u.light] = true;
        }
        skip
    };
    let first = std::sync::Mutex::new(Some(first));
    let results: Vec<Result<bool, SceneError>> = files
        .par_iter()
        .zip(slots)
        .enumerate()
        .map(|(i, (&file, slots))| {
            if skip[i] {
                return Ok(false);
            }
            let taken = if i == first_light {
                first.lock().map_or(None, |mut f| f.take())
            } else {
                None
            };
            let (lw, lh, planes) = match taken {
                Some(d) => d,
                None => decode(file)?,
            };
            if (lw, lh) != (w, h) {
                return Err(SceneError::Basis {
                    path: file.to_path_buf(),
                    message: format!(
                        "is {lw}x{lh} but {} is {w}x{h}; every basis image must have the same size",
                        reference.display()
                    ),
                });
            }
            let mut overflow = false;
            for (rows, &(width, _)) in slots.into_iter().zip(widths) {
                let (nw, nh) = scaled_size(w, h, width);
                let scaled = std::array::from_fn(|c| resample(&planes[c], w, h, nw, nh));
                overflow |= rows.fill(&scaled);
            }
            Ok(overflow)
        })
        .collect();
    let mut overflow = false;
    let mut unseen_positions = Vec::new();
    for (i, r) in results.into_iter().enumerate() {
        match (r, palette_of.get(i).copied().flatten()) {
            (Ok(o), _) => overflow |= o,
            (Err(error), Some(palette)) => unseen_positions.push(UnseenPosition {
                light: owner[i],
                palette,
                error,
            }),
            (Err(error), None) => unseen.push(Unseen {
                light: owner[i],
                error,
            }),
        }
    }
    for u in &unseen_positions {
        positions[u.light].retain(|&(n, _)| n != u.palette);
    }
    if overflow {
        let single: Vec<(usize, Precision)> = widths
            .iter()
            .map(|&(w, _)| (w, Precision::Single))
            .collect();
        return load(scene, &single);
    }
    // One entry per light (its first bad file), and none of its images left lit.
    unseen.sort_by_key(|u| u.light);
    unseen.dedup_by_key(|u| u.light);
    if !unseen.is_empty() {
        let mut unseen_light = vec![false; lights];
        for u in &unseen {
            unseen_light[u.light] = true;
        }
        let dark: Vec<bool> = owner.iter().map(|&l| unseen_light[l]).collect();
        for img in &mut images {
            let zero: [Vec<f32>; 3] = std::array::from_fn(|_| vec![0.0; img.width * img.height]);
            for (rows, _) in img
                .rows_by_image()
                .into_iter()
                .zip(&dark)
                .filter(|(_, d)| **d)
            {
                rows.fill(&zero);
            }
        }
    }
    let colours: Vec<ColourModel> = (0..lights).map(|l| scene.colour_model(l)).collect();
    for img in &mut images {
        img.colours.clone_from(&colours);
        img.positions.clone_from(&positions);
    }
    unseen_positions.sort_by_key(|u| (u.light, u.palette));
    Ok(Loaded {
        images,
        unseen,
        unseen_positions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resample_preserves_mean_and_box_averages() {
        let src: Vec<f32> = (0..12).map(|v| v as f32).collect(); // 4x3
        let out = resample(&src, 4, 3, 2, 1);
        let mean_src: f32 = src.iter().sum::<f32>() / 12.0;
        let mean_out: f32 = out.iter().sum::<f32>() / 2.0;
        assert!((mean_src - mean_out).abs() < 1e-5);
        // Left half of a 4x3 ramp: columns 0,1 of rows 0..3.
        assert!((out[0] - (0.0 + 1.0 + 4.0 + 5.0 + 8.0 + 9.0) / 6.0).abs() < 1e-5);
        let odd = resample(&src, 4, 3, 3, 2);
        let mean_odd: f32 = odd.iter().sum::<f32>() / 6.0;
        assert!((mean_src - mean_odd).abs() < 1e-4);
    }

    #[test]
    fn packed_planes_read_back_as_stored() {
        let (w, h, lights) = (100, 3, 2); // 300 pixels: four strips, the last one short
        let planes: Vec<f32> = (0..3 * lights * w * h).map(|i| i as f32 * 0.25).collect();
        let img = BasisImages::from_planes(w, h, lights, &planes, Precision::Single);
        assert_eq!(img.strips(), 4);
        for ch in 0..3 {
            for l in 0..lights {
                let start = (ch * lights + l) * w * h;
                assert_eq!(img.plane(ch, l), planes[start..start + w * h]);
            }
        }
        let half = BasisImages::from_planes(w, h, lights, &[1e6; 1800], Precision::Half);
        assert_eq!(half.plane(0, 0)[0], 65504.0, "half floats saturate");
    }

    #[test]
    fn scaled_size_never_upscales() {
        assert_eq!(scaled_size(480, 270, 120), (120, 68));
        assert_eq!(scaled_size(480, 270, 960), (480, 270));
        assert_eq!(scaled_size(480, 270, 0), (480, 270));
        assert_eq!(scaled_size(1000, 1, 10), (10, 1));
    }
}
