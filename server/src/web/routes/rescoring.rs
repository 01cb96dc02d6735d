//! `/rescoring` and `GET /api/v1/rescoring`: every score a re-scoring by a newer evaluator
//! changed, before and after (see `crate::service::rescoring`).

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::State;
use axum::routing::get;
use axum::{Json, Router};

use crate::app::AppState;
use crate::error::AppResult;
use crate::service::rescoring::{Rescoring, view};
use crate::web::auth::Viewer;
use crate::web::routes::pages::filters;

pub fn page_router() -> Router<AppState> {
    Router::new().route("/rescoring", get(page))
}

pub fn api_router() -> Router<AppState> {
    Router::new().route("/api/v1/rescoring", get(json))
}

#[derive(Template, WebTemplate)]
#[template(path = "rescoring.html")]
struct RescoringPage {
    view: Rescoring,
}

async fn page(State(app): State<AppState>, viewer: Viewer) -> AppResult<RescoringPage> {
    Ok(RescoringPage {
        view: view(&app, viewer.user.as_ref()).await?,
    })
}

async fn json(State(app): State<AppState>, viewer: Viewer) -> AppResult<Json<Rescoring>> {
    Ok(Json(view(&app, viewer.user.as_ref()).await?))
}
