//! The designer's web page (docs/web.md): an optional HTTP/1.1 server (`[http] listen`)
//! on axum, serving one self-contained page, the pictures it shows, an event stream of
//! every change, and `POST /osc`, through which every change the page makes runs the same
//! OSC command path a tablet's message does (one implementation per change).
//!
//! Access, in order: the `osc.allow` list on accept (before a byte is read); the `Host`
//! must be an address, `localhost` or a name in `[http] hosts` (a page on another site that
//! rebinds its own name to the booth's address cannot reach it); the optional password
//! (`[http] password`, HTTP Basic); and on every state change (anything but GET and HEAD)
//! the `Origin` and `Sec-Fetch-Site` a browser sends must be this page's own. GET never
//! changes anything. Bounded: 32 connections, 10 s for a request head of at most 16 KiB,
//! 4 KiB of command body, 32 MiB of upload, 60 s per request (the event stream excepted).

use std::convert::Infallible;
use std::hash::{Hash, Hasher};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Extension, Path as UrlPath, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use base64::Engine as _;
use rosc::{OscMessage, OscType};
use serde_json::{Value, json};
use tokio::net::TcpListener;
use tokio::sync::{Mutex, Semaphore};

use crate::config::{Cidr, permits};
use crate::engine::rules::Exclude;
use crate::engine::{Engine, EngineHandler};
use crate::osc::{Handler, Peer};
use visobjd_method::constrain::Saturation;
use visobjd_scene::look::Look;

/// Largest request head (request line and headers); hyper answers 431 beyond it.
const MAX_HEAD: usize = 16 * 1024;
/// Largest command body (`POST /osc`).
const MAX_COMMAND: usize = 4 * 1024;
/// Largest upload (`PUT /references/<name>`).
pub const MAX_UPLOAD: usize = 32 * 1024 * 1024;
/// Time a client has to send a request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// Time a request has to be answered (the body read included); not the event stream.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(60);
/// Connections served at once; more are closed at once.
const MAX_CONNECTIONS: usize = 32;
/// Width of the reference images on the page.
const REFERENCE_WIDTH: u32 = 320;
/// JPEG quality of every picture served.
const JPEG_QUALITY: u8 = 85;
/// Pictures kept per cache.
const CACHED: usize = 64;

const PAGE: &str = include_str!("http_page.html");

/// Who may reach the page besides the allow-list (`[http]`, docs/web.md).
#[derive(Debug, Clone, Default)]
pub struct Access {
    /// The password (HTTP Basic, any user name); `None`: none asked.
    pub password: Option<String>,
    /// Host names besides addresses and `localhost` the page may be opened by.
    pub hosts: Vec<String>,
}

/// The running server; dropping the runtime stops it.
pub struct Http {
    addr: SocketAddr,
    accept: tokio::task::JoinHandle<()>,
}

impl Http {
    /// Binds `listen` and serves in the current tokio runtime.
    pub async fn start(
        listen: &str,
        allow: Vec<Cidr>,
        access: Access,
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
            access,
            thumbs: Mutex::new(None),
            renders: Mutex::new(Vec::new()),
            files: Mutex::new(Vec::new()),
        });
        let accept = tokio::spawn(accept(listener, allow, router(shared)));
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

/// An encoded picture, shared between the caches and the answers being sent.
type Picture = Bytes;

/// Encoded pictures of one gallery's representatives, by entry.
type Thumbs = (u64, Arc<Vec<Picture>>);

struct Shared {
    engine: Arc<Engine>,
    access: Access,
    /// The current gallery's thumbnails, encoded together on the first request.
    thumbs: Mutex<Option<Thumbs>>,
    /// Rendered looks (live, members, history, saved looks, selections), newest last.
    renders: Mutex<Vec<(Look, Picture)>>,
    /// Reference images by (file name, size, modified), newest last.
    files: Mutex<Vec<(FileKey, Picture)>>,
}

type FileKey = (String, u64, Option<std::time::SystemTime>);

/// The client's address, put on each request by the accept loop.
#[derive(Clone, Copy)]
struct Client(SocketAddr);

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(|| async { page() }))
        .route("/state.json", get(state_json))
        .route("/events", get(events))
        .route("/live.jpg", get(live))
        .route("/thumb/{serial}/{file}", get(thumb))
        .route("/thumb/{serial}/{k}/{file}", get(member))
        .route("/ref/{file}", get(objective_reference))
        .route("/selected/{file}", get(selected))
        .route("/history/{file}", get(history))
        .route("/look/{file}", get(saved_look))
        .route("/references.json", get(references))
        .route(
            "/references/{name}",
            get(reference_file).merge(put(upload).layer(DefaultBodyLimit::disable())),
        )
        .route(
            "/osc",
            post(command).layer(DefaultBodyLimit::max(MAX_COMMAND)),
        )
        .fallback(|| async { refuse(StatusCode::NOT_FOUND, "not found") })
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            REQUEST_TIMEOUT,
        ))
        .layer(middleware::from_fn_with_state(Arc::clone(&shared), guard))
        .with_state(shared)
}

async fn accept(listener: TcpListener, allow: Vec<Cidr>, app: Router) {
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    loop {
        let (stream, from) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("http: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        if !permits(&allow, from.ip()) {
            tracing::info!("http: refused {from}, not in osc.allow");
            continue;
        }
        let Ok(slot) = Arc::clone(&slots).try_acquire_owned() else {
            tracing::info!("http: {from} refused, {MAX_CONNECTIONS} connections busy");
            continue;
        };
        let service = hyper_util::service::TowerToHyperService::new(
            app.clone().layer(Extension(Client(from))),
        );
        tokio::spawn(async move {
            let served = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(HEAD_TIMEOUT)
                .max_buf_size(MAX_HEAD)
                .serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                .await;
            if let Err(e) = served {
                tracing::debug!("http: {from}: {e}");
            }
            drop(slot);
        });
    }
}

/// A refusal: its status and a sentence, as `{"error": ...}`.
fn refuse(status: StatusCode, sentence: &str) -> Response {
    (status, axum::Json(json!({ "error": sentence }))).into_response()
}

fn page() -> Response {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE).into_response()
}

/// The access rules every request passes (module header), and headers every answer gets:
/// nothing cached, nothing sniffed, never framed by another page.
async fn guard(State(sh): State<Arc<Shared>>, req: Request, next: Next) -> Response {
    if let Err(refusal) = admit(&sh.access, req.method(), req.headers()) {
        let from = req.extensions().get::<Client>().map(|c| c.0);
        tracing::info!(
            "http: {} {} from {from:?} refused: {}",
            req.method(),
            req.uri().path(),
            refusal.1
        );
        let mut r = refuse(refusal.0, &refusal.1);
        if refusal.0 == StatusCode::UNAUTHORIZED {
            r.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Basic realm=\"visobjd\", charset=\"UTF-8\""),
            );
        }
        return r;
    }
    let mut r = next.run(req).await;
    let h = r.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; img-src 'self' blob:; frame-ancestors 'none'",
        ),
    );
    r
}

/// Whether a request may go on: Host, password, and for a state change its origin.
fn admit(
    access: &Access,
    method: &Method,
    headers: &HeaderMap,
) -> Result<(), (StatusCode, String)> {
    let text = |name: header::HeaderName| headers.get(name).and_then(|v| v.to_str().ok());
    let host = text(header::HOST).unwrap_or_default();
    if !host_allowed(host, &access.hosts) {
        return Err((
            StatusCode::FORBIDDEN,
            format!(
                "Host `{host}` is not this daemon: open the page by its IP address, localhost, or a name listed in [http] hosts"
            ),
        ));
    }
    if let Some(password) = &access.password {
        let given = text(header::AUTHORIZATION)
            .and_then(|v| v.strip_prefix("Basic "))
            .and_then(|b| {
                base64::engine::general_purpose::STANDARD
                    .decode(b.trim())
                    .ok()
            })
            .and_then(|raw| String::from_utf8(raw).ok());
        let ok = given
            .as_deref()
            .and_then(|up| up.split_once(':'))
            .is_some_and(|(_, p)| same(p.as_bytes(), password.as_bytes()));
        if !ok {
            return Err((
                StatusCode::UNAUTHORIZED,
                "the password is missing or wrong ([http] password)".into(),
            ));
        }
    }
    if method == Method::GET || method == Method::HEAD {
        return Ok(());
    }
    if let Some(origin) = text(header::ORIGIN)
        && !origin.eq_ignore_ascii_case(&format!("http://{host}"))
    {
        return Err((
            StatusCode::FORBIDDEN,
            format!(
                "a change from the page of `{origin}` is refused: only this daemon's own page may change the rig"
            ),
        ));
    }
    if let Some(site) = headers.get("sec-fetch-site").and_then(|v| v.to_str().ok())
        && site != "same-origin"
        && site != "none"
    {
        return Err((
            StatusCode::FORBIDDEN,
            format!("a {site} change is refused: only this daemon's own page may change the rig"),
        ));
    }
    Ok(())
}

/// A `Host` header naming an IP address, `localhost` or one of `hosts`, with any port.
fn host_allowed(host: &str, hosts: &[String]) -> bool {
    let name = match host.strip_prefix('[') {
        Some(rest) => match rest.split_once(']') {
            Some((v6, port)) if port.is_empty() || port.starts_with(':') => v6,
            _ => return false,
        },
        None => match host.rsplit_once(':') {
            Some((name, port)) if port.bytes().all(|b| b.is_ascii_digit()) => name,
            Some(_) => return false,
            None => host,
        },
    };
    !name.is_empty()
        && (name.parse::<std::net::IpAddr>().is_ok()
            || name.eq_ignore_ascii_case("localhost")
            || hosts.iter().any(|h| h.eq_ignore_ascii_case(name)))
}

/// Equal bytes, in time that does not depend on where they differ.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

async fn state_json(State(sh): State<Arc<Shared>>) -> Response {
    axum::Json(state(&sh.engine)).into_response()
}

/// A short hash of a look, so the page fetches a picture again only when it changed.
fn look_key(look: &Look) -> String {
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for l in &look.levels {
        l.intensity.to_bits().hash(&mut hasher);
        l.color.map(f32::to_bits).hash(&mut hasher);
    }
    format!("{:016x}", hasher.finish())
}

/// What the page shows, as JSON. The session is held only to build it (no I/O).
fn state(e: &Engine) -> Value {
    let scene = &e.stage.scene;
    let s = e.session();
    let (undo, redo, _) = s.history();
    let rules = &s.rules;
    let lights: Vec<Value> = scene
        .lights
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let lv = s.live.levels[i];
            let mut light = json!({
                "ch": l.channel,
                "name": l.name,
                "group": scene.groups[l.group].name,
                "colour": scene.profile(i).has_colour(),
                "intensity": lv.intensity,
                "color": lv.color,
                "lock": s.locked_lights[i],
            });
            rules_json(
                &mut light,
                None,
                rules.light_saturation[i],
                rules.light_exclude[i],
            );
            light
        })
        .collect();
    let groups: Vec<Value> = scene
        .groups
        .iter()
        .enumerate()
        .map(|(g, group)| {
            let n = group.lights.len().max(1) as f32;
            let mut row = json!({
                "name": group.name,
                "address": group.address(),
                "lights": group.lights.iter().map(|&l| scene.lights[l].channel).collect::<Vec<_>>(),
                "intensity": group.lights.iter().map(|&l| s.live.levels[l].intensity).sum::<f32>() / n,
                "key": s.key_groups[g],
                "lock": s.locked_groups[g],
                "colour": group.lights.iter().any(|&l| scene.profile(l).has_colour()),
            });
            let ratio = rules.ratios[g].map(|(a, r)| (scene.groups[a].name.as_str(), r));
            rules_json(
                &mut row,
                ratio,
                rules.group_saturation[g],
                rules.group_exclude[g],
            );
            row
        })
        .collect();
    let pins: Vec<Value> = rules
        .pins
        .iter()
        .map(|p| {
            let r = p.region;
            json!({
                "id": p.id,
                "region": [r.x0, r.y0, r.x1, r.y1],
                "lights": p.lights.iter().map(|&l| scene.lights[l].channel).collect::<Vec<_>>(),
            })
        })
        .collect();
    let objectives: Vec<Value> = s
        .objectives
        .iter()
        .map(|o| {
            let r = o.objective.region;
            let chosen = e.stage.footprints.select(r);
            json!({
                "id": o.id,
                "image": o.objective.image,
                "aspects": o.objective.aspects.name(),
                "region": [r.x0, r.y0, r.x1, r.y1],
                "palette": o.objective.analysis.palette.iter().map(|p| {
                    json!([p.color[0], p.color[1], p.color[2], p.weight])
                }).collect::<Vec<_>>(),
                "selected": scene.lights.iter().zip(&chosen)
                    .filter(|(_, on)| **on).map(|(l, _)| l.channel).collect::<Vec<_>>(),
            })
        })
        .collect();
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
    let entry = s.entry.unwrap_or((0, 0));
    json!({
        "scene": scene.name,
        "aspect": e.stage.thumbs.width as f32 / e.stage.thumbs.height.max(1) as f32,
        "status": e.status_text(&s),
        "output": output,
        "console": console,
        "generating": e.is_generating(),
        "gallery": s.gallery.as_ref().map(|g| json!({
            "serial": g.serial,
            "seed": g.seed,
            "sizes": g.generation.entries.iter().map(Vec::len).collect::<Vec<_>>(),
        })),
        "entry": entry.0,
        "member": entry.1,
        "live": look_key(&s.live),
        "fade": s.fade_s,
        "master": s.master,
        "blackout": s.blackout,
        "history": {
            "undo": undo.iter().rev().map(look_key).collect::<Vec<_>>(),
            "redo": redo.iter().rev().map(look_key).collect::<Vec<_>>(),
        },
        "looks": s.looks.iter().map(|(n, f)| json!({
            "n": n,
            "label": f.label,
            "key": f.to_look(scene).map(|l| look_key(&l)).unwrap_or_default(),
        })).collect::<Vec<_>>(),
        "lights": lights,
        "groups": groups,
        "pins": pins,
        "objectives": objectives,
    })
}

/// A setting as the designer typed it: the shortest decimal that reads back as the same
/// f32 (0.2, not 0.20000000298023224), so the page's number fields show it as typed.
fn decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(f64::from(v))
}

/// Adds a group's or a light's constraints to its row, each only when set (a scene of
/// hundreds of lights with none set adds nothing): `ratio` `[of, r]`, `saturation`
/// `[min, max]`, `exclude` (`ignore` or `off`).
fn rules_json(
    row: &mut Value,
    ratio: Option<(&str, f32)>,
    saturation: Saturation,
    exclude: Exclude,
) {
    if let Some(row) = row.as_object_mut() {
        if let Some((of, r)) = ratio {
            row.insert("ratio".into(), json!([of, decimal(r)]));
        }
        if !saturation.is_any() {
            row.insert(
                "saturation".into(),
                json!([decimal(saturation.min), decimal(saturation.max)]),
            );
        }
        if exclude != Exclude::None {
            row.insert("exclude".into(), json!(exclude.name()));
        }
    }
}

/// Every change the engine pushes to tablets, as server-sent events: one event per push,
/// its data the messages as `[{"address": ..., "args": [...]}]` (`[]` when the page fell
/// behind or the change pushes nothing to tablets: read `/state.json` again).
async fn events(State(sh): State<Arc<Shared>>) -> Response {
    let changes = sh.engine.changes();
    let stream = futures_util::stream::unfold(changes, |mut rx| async move {
        use tokio::sync::broadcast::error::RecvError;
        let data = match rx.recv().await {
            Ok(msgs) => Value::Array(msgs.iter().map(message_json).collect()),
            Err(RecvError::Lagged(_)) => json!([]),
            Err(RecvError::Closed) => return None,
        };
        Some((
            Ok::<_, Infallible>(Event::default().data(data.to_string())),
            rx,
        ))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}

/// An OSC message as JSON: `{"address": "/vo/picked", "args": [2, 1]}`.
fn message_json(m: &OscMessage) -> Value {
    let args: Vec<Value> = m
        .args
        .iter()
        .map(|a| match a {
            OscType::Int(i) => json!(i),
            OscType::Long(i) => json!(i),
            OscType::Float(f) => json!(f),
            OscType::Double(f) => json!(f),
            OscType::String(s) => json!(s),
            OscType::Bool(b) => json!(b),
            other => json!(format!("{other:?}")),
        })
        .collect();
    json!({ "address": m.addr, "args": args })
}

/// A command from the page: an OSC address under `/vo/` and its arguments.
#[derive(serde::Deserialize)]
struct Call {
    address: String,
    #[serde(default)]
    args: Vec<Value>,
}

/// Commands the page may not send (their first segment after `vo`): they set up links
/// between daemons or subscriptions to the sender's UDP port, which a browser does not
/// have. Told from the parsed address, as the handler reads it (`/vo//subscribe` is
/// `/vo/subscribe`).
const NOT_FROM_THE_PAGE: [&str; 3] = ["backup", "subscribe", "unsubscribe"];

/// `POST /osc`: runs the command through the OSC handler as if the browser's host had sent
/// it: 200 with the replies, 409 with the `/vo/error` sentence (nothing changed).
async fn command(
    State(sh): State<Arc<Shared>>,
    Extension(Client(from)): Extension<Client>,
    call: Result<axum::Json<Call>, axum::extract::rejection::JsonRejection>,
) -> Response {
    let call = match call {
        Ok(axum::Json(c)) => c,
        Err(e) => {
            return refuse(
                e.status(),
                &format!(
                    "a command is JSON {{\"address\": \"/vo/...\", \"args\": [...]}}: {}",
                    e.body_text()
                ),
            );
        }
    };
    let mut args = Vec::with_capacity(call.args.len());
    for a in &call.args {
        args.push(match a {
            Value::Number(n) => match n.as_i64().and_then(|i| i32::try_from(i).ok()) {
                Some(i) => OscType::Int(i),
                None => OscType::Float(n.as_f64().unwrap_or(f64::NAN) as f32),
            },
            Value::String(s) => OscType::String(s.clone()),
            Value::Bool(b) => OscType::Bool(*b),
            other => {
                return refuse(
                    StatusCode::BAD_REQUEST,
                    &format!(
                        "{}: an argument is a number, a string or true/false, not {other}",
                        call.address
                    ),
                );
            }
        });
    }
    let request = crate::osc::args::Request::new(OscMessage {
        addr: call.address.clone(),
        args,
    });
    let refused = match request.segments.as_slice() {
        [vo, command, ..] => vo != "vo" || NOT_FROM_THE_PAGE.contains(&command.as_str()),
        _ => true,
    };
    if refused {
        return refuse(
            StatusCode::FORBIDDEN,
            &format!("{} cannot be sent from the page", call.address),
        );
    }
    let handler = EngineHandler(Arc::clone(&sh.engine));
    let (peer, _later) = Peer::capture(from);
    let Some(replies) = blocking(move || handler.handle(request, &peer)).await else {
        return refuse(StatusCode::INTERNAL_SERVER_ERROR, "the command failed");
    };
    let listed: Vec<Value> = replies.iter().map(message_json).collect();
    match replies.iter().find(|m| m.addr == "/vo/error") {
        Some(m) => {
            let sentence = match m.args.get(1) {
                Some(OscType::String(s)) => s.clone(),
                _ => "refused".into(),
            };
            (
                StatusCode::CONFLICT,
                axum::Json(json!({ "error": sentence, "replies": listed })),
            )
                .into_response()
        }
        None => axum::Json(json!({ "replies": listed })).into_response(),
    }
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
    if let Some(pic) = cached(&sh.renders, &look).await {
        return jpeg(pic);
    }
    let engine = Arc::clone(&sh.engine);
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
        return refuse(StatusCode::INTERNAL_SERVER_ERROR, "the render failed");
    };
    let pic = Bytes::from(pic);
    keep(&mut *sh.renders.lock().await, look, &pic);
    jpeg(pic)
}

async fn live(State(sh): State<Arc<Shared>>) -> Response {
    let look = sh.engine.session().live.clone();
    render(&sh, look).await
}

async fn thumb(
    State(sh): State<Arc<Shared>>,
    UrlPath((serial, file)): UrlPath<(String, String)>,
) -> Response {
    let (Ok(serial), Some(k)) = (serial.parse::<u64>(), number_jpg::<usize>(&file)) else {
        return refuse(StatusCode::NOT_FOUND, "no such thumbnail");
    };
    let mut cache = sh.thumbs.lock().await;
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
async fn member(
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
        crate::engine::gallery_look(&s, k, m)
    };
    match look {
        Ok(look) => render(&sh, look).await,
        Err(e) => refuse(StatusCode::NOT_FOUND, &e),
    }
}

/// Undo step i (`u1.jpg`: one step back) or redo step i (`r1.jpg`).
async fn history(State(sh): State<Arc<Shared>>, UrlPath(file): UrlPath<String>) -> Response {
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
async fn saved_look(State(sh): State<Arc<Shared>>, UrlPath(file): UrlPath<String>) -> Response {
    let Some(n) = number_jpg::<u32>(&file) else {
        return refuse(StatusCode::NOT_FOUND, "no such look");
    };
    let look = {
        let s = sh.engine.session();
        s.looks.get(&n).map(|f| f.to_look(&sh.engine.stage.scene))
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
async fn selected(State(sh): State<Arc<Shared>>, UrlPath(file): UrlPath<String>) -> Response {
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
    let chosen = sh.engine.stage.footprints.select(region);
    let mut look = Look::off(chosen.len());
    for (level, on) in look.levels.iter_mut().zip(chosen) {
        if on {
            level.intensity = 1.0;
        }
    }
    render(&sh, look).await
}

/// The image files of the references folder, by name.
async fn references(State(sh): State<Arc<Shared>>) -> Response {
    match sh.engine.reference_names() {
        Ok(names) => axum::Json(json!({ "references": names })).into_response(),
        Err(e) => refuse(StatusCode::INTERNAL_SERVER_ERROR, &e),
    }
}

/// Objective id's reference image, at most [`REFERENCE_WIDTH`] wide.
async fn objective_reference(
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

async fn reference_file(State(sh): State<Arc<Shared>>, UrlPath(name): UrlPath<String>) -> Response {
    reference_picture(&sh, name).await
}

/// A reference image by name, checked and decoded as an objective's is, at most
/// [`REFERENCE_WIDTH`] wide; cached while the file keeps its size and time.
async fn reference_picture(sh: &Shared, name: String) -> Response {
    let path = match crate::engine::resolve_reference(sh.engine.references(), &name) {
        Ok(p) => p,
        Err(e) => return refuse(StatusCode::NOT_FOUND, &e),
    };
    // Not the runtime's thread's time: the file system may be slow.
    let meta = tokio::fs::metadata(&path).await.ok();
    let key: FileKey = (
        name.clone(),
        meta.as_ref().map_or(0, std::fs::Metadata::len),
        meta.and_then(|m| m.modified().ok()),
    );
    if let Some(pic) = cached(&sh.files, &key).await {
        return jpeg(pic);
    }
    let engine = Arc::clone(&sh.engine);
    let decoded = blocking(move || {
        engine.decode_reference(&path).map(|img| {
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
            keep(&mut *sh.files.lock().await, key, &pic);
            jpeg(pic)
        }
        Some(Err(e)) => refuse(StatusCode::NOT_FOUND, &format!("{name} {e}")),
        None => refuse(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the reference could not be read",
        ),
    }
}

/// `PUT /references/<name>`: a new reference image, checked as every reference is and
/// stored atomically; never replaces one (objectives may be using it).
async fn upload(
    State(sh): State<Arc<Shared>>,
    UrlPath(name): UrlPath<String>,
    req: Request,
) -> Response {
    let too_big = || {
        let sentence = format!(
            "upload `{name}`: an upload is at most {} MiB",
            MAX_UPLOAD >> 20
        );
        tracing::info!("http: {sentence}");
        refuse(StatusCode::PAYLOAD_TOO_LARGE, &sentence)
    };
    // A declared length over the limit is refused before a byte of it is read.
    let declared = req
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    if declared.is_some_and(|n| n > MAX_UPLOAD as u64) {
        return too_big();
    }
    let bytes = match axum::body::to_bytes(req.into_body(), MAX_UPLOAD).await {
        Ok(b) => b,
        Err(_) if declared.is_none() => return too_big(),
        Err(e) => {
            let sentence = format!("upload `{name}`: the upload could not be read: {e}");
            tracing::info!("http: {sentence}");
            return refuse(StatusCode::BAD_REQUEST, &sentence);
        }
    };
    let engine = Arc::clone(&sh.engine);
    let stored = blocking(move || engine.store_reference(&name, &bytes)).await;
    match stored {
        Some(Ok(name)) => {
            (StatusCode::CREATED, axum::Json(json!({ "stored": name }))).into_response()
        }
        Some(Err((exists, e))) => {
            tracing::info!("http: upload refused: {e}");
            let status = if exists {
                StatusCode::CONFLICT
            } else {
                StatusCode::BAD_REQUEST
            };
            refuse(status, &e)
        }
        None => refuse(StatusCode::INTERNAL_SERVER_ERROR, "the upload failed"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_are_addresses_localhost_or_listed() {
        let listed = vec!["booth.local".to_string()];
        for ok in [
            "127.0.0.1:8080",
            "10.0.0.5",
            "[::1]:8080",
            "[fe80::1]",
            "localhost:80",
            "LOCALHOST",
            "booth.local:8080",
        ] {
            assert!(host_allowed(ok, &listed), "{ok}");
        }
        for bad in [
            "",
            "evil.example",
            "evil.example:8080",
            "127.0.0.1.evil.example",
            "[::1",
            "[::1]x",
            "localhost:http",
            ":8080",
        ] {
            assert!(!host_allowed(bad, &listed), "{bad}");
        }
    }

    #[test]
    fn state_changes_need_their_own_origin_and_the_password() {
        let access = Access {
            password: Some("stage left".into()),
            hosts: Vec::new(),
        };
        let headers = |pairs: &[(&'static str, &str)]| {
            let mut h = HeaderMap::new();
            for (k, v) in pairs {
                h.insert(*k, HeaderValue::from_str(v).unwrap());
            }
            h
        };
        let auth = format!(
            "Basic {}",
            base64::engine::general_purpose::STANDARD.encode("any:stage left")
        );
        let good = [("host", "127.0.0.1:8080"), ("authorization", auth.as_str())];
        assert!(admit(&access, &Method::POST, &headers(&good)).is_ok());
        let same = [
            good[0],
            good[1],
            ("origin", "http://127.0.0.1:8080"),
            ("sec-fetch-site", "same-origin"),
        ];
        assert!(admit(&access, &Method::POST, &headers(&same)).is_ok());
        let evil = [good[0], good[1], ("origin", "http://evil.example")];
        assert_eq!(
            admit(&access, &Method::POST, &headers(&evil))
                .unwrap_err()
                .0,
            StatusCode::FORBIDDEN
        );
        // A GET is not a change: another origin may load a picture.
        assert!(admit(&access, &Method::GET, &headers(&evil)).is_ok());
        let cross = [good[0], good[1], ("sec-fetch-site", "cross-site")];
        assert!(admit(&access, &Method::PUT, &headers(&cross)).is_err());
        let wrong = format!(
            "Basic {}",
            base64::engine::general_purpose::STANDARD.encode("any:stage right")
        );
        for auth in ["", "Basic", "Basic !!", wrong.as_str()] {
            let h = headers(&[good[0], ("authorization", auth)]);
            assert_eq!(
                admit(&access, &Method::GET, &h).unwrap_err().0,
                StatusCode::UNAUTHORIZED,
                "{auth}"
            );
        }
        let rebound = [("host", "evil.example:8080"), good[1]];
        assert_eq!(
            admit(&access, &Method::GET, &headers(&rebound))
                .unwrap_err()
                .0,
            StatusCode::FORBIDDEN
        );
    }
}
