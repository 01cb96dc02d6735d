//! Operations endpoints: `/healthz` (the process answers), `/readyz` (it can do its work),
//! `/metrics` (Prometheus text), and the layer that counts every request by route template.

use std::time::Instant;

use axum::extract::{MatchedPath, Request, State};
use axum::http::{Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};

use crate::app::AppState;
use crate::ops::health;

pub fn router() -> Router<AppState> {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics))
}

/// Serves only these endpoints (with the request counting): what a `poseboard worker`, which
/// has no pages, offers on `--metrics-bind`.
/// Runs until the process ends; a failure is logged (the worker goes on evaluating).
pub async fn serve_alone(app: AppState, listener: tokio::net::TcpListener) {
    let service = router()
        .layer(axum::middleware::from_fn(count_requests))
        .with_state(app);
    if let Err(e) = axum::serve(listener, service).await {
        tracing::error!(error = %e, "the metrics endpoint stopped");
    }
}

async fn healthz() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "status": "ok" }))
}

async fn readyz(State(app): State<AppState>) -> Response {
    let readiness = health::readiness(&app).await;
    let status = if readiness.ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (status, Json(readiness)).into_response()
}

async fn metrics(State(app): State<AppState>) -> Response {
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        health::metrics_text(&app).await,
    )
        .into_response()
}

/// Counts the request under the route that matched it (`unmatched` for the not-found answers,
/// so that probing random addresses cannot create series without end).
pub async fn count_requests(request: Request, next: Next) -> Response {
    let started = Instant::now();
    // Only the standard methods by name: any token is a valid method, and each would be a
    // series of its own.
    let method = match *request.method() {
        Method::GET
        | Method::HEAD
        | Method::POST
        | Method::PUT
        | Method::DELETE
        | Method::PATCH
        | Method::OPTIONS => request.method().as_str().to_string(),
        _ => "other".to_string(),
    };
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let response = next.run(request).await;
    crate::ops::metrics::http_request(
        &method,
        &route,
        response.status().as_u16(),
        started.elapsed().as_secs_f64(),
    );
    response
}
