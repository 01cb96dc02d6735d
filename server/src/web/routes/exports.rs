//! Leaderboard downloads (`/leaderboards/{protocol}/export.csv`, `.json`, `.tex`), with the
//! query of the board pages. They are read fresh on every request rather than through the
//! board cache: a download is rare, and a fresh read follows every change at once.

use axum::Router;
use axum::extract::{Path, Query, State};
use axum::response::Response;
use axum::routing::get;

use crate::app::AppState;
use crate::domain::BoardProtocol;
use crate::error::{AppError, AppResult};
use crate::web::render::exports::Export;
use crate::web::routes::api::attachment;
use crate::web::views::{self, BoardFilter};

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/leaderboards/{protocol}/export.csv", get(csv))
        .route("/leaderboards/{protocol}/export.json", get(json))
        .route("/leaderboards/{protocol}/export.tex", get(tex))
}

async fn csv(
    State(app): State<AppState>,
    Path(protocol): Path<String>,
    Query(filter): Query<BoardFilter>,
) -> AppResult<Response> {
    export(&app, &protocol, &filter, Export::Csv).await
}

async fn json(
    State(app): State<AppState>,
    Path(protocol): Path<String>,
    Query(filter): Query<BoardFilter>,
) -> AppResult<Response> {
    export(&app, &protocol, &filter, Export::Json).await
}

async fn tex(
    State(app): State<AppState>,
    Path(protocol): Path<String>,
    Query(filter): Query<BoardFilter>,
) -> AppResult<Response> {
    export(&app, &protocol, &filter, Export::Tex).await
}

async fn export(
    app: &AppState,
    protocol: &str,
    filter: &BoardFilter,
    format: Export,
) -> AppResult<Response> {
    let protocol = BoardProtocol::named(protocol).ok_or(AppError::NotFound)?;
    let board = views::leaderboard(app, protocol, filter).await?;
    let body = format.render(&board)?;
    Ok(attachment(
        format.content_type(),
        &format.file_name(&board),
        body,
    ))
}
