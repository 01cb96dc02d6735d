//! The service's one error type and its mapping to HTTP statuses, in one place. Internal
//! details (database, I/O) are logged and never shown to the client.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::clock::now_ms;
use crate::domain::FieldError;
use crate::store::StoreError;

pub type AppResult<T> = Result<T, AppError>;

/// A problem of an uploaded file, with its line (0 = the file as a whole).
#[derive(Clone, Debug, Serialize)]
pub struct LineProblem {
    /// The file's name when an upload holds several (the message then names it too).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    pub line: u64,
    pub message: String,
}

#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error("not found")]
    NotFound,
    /// No valid credentials (or a revoked token).
    #[error("{0}")]
    Unauthorized(String),
    /// Credentials, but not for this (e.g. a missing or forged CSRF token).
    #[error("{0}")]
    Forbidden(String),
    #[error("{0}")]
    Conflict(String),
    /// Over a fair-use limit; `retry_at` (epoch ms) is when the next request is allowed.
    #[error("{message}")]
    TooMany { message: String, retry_at: i64 },
    #[error("{0}")]
    BadRequest(String),
    /// An upload that cannot be evaluated, with every problem found.
    #[error("{message}")]
    Invalid {
        message: String,
        problems: Vec<LineProblem>,
    },
    #[error("the upload is larger than the limit of {} ({limit} bytes)", size(*limit))]
    TooLarge { limit: u64 },
    /// The client took too long: a request past its time, or an upload that stopped progressing.
    #[error("{0}")]
    TimedOut(String),
    #[error("{0}")]
    Store(StoreError),
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Internal(String),
}

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
}

/// A size in bytes as people say it: `64 MiB`, `512 KiB`, `100 bytes`.
fn size(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 20 && b % (1 << 20) == 0 => format!("{} MiB", b >> 20),
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / f64::from(1 << 20)),
        b if b >= 1 << 10 && b % (1 << 10) == 0 => format!("{} KiB", b >> 10),
        b => format!("{b} bytes"),
    }
}

impl From<StoreError> for AppError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::NotFound => AppError::NotFound,
            StoreError::Unique { .. } => AppError::Conflict("it exists already".into()),
            e => AppError::Store(e),
        }
    }
}

impl From<FieldError> for AppError {
    fn from(e: FieldError) -> Self {
        AppError::BadRequest(e.to_string())
    }
}

impl AppError {
    pub fn status(&self) -> StatusCode {
        match self {
            AppError::NotFound => StatusCode::NOT_FOUND,
            AppError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            AppError::Forbidden(_) => StatusCode::FORBIDDEN,
            AppError::Conflict(_) => StatusCode::CONFLICT,
            AppError::TooMany { .. } => StatusCode::TOO_MANY_REQUESTS,
            AppError::BadRequest(_) => StatusCode::BAD_REQUEST,
            AppError::Invalid { .. } => StatusCode::UNPROCESSABLE_ENTITY,
            AppError::TooLarge { .. } => StatusCode::PAYLOAD_TOO_LARGE,
            AppError::TimedOut(_) => StatusCode::REQUEST_TIMEOUT,
            AppError::Store(_) | AppError::Io(_) | AppError::Internal(_) => {
                StatusCode::INTERNAL_SERVER_ERROR
            }
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
        ErrorBody {
            error,
            problems,
            retry_at,
            limit_bytes,
        }
    }
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        let status = self.status();
        if status.is_server_error() {
            tracing::error!(error = %self, "request failed");
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
