//! The basis image file: half-float RGB OpenEXR, ZIP-compressed (what `visobjd synth`
//! writes and the compositor reads), written atomically so a crash never leaves half a
//! basis image behind.

use std::io::Cursor;
use std::path::Path;

use crate::{HdrError, Radiance};

/// Encodes `img` as a half-float RGB EXR in memory. Samples are clamped to the half range
/// (0..=65504; NaN becomes 0), since a basis holds no negative light.
pub fn encode_exr(img: &Radiance) -> Result<Vec<u8>, HdrError> {
    use exr::prelude::*;
    let w = img.width;
    if w == 0 || img.height == 0 || img.pixels.len() != w * img.height {
        return Err(HdrError::Exr(format!(
            "the image is {}x{} with {} pixels",
            img.width,
            img.height,
            img.pixels.len()
        )));
    }
    let max = f16::MAX.to_f32();
    let h16 = |v: f32| f16::from_f32(if v.is_nan() { 0.0 } else { v.clamp(0.0, max) });
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let v = img.pixels[p.y() * w + p.x()];
        (h16(v[0]), h16(v[1]), h16(v[2]))
    });
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        (w, img.height),
        LayerAttributes::default(),
        encoding,
        channels,
    );
    let mut bytes = Vec::new();
    Image::from_layer(layer)
        .write()
        .to_buffered(Cursor::new(&mut bytes))
        .map_err(|e| HdrError::Exr(e.to_string()))?;
    Ok(bytes)
}

/// Writes `img` to `path` (e.g. `scene/basis/017.exr`) atomically: encoded in memory, then
/// temp file, fsync, rename.
pub fn write_exr(path: &Path, img: &Radiance) -> Result<(), HdrError> {
    let bytes = encode_exr(img)?;
    visobjd_files::write_atomic(path, &bytes).map_err(|source| HdrError::Io {
        path: path.display().to_string(),
        source,
    })
}
