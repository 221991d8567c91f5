//! The page's link to the commands and to the changes: `POST /osc` runs a command through
//! the same [`crate::cmd::Runner`] a tablet's message takes, and `GET /events` streams every
//! batch the engine pushes to tablets.

use std::convert::Infallible;
use std::sync::Arc;

use axum::extract::{Extension, State};
use axum::http::StatusCode;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use rosc::{OscMessage, OscType};
use serde_json::{Value, json};

use super::{Client, Connection, Shared, blocking, refuse, status};
use crate::osc::Peer;
use crate::osc::args::Request;

/// Every change the engine pushes to tablets, as server-sent events: one event per push,
/// its data the messages as `[{"address": ..., "args": [...]}]` (`[]` when the page fell
/// behind or the change pushes nothing to tablets: read `/state.json` again). The
/// connection counts as a stream while it runs: its host's fifth closes its oldest
/// (`super::STREAMS_PER_HOST`; the browser opens a closed one again).
pub(super) async fn events(
    State(sh): State<Arc<Shared>>,
    Extension(Connection(slot)): Extension<Connection>,
) -> Response {
    let changes = sh.engine.changes();
    let streaming = slot.stream(std::time::Instant::now());
    let stream =
        futures_util::stream::unfold((changes, streaming), |(mut rx, streaming)| async move {
            use tokio::sync::broadcast::error::RecvError;
            let data = match rx.recv().await {
                Ok(msgs) => Value::Array(msgs.iter().map(message_json).collect()),
                Err(RecvError::Lagged(_)) => json!([]),
                Err(RecvError::Closed) => return None,
            };
            Some((
                Ok::<_, Infallible>(Event::default().data(data.to_string())),
                (rx, streaming),
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
pub(super) struct Call {
    address: String,
    #[serde(default)]
    args: Vec<Value>,
}

/// Commands the page may not send (their first segment after `vo`): they set up links
/// between daemons or subscriptions to the sender's UDP port, which a browser does not
/// have. Told from the parsed address, as the handler reads it (`/vo//subscribe` is
/// `/vo/subscribe`).
const NOT_FROM_THE_PAGE: [&str; 3] = ["backup", "subscribe", "unsubscribe"];

/// `POST /osc`: runs the command as if the browser's host had sent it over OSC: 200 with the
/// replies, or the refusal's sentence with its status (400 a wrong message, 409 not now,
/// 500 an internal failure; nothing changed).
pub(super) async fn command(
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
    let request = Request::new(OscMessage {
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
    let runner = sh.runner.clone();
    let (peer, _later) = Peer::capture(from);
    let Some(ran) = blocking(move || runner.run(&request, &peer)).await else {
        return refuse(StatusCode::INTERNAL_SERVER_ERROR, "the command failed");
    };
    match ran {
        Ok(replies) => {
            let listed: Vec<Value> = replies.iter().map(message_json).collect();
            axum::Json(json!({ "replies": listed })).into_response()
        }
        Err(refusal) => {
            tracing::info!("http: {} from {from}: {refusal}", call.address);
            refuse(status(refusal.kind), &refusal.sentence)
        }
    }
}
