//! Basis images: one linear HDR image per light, read once at load and kept at the
//! resolutions in use, in the planar layout the compositor wants.

use std::path::Path;

use rayon::prelude::*;

use crate::scene::{Scene, SceneError};

/// All lights' basis images at one resolution, planar: `planes[(ch * lights + l) * pixels + p]`.
///
/// Planar per channel makes a render a matrix product (candidates x lights) x (lights x
/// pixels) per channel, which is what the batched compositor computes.
#[derive(Debug, Clone)]
pub struct BasisImages {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Number of lights.
    pub lights: usize,
    /// The samples, channel-major then light then pixel.
    pub planes: Vec<f32>,
}

impl BasisImages {
    /// Pixels per image.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// One light's plane for one channel (0 = R, 1 = G, 2 = B).
    pub fn plane(&self, channel: usize, light: usize) -> &[f32] {
        let n = self.pixels();
        let start = (channel * self.lights + light) * n;
        &self.planes[start..start + n]
    }

    /// One light's luminance image (Rec. 709 weights on linear RGB).
    pub fn luminance(&self, light: usize) -> Vec<f32> {
        let (r, g, b) = (
            self.plane(0, light),
            self.plane(1, light),
            self.plane(2, light),
        );
        r.iter()
            .zip(g)
            .zip(b)
            .map(|((&r, &g), &b)| crate::color::luminance([r, g, b]))
            .collect()
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.planes.len() * std::mem::size_of::<f32>()
    }
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

/// Reads an OpenEXR file's first RGB(A) layer (half or float, scanline or tiled).
///
/// Decoding runs under `catch_unwind`: a hostile file must produce an error, never take
/// the daemon down.
pub fn read_exr(path: &Path) -> Result<RgbImage, String> {
    let owned = path.to_path_buf();
    let result = std::panic::catch_unwind(move || {
        exr::prelude::read_first_rgba_layer_from_file(
            &owned,
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

/// Loads every light's basis image and keeps it at each requested width (0 = full size).
///
/// Each EXR is decoded once; the full-size image is dropped unless asked for. All images
/// must share one size, or the scene does not load and the error names the odd file.
pub fn load(scene: &Scene, widths: &[usize]) -> Result<Vec<BasisImages>, SceneError> {
    // Per light: its full size and, per requested width, its three resampled planes.
    type Scaled = ((usize, usize), Vec<[Vec<f32>; 3]>);
    let decoded: Vec<Result<Scaled, SceneError>> = scene
        .lights
        .par_iter()
        .map(|light| {
            let fail = |message: String| SceneError::Basis {
                path: light.basis.clone(),
                message,
            };
            let img = read_exr(&light.basis).map_err(fail)?;
            if img.pixels.iter().flatten().any(|v| !v.is_finite()) {
                return Err(fail(
                    "contains NaN or infinite samples; re-export it with finite values".into(),
                ));
            }
            let (w, h) = (img.width, img.height);
            let planes: [Vec<f32>; 3] =
                std::array::from_fn(|c| img.pixels.iter().map(|p| p[c].max(0.0)).collect());
            drop(img);
            let scaled = widths
                .iter()
                .map(|&width| {
                    let (nw, nh) = scaled_size(w, h, width);
                    std::array::from_fn(|c| resample(&planes[c], w, h, nw, nh))
                })
                .collect();
            Ok(((w, h), scaled))
        })
        .collect();
    let mut lights = Vec::with_capacity(decoded.len());
    for d in decoded {
        lights.push(d?);
    }
    let (w, h) = lights[0].0;
    if let Some(i) = lights.iter().position(|l| l.0 != (w, h)) {
        return Err(SceneError::Basis {
            path: scene.lights[i].basis.clone(),
            message: format!(
                "is {}x{} but {} is {w}x{h}; every basis image must have the same size",
                lights[i].0.0,
                lights[i].0.1,
                scene.lights[0].basis.display()
            ),
        });
    }
    Ok(widths
        .iter()
        .enumerate()
        .map(|(k, &width)| {
            let (nw, nh) = scaled_size(w, h, width);
            let mut planes = Vec::with_capacity(3 * lights.len() * nw * nh);
            for c in 0..3 {
                for light in &mut lights {
                    planes.append(&mut light.1[k][c]);
                }
            }
            BasisImages {
                width: nw,
                height: nh,
                lights: lights.len(),
                planes,
            }
        })
        .collect())
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
    fn scaled_size_never_upscales() {
        assert_eq!(scaled_size(480, 270, 120), (120, 68));
        assert_eq!(scaled_size(480, 270, 960), (480, 270));
        assert_eq!(scaled_size(480, 270, 0), (480, 270));
        assert_eq!(scaled_size(1000, 1, 10), (10, 1));
    }
}
