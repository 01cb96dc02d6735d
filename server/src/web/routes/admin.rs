//! What administrators do: hide, delete and re-run submissions, add and retire datasets, save
//! and delete dataset groups, create challenges and override their awards, from the API and from buttons on the pages. Every action is written to the audit log. To anyone
//! else these routes answer as if they did not exist, whatever the method and body.

use axum::extract::{Form, FromRequestParts, Path, Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{delete, get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::json;

use crate::app::AppState;
use crate::domain::{ChallengeForm, FieldError, MethodId, SubmissionId};
use crate::error::{AppError, AppResult};
use crate::service::challenges::{self, OverrideRequest};
use crate::service::{groups, moderation};
use crate::store::accounts::User;
use crate::store::audit::AdminAction;
use crate::web::auth::Viewer;
use crate::web::routes::{pages, snapshots};
use crate::web::views::challenges::{ChallengeSummary, ChallengeView, challenge_url};

pub fn router(app: AppState) -> Router<AppState> {
    Router::new()
        .route(
            "/api/v1/admin/submissions/{id}/{action}",
            post(api_submission_action),
        )
        .route("/api/v1/admin/datasets", post(api_add_dataset))
        .route(
            "/api/v1/admin/datasets/{name}/retire",
            post(api_retire_dataset),
        )
        .route("/api/v1/admin/datasets/{name}/core", post(api_set_core))
        .route("/api/v1/admin/groups", post(api_save_group))
        .route("/api/v1/admin/groups/{name}", delete(api_delete_group))
        .route("/api/v1/admin/audit", get(api_audit))
        .route("/api/v1/admin/snapshots", post(api_take_snapshot))
        .route("/api/v1/admin/challenges", post(api_create_challenge))
        .route(
            "/api/v1/admin/challenges/{slug}/awards",
            post(api_override_award),
        )
        .route("/admin/challenges", post(page_create_challenge))
        .route("/admin/challenges/{slug}/awards", post(page_override_award))
        .route(
            "/admin/submissions/{id}/{action}",
            post(page_submission_action),
        )
        .route("/admin/datasets", post(page_add_dataset))
        .route("/admin/datasets/{name}/retire", post(page_retire_dataset))
        .route("/admin/datasets/{name}/core", post(page_set_core))
        .route("/admin/groups", post(page_save_group))
        .route("/admin/groups/{name}/delete", post(page_delete_group))
        .layer(axum::middleware::from_fn_with_state(app, admins_only))
}

/// Answers everyone but administrators with the page of a path that does not exist, before
/// the method, path parameters or body are looked at (a 405 or 422 would tell the route is
/// there). The viewer is kept for the handler.
async fn admins_only(
    State(app): State<AppState>,
    request: Request,
    next: Next,
) -> Result<Response, AppError> {
    let (mut parts, body) = request.into_parts();
    let viewer = Viewer::from_request_parts(&mut parts, &app).await?;
    if admin(&viewer).is_err() {
        return Ok(pages::not_found().await);
    }
    parts.extensions.insert(viewer);
    Ok(next.run(Request::from_parts(parts, body)).await)
}

fn admin(viewer: &Viewer) -> AppResult<&User> {
    viewer
        .user
        .as_ref()
        .filter(|u| u.is_admin)
        .ok_or(AppError::NotFound)
}

/// The submission actions of the URL; anything else is a route that does not exist.
fn submission_action_named(action: &str) -> AppResult<AdminAction> {
    match action.parse() {
        Ok(
            a
            @ (AdminAction::Hide | AdminAction::Unhide | AdminAction::Rerun | AdminAction::Delete),
        ) => Ok(a),
        _ => Err(AppError::NotFound),
    }
}

async fn api_submission_action(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, action)): Path<(SubmissionId, String)>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    moderation::submission_action(&app, actor, id, submission_action_named(&action)?).await?;
    Ok(Json(
        json!({ "ok": true, "action": action, "submission": id }),
    ))
}

#[derive(Deserialize)]
struct CsrfForm {
    #[serde(default)]
    csrf: String,
}

async fn page_submission_action(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, action)): Path<(SubmissionId, String)>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    moderation::submission_action(&app, actor, id, submission_action_named(&action)?).await?;
    let to = if action == "delete" {
        "/".to_string()
    } else {
        format!("/submissions/{id}")
    };
    Ok(Redirect::to(&to).into_response())
}

#[derive(Deserialize)]
struct NewDataset {
    /// A folder name inside the datasets directory.
    name: String,
    #[serde(default)]
    csrf: String,
}

async fn api_add_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Json(d): Json<NewDataset>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    let row = moderation::add_dataset(&app, actor, &d.name).await?;
    Ok(Json(json!({ "dataset": row })))
}

async fn api_retire_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    moderation::retire_dataset(&app, actor, &name).await?;
    Ok(Json(json!({ "ok": true, "retired": name })))
}

async fn page_add_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Form(d): Form<NewDataset>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&d.csrf)?;
    moderation::add_dataset(&app, actor, d.name.trim()).await?;
    Ok(Redirect::to("/datasets").into_response())
}

async fn page_retire_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    moderation::retire_dataset(&app, actor, &name).await?;
    Ok(Redirect::to("/datasets").into_response())
}

#[derive(Deserialize)]
struct Core {
    core: bool,
}

async fn api_set_core(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Json(c): Json<Core>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    moderation::set_core(&app, actor, &name, c.core).await?;
    Ok(Json(json!({ "ok": true, "dataset": name, "core": c.core })))
}

#[derive(Deserialize)]
struct CoreForm {
    /// `yes` or `no`.
    core: String,
    #[serde(default)]
    csrf: String,
}

async fn page_set_core(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<CoreForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    let core = match f.core.as_str() {
        "yes" => true,
        "no" => false,
        _ => return Err(AppError::BadRequest("`core` must be yes or no".into())),
    };
    moderation::set_core(&app, actor, &name, core).await?;
    Ok(Redirect::to("/datasets").into_response())
}

#[derive(Deserialize)]
struct GroupBody {
    name: String,
    /// Dataset folder names, served or not.
    datasets: Vec<String>,
}

/// Creates a group (201) or replaces the members of the group of that name (200).
async fn api_save_group(
    State(app): State<AppState>,
    viewer: Viewer,
    Json(g): Json<GroupBody>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    let (group, created) = groups::save(&app, actor, &g.name, &g.datasets).await?;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((status, Json(json!({ "group": group, "created": created }))).into_response())
}

async fn api_delete_group(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    groups::delete(&app, actor, &name).await?;
    Ok(Json(json!({ "ok": true, "deleted": name })))
}

#[derive(Deserialize)]
struct GroupForm {
    name: String,
    /// Dataset folder names separated by spaces or commas.
    datasets: String,
    #[serde(default)]
    csrf: String,
}

async fn page_save_group(
    State(app): State<AppState>,
    viewer: Viewer,
    Form(f): Form<GroupForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    let datasets: Vec<String> = f
        .datasets
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|d| !d.is_empty())
        .map(str::to_string)
        .collect();
    groups::save(&app, actor, &f.name, &datasets).await?;
    Ok(Redirect::to("/groups").into_response())
}

async fn page_delete_group(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    groups::delete(&app, actor, &name).await?;
    Ok(Redirect::to("/groups").into_response())
}

async fn api_audit(
    State(app): State<AppState>,
    viewer: Viewer,
) -> AppResult<Json<serde_json::Value>> {
    admin(&viewer)?;
    Ok(Json(
        json!({ "audit": moderation::audit_log(&app, 500).await? }),
    ))
}

/// Takes a snapshot of every board: 201 with its `id` and the permalinks of its boards. The
/// permalinks in its pages' banners are absolute, at the service's public address (else the
/// host this request came to).
async fn api_take_snapshot(
    State(app): State<AppState>,
    headers: HeaderMap,
    viewer: Viewer,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    let entry = snapshots::take(&app, actor, &pages::site_url(&app, &headers)).await?;
    Ok((StatusCode::CREATED, Json(entry)).into_response())
}

/// A challenge as the API sends it: `{slug, name, tasks, groups, deadline}` and optionally
/// `objects`, `onboarding`, `fast_seconds` and `awards`. 201 with the challenge.
async fn api_create_challenge(
    State(app): State<AppState>,
    viewer: Viewer,
    Json(form): Json<ChallengeForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    let row = challenges::create(&app, actor, form.parse()?).await?;
    let challenge = ChallengeSummary::from(&row);
    Ok((StatusCode::CREATED, Json(json!({ "challenge": challenge }))).into_response())
}

/// The form of the challenges page: lists as words separated by spaces or commas.
#[derive(Deserialize)]
struct ChallengeFormText {
    #[serde(default)]
    slug: String,
    #[serde(default)]
    name: String,
    #[serde(default)]
    tasks: String,
    #[serde(default)]
    groups: String,
    #[serde(default)]
    deadline: String,
    #[serde(default)]
    objects: String,
    #[serde(default)]
    onboarding: String,
    #[serde(default)]
    fast_seconds: String,
    #[serde(default)]
    awards: String,
    #[serde(default)]
    csrf: String,
}

/// Words separated by spaces or commas.
fn words(text: &str) -> Vec<String> {
    text.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

async fn page_create_challenge(
    State(app): State<AppState>,
    viewer: Viewer,
    Form(f): Form<ChallengeFormText>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    let fast_seconds = match f.fast_seconds.trim() {
        "" => None,
        text => Some(text.parse::<f64>().map_err(|_| FieldError {
            field: "fast_seconds",
            problem: format!("must be a number of seconds, not `{text}`"),
        })?),
    };
    let awards = words(&f.awards);
    let form = ChallengeForm {
        slug: f.slug,
        name: f.name,
        tasks: words(&f.tasks),
        groups: words(&f.groups),
        deadline: f.deadline,
        objects: f.objects,
        onboarding: f.onboarding,
        fast_seconds,
        awards: (!awards.is_empty()).then_some(awards),
    };
    let row = challenges::create(&app, actor, form.parse()?).await?;
    Ok(Redirect::to(&challenge_url(&row.slug)).into_response())
}

/// An override of an award: the task and award, the method it goes to (none: not awarded)
/// and the note saying why.
#[derive(Deserialize)]
struct OverrideBody {
    #[serde(default)]
    task: String,
    #[serde(default)]
    award: String,
    method_id: Option<MethodId>,
    #[serde(default)]
    note: String,
}

async fn api_override_award(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(slug): Path<String>,
    Json(o): Json<OverrideBody>,
) -> AppResult<Json<ChallengeView>> {
    let actor = admin(&viewer)?;
    let request = OverrideRequest {
        task: o.task,
        award: o.award,
        method_id: o.method_id,
        note: o.note,
    };
    Ok(Json(
        challenges::override_award(&app, actor, &slug, request)
            .await?
            .into(),
    ))
}

#[derive(Deserialize)]
struct OverrideForm {
    #[serde(default)]
    task: String,
    #[serde(default)]
    award: String,
    /// A method id; empty: not awarded.
    #[serde(default)]
    method_id: String,
    #[serde(default)]
    note: String,
    #[serde(default)]
    csrf: String,
}

async fn page_override_award(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(slug): Path<String>,
    Form(f): Form<OverrideForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    let method_id = match f.method_id.trim() {
        "" => None,
        text => Some(text.parse::<MethodId>().map_err(|_| FieldError {
            field: "method_id",
            problem: format!("must be a method id, not `{text}`"),
        })?),
    };
    let request = OverrideRequest {
        task: f.task,
        award: f.award,
        method_id,
        note: f.note,
    };
    let c = challenges::override_award(&app, actor, &slug, request).await?;
    Ok(Redirect::to(&challenge_url(&c.row.slug)).into_response())
}
