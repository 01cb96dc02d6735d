//! One answer for a body over the size limit, whichever layer refused it: tower-http's body
//! limit answers a bare text 413 before any route runs, and a multipart body that grows past
//! its route's limit does not know the configured size. Those 413s are replaced here by the
//! service's own error, stating the limit: JSON on the API, an HTML page elsewhere. A 413 the
//! service wrote itself (with the limit, or a page such as the upload form shown again) stays.

use axum::extract::{Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::error::AppError;
use crate::web::error::ErrorBody;
use crate::web::routes::pages;

/// The upload limit, in bytes, that a 413 states.
#[derive(Clone, Copy, Debug)]
pub struct UploadLimit(pub u64);

pub async fn too_large(
    State(UploadLimit(limit)): State<UploadLimit>,
    request: Request,
    next: Next,
) -> Response {
    let api = request.uri().path().starts_with("/api/");
    let response = next.run(request).await;
    if response.status() != StatusCode::PAYLOAD_TOO_LARGE {
        return response;
    }
    let states_limit = match response.extensions().get::<ErrorBody>() {
        Some(body) => body.limit_bytes.is_some_and(|l| l > 0),
        None => response
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .is_some_and(|v| v.starts_with("text/html")),
    };
    if states_limit {
        return response;
    }
    let error = AppError::TooLarge { limit }.into_response();
    if api { error } else { pages::error_page(error) }
}
