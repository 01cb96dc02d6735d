//! What administrators do: hide, delete and re-run submissions, add and retire datasets, from
//! the API and from buttons on the pages. Every action is written to the audit log. To anyone
//! else these routes answer as if they did not exist.

use axum::extract::{Form, Path, State};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::json;

use crate::app::AppState;
use crate::auth::Viewer;
use crate::error::{AppError, AppResult};
use crate::store::accounts::User;

pub fn router() -> Router<AppState> {
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
        .route("/api/v1/admin/audit", get(api_audit))
        .route(
            "/admin/submissions/{id}/{action}",
            post(page_submission_action),
        )
        .route("/admin/datasets", post(page_add_dataset))
        .route("/admin/datasets/{name}/retire", post(page_retire_dataset))
}

fn admin(viewer: &Viewer) -> AppResult<&User> {
    viewer
        .user
        .as_ref()
        .filter(|u| u.is_admin)
        .ok_or(AppError::NotFound)
}

/// Applies `action` (hide, unhide, rerun, delete) to a submission and records it.
async fn submission_action(app: &AppState, actor: &User, id: i64, action: &str) -> AppResult<()> {
    let done = match action {
        "hide" => app.store.set_hidden(id, true).await?,
        "unhide" => app.store.set_hidden(id, false).await?,
        "rerun" => {
            let queued = app.store.rerun(id).await?;
            app.wake.notify_waiters();
            queued
        }
        "delete" => match app.store.delete_submission(id).await? {
            Some(unused_file) => {
                if let Some(sha) = unused_file {
                    let _ = tokio::fs::remove_file(app.stored_file(&sha)).await;
                }
                true
            }
            None => false,
        },
        _ => return Err(AppError::NotFound),
    };
    if !done {
        return Err(AppError::BadRequest(format!(
            "cannot {action} submission {id} (missing, or not finished for a re-run)"
        )));
    }
    app.store
        .audit(actor.id, action, &format!("submission {id}"))
        .await
}

async fn api_submission_action(
    State(app): State<AppState>,
    viewer: Viewer,
    Path((id, action)): Path<(i64, String)>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    submission_action(&app, actor, id, &action).await?;
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
    Path((id, action)): Path<(i64, String)>,
    Form(f): Form<CsrfForm>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&f.csrf)?;
    submission_action(&app, actor, id, &action).await?;
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

/// Serves the dataset in a folder of the datasets directory, named by a plain folder name.
async fn add_dataset(
    app: &AppState,
    actor: &User,
    name: &str,
) -> AppResult<crate::store::DatasetRow> {
    // Only a plain folder name: no path separators, no `..`.
    if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
        return Err(AppError::BadRequest(
            "`name` must be a folder name inside the datasets directory".into(),
        ));
    }
    let row = app
        .register_dataset(&app.config.datasets_dir().join(name))
        .await?;
    app.store.audit(actor.id, "add dataset", &row.name).await?;
    Ok(row)
}

async fn retire_dataset(app: &AppState, actor: &User, name: &str) -> AppResult<()> {
    if !app.store.retire_dataset(name).await? {
        return Err(AppError::NotFound);
    }
    app.store.audit(actor.id, "retire dataset", name).await
}

async fn api_add_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Json(d): Json<NewDataset>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    let row = add_dataset(&app, actor, &d.name).await?;
    Ok(Json(json!({ "dataset": row })))
}

async fn api_retire_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(name): Path<String>,
) -> AppResult<Json<serde_json::Value>> {
    let actor = admin(&viewer)?;
    retire_dataset(&app, actor, &name).await?;
    Ok(Json(json!({ "ok": true, "retired": name })))
}

async fn page_add_dataset(
    State(app): State<AppState>,
    viewer: Viewer,
    Form(d): Form<NewDataset>,
) -> AppResult<Response> {
    let actor = admin(&viewer)?;
    viewer.check_csrf(&d.csrf)?;
    add_dataset(&app, actor, d.name.trim()).await?;
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
    retire_dataset(&app, actor, &name).await?;
    Ok(Redirect::to("/datasets").into_response())
}

async fn api_audit(
    State(app): State<AppState>,
    viewer: Viewer,
) -> AppResult<Json<serde_json::Value>> {
    admin(&viewer)?;
    Ok(Json(json!({ "audit": app.store.audit_log(500).await? })))
}
