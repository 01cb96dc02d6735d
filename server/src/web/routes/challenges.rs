//! `/challenges` and `/challenges/{slug}` with their JSON twins under `/api/v1`: the
//! challenges, each with its boards, its snapshot at the deadline and its awards (see
//! `crate::service::challenges`). Creating one and overriding an award are administrators'
//! (`crate::web::routes::admin`); the pages carry their forms for an administrator's browser.

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::{Path, State};
use axum::routing::get;
use axum::{Json, Router};
use serde_json::{Value, json};

use crate::app::AppState;
use crate::domain::{Award, BoardProtocol};
use crate::error::AppResult;
use crate::service::challenges::awards;
use crate::web::auth::Viewer;
use crate::web::routes::pages::filters;
use crate::web::views::challenges::{self, AwardView, BoardView, ChallengeSummary, ChallengeView};

pub fn page_router() -> Router<AppState> {
    Router::new()
        .route("/challenges", get(list_page))
        .route("/challenges/{slug}", get(challenge_page))
}

pub fn api_router() -> Router<AppState> {
    Router::new()
        .route("/api/v1/challenges", get(list_json))
        .route("/api/v1/challenges/{slug}", get(challenge_json))
}

/// An administrator's browser: the CSRF token of the page's forms.
fn admin_csrf(viewer: &Viewer) -> Option<String> {
    viewer
        .session
        .as_ref()
        .filter(|s| s.user.is_admin)
        .map(|s| s.csrf_token.clone())
}

#[derive(Template, WebTemplate)]
#[template(path = "challenges.html")]
struct ListPage {
    challenges: Vec<ChallengeSummary>,
    admin_csrf: Option<String>,
    tasks: [BoardProtocol; 5],
    awards: &'static [Award],
}

impl ListPage {
    fn award_title(&self, award: &Award) -> &'static str {
        awards::title(*award)
    }
}

async fn list_page(State(app): State<AppState>, viewer: Viewer) -> AppResult<ListPage> {
    Ok(ListPage {
        challenges: challenges::list(&app).await?,
        admin_csrf: admin_csrf(&viewer),
        tasks: BoardProtocol::ALL,
        awards: Award::ALL,
    })
}

async fn list_json(State(app): State<AppState>) -> AppResult<Json<Value>> {
    Ok(Json(json!({ "challenges": challenges::list(&app).await? })))
}

#[derive(Template, WebTemplate)]
#[template(path = "challenge.html")]
struct ChallengePage {
    c: ChallengeSummary,
    snapshot_url: Option<String>,
    awards: Vec<AwardView>,
    boards: Vec<BoardView>,
    admin_csrf: Option<String>,
}

async fn challenge_page(
    State(app): State<AppState>,
    viewer: Viewer,
    Path(slug): Path<String>,
) -> AppResult<ChallengePage> {
    let view = challenges::page(&app, &slug).await?;
    Ok(ChallengePage {
        c: view.summary,
        snapshot_url: view.snapshot_url,
        awards: view.awards,
        boards: view.boards,
        admin_csrf: admin_csrf(&viewer),
    })
}

async fn challenge_json(
    State(app): State<AppState>,
    Path(slug): Path<String>,
) -> AppResult<Json<ChallengeView>> {
    Ok(Json(challenges::page(&app, &slug).await?))
}
