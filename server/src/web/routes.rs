//! The HTTP surface: pages, the JSON API, static files, and the tower-http layers around them.

pub mod account;
pub mod admin;
pub mod api;
pub mod boards;
pub mod challenges;
pub mod deadlines;
pub mod docs;
pub mod exports;
pub mod limits;
pub mod ops;
pub mod pages;
pub mod recent;
pub mod rescoring;
pub mod snapshots;
pub mod submissions;
pub mod targets;
pub mod teams;
pub mod unavailable;

use axum::Router;
use axum::http::{HeaderValue, header};
use tower_http::compression::CompressionLayer;
use tower_http::limit::RequestBodyLimitLayer;
use tower_http::services::ServeDir;
use tower_http::set_header::SetResponseHeaderLayer;
use tower_http::trace::TraceLayer;

use crate::app::AppState;
use crate::web::routes::deadlines::Deadlines;
use crate::web::routes::limits::UploadLimit;

/// Where the stylesheet and scripts are served from: the repository's `static/` folder.
fn static_dir() -> std::path::PathBuf {
    std::env::var_os("POSEBOARD_STATIC")
        .map(Into::into)
        .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../static"))
}

/// The content security policy of every answer: scripts, styles and everything else only from
/// this site and never inline (the templates have none: scripts and styles are files under
/// `static/`), so injected markup cannot run; and never inside a frame (no clickjacking).
const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
                   object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'";

/// Sets `name` on every answer that has not set it itself.
fn every_answer(
    name: header::HeaderName,
    value: &'static str,
) -> SetResponseHeaderLayer<HeaderValue> {
    SetResponseHeaderLayer::if_not_present(name, HeaderValue::from_static(value))
}

pub fn router(app: AppState, deadlines: Deadlines) -> Router {
    let max_upload = app.config.max_upload_bytes();
    let static_files = Router::new()
        .nest_service("/static", ServeDir::new(static_dir()))
        .layer(SetResponseHeaderLayer::overriding(
            header::CACHE_CONTROL,
            HeaderValue::from_static("public, max-age=3600"),
        ));
    let pages = pages::router(max_upload)
        .merge(account::router())
        .merge(docs::router())
        .merge(snapshots::page_router())
        .merge(targets::page_router())
        .merge(exports::router())
        .merge(rescoring::page_router())
        .merge(recent::page_router())
        .merge(teams::page_router())
        .merge(challenges::page_router())
        .fallback(pages::not_found)
        .layer(axum::middleware::from_fn(pages::html_errors));
    Router::new()
        .merge(api::router(max_upload))
        .merge(snapshots::api_router())
        .merge(targets::api_router())
        .merge(rescoring::api_router())
        .merge(teams::api_router())
        .merge(challenges::api_router())
        .merge(admin::router(app.clone()))
        .merge(pages)
        .merge(static_files)
        .merge(ops::router())
        .layer(CompressionLayer::new())
        // Uploads are bounded per route; this bounds every other body.
        .layer(RequestBodyLimitLayer::new(max_upload as usize + 64 * 1024))
        .layer(axum::middleware::from_fn_with_state(
            UploadLimit(max_upload),
            limits::too_large,
        ))
        .layer(axum::middleware::from_fn_with_state(
            deadlines,
            deadlines::plain_timeout,
        ))
        .layer(every_answer(header::CONTENT_SECURITY_POLICY, CSP))
        .layer(every_answer(header::X_FRAME_OPTIONS, "DENY"))
        // No guessing of content types (an upload shown as HTML), and no address (with its
        // `next` and filters) sent to other sites.
        .layer(every_answer(header::X_CONTENT_TYPE_OPTIONS, "nosniff"))
        .layer(every_answer(header::REFERRER_POLICY, "same-origin"))
        .layer(axum::middleware::from_fn(unavailable::retry_reads))
        .layer(axum::middleware::from_fn(ops::count_requests))
        .layer(TraceLayer::new_for_http())
        .with_state(app)
}
