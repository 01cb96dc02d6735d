//! `/submissions`, its JSON twin `GET /api/v1/submissions` and the Atom feed
//! `/submissions.atom`: the public finished submissions, newest first (see
//! `crate::service::catalogue::recent`).

use askama::Template;
use askama_web::WebTemplate;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::Deserialize;

use crate::app::AppState;
use crate::clock::now_ms;
use crate::domain::PageNumber;
use crate::error::AppResult;
use crate::web::render::feed;
use crate::web::routes::pages::{filters, site_url};
use crate::web::views::{self, RecentList, recent_href};

/// The page and the feed; the JSON twin shares its path with the upload (see
/// `crate::web::routes::api`).
pub fn page_router() -> Router<AppState> {
    Router::new()
        .route("/submissions", get(page))
        .route("/submissions.atom", get(atom))
}

#[derive(Deserialize)]
pub(crate) struct PageQuery {
    page: Option<String>,
}

impl PageQuery {
    fn page(&self) -> AppResult<PageNumber> {
        Ok(match &self.page {
            Some(p) => PageNumber::parse(p)?,
            None => PageNumber::FIRST,
        })
    }
}

#[derive(Template, WebTemplate)]
#[template(path = "recent.html")]
struct RecentPage {
    list: RecentList,
}

impl RecentPage {
    fn href(&self, page: &u32) -> String {
        recent_href("/submissions", *page)
    }

    fn json_href(&self) -> String {
        recent_href("/api/v1/submissions", self.list.list.page.get())
    }
}

async fn page(State(app): State<AppState>, Query(q): Query<PageQuery>) -> AppResult<RecentPage> {
    Ok(RecentPage {
        list: views::recent(&app, q.page()?).await?,
    })
}

pub(crate) async fn json(
    State(app): State<AppState>,
    Query(q): Query<PageQuery>,
) -> AppResult<Json<RecentList>> {
    Ok(Json(views::recent(&app, q.page()?).await?))
}

/// The newest page as Atom, its addresses absolute (a feed reader fetches it out of context).
async fn atom(State(app): State<AppState>, headers: HeaderMap) -> AppResult<Response> {
    let list = views::recent(&app, PageNumber::FIRST).await?;
    let body = feed::atom(&site_url(&app, &headers), &list.list.submissions, now_ms());
    Ok((
        [(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/atom+xml"),
        )],
        body,
    )
        .into_response())
}
