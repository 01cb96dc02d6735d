//! Errors as HTTP answers: the status of each [`AppError`], the body the error pages and the
//! JSON API are rendered from, and the `Retry-After` of a refusal over a limit. One place, so a
//! page and the API answer the same error alike; internal details (database, I/O) are logged
//! and never shown to the client.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::clock::now_ms;
use crate::error::{AppError, Chain, LineProblem};

/// What the error pages are rendered from (attached to error responses).
#[derive(Clone, Debug, Serialize)]
pub struct ErrorBody {
    pub error: String,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub problems: Vec<LineProblem>,
    /// For 429: when the next request is allowed (epoch milliseconds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub retry_at: Option<i64>,
    /// For 413: the largest body accepted, in bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit_bytes: Option<u64>,
    /// Where to go instead (404 of something a resource does not have).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<ErrorLink>,
}

/// A page of this service an error answer points to.
#[derive(Clone, Debug, Serialize)]
pub struct ErrorLink {
    pub label: String,
    pub href: String,
}

impl AppError {
    pub fn status(&self) -> StatusCode {
        match self {
            AppError::NotFound | AppError::Unknown(_) | AppError::NotHere { .. } => {
                StatusCode::NOT_FOUND
            }
            AppError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            AppError::Forbidden(_) => StatusCode::FORBIDDEN,
            AppError::Conflict(_) => StatusCode::CONFLICT,
            AppError::TooMany { .. } => StatusCode::TOO_MANY_REQUESTS,
            AppError::BadRequest(_) => StatusCode::BAD_REQUEST,
            AppError::Invalid { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            AppError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            AppError::TimedOut(_) => StatusCode::REQUEST_TIMEOUT,
            AppError::Store(_)
            | AppError::Io(_)
            | AppError::Internal(_)
            | AppError::Failed { .. } => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    pub fn body(&self) -> ErrorBody {
        let status = self.status();
        let error = if status.is_server_error() {
            "internal error: the service could not complete the request".to_string()
        } else {
            self.to_string()
        };
        let problems = match self {
            AppError::Invalid { problems, .. } => problems.clone(),
            _ => Vec::new(),
        };
        let retry_at = match self {
            AppError::TooMany { retry_at, .. } => Some(*retry_at),
            _ => None,
        };
        let limit_bytes = match self {
            AppError::TooLarge { limit } => Some(*limit),
            _ => None,
        };
        let links = match self {
            AppError::NotHere { links, .. } => links
                .iter()
                .map(|(label, href)| ErrorLink {
                    label: label.clone(),
                    href: href.clone(),
                })
                .collect(),
            _ => Vec::new(),
        };
        ErrorBody {
            error,
            problems,
            retry_at,
            limit_bytes,
            links,
        }
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        let status = self.status();
        if status.is_server_error() {
            tracing::error!(error = %Chain(&self), "request failed");
        }
        let body = self.body();
        let mut response = (status, Json(body.clone())).into_response();
        if let Some(at) = body.retry_at {
            let secs = ((at - now_ms()).max(0) + 999) / 1000;
            if let Ok(v) = axum::http::HeaderValue::from_str(&secs.to_string()) {
                response
                    .headers_mut()
                    .insert(axum::http::header::RETRY_AFTER, v);
            }
        }
        response.extensions_mut().insert(body);
        response
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::sync::{Arc, Mutex};

    use axum::response::IntoResponse;

    use super::*;

    /// What the subscriber under test writes: the log lines.
    #[derive(Clone, Default)]
    struct Captured(Arc<Mutex<Vec<u8>>>);

    impl Write for Captured {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().expect("log buffer").extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn an_internal_error_is_logged_with_its_causes_and_answered_without_them() {
        let cause = std::io::Error::other("disk /var/lib/poseboard is full");
        let error = AppError::failed("compressing the upload", cause);
        assert_eq!(
            Chain(&error).to_string(),
            "compressing the upload: disk /var/lib/poseboard is full"
        );

        let log = Captured::default();
        let writer = log.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_writer(move || writer.clone())
            .with_ansi(false)
            .finish();
        let response = tracing::subscriber::with_default(subscriber, || error.into_response());
        let logged = String::from_utf8(log.0.lock().expect("log buffer").clone()).expect("utf-8");
        assert!(
            logged.contains("compressing the upload: disk /var/lib/poseboard is full"),
            "{logged}"
        );

        assert_eq!(response.status(), StatusCode::INTERNAL_SERVER_ERROR);
        let page = response
            .extensions()
            .get::<ErrorBody>()
            .expect("error body");
        assert!(!page.error.contains("disk") && !page.error.contains("compressing"));
        let bytes = tokio::runtime::Builder::new_current_thread()
            .build()
            .expect("runtime")
            .block_on(axum::body::to_bytes(response.into_body(), usize::MAX))
            .expect("body");
        let shown = String::from_utf8_lossy(&bytes);
        assert!(!shown.contains("disk"), "{shown}");
        assert!(!shown.contains("compressing"), "{shown}");
    }

    #[test]
    fn a_chain_does_not_repeat_a_cause_its_error_already_says() {
        let error = AppError::Io(std::io::Error::other("broken pipe"));
        assert_eq!(Chain(&error).to_string(), "broken pipe");
    }
}
