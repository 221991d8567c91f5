//! The references folder from the page: its list (`GET /references.json`) and uploads
//! (`PUT /references/<name>`), checked and stored by the engine as every reference is.

use std::sync::Arc;

use axum::extract::{Path as UrlPath, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde_json::json;

use super::{Shared, blocking, refuse, status};

/// Largest upload (`PUT /references/<name>`).
const MAX_UPLOAD: usize = 32 * 1024 * 1024;

/// The image files of the references folder, by name.
pub(super) async fn references(State(sh): State<Arc<Shared>>) -> Response {
    match sh.engine.reference_names() {
        Ok(names) => axum::Json(json!({ "references": names })).into_response(),
        Err(e) => refuse(status(e.kind), &e.sentence),
    }
}

/// `PUT /references/<name>`: a new reference image, checked as every reference is and
/// stored atomically; never replaces one (objectives may be using it).
pub(super) async fn upload(
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
        Some(Err(e)) => {
            tracing::info!("http: upload refused: {e}");
            refuse(status(e.kind), &e.sentence)
        }
        None => refuse(StatusCode::INTERNAL_SERVER_ERROR, "the upload failed"),
    }
}
