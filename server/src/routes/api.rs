//! The REST API under `/api/v1`: the JSON twin of every page, and submission upload.

use std::str::FromStr;

use axum::extract::multipart::MultipartRejection;
use axum::extract::{DefaultBodyLimit, Multipart, Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use axum::middleware::from_fn;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use evaluator::protocol::ProtocolName;
use serde_json::json;

use crate::app::{App, AppState};
use crate::auth::Viewer;
use crate::board_cache::Format;
use crate::error::{AppError, AppResult};
use crate::routes::boards;
use crate::routes::deadlines;
use crate::routes::submissions::read_upload;
use crate::submissions::{Accepted, submit};
use crate::views;

pub fn router(max_upload: u64) -> Router<AppState> {
    Router::new()
        .route("/api/v1/datasets", get(datasets))
        .route("/api/v1/methods", get(methods))
        .route("/api/v1/methods/{id}", get(method))
        .route(
            "/api/v1/submissions",
            get(recent_submissions).merge(
                post(create_submission)
                    .layer(DefaultBodyLimit::max(max_upload as usize + 64 * 1024))
                    .layer(from_fn(deadlines::by_progress)),
            ),
        )
        .route("/api/v1/submissions/{id}", get(submission))
        .route("/api/v1/leaderboards/{protocol}", get(leaderboard))
        .route("/api/v1/openapi.json", get(openapi))
}

async fn datasets(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(json!({ "datasets": app.store.datasets().await? })))
}

async fn methods(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(
        json!({ "methods": app.store.public_methods().await? }),
    ))
}

async fn method(
    State(app): State<AppState>,
    Path(id): Path<i64>,
) -> AppResult<Json<serde_json::Value>> {
    let submissions = app.store.public_submissions_of_method(id).await?;
    let method = app.store.method(id).await?.ok_or(AppError::NotFound)?;
    if submissions.is_empty() {
        // A method with only private submissions is not public.
        return Err(AppError::NotFound);
    }
    Ok(Json(
        json!({ "method": method, "submissions": submissions }),
    ))
}

async fn recent_submissions(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(
        json!({ "submissions": app.store.recent_public_submissions(100).await? }),
    ))
}

async fn create_submission(
    State(app): State<AppState>,
    viewer: Viewer,
    multipart: Result<Multipart, MultipartRejection>,
) -> AppResult<Response> {
    // Refused before a byte of the body is read.
    let owner = viewer.require_user()?.clone();
    // Credentials are checked before the body is looked at, even a malformed one.
    let multipart = multipart.map_err(|e| AppError::BadRequest(e.body_text()))?;
    let (fields, files) = read_upload(&app, multipart, app.config.max_upload_bytes()).await?;
    let accepted = submit(&app, &owner, fields.parse(files)?).await?;
    // 200 only when every file had been submitted before.
    let status = if accepted.iter().all(|a| a.duplicate) {
        StatusCode::OK
    } else {
        StatusCode::ACCEPTED
    };
    let entries: Vec<serde_json::Value> = accepted.iter().map(entry).collect();
    // One file: its submission at the top level, as before several files were taken.
    let mut body = match entries.as_slice() {
        [one] => one.clone(),
        _ => json!({}),
    };
    body["submissions"] = json!(entries);
    Ok((status, Json(body)).into_response())
}

fn entry(a: &Accepted) -> serde_json::Value {
    json!({
        "id": a.submission.id,
        "duplicate": a.duplicate,
        "submission": a.submission,
        "preflight": a.preflight,
        "url": format!("/submissions/{}", a.submission.id),
    })
}

async fn submission(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<i64>,
) -> AppResult<Json<views::SubmissionView>> {
    Ok(Json(views::submission(&app, id, &viewer).await?))
}

/// The same for every reader, like its page: served from the board cache.
async fn leaderboard(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(protocol): Path<String>,
    Query(filter): Query<views::BoardFilter>,
) -> AppResult<Response> {
    let protocol = ProtocolName::from_str(&protocol).map_err(|_| AppError::NotFound)?;
    let key = boards::key(Format::Json, protocol, &filter);
    boards::answer(&app, &headers, key, || {
        leaderboard_json(&app, protocol, &filter)
    })
    .await
}

/// A board's JSON as it stands: served live, and kept by snapshots.
pub(crate) async fn leaderboard_json(
    app: &App,
    protocol: ProtocolName,
    filter: &views::BoardFilter,
) -> AppResult<Vec<u8>> {
    let board = views::leaderboard(app, protocol, filter).await?;
    serde_json::to_vec(&board).map_err(|e| AppError::Internal(format!("leaderboard JSON: {e}")))
}

/// The OpenAPI description of this API, written by hand: it is small, and a generator would
/// need every handler annotated twice.
async fn openapi() -> Json<serde_json::Value> {
    Json(crate::openapi::document())
}
