//! Dated snapshots of every leaderboard, for papers to cite: an administrator takes one
//! ([`crate::service::snapshots`] decides which boards and keeps them), and each board is
//! rendered here by the very functions that serve the live board. Its pages serve those bytes
//! back, unchanged whatever comes later (new scores, a changed template, another evaluator).
//!
//! The HTML of a snapshot's board is the live page rendered with a banner (the date and the
//! absolute permalink), so the banner is part of the stored bytes rather than spliced into them
//! later. A snapshot is self-contained: its tabs lead to its own stored boards, its exports
//! (CSV and JSON, kept with the boards) download its rows, and the one link to the live board
//! is marked as such; the orders and filters it did not keep are not offered.

use std::io::Read;
use std::ops::Deref;

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::app::{App, AppState};
use crate::domain::{BoardProtocol, SnapshotId};
use crate::error::{AppError, AppResult};
use crate::service::snapshots::{self, Board, Boards, Rendered};
use crate::store::accounts::User;
use crate::store::snapshots::{BoardFormat, SnapshotRow};
use crate::web::render::exports::Export;
use crate::web::routes::api::{attachment, leaderboard_json};
use crate::web::routes::boards::accepts_gzip;
use crate::web::routes::pages::filters;
use crate::web::routes::pages::{LeaderboardPage, html};
use crate::web::views::{BoardFilter, snapshot_board_url};

/// The pages: the list and each stored board.
pub fn page_router() -> Router<AppState> {
    Router::new()
        .route("/snapshots", get(list_page))
        .route("/snapshots/{id}", get(board_page))
        .route("/snapshots/{id}/export.csv", get(export_csv))
        .route("/snapshots/{id}/export.json", get(export_json))
}

/// Their JSON twins.
pub fn api_router() -> Router<AppState> {
    Router::new()
        .route("/api/v1/snapshots", get(list_json))
        .route("/api/v1/snapshots/{id}", get(board_json))
}

/// A board of a snapshot, as the permalink of a paper names it.
#[derive(Clone, Debug, Serialize)]
pub struct BoardLink {
    pub protocol: BoardProtocol,
    /// Empty for the board of all datasets.
    pub dataset: String,
    pub url: String,
    pub json_url: String,
}

/// A snapshot as listed.
#[derive(Clone, Debug, Serialize)]
pub struct SnapshotEntry {
    pub id: SnapshotId,
    pub taken_at: i64,
    pub taken_by: String,
    pub url: String,
    pub boards: Vec<BoardLink>,
}

impl From<SnapshotRow> for SnapshotEntry {
    fn from(s: SnapshotRow) -> SnapshotEntry {
        SnapshotEntry {
            id: s.id,
            taken_at: s.taken_at,
            url: format!("/snapshots/{}", s.id),
            boards: s
                .boards
                .into_iter()
                .map(|(protocol, dataset)| {
                    let url = snapshot_board_url(s.id, protocol, &dataset);
                    BoardLink {
                        json_url: format!("/api/v1{url}"),
                        url,
                        protocol,
                        dataset,
                    }
                })
                .collect(),
            taken_by: s.taken_by,
        }
    }
}

/// A board page of a snapshot: the live page's template and data, with the banner.
#[derive(Template)]
#[template(path = "snapshot_board.html")]
struct SnapshotBoardPage {
    page: LeaderboardPage,
    id: SnapshotId,
    taken_at: i64,
    /// The absolute address of this board of this snapshot, for a paper to cite.
    permalink: String,
    /// The same board today (the one link out of the snapshot, marked as such).
    live: String,
}

/// The template reads the live page's fields through this.
impl Deref for SnapshotBoardPage {
    type Target = LeaderboardPage;
    fn deref(&self) -> &LeaderboardPage {
        &self.page
    }
}

/// Takes a snapshot of every board now, by `actor` (an administrator); `site` is the address
/// its permalinks start with.
pub(crate) async fn take(app: &App, actor: &User, site: &str) -> AppResult<SnapshotEntry> {
    Ok(snapshots::take(app, actor, &LiveBoards { app, site })
        .await?
        .into())
}

/// The live boards as the service snapshots them by itself at a challenge's deadline, with
/// permalinks at `site`: owned, for the background task that watches the deadlines.
pub struct DeadlineBoards {
    app: AppState,
    site: String,
}

impl DeadlineBoards {
    pub fn new(app: AppState, site: String) -> DeadlineBoards {
        DeadlineBoards { app, site }
    }
}

impl Boards for DeadlineBoards {
    async fn render(&self, board: &Board<'_>) -> AppResult<Rendered> {
        LiveBoards {
            app: &self.app,
            site: &self.site,
        }
        .render(board)
        .await
    }
}

/// The live boards, rendered as a snapshot keeps them.
struct LiveBoards<'a> {
    app: &'a App,
    /// The service's address, without a trailing slash.
    site: &'a str,
}

impl Boards for LiveBoards<'_> {
    async fn render(&self, board: &Board<'_>) -> AppResult<Rendered> {
        let (app, protocol, dataset, id) =
            (self.app, board.protocol, board.dataset, board.snapshot);
        let filter = BoardFilter {
            dataset: (!dataset.is_empty()).then(|| dataset.to_string()),
            ..BoardFilter::default()
        };
        let mut page = LeaderboardPage::of(app, protocol, &filter).await?;
        // A snapshot is fixed: it draws the best entries' curves and offers no other.
        page.board.curve_choices.clear();
        page.snapshot = Some(id);
        let csv = Export::Csv.render(&page.board)?;
        let export_json = Export::Json.render(&page.board)?;
        let page = SnapshotBoardPage {
            live: page.live_href(filter.query()),
            page,
            id,
            taken_at: board.taken_at,
            permalink: format!("{}{}", self.site, snapshot_board_url(id, protocol, dataset)),
        };
        Ok(Rendered {
            html: html(&page)?,
            json: leaderboard_json(app, protocol, &filter).await?,
            csv,
            export_json,
        })
    }
}

#[derive(Template, WebTemplate)]
#[template(path = "snapshots.html")]
struct SnapshotsPage {
    snapshots: Vec<SnapshotEntry>,
}

async fn entries(app: &App) -> AppResult<Vec<SnapshotEntry>> {
    Ok(snapshots::list(app)
        .await?
        .into_iter()
        .map(Into::into)
        .collect())
}

async fn list_page(State(app): State<AppState>) -> AppResult<SnapshotsPage> {
    Ok(SnapshotsPage {
        snapshots: entries(&app).await?,
    })
}

async fn list_json(State(app): State<AppState>) -> AppResult<Json<serde_json::Value>> {
    Ok(Json(json!({ "snapshots": entries(&app).await? })))
}

/// Which board of a snapshot: the BOP'19 board of all datasets unless named.
#[derive(Debug, Default, Deserialize)]
struct BoardQuery {
    protocol: Option<String>,
    dataset: Option<String>,
}

async fn board_page(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    Query(q): Query<BoardQuery>,
) -> AppResult<Response> {
    stored(&app, &headers, &id, &q, BoardFormat::Html).await
}

async fn board_json(
    State(app): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    Query(q): Query<BoardQuery>,
) -> AppResult<Response> {
    stored(&app, &headers, &id, &q, BoardFormat::Json).await
}

async fn export_csv(
    State(app): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<BoardQuery>,
) -> AppResult<Response> {
    export(&app, &id, &q, Export::Csv).await
}

async fn export_json(
    State(app): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<BoardQuery>,
) -> AppResult<Response> {
    export(&app, &id, &q, Export::Json).await
}

/// Which board of which snapshot a request names.
fn named(id: &str, q: &BoardQuery) -> AppResult<(SnapshotId, BoardProtocol, String)> {
    let id: SnapshotId = id.parse().map_err(|_| AppError::NotFound)?;
    let protocol =
        BoardProtocol::named(q.protocol.as_deref().unwrap_or("bop19")).ok_or(AppError::NotFound)?;
    Ok((id, protocol, q.dataset.clone().unwrap_or_default()))
}

/// A board's export as the snapshot kept it, as a download named after the snapshot and the
/// board (`poseboard-snapshot-3-bop19-lmo.csv`).
async fn export(app: &App, id: &str, q: &BoardQuery, format: Export) -> AppResult<Response> {
    let (id, protocol, dataset) = named(id, q)?;
    let kept = match format {
        Export::Csv => BoardFormat::Csv,
        Export::Json => BoardFormat::ExportJson,
        Export::Tex => return Err(AppError::NotFound),
    };
    let body = inflate(
        id,
        &snapshots::board(app, id, protocol, &dataset, kept).await?,
    )?;
    let suffix = if dataset.is_empty() {
        String::new()
    } else {
        format!("-{dataset}")
    };
    let name = format!(
        "poseboard-snapshot-{id}-{}{suffix}.{}",
        protocol.as_str(),
        format.extension()
    );
    Ok(attachment(format.content_type(), &name, body))
}

/// The bytes a snapshot kept gzipped.
fn inflate(id: SnapshotId, gz: &[u8]) -> AppResult<Vec<u8>> {
    let mut body = Vec::with_capacity(gz.len() * 4);
    flate2::read::GzDecoder::new(gz)
        .read_to_end(&mut body)
        .map_err(|e| AppError::failed(format!("inflating snapshot {id}"), e))?;
    Ok(body)
}

/// The stored bytes of a board, gzipped to clients that take gzip, unpacked for the others.
async fn stored(
    app: &App,
    headers: &HeaderMap,
    id: &str,
    q: &BoardQuery,
    format: BoardFormat,
) -> AppResult<Response> {
    let (id, protocol, dataset) = named(id, q)?;
    let gz = snapshots::board(app, id, protocol, &dataset, format).await?;
    let mut response = if accepts_gzip(headers) {
        let mut r = gz.into_response();
        r.headers_mut()
            .insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
        r
    } else {
        inflate(id, &gz)?.into_response()
    };
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(match format {
            BoardFormat::Html => "text/html; charset=utf-8",
            BoardFormat::Json | BoardFormat::ExportJson => "application/json",
            BoardFormat::Csv => "text/csv; charset=utf-8",
        }),
    );
    h.insert(header::VARY, HeaderValue::from_static("accept-encoding"));
    // A snapshot never changes.
    h.insert(
        header::CACHE_CONTROL,
        HeaderValue::from_static("public, max-age=31536000, immutable"),
    );
    Ok(response)
}
