//! The references folder: the designer's images, listed, uploaded and read into objectives,
//! from that folder only (no absolute paths, no `..`, no links out), and decoded one at a
//! time, within a memory bound (`visobjd_method::decode`: at most 256 MiB, a 64-megapixel
//! image about 200 MB), on the compute pool: its threads run below the DMX clock and the
//! OSC threads (nice 10, `crate::cli::COMPUTE_NICE`), so a decode, like a generate, takes
//! only the time they leave.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::{Engine, Refusal};
use crate::config::Config;
use visobjd_method::objective::{self, Aspects, Objective, Region};

/// Largest name of an uploaded reference image.
const MAX_REFERENCE_NAME: usize = 100;

/// What reading from the folder (named by the config, which a reload may change) needs.
#[derive(Default)]
pub(super) struct References {
    /// Held while a reference is decoded: one at a time, so many senders adding
    /// 64-megapixel images at once cannot multiply the ~200 MB each decode takes.
    reading: Mutex<()>,
}

impl References {
    fn one_at_a_time(&self) -> std::sync::MutexGuard<'_, ()> {
        self.reading.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Engine {
    /// The references folder (objective images are read from it, and only from it).
    pub fn references(&self) -> PathBuf {
        self.config().references.clone()
    }

    /// The image files (PNG, JPEG by their extension) in the references folder, sorted.
    pub fn reference_names(&self) -> Result<Vec<String>, Refusal> {
        let folder = self.references();
        reference_files(&folder).map_err(|e| {
            Refusal::internal(format!(
                "the references folder {} is not readable: {e}",
                folder.display()
            ))
        })
    }

    /// Stores an uploaded reference image as `name` in the references folder, atomically,
    /// after the checks every reference passes (a plain file name with a PNG or JPEG
    /// extension, content of that type, within the size limit, decodable). Never replaces a
    /// file: a name taken is a conflict.
    pub fn store_reference(&self, name: &str, bytes: &[u8]) -> Result<String, Refusal> {
        let refused = |why: String| Refusal::input(format!("upload `{name}`: {why}"));
        let plain = !name.is_empty()
            && name.len() <= MAX_REFERENCE_NAME
            && !name.starts_with('.')
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._- ".contains(&b));
        if !plain {
            return Err(refused(format!(
                "a reference's name is a plain file name of at most {MAX_REFERENCE_NAME} letters, digits, spaces, '.', '_' or '-' (no folders), not starting with '.'"
            )));
        }
        let Some(format) = reference_format(name) else {
            return Err(refused("a reference is a .png, .jpg or .jpeg file".into()));
        };
        if image::guess_format(bytes).ok() != Some(format) {
            return Err(refused(format!(
                "the content is not a {} image",
                format
                    .extensions_str()
                    .first()
                    .copied()
                    .unwrap_or("")
                    .to_uppercase()
            )));
        }
        self.decoded(|| objective::decode_reference_bytes(bytes).map(drop))
            .map_err(&refused)?;
        let path = self.references().join(name);
        visobjd_files::write_new_atomic(&path, bytes).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => Refusal::conflict(format!(
                "upload `{name}`: a reference of that name exists; choose another name"
            )),
            _ => Refusal::internal(format!(
                "upload `{name}`: cannot write it in the references folder {}: {e}",
                self.references().display()
            )),
        })?;
        tracing::info!("reference {name} stored ({} bytes)", bytes.len());
        Ok(name.to_string())
    }

    /// Reads and analyses a reference image from the references folder for a new
    /// objective. One at a time, and slow for a big image: the sender's own handling thread
    /// waits for it with the session unlocked, so a slow decode holds up only that sender,
    /// whose later messages then see the objective.
    pub fn read_objective(&self, name: &str, aspects: Aspects) -> Result<Objective, Refusal> {
        let path = resolve_reference(&self.references(), name)?;
        let palette = self.config().generate.palette as usize;
        let analysis = self
            .decode_reference(&path, |img| objective::analyze(&img, Region::FULL, palette))
            .map_err(|e| Refusal::input(format!("{name} {e}")))?;
        Ok(Objective {
            image: name.to_string(),
            aspects,
            region: Region::FULL,
            analysis,
        })
    }

    /// Decodes the reference image at `path` (resolved in the references folder) and hands
    /// it to `then` (an analysis, a thumbnail), both on the compute pool, one decode at a
    /// time: a big image takes up to [`objective::DECODE_LIMIT`] while it decodes, and a
    /// page asks for every reference's picture at once. The calling thread waits. Err is
    /// the decoder's phrase ("is not a PNG ...").
    pub fn decode_reference<T: Send>(
        &self,
        path: &Path,
        then: impl FnOnce(image::RgbImage) -> T + Send,
    ) -> Result<T, String> {
        self.decoded(|| objective::decode_reference(path).map(then))
    }

    /// Runs `decode` on the compute pool, one at a time.
    fn decoded<T: Send>(
        &self,
        decode: impl FnOnce() -> Result<T, String> + Send,
    ) -> Result<T, String> {
        let _one = self.references.one_at_a_time();
        // Called from outside the pool (a sender's thread, the page's blocking tasks),
        // `scope` runs its body on a pool thread and waits for it.
        rayon::scope(|_| decode())
    }
}

/// The file `name` inside `references`, refusing anything that leads outside it.
pub fn resolve_reference(references: &Path, name: &str) -> Result<PathBuf, Refusal> {
    let relative = visobjd_scene::safe_relative(name).ok_or_else(|| {
        Refusal::input(format!(
            "image `{name}` must be a file name inside the references folder (no absolute paths, no ..)"
        ))
    })?;
    let root = references.canonicalize().map_err(|e| {
        Refusal::internal(format!(
            "the references folder {} is not readable: {e}",
            references.display()
        ))
    })?;
    let path = root.join(relative).canonicalize().map_err(|_| {
        Refusal::conflict(format!("image `{name}` is not in the references folder"))
    })?;
    if !path.starts_with(&root) {
        return Err(Refusal::input(format!(
            "image `{name}` leads outside the references folder"
        )));
    }
    if !path.is_file() {
        return Err(Refusal::conflict(format!("image `{name}` is not a file")));
    }
    Ok(path)
}

/// The image format a reference's file name promises, by its extension.
/// The reference images (PNG, JPEG by extension, not hidden) in `folder`, sorted by name.
pub fn reference_files(folder: &Path) -> std::io::Result<Vec<String>> {
    let mut names: Vec<String> = std::fs::read_dir(folder)?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| reference_format(n).is_some() && !n.starts_with('.'))
        .collect();
    names.sort();
    Ok(names)
}

/// Makes the references folder if it is missing and, while it holds no image, copies in the
/// images the scene ships in its own `refs/` folder: a booth's library lives in writable
/// state (the unit's file system is read-only elsewhere) and starts with what came with the
/// scene. Never replaces a file. Failures cost only the copy, so they are logged.
pub fn stock_references(config: &Config) {
    let folder = &config.references;
    let shipped = config.scene.join("refs");
    if let Err(e) = std::fs::create_dir_all(folder) {
        tracing::error!(
            "references folder {}: cannot create it ({e}); uploads will fail",
            folder.display()
        );
        return;
    }
    let empty = reference_files(folder).is_ok_and(|n| n.is_empty());
    let same = folder.canonicalize().ok() == shipped.canonicalize().ok();
    let Ok(names) = reference_files(&shipped) else {
        return;
    };
    if !empty || same || names.is_empty() {
        return;
    }
    let copied = names
        .iter()
        .filter(|n| {
            std::fs::read(shipped.join(n))
                .and_then(|bytes| visobjd_files::write_new_atomic(&folder.join(n), &bytes))
                .inspect_err(|e| {
                    tracing::warn!("reference {n} not copied to {}: {e}", folder.display())
                })
                .is_ok()
        })
        .count();
    tracing::info!(
        "references folder {} was empty: copied the scene's {copied} reference images from {}",
        folder.display(),
        shipped.display()
    );
}

fn reference_format(name: &str) -> Option<image::ImageFormat> {
    let (_, ext) = name.rsplit_once('.')?;
    match ext.to_ascii_lowercase().as_str() {
        "png" => Some(image::ImageFormat::Png),
        "jpg" | "jpeg" => Some(image::ImageFormat::Jpeg),
        _ => None,
    }
}
