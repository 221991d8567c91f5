//! The pictures the page shows: the live look, the gallery's thumbnails and members, history
//! steps, saved looks, what an objective's region selects, and reference images, each
//! rendered or decoded off the runtime's threads and kept in a small cache.

use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::{Path as UrlPath, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::sync::Mutex;

use super::{Shared, blocking, refuse};
use visobjd_scene::look::Look;

/// Width of the reference images on the page.
const REFERENCE_WIDTH: u32 = 320;
/// JPEG quality of every picture served.
const JPEG_QUALITY: u8 = 85;
/// Pictures kept per cache.
const CACHED: usize = 64;

/// An encoded picture, shared between the caches and the answers being sent.
type Picture = Bytes;

/// Encoded pictures of one gallery's representatives, by entry.
type Thumbs = (u64, Arc<Vec<Picture>>);

type FileKey = (String, u64, Option<std::time::SystemTime>);

/// The caches, one per kind of picture.
#[derive(Default)]
pub(super) struct Caches {
    /// The current gallery's thumbnails, encoded together on the first request.
    thumbs: Mutex<Option<Thumbs>>,
    /// Rendered looks (live, members, history, saved looks, selections), newest last.
    renders: Mutex<Vec<(Look, Picture)>>,
    /// Reference images by (file name, size, modified), newest last.
    files: Mutex<Vec<(FileKey, Picture)>>,
}

fn encode_jpeg(img: &image::RgbImage) -> Vec<u8> {
    let mut out = Vec::new();
    let encoded = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
        .encode_image(img);
    if let Err(e) = encoded {
        tracing::warn!("http: cannot encode a picture: {e}");
    }
    out
}

fn jpeg(pic: Picture) -> Response {
    ([(header::CONTENT_TYPE, "image/jpeg")], pic).into_response()
}

/// The picture cached under `key`. The cache is held to look up (and to [`keep`]), not
/// across a render or a decode: pictures the page asks for at once render side by side.
async fn cached<K: PartialEq>(cache: &Mutex<Vec<(K, Picture)>>, key: &K) -> Option<Picture> {
    let cache = cache.lock().await;
    cache
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, pic)| pic.clone())
}

/// Keeps `value` under `key` in a cache of at most [`CACHED`] entries, oldest dropped.
fn keep<K>(cache: &mut Vec<(K, Picture)>, key: K, value: &Picture) {
    if cache.len() >= CACHED {
        cache.remove(0);
    }
    cache.push((key, value.clone()));
}

/// `7.jpg` gives 7.
fn number_jpg<T: std::str::FromStr>(file: &str) -> Option<T> {
    file.strip_suffix(".jpg")?.parse().ok()
}

/// A look as the stage picture, from the cache or rendered.
async fn render(sh: &Shared, look: Look) -> Response {
    if let Some(pic) = cached(&sh.pictures.renders, &look).await {
        return jpeg(pic);
    }
    let engine = Arc::clone(&sh.engine);
    let rendered = look.clone();
    let Some(pic) = blocking(move || {
        engine
            .stage()
            .thumbnails(&[&rendered])
            .first()
            .map(encode_jpeg)
            .unwrap_or_default()
    })
    .await
    else {
        return refuse(StatusCode::INTERNAL_SERVER_ERROR, "the render failed");
    };
    let pic = Bytes::from(pic);
    keep(&mut *sh.pictures.renders.lock().await, look, &pic);
    jpeg(pic)
}

pub(super) async fn live(State(sh): State<Arc<Shared>>) -> Response {
    let look = sh.engine.session().live.clone();
    render(&sh, look).await
}

pub(super) async fn thumb(
    State(sh): State<Arc<Shared>>,
    UrlPath((serial, file)): UrlPath<(String, String)>,
) -> Response {
    let (Ok(serial), Some(k)) = (serial.parse::<u64>(), number_jpg::<usize>(&file)) else {
        return refuse(StatusCode::NOT_FOUND, "no such thumbnail");
    };
    let mut cache = sh.pictures.thumbs.lock().await;
    let current = match cache.as_ref() {
        Some((s, pics)) if *s == serial => Arc::clone(pics),
        _ => {
            // The representatives' thumbnails were rendered with the gallery.
            let thumbs = {
                let s = sh.engine.session();
                match s.gallery.as_ref() {
                    Some(g) if g.serial == serial => Arc::clone(&g.generation.thumbnails),
                    _ => {
                        return refuse(
                            StatusCode::NOT_FOUND,
                            "that gallery was replaced by a newer one",
                        );
                    }
                }
            };
            let Some(pics) = blocking(move || {
                thumbs
                    .iter()
                    .map(|img| Bytes::from(encode_jpeg(img)))
                    .collect::<Vec<_>>()
            })
            .await
            else {
                return refuse(StatusCode::INTERNAL_SERVER_ERROR, "the encoding failed");
            };
            let pics = Arc::new(pics);
            *cache = Some((serial, Arc::clone(&pics)));
            pics
        }
    };
    match k.checked_sub(1).and_then(|i| current.get(i)) {
        Some(pic) => jpeg(pic.clone()),
        None => refuse(StatusCode::NOT_FOUND, "no such entry"),
    }
}

/// Member m of entry k of gallery `serial`, rendered on demand.
pub(super) async fn member(
    State(sh): State<Arc<Shared>>,
    UrlPath((serial, k, file)): UrlPath<(String, String, String)>,
) -> Response {
    let (Ok(serial), Ok(k), Some(m)) = (
        serial.parse::<u64>(),
        k.parse::<usize>(),
        number_jpg::<usize>(&file),
    ) else {
        return refuse(StatusCode::NOT_FOUND, "no such member");
    };
    let look = {
        let s = sh.engine.session();
        if s.gallery.as_ref().map(|g| g.serial) != Some(serial) {
            return refuse(
                StatusCode::NOT_FOUND,
                "that gallery was replaced by a newer one",
            );
        }
        s.gallery_look(k, m)
    };
    match look {
        Ok(look) => render(&sh, look).await,
        Err(e) => refuse(StatusCode::NOT_FOUND, &e.sentence),
    }
}

/// Undo step i (`u1.jpg`: one step back) or redo step i (`r1.jpg`).
pub(super) async fn history(
    State(sh): State<Arc<Shared>>,
    UrlPath(file): UrlPath<String>,
) -> Response {
    let look = {
        let s = sh.engine.session();
        let (undo, redo, _) = s.history();
        let pick = |list: &[Look], i: &str| {
            let i: usize = i.parse().ok()?;
            list.len().checked_sub(i).and_then(|j| list.get(j)).cloned()
        };
        let name = file.strip_suffix(".jpg").unwrap_or_default();
        match name.split_at_checked(1) {
            Some(("u", i)) => pick(undo, i),
            Some(("r", i)) => pick(redo, i),
            _ => None,
        }
    };
    match look {
        Some(look) => render(&sh, look).await,
        None => refuse(StatusCode::NOT_FOUND, "no such history step"),
    }
}

/// Saved look n.
pub(super) async fn saved_look(
    State(sh): State<Arc<Shared>>,
    UrlPath(file): UrlPath<String>,
) -> Response {
    let Some(n) = number_jpg::<u32>(&file) else {
        return refuse(StatusCode::NOT_FOUND, "no such look");
    };
    let look = {
        let s = sh.engine.session();
        s.looks.get(&n).map(|f| f.to_look(&sh.engine.stage().scene))
    };
    match look {
        Some(Ok(look)) => render(&sh, look).await,
        Some(Err(e)) => refuse(StatusCode::NOT_FOUND, &e),
        None => refuse(
            StatusCode::NOT_FOUND,
            &format!("there is no saved look {n}"),
        ),
    }
}

/// The lights objective id's region selects, at full in white (what its region reaches).
pub(super) async fn selected(
    State(sh): State<Arc<Shared>>,
    UrlPath(file): UrlPath<String>,
) -> Response {
    let Some(id) = number_jpg::<u32>(&file) else {
        return refuse(StatusCode::NOT_FOUND, "no such objective");
    };
    let region = {
        let s = sh.engine.session();
        s.objectives
            .iter()
            .find(|o| o.id == id)
            .map(|o| o.objective.region)
    };
    let Some(region) = region else {
        return refuse(StatusCode::NOT_FOUND, "no such objective");
    };
    let chosen = sh.engine.stage().footprints.select(region);
    let mut look = Look::off(chosen.len());
    for (level, on) in look.levels.iter_mut().zip(chosen) {
        if on {
            level.intensity = 1.0;
        }
    }
    render(&sh, look).await
}

/// Objective id's reference image, at most [`REFERENCE_WIDTH`] wide.
pub(super) async fn objective_reference(
    State(sh): State<Arc<Shared>>,
    UrlPath(file): UrlPath<String>,
) -> Response {
    let image = number_jpg::<u32>(&file).and_then(|id| {
        sh.engine
            .session()
            .objectives
            .iter()
            .find(|o| o.id == id)
            .map(|o| o.objective.image.clone())
    });
    match image {
        Some(image) => reference_picture(&sh, image).await,
        None => refuse(StatusCode::NOT_FOUND, "no such objective"),
    }
}

pub(super) async fn reference_file(
    State(sh): State<Arc<Shared>>,
    UrlPath(name): UrlPath<String>,
) -> Response {
    reference_picture(&sh, name).await
}

/// A reference image by name, checked and decoded as an objective's is, at most
/// [`REFERENCE_WIDTH`] wide; cached while the file keeps its size and time.
async fn reference_picture(sh: &Shared, name: String) -> Response {
    let path = match crate::engine::resolve_reference(&sh.engine.references(), &name) {
        Ok(p) => p,
        Err(e) => return refuse(StatusCode::NOT_FOUND, &e.sentence),
    };
    // Not the runtime's thread's time: the file system may be slow.
    let meta = tokio::fs::metadata(&path).await.ok();
    let key: FileKey = (
        name.clone(),
        meta.as_ref().map_or(0, std::fs::Metadata::len),
        meta.and_then(|m| m.modified().ok()),
    );
    if let Some(pic) = cached(&sh.pictures.files, &key).await {
        return jpeg(pic);
    }
    let engine = Arc::clone(&sh.engine);
    let decoded = blocking(move || {
        engine.decode_reference(&path, |img| {
            let (w, h) = img.dimensions();
            let img = if w > REFERENCE_WIDTH {
                let h = (u64::from(h) * u64::from(REFERENCE_WIDTH) / u64::from(w)).max(1) as u32;
                image::imageops::thumbnail(&img, REFERENCE_WIDTH, h)
            } else {
                img
            };
            encode_jpeg(&img)
        })
    })
    .await;
    match decoded {
        Some(Ok(pic)) => {
            let pic = Bytes::from(pic);
            keep(&mut *sh.pictures.files.lock().await, key, &pic);
            jpeg(pic)
        }
        Some(Err(e)) => refuse(StatusCode::NOT_FOUND, &format!("{name} {e}")),
        None => refuse(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the reference could not be read",
        ),
    }
}
