//! The designer's web page (docs/web.md): an optional HTTP/1.1 server (`[http] listen`)
//! on axum, serving one self-contained page, the pictures it shows, an event stream of
//! every change, and `POST /osc`, through which every change the page makes runs the same
//! command path a tablet's message does (`crate::cmd::Runner`: one implementation per
//! change). Reads (the page's state, pictures) go to the engine directly; nothing here
//! changes the session but through the commands.
//!
//! By concern: this file (start, routes, the accept loop); `access` (who may reach it);
//! `view` (the page's state as JSON); `pictures` (renders, thumbnails, reference images and
//! their caches); `upload` (the references folder: list and upload); `bridge` (`POST /osc`
//! and the event stream).
//!
//! Bounded: 32 connections, shared out by host (`crate::slots`: at most 8 from one host,
//! every loopback address counting as one, of which at most 4 event streams; when all are
//! taken, a newcomer takes the slot of the oldest idle connection, or else the oldest event
//! stream, of the host with the most), 10 s for a request head of at most 16 KiB, 4 KiB of
//! command body, 32 MiB of upload, 60 s per request (the event stream excepted).

mod access;
mod bridge;
mod pictures;
mod upload;
mod view;

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{DefaultBodyLimit, Extension};
use axum::http::{StatusCode, header};
use axum::middleware;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use serde_json::json;
use tokio::net::TcpListener;

use crate::cmd::Runner;
use crate::config::permits;
use crate::engine::{Engine, RefusalKind};
use crate::slots::{self, Slot, Slots};

/// Largest request head (request line and headers); hyper answers 431 beyond it.
const MAX_HEAD: usize = 16 * 1024;
/// Largest command body (`POST /osc`).
const MAX_COMMAND: usize = 4 * 1024;
/// Time a client has to send a request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// Time a request has to be answered (the body read included); not the event stream.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(60);
/// Connections served at once, all hosts together.
const MAX_CONNECTIONS: usize = 32;
/// Connections one host may have open (a browser opens up to 6).
const PER_HOST: usize = 8;
/// Event streams one host may have open (a page each); a further one closes its oldest.
const STREAMS_PER_HOST: usize = 4;

const PAGE: &str = include_str!("page.html");

/// The running server; dropping the runtime stops it.
pub struct Http {
    addr: SocketAddr,
    accept: tokio::task::JoinHandle<()>,
}

impl Http {
    /// Binds `listen` (`http.listen`), before the daemon's first DMX frame.
    pub fn bind(listen: &str) -> Result<std::net::TcpListener, String> {
        std::net::TcpListener::bind(listen)
            .and_then(|l| l.set_nonblocking(true).map(|()| l))
            .map_err(|e| format!("http.listen {listen}: cannot listen there: {e}"))
    }

    /// Serves `listener` (from [`Http::bind`]) in the current tokio runtime: reads from
    /// `engine`, changes through `runner`.
    pub fn start(
        listener: std::net::TcpListener,
        engine: Arc<Engine>,
        runner: Runner,
    ) -> Result<Http, String> {
        let addr = listener
            .local_addr()
            .map_err(|e| format!("http.listen: {e}"))?;
        let listener =
            TcpListener::from_std(listener).map_err(|e| format!("http.listen {addr}: {e}"))?;
        let shared = Arc::new(Shared {
            engine: Arc::clone(&engine),
            runner,
            pictures: pictures::Caches::default(),
            guesses: access::Guesses::default(),
        });
        let accept = tokio::spawn(accept(listener, engine, router(shared)));
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

/// What every request's handler is given.
struct Shared {
    engine: Arc<Engine>,
    runner: Runner,
    pictures: pictures::Caches,
    guesses: access::Guesses,
}

/// The client's address, put on each request by the accept loop.
#[derive(Clone, Copy)]
struct Client(SocketAddr);

/// The connection's slot, put on each request by the accept loop: the event stream marks
/// it a stream.
#[derive(Clone)]
struct Connection(Arc<Slot>);

/// The host a client's connections count towards: its address, every loopback address
/// being one host.
fn host_of(ip: IpAddr) -> IpAddr {
    let ip = ip.to_canonical();
    if ip.is_loopback() {
        IpAddr::V4(Ipv4Addr::LOCALHOST)
    } else {
        ip
    }
}

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(|| async { page() }))
        .route("/state.json", get(view::state_json))
        .route("/events", get(bridge::events))
        .route("/live.jpg", get(pictures::live))
        .route("/thumb/{serial}/{file}", get(pictures::thumb))
        .route("/thumb/{serial}/{k}/{file}", get(pictures::member))
        .route("/ref/{file}", get(pictures::objective_reference))
        .route("/selected/{file}", get(pictures::selected))
        .route("/history/{file}", get(pictures::history))
        .route("/look/{file}", get(pictures::saved_look))
        .route("/references.json", get(upload::references))
        .route(
            "/references/{name}",
            get(pictures::reference_file)
                .merge(put(upload::upload).layer(DefaultBodyLimit::disable())),
        )
        .route(
            "/osc",
            post(bridge::command).layer(DefaultBodyLimit::max(MAX_COMMAND)),
        )
        .fallback(|| async { refuse(StatusCode::NOT_FOUND, "not found") })
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            REQUEST_TIMEOUT,
        ))
        .layer(middleware::from_fn_with_state(
            Arc::clone(&shared),
            access::guard,
        ))
        .with_state(shared)
}

/// Takes connections from senders `osc.allow` permits (as the running config says now).
async fn accept(listener: TcpListener, engine: Arc<Engine>, app: Router) {
    let slots = Slots::new(slots::Limits {
        total: MAX_CONNECTIONS,
        per_host: PER_HOST,
        streams_per_host: STREAMS_PER_HOST,
    });
    // Refusals are logged at most every 10 s, with the count left out: a flood of
    // connections from outside must not flood the journal.
    let mut refused = visobjd_throttle::Throttle::default();
    let mut busy = visobjd_throttle::Throttle::default();
    let mut made_room = visobjd_throttle::Throttle::default();
    loop {
        let (stream, from) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                tracing::warn!("http: accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        if !permits(&engine.config().allow_list(), from.ip()) {
            if let Some(suppressed) = refused.allow(std::time::Instant::now()) {
                tracing::info!(suppressed, "http: refused {from}, not in osc.allow");
            }
            continue;
        }
        let slot = match slots.admit(host_of(from.ip()), false, std::time::Instant::now()) {
            Ok(admitted) => {
                if let Some(gave) = admitted.made_room
                    && let Some(suppressed) = made_room.allow(std::time::Instant::now())
                {
                    tracing::info!(
                        suppressed,
                        "http: closed the oldest idle connection or event stream of {gave} to make room for {from}"
                    );
                }
                admitted.slot
            }
            Err(why) => {
                if let Some(suppressed) = busy.allow(std::time::Instant::now()) {
                    tracing::info!(suppressed, "http: {from} refused: {why}");
                }
                continue;
            }
        };
        let service = hyper_util::service::TowerToHyperService::new(
            app.clone()
                .layer(Extension(Client(from)))
                .layer(Extension(Connection(Arc::clone(&slot)))),
        );
        // Each request marks the connection busy until it is answered: a connection in a
        // request is never closed for another host's.
        let counted = {
            let slot = Arc::clone(&slot);
            hyper::service::service_fn(move |req| {
                let busy = slot.busy();
                let answer = hyper::service::Service::call(&service, req);
                async move {
                    let answer = answer.await;
                    drop(busy);
                    answer
                }
            })
        };
        tokio::spawn(async move {
            let served = hyper::server::conn::http1::Builder::new()
                .timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(HEAD_TIMEOUT)
                .max_buf_size(MAX_HEAD)
                .serve_connection(hyper_util::rt::TokioIo::new(stream), counted);
            tokio::select! {
                served = served => {
                    if let Err(e) = served {
                        tracing::debug!("http: {from}: {e}");
                    }
                }
                () = slot.closed() => {
                    tracing::debug!("http: {from}: closed, its slot went to another connection");
                }
            }
            drop(slot);
        });
    }
}

/// A refusal: its status and a sentence, as `{"error": ...}`.
fn refuse(status: StatusCode, sentence: &str) -> Response {
    (status, axum::Json(json!({ "error": sentence }))).into_response()
}

/// The status a refused command or upload is answered with: 400 for a wrong message, 409
/// when the state does not allow it, 500 when something inside failed (docs/web.md).
fn status(kind: RefusalKind) -> StatusCode {
    match kind {
        RefusalKind::Input => StatusCode::BAD_REQUEST,
        RefusalKind::Conflict => StatusCode::CONFLICT,
        RefusalKind::Internal => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

fn page() -> Response {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE).into_response()
}

/// Renders and encodes off the runtime's threads.
async fn blocking<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> Option<T> {
    tokio::task::spawn_blocking(f).await.ok()
}
