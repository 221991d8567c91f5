//! The web gallery: an optional HTTP/1.1 listener (`[http] listen`) serving one
//! self-contained page that shows the gallery as numbered thumbnails, the live look, and
//! the objectives with their reference images and regions; it polls `/state.json` and
//! picks through the same handler OSC uses, so there is one implementation of a pick.
//!
//! Deliberately tiny and bounded instead of a web framework (compile time, attack
//! surface): GET and POST only, one request per connection, 8 KiB of head, 1 KiB of body,
//! 10 s to send the request, 32 connections at once, and the `osc.allow` list checked on
//! accept, before a byte is read.
//!
//! | request | answer |
//! | --- | --- |
//! | `GET /` | the page |
//! | `GET /state.json` | status line, gallery serial and sizes, live entry, live-look hash, objectives, the console sources (`console`: name, priority, universes, `age_s`, `sampling`; null without `[input.sacn]`) |
//! | `GET /thumb/<serial>/<k>.jpg` | entry k of gallery `serial` (404 once a newer generate replaced it) |
//! | `GET /live.jpg` | the live look |
//! | `GET /ref/<id>.jpg` | objective id's reference image, at most 320 px wide |
//! | `POST /pick/<k>` | `/vo/pick k` through the OSC handler: 200 with the reply, 409 with the error |

use std::hash::{Hash, Hasher};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use rosc::{OscMessage, OscType};
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Mutex, Semaphore};

use crate::config::{Cidr, permits};
use crate::engine::{Engine, EngineHandler, msg};
use crate::osc::{Handler, Peer};
use visobjd_scene::look::Look;

/// Largest request head (request line and headers).
const MAX_HEAD: usize = 8 * 1024;
/// Largest request body (a pick needs none).
const MAX_BODY: usize = 1024;
/// Time a client has to send its whole request.
const READ_TIMEOUT: Duration = Duration::from_secs(10);
/// Time a client has to take the whole answer.
const WRITE_TIMEOUT: Duration = Duration::from_secs(30);
/// Connections served at once; more are closed at once.
const MAX_CONNECTIONS: usize = 32;
/// Width of the reference images on the page.
const REFERENCE_WIDTH: u32 = 320;
/// JPEG quality of every picture served.
const JPEG_QUALITY: u8 = 85;

const PAGE: &str = include_str!("http_page.html");

/// The running listener; dropping the runtime stops it.
pub struct Http {
    addr: SocketAddr,
    accept: tokio::task::JoinHandle<()>,
}

impl Http {
    /// Binds `listen` and serves in the current tokio runtime.
    pub async fn start(
        listen: &str,
        allow: Vec<Cidr>,
        engine: Arc<Engine>,
    ) -> Result<Http, String> {
        let listener = TcpListener::bind(listen)
            .await
            .map_err(|e| format!("http.listen {listen}: cannot listen there: {e}"))?;
        let addr = listener
            .local_addr()
            .map_err(|e| format!("http.listen {listen}: {e}"))?;
        let shared = Arc::new(Shared {
            engine,
            allow,
            slots: Arc::new(Semaphore::new(MAX_CONNECTIONS)),
            thumbs: Mutex::new(None),
            live: Mutex::new(None),
            refs: Mutex::new(Vec::new()),
        });
        let accept = tokio::spawn(accept(listener, shared));
        Ok(Http { addr, accept })
    }

    /// Stops taking connections (those open end with the runtime).
    pub async fn stop(self) {
        self.accept.abort();
        // A cancelled task's error is the expected outcome.
        let _ = self.accept.await;
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

/// An encoded picture, shared between the cache and the answers being sent.
type Picture = Arc<Vec<u8>>;

/// Encoded pictures of one gallery, by entry.
type Thumbs = (u64, Arc<Vec<Picture>>);

struct Shared {
    engine: Arc<Engine>,
    allow: Vec<Cidr>,
    slots: Arc<Semaphore>,
    /// The current gallery's thumbnails, rendered together on the first request.
    thumbs: Mutex<Option<Thumbs>>,
    /// The last live look served and its picture.
    live: Mutex<Option<(Look, Picture)>>,
    /// Reference pictures by (objective id, image name).
    refs: Mutex<Vec<((u32, String), Picture)>>,
}

async fn accept(listener: TcpListener, shared: Arc<Shared>) {
    loop {
        let (stream, from) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("http: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        if !permits(&shared.allow, from.ip()) {
            tracing::info!("http: refused {from}, not in osc.allow");
            continue;
        }
        let Ok(slot) = Arc::clone(&shared.slots).try_acquire_owned() else {
            tracing::info!("http: {from} refused, {MAX_CONNECTIONS} connections busy");
            continue;
        };
        let shared = Arc::clone(&shared);
        tokio::spawn(async move {
            connection(stream, from, &shared).await;
            drop(slot);
        });
    }
}

/// A request: method, path without query, body.
struct Request {
    method: String,
    path: String,
}

/// An answer: status, content type, body.
struct Answer {
    status: u16,
    kind: &'static str,
    body: Arc<Vec<u8>>,
}

impl Answer {
    fn new(status: u16, kind: &'static str, body: Vec<u8>) -> Answer {
        Answer {
            status,
            kind,
            body: Arc::new(body),
        }
    }

    fn json(status: u16, v: serde_json::Value) -> Answer {
        Answer::new(status, "application/json", v.to_string().into_bytes())
    }

    fn jpeg(body: Arc<Vec<u8>>) -> Answer {
        Answer {
            status: 200,
            kind: "image/jpeg",
            body,
        }
    }

    fn text(status: u16, s: &str) -> Answer {
        Answer::new(
            status,
            "text/plain; charset=utf-8",
            format!("{s}\n").into_bytes(),
        )
    }
}

async fn connection(mut stream: TcpStream, from: SocketAddr, shared: &Shared) {
    let answer = match tokio::time::timeout(READ_TIMEOUT, read_request(&mut stream)).await {
        Err(_) => Answer::text(408, "the request took too long"),
        Ok(Err(a)) => a,
        Ok(Ok(req)) => route(&req, from, shared).await,
    };
    let reason = match answer.status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        413 => "Content Too Large",
        431 => "Request Header Fields Too Large",
        _ => "Internal Server Error",
    };
    let head = format!(
        "HTTP/1.1 {} {reason}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        answer.status,
        answer.kind,
        answer.body.len()
    );
    let write = async {
        stream.write_all(head.as_bytes()).await?;
        stream.write_all(&answer.body).await?;
        stream.shutdown().await?;
        // A lingering close: what the client still sends (a refused request's rest) is
        // read and dropped, bounded, so the close does not reset the answer away.
        let mut sink = [0u8; 4096];
        let mut left: usize = 64 * 1024;
        while left > 0 {
            match tokio::time::timeout(Duration::from_secs(1), stream.read(&mut sink)).await {
                Ok(Ok(n)) if n > 0 => left = left.saturating_sub(n),
                _ => break,
            }
        }
        Ok(())
    };
    if let Ok(Err(e)) | Err(e) = tokio::time::timeout(WRITE_TIMEOUT, write)
        .await
        .map_err(std::io::Error::other)
    {
        tracing::debug!("http: {from}: {e}");
    }
}

/// Reads at least one byte of `what` into `chunk`: a failed read or an early end is
/// answered 400.
async fn read_some(stream: &mut TcpStream, chunk: &mut [u8], what: &str) -> Result<usize, Answer> {
    match stream.read(chunk).await {
        Ok(0) => Err(Answer::text(400, &format!("{what} ended early"))),
        Ok(n) => Ok(n),
        Err(_) => Err(Answer::text(400, &format!("{what} could not be read"))),
    }
}

/// Reads one request within the size limits; the error is the answer to give.
async fn read_request(stream: &mut TcpStream) -> Result<Request, Answer> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let head_end = loop {
        let end = buf.windows(4).position(|w| w == b"\r\n\r\n").map(|i| i + 4);
        if end.unwrap_or(buf.len()) > MAX_HEAD {
            return Err(Answer::text(431, "request head over 8 KiB"));
        }
        if let Some(end) = end {
            break end;
        }
        let n = read_some(stream, &mut chunk, "the request").await?;
        buf.extend_from_slice(&chunk[..n]);
    };
    let head = std::str::from_utf8(&buf[..head_end])
        .map_err(|_| Answer::text(400, "the request head is not text"))?;
    let mut lines = head.split("\r\n");
    let mut first = lines.next().unwrap_or_default().split(' ');
    let (Some(method), Some(target), Some(version)) = (first.next(), first.next(), first.next())
    else {
        return Err(Answer::text(400, "not an HTTP request line"));
    };
    if !version.starts_with("HTTP/1.") {
        return Err(Answer::text(400, "HTTP/1.x only"));
    }
    let length = lines
        .filter_map(|l| l.split_once(':'))
        .find(|(k, _)| k.trim().eq_ignore_ascii_case("content-length"))
        .map(|(_, v)| v.trim().parse::<usize>())
        .transpose()
        .map_err(|_| Answer::text(400, "Content-Length is not a number"))?
        .unwrap_or(0);
    if length > MAX_BODY {
        return Err(Answer::text(413, "request body over 1 KiB"));
    }
    // The body is read (and ignored) so closing the connection does not reset it.
    let mut have = buf.len() - head_end;
    while have < length {
        have += read_some(stream, &mut chunk, "the request body").await?;
    }
    Ok(Request {
        method: method.to_string(),
        path: target.split('?').next().unwrap_or_default().to_string(),
    })
}

async fn route(req: &Request, from: SocketAddr, shared: &Shared) -> Answer {
    let segments: Vec<&str> = req.path.split('/').filter(|s| !s.is_empty()).collect();
    match (req.method.as_str(), segments.as_slice()) {
        ("GET", []) => Answer::new(200, "text/html; charset=utf-8", PAGE.as_bytes().to_vec()),
        ("GET", ["state.json"]) => Answer::json(200, state(&shared.engine)),
        ("GET", ["live.jpg"]) => live(shared).await,
        ("GET", ["thumb", serial, file]) => match (serial.parse::<u64>(), number_jpg(file)) {
            (Ok(serial), Some(k)) => thumb(shared, serial, k).await,
            _ => Answer::text(404, "no such thumbnail"),
        },
        ("GET", ["ref", file]) => match number_jpg(file) {
            Some(id) => reference(shared, id).await,
            None => Answer::text(404, "no such reference"),
        },
        ("POST", ["pick", k]) => match k.parse::<i32>() {
            Ok(k) => pick(shared, from, k).await,
            Err(_) => Answer::text(404, "pick takes an entry number: POST /pick/3"),
        },
        ("GET" | "POST", _) => Answer::text(404, "not found"),
        _ => Answer::text(405, "GET and POST only"),
    }
}

/// `7.jpg` gives 7.
fn number_jpg<T: std::str::FromStr>(file: &str) -> Option<T> {
    file.strip_suffix(".jpg")?.parse().ok()
}

/// What the page shows, as JSON. The session is held only to copy the few values out;
/// the JSON is built after it is released.
fn state(e: &Engine) -> serde_json::Value {
    let (status, live, gallery, entry, objectives) = {
        let s = e.session();
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        for l in &s.live.levels {
            l.intensity.to_bits().hash(&mut hasher);
            l.color.map(f32::to_bits).hash(&mut hasher);
        }
        let gallery = s.gallery.as_ref().map(|g| {
            let sizes: Vec<usize> = g.generation.entries.iter().map(Vec::len).collect();
            (g.serial, g.seed, sizes)
        });
        let objectives: Vec<(u32, String, &'static str, [f32; 4])> = s
            .objectives
            .iter()
            .map(|o| {
                let r = o.objective.region;
                (
                    o.id,
                    o.objective.image.clone(),
                    o.objective.aspects.name(),
                    [r.x0, r.y0, r.x1, r.y1],
                )
            })
            .collect();
        (
            e.status_text(&s),
            hasher.finish(),
            gallery,
            s.entry.unwrap_or((0, 0)),
            objectives,
        )
    };
    let output = e.output_stats().map(|h| {
        json!({
            "fps": h.tick_rate,
            "late": h.late_ticks,
            "send_errors": h.send_errors,
            "destinations": h.destinations.iter().map(|(name, errors)| json!({
                "name": name,
                "send_errors": errors,
            })).collect::<Vec<_>>(),
        })
    });
    let console = e.console_sources().map(|sources| {
        sources
            .iter()
            .map(|s| {
                json!({
                    "name": s.name,
                    "priority": s.priority,
                    "universes": s.universes,
                    "age_s": s.age.as_secs_f32(),
                    "sampling": !s.active,
                })
            })
            .collect::<Vec<_>>()
    });
    json!({
        "scene": e.stage.scene.name,
        "aspect": e.stage.thumbs.width as f32 / e.stage.thumbs.height.max(1) as f32,
        "status": status,
        "output": output,
        "console": console,
        "generating": e.is_generating(),
        "gallery": gallery.map(|(serial, seed, sizes)| json!({
            "serial": serial,
            "seed": seed,
            "sizes": sizes,
        })),
        "entry": entry.0,
        "member": entry.1,
        "live": format!("{live:016x}"),
        "objectives": objectives.into_iter().map(|(id, image, aspects, region)| json!({
            "id": id,
            "image": image,
            "aspects": aspects,
            "region": region,
        })).collect::<Vec<_>>(),
    })
}

/// Renders and encodes off the runtime's threads.
async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> Option<T> {
    tokio::task::spawn_blocking(f).await.ok()
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

async fn thumb(shared: &Shared, serial: u64, k: usize) -> Answer {
    let mut cache = shared.thumbs.lock().await;
    let current = match cache.as_ref() {
        Some((s, pics)) if *s == serial => Arc::clone(pics),
        _ => {
            // The representatives' thumbnails were rendered with the gallery.
            let thumbs = {
                let s = shared.engine.session();
                match s.gallery.as_ref() {
                    Some(g) if g.serial == serial => Arc::clone(&g.generation.thumbnails),
                    _ => return Answer::text(404, "that gallery was replaced by a newer one"),
                }
            };
            let Some(pics) = blocking(move || {
                thumbs
                    .iter()
                    .map(|img| Arc::new(encode_jpeg(img)))
                    .collect::<Vec<_>>()
            })
            .await
            else {
                return Answer::text(500, "the encoding failed");
            };
            let pics = Arc::new(pics);
            *cache = Some((serial, Arc::clone(&pics)));
            pics
        }
    };
    match k.checked_sub(1).and_then(|i| current.get(i)) {
        Some(pic) => Answer::jpeg(Arc::clone(pic)),
        None => Answer::text(404, "no such entry"),
    }
}

async fn live(shared: &Shared) -> Answer {
    let look = shared.engine.session().live.clone();
    let mut cache = shared.live.lock().await;
    if let Some((l, pic)) = cache.as_ref()
        && *l == look
    {
        return Answer::jpeg(Arc::clone(pic));
    }
    let engine = Arc::clone(&shared.engine);
    let rendered = look.clone();
    let Some(pic) = blocking(move || {
        engine
            .stage
            .thumbnails(&[&rendered])
            .first()
            .map(encode_jpeg)
            .unwrap_or_default()
    })
    .await
    else {
        return Answer::text(500, "the render failed");
    };
    let pic = Arc::new(pic);
    *cache = Some((look, Arc::clone(&pic)));
    Answer::jpeg(pic)
}

async fn reference(shared: &Shared, id: u32) -> Answer {
    let Some(image) = shared
        .engine
        .session()
        .objectives
        .iter()
        .find(|o| o.id == id)
        .map(|o| o.objective.image.clone())
    else {
        return Answer::text(404, "no such objective");
    };
    let key = (id, image.clone());
    let mut cache = shared.refs.lock().await;
    if let Some((_, pic)) = cache.iter().find(|(k, _)| *k == key) {
        return Answer::jpeg(Arc::clone(pic));
    }
    let path = match crate::engine::resolve_reference(shared.engine.references(), &image) {
        Ok(p) => p,
        Err(e) => return Answer::text(404, &e),
    };
    let decoded = blocking(move || {
        visobjd_method::objective::decode_reference(&path).map(|img| {
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
            let pic = Arc::new(pic);
            // Objectives come and go; a few dozen pictures at most are kept.
            if cache.len() >= 32 {
                cache.remove(0);
            }
            cache.push((key, Arc::clone(&pic)));
            Answer::jpeg(pic)
        }
        Some(Err(e)) => Answer::text(404, &format!("{image} {e}")),
        None => Answer::text(500, "the reference could not be read"),
    }
}

/// `/vo/pick k` through the OSC handler, as if the browser's host had sent it.
async fn pick(shared: &Shared, from: SocketAddr, k: i32) -> Answer {
    let handler = EngineHandler(Arc::clone(&shared.engine));
    let (peer, _replies) = Peer::capture(from);
    let Some(replies) = blocking(move || {
        let pick = crate::osc::args::Request::new(msg("/vo/pick", vec![OscType::Int(k)]));
        handler.handle(pick, &peer)
    })
    .await
    else {
        return Answer::text(500, "the pick failed");
    };
    // Replies as words: "/vo/picked 2 1"; an error's sentence alone.
    let words = |m: &OscMessage| -> Vec<String> {
        m.args
            .iter()
            .map(|a| match a {
                OscType::String(s) => s.clone(),
                OscType::Int(i) => i.to_string(),
                other => format!("{other:?}"),
            })
            .collect()
    };
    match replies.first() {
        Some(m) if m.addr == "/vo/error" => {
            let sentence = words(m).get(1).cloned().unwrap_or_default();
            Answer::json(409, json!({ "error": sentence }))
        }
        Some(m) => Answer::json(
            200,
            json!({ "reply": format!("{} {}", m.addr, words(m).join(" ")) }),
        ),
        None => Answer::json(500, json!({ "error": "no reply" })),
    }
}
