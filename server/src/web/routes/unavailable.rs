//! Reads tried twice. When the database drops a connection (killed by an operator, a
//! failover, a restart), the request on it fails while the pool opens a new one; a GET or HEAD
//! answered `503` for that is run once more at once, so that a reader rarely sees the outage
//! of one connection. Writes are not repeated here: their `503` says nothing was changed and
//! when to try again, and the client decides (`poseboard submit` does).

use axum::body::Body;
use axum::extract::Request;
use axum::http::{Method, StatusCode};
use axum::middleware::Next;
use axum::response::Response;

use crate::web::error::database_answered;

pub async fn retry_reads(request: Request, next: Next) -> Response {
    let response = if matches!(*request.method(), Method::GET | Method::HEAD) {
        let (parts, body) = request.into_parts();
        let first = next
            .clone()
            .run(Request::from_parts(parts.clone(), body))
            .await;
        if first.status() == StatusCode::SERVICE_UNAVAILABLE {
            // A read has no body to send again.
            next.run(Request::from_parts(parts, Body::empty())).await
        } else {
            first
        }
    } else {
        next.run(request).await
    };
    if response.status() != StatusCode::SERVICE_UNAVAILABLE {
        database_answered();
    }
    response
}
