//! The REST API under `/api/v1`: the JSON twin of every page, and submission upload.

use std::str::FromStr;

use axum::extract::multipart::MultipartRejection;
use axum::extract::{DefaultBodyLimit, Form, FromRequest, Multipart, Path, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::from_fn;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use evaluator::protocol::ProtocolName;
use serde::Deserialize;
use serde_json::json;

use crate::app::{App, AppState};
use crate::board_cache::Format;
use crate::domain::{BoardProtocol, MethodForm, MethodId, SubmissionId, Task, Visibility};
use crate::error::{AppError, AppResult};
use crate::service::submissions::{Accepted, quota, submit};
use crate::service::{catalogue, downloads, groups, methods, publishing};
use crate::store::accounts::User;
use crate::web::auth::Viewer;
use crate::web::render::overlay::{self, TargetId};
use crate::web::routes::deadlines;
use crate::web::routes::submissions::{field_text, multipart_error, parse_fields, read_upload};
use crate::web::routes::{boards, recent};
use crate::web::views;

pub fn router(max_upload: u64) -> Router<AppState> {
    Router::new()
        .route("/api/v1/datasets", get(datasets))
        .route("/api/v1/groups", get(dataset_groups))
        .route("/api/v1/methods", get(methods))
        .route("/api/v1/methods/{id}", get(method).post(edit_method))
        .route("/api/v1/methods/{id}/reveal", post(reveal_method))
        .route(
            "/api/v1/submissions",
            get(recent::json).merge(
                post(create_submission)
                    .layer(DefaultBodyLimit::max(max_upload as usize + 64 * 1024))
                    .layer(from_fn(deadlines::by_progress)),
            ),
        )
        .route("/api/v1/submissions/{id}/pin", post(pin))
        .route("/api/v1/submissions/{id}/unpin", post(unpin))
        .route(
            "/api/v1/submissions/{id}",
            get(submission).delete(delete_submission),
        )
        .route("/api/v1/submissions/{id}/visibility", post(visibility))
        .route("/api/v1/submissions/{id}/file", get(file))
        .route("/api/v1/submissions/{id}/report", get(report))
        .route("/api/v1/submissions/{id}/errors/{protocol}", get(errors))
        .route(
            "/api/v1/submissions/{id}/targets/{scene}/{im}/{picture}",
            get(target_picture),
        )
        .route("/api/v1/me/submissions", get(my_submissions))
        .route("/api/v1/me/quota", get(my_quota))
        .route("/api/v1/leaderboards/{protocol}", get(leaderboard))
        .route("/api/v1/openapi.json", get(openapi))
}

async fn datasets(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(
        json!({ "datasets": catalogue::datasets(&app).await? }),
    ))
}

async fn dataset_groups(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(json!({ "groups": groups::all(&app).await? })))
}

async fn methods(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(
        json!({ "methods": catalogue::public_methods(&app).await? }),
    ))
}

async fn method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
) -> AppResult<Json<serde_json::Value>> {
    let home = methods::home(&app, id, viewer.user.as_ref()).await?;
    Ok(Json(json!({
        "method": home.method,
        "standings": home.standings,
        "submissions": home.submissions,
    })))
}

/// The owner (or an administrator) states the method's details; fields left out stay.
async fn edit_method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
    Json(form): Json<MethodForm>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?;
    let method = methods::edit(&app, user, id, form).await?;
    Ok(Json(json!({ "method": method })))
}

/// The end of a method's double-blind review: the owner is named again everywhere live.
async fn reveal_method(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<MethodId>,
) -> AppResult<Json<serde_json::Value>> {
    let method = methods::reveal(&app, viewer.require_user()?, id).await?;
    Ok(Json(json!({ "method": method })))
}

async fn pin(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<Json<serde_json::Value>> {
    methods::pin(&app, viewer.require_user()?, id, true).await?;
    Ok(Json(
        json!({ "ok": true, "submission": id, "pinned": true }),
    ))
}

async fn unpin(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<Json<serde_json::Value>> {
    methods::pin(&app, viewer.require_user()?, id, false).await?;
    Ok(Json(
        json!({ "ok": true, "submission": id, "pinned": false }),
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
    let accepted = submit(&app, &owner, parse_fields(&fields, files)?).await?;
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
    Path(id): Path<SubmissionId>,
) -> AppResult<Json<views::SubmissionView>> {
    Ok(Json(views::submission(&app, id, &viewer).await?))
}

/// A change of visibility, as a form (`visibility=public&confirm=true`) or as JSON.
#[derive(Deserialize)]
pub struct VisibilityChange {
    pub visibility: String,
    /// Publish despite red flags.
    #[serde(default)]
    pub confirm: bool,
}

/// The body of a small request, as JSON when it says so, else as a form.
async fn form_or_json<T: serde::de::DeserializeOwned + 'static>(request: Request) -> AppResult<T> {
    let json = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if json {
        let Json(t) = Json::<T>::from_request(request, &())
            .await
            .map_err(|e| AppError::BadRequest(e.body_text()))?;
        Ok(t)
    } else {
        let Form(t) = Form::<T>::from_request(request, &())
            .await
            .map_err(|e| AppError::BadRequest(e.body_text()))?;
        Ok(t)
    }
}

/// A change of visibility as JSON, a plain form, or the multipart form the upload takes (a
/// script that uploads with `curl -F` publishes with `curl -F` too).
async fn visibility_change(request: Request) -> AppResult<VisibilityChange> {
    let multipart = request
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("multipart/form-data"));
    if !multipart {
        return form_or_json(request).await;
    }
    let mut form = Multipart::from_request(request, &())
        .await
        .map_err(|e| AppError::BadRequest(e.body_text()))?;
    let (mut visibility, mut confirm) = (None, false);
    while let Some(field) = form.next_field().await.map_err(multipart_error)? {
        let name = field.name().unwrap_or_default().to_string();
        let value = field_text(field).await?;
        match name.as_str() {
            "visibility" => visibility = Some(value),
            "confirm" => {
                confirm = value.trim().parse::<bool>().map_err(|_| {
                    AppError::BadRequest(format!("field `confirm` is true or false, not `{value}`"))
                })?;
            }
            _ => {}
        }
    }
    let visibility = visibility.ok_or_else(|| {
        AppError::BadRequest("field `visibility` (public or private) is required".into())
    })?;
    Ok(VisibilityChange {
        visibility,
        confirm,
    })
}

async fn visibility(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
    request: Request,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?.clone();
    let change = visibility_change(request).await?;
    let asked = change.visibility.trim().parse::<Visibility>()?;
    let s = publishing::set_visibility(&app, &user, id, asked, change.confirm).await?;
    Ok(Json(json!({
        "id": s.id,
        "visibility": s.visibility,
        "held": s.held,
        "publication": publishing::state(&s),
    })))
}

async fn delete_submission(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<Json<serde_json::Value>> {
    let user = viewer.require_user()?.clone();
    publishing::delete(&app, &user, id).await?;
    Ok(Json(json!({ "ok": true, "deleted": id })))
}

/// The owner (or an administrator); everyone else is told there is nothing here.
fn owner_or_missing(viewer: &Viewer) -> AppResult<&User> {
    viewer.user.as_ref().ok_or(AppError::NotFound)
}

/// The uploaded file, as it was sent: for its owner only.
async fn file(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<Response> {
    let (s, bytes) = downloads::file(&app, owner_or_missing(&viewer)?, id).await?;
    let content_type = match s.task {
        Some(Task::Coco(_)) => "application/json",
        Some(Task::Bop24) | None => "text/csv; charset=utf-8",
    };
    Ok(attachment(content_type, &s.file_name, bytes))
}

/// The reports (one per protocol, as `poseboard eval --out` writes them): for whoever may see
/// the submission.
async fn report(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(id): Path<SubmissionId>,
) -> AppResult<Response> {
    let view = views::submission(&app, id, &viewer).await?;
    // Keyed by protocol: the 6D reports, or the task's one.
    let body = match (&view.coco, &view.bop24, view.submission.task) {
        (Some(report), _, Some(task)) => serde_json::to_vec(&json!({ task.as_str(): report })),
        (_, Some(report), Some(task)) => serde_json::to_vec(&json!({ task.as_str(): report })),
        _ => serde_json::to_vec(&view.scores),
    }
    .map_err(|e| AppError::failed("writing the report JSON", e))?;
    Ok(attachment(
        "application/json",
        &format!("submission-{id}-report.json"),
        body,
    ))
}

/// Every evaluated estimate's errors under one protocol (the layout of `poseboard eval
/// --errors-out`): for its owner only.
async fn errors(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, protocol)): Path<(SubmissionId, String)>,
) -> AppResult<Response> {
    let user = owner_or_missing(&viewer)?;
    let protocol = ProtocolName::from_str(&protocol).map_err(|_| AppError::NotFound)?;
    let json = downloads::errors(&app, user, id, protocol).await?;
    Ok(attachment(
        "application/json",
        &format!("submission-{id}-{}-errors.json", protocol.as_str()),
        json,
    ))
}

/// Which protocol's n_top decides the estimates a target picture shows.
#[derive(Deserialize)]
struct PictureQuery {
    protocol: Option<String>,
    /// `object`: the picture cut to the object, for a gallery.
    crop: Option<String>,
}

/// A target seen through a submission, as `{obj_id}.png` (the router cannot match a segment
/// that only starts with a parameter): for whoever may see the submission.
async fn target_picture(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, scene_id, im_id, picture)): Path<(SubmissionId, u32, u32, String)>,
    Query(q): Query<PictureQuery>,
) -> AppResult<Response> {
    let obj_id = picture
        .strip_suffix(".png")
        .and_then(|o| o.parse::<u32>().ok())
        .ok_or(AppError::NotFound)?;
    let protocol = q
        .protocol
        .map(|p| ProtocolName::from_str(&p).map_err(|_| AppError::NotFound))
        .transpose()?;
    let thumbnail = match q.crop.as_deref() {
        None => false,
        Some("object") => true,
        Some(other) => {
            return Err(AppError::BadRequest(format!(
                "`crop` is `{other}`: the only crop is `object` (the picture cut to the object)"
            )));
        }
    };
    let target = TargetId {
        scene_id,
        im_id,
        obj_id,
    };
    let png = overlay::target_png(&app, &viewer, id, target, protocol, thumbnail).await?;
    Ok((
        [(header::CONTENT_TYPE, HeaderValue::from_static("image/png"))],
        png,
    )
        .into_response())
}

/// A download: its type, and the name a browser saves it under (plain ASCII, no quotes).
pub(crate) fn attachment(content_type: &'static str, name: &str, body: Vec<u8>) -> Response {
    let safe: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    let disposition = format!("attachment; filename=\"{safe}\"");
    let mut response = (
        [(header::CONTENT_TYPE, HeaderValue::from_static(content_type))],
        body,
    )
        .into_response();
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        response
            .headers_mut()
            .insert(header::CONTENT_DISPOSITION, v);
    }
    response
}

async fn my_submissions(
    State(app): State<AppState>,
    viewer: Viewer,
) -> AppResult<Json<views::MySubmissions>> {
    let user = viewer.require_user()?;
    Ok(Json(views::my_submissions(&app, user).await?))
}

#[derive(Deserialize)]
struct QuotaQuery {
    #[serde(default)]
    dataset: String,
}

/// How many submissions the caller has left on a dataset, as the upload form shows it.
async fn my_quota(
    State(app): State<AppState>,
    viewer: Viewer,
    Query(q): Query<QuotaQuery>,
) -> AppResult<Json<quota::Quota>> {
    let user = viewer.require_user()?;
    if q.dataset.trim().is_empty() {
        return Err(AppError::BadRequest(
            "the parameter `dataset` (a served dataset's name) is required".into(),
        ));
    }
    Ok(Json(quota::quota(&app, user, q.dataset.trim()).await?))
}

/// The same for every reader, like its page: served from the board cache.
async fn leaderboard(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(protocol): Path<String>,
    Query(filter): Query<views::BoardFilter>,
) -> AppResult<Response> {
    let protocol = BoardProtocol::named(&protocol).ok_or(AppError::NotFound)?;
    let key = boards::key(Format::Json, protocol, &filter);
    boards::answer(&app, &headers, key, || {
        leaderboard_json(&app, protocol, &filter)
    })
    .await
}

/// A board's JSON as it stands: served live, and kept by snapshots.
pub(crate) async fn leaderboard_json(
    app: &App,
    protocol: BoardProtocol,
    filter: &views::BoardFilter,
) -> AppResult<Vec<u8>> {
    let board = views::leaderboard(app, protocol, filter).await?;
    serde_json::to_vec(&board).map_err(|e| AppError::failed("writing the leaderboard JSON", e))
}

/// The OpenAPI description of this API, written by hand: it is small, and a generator would
/// need every handler annotated twice.
async fn openapi() -> Json<serde_json::Value> {
    Json(crate::web::render::openapi::document())
}
