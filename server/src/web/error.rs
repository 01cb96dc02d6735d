//! Errors as HTTP answers: the status of each [`AppError`], the body the error pages and the
//! JSON API are rendered from, and the `Retry-After` of a refusal over a limit. One place, so a
//! page and the API answer the same error alike; internal details (database, I/O) are logged
//! and never shown to the client.
//!
//! A database that cannot be reached for a moment is not a fault of the request nor a bug:
//! such errors answer `503` with `Retry-After`, and are logged once per outage (the first
//! failure, then one line when requests succeed again) instead of once per request, which
//! during an outage would bury the log. The outage is process-wide, as the pool is, so its
//! count lives in a static rather than in each request's state.
//!
//! A full disk (the data directory's or the database's) is not the request's fault either, but
//! it does not pass by itself: it answers `507 Insufficient Storage` saying that nothing was
//! stored, so an uploader knows the refusal is the service's and that no half of the upload
//! stayed behind, and every such refusal is logged with its cause for the operator who must
//! make room.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use std::sync::atomic::{AtomicU64, Ordering};

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

/// When a client should try again after a `503`, in seconds: a lost connection is replaced at
/// once, and a restarting database takes a few seconds.
const RETRY_AFTER_UNAVAILABLE_SECS: i64 = 2;

/// Requests answered `503` since the database last answered; 0 while it answers.
static UNANSWERED: AtomicU64 = AtomicU64::new(0);

/// Notes a request that succeeded: the end of an outage, if there was one, is logged once.
pub fn database_answered() {
    let failed = UNANSWERED.swap(0, Ordering::Relaxed);
    if failed > 0 {
        tracing::warn!(
            requests_answered_503 = failed,
            "the database answers again after an outage"
        );
    }
}

impl AppError {
    pub fn status(&self) -> StatusCode {
        if self.is_unavailable() {
            return StatusCode::SERVICE_UNAVAILABLE;
        }
        if self.is_storage_full() {
            return StatusCode::INSUFFICIENT_STORAGE;
        }
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
        let error = if status == StatusCode::SERVICE_UNAVAILABLE {
            "the database is unavailable for a moment: nothing was changed, try again in a few \
             seconds"
                .to_string()
        } else if status == StatusCode::INSUFFICIENT_STORAGE {
            "the service has run out of disk space: nothing was stored, try again once its \
             operators have made room"
                .to_string()
        } else if status.is_server_error() {
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
            _ if status == StatusCode::SERVICE_UNAVAILABLE => {
                Some(now_ms() + RETRY_AFTER_UNAVAILABLE_SECS * 1000)
            }
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
        if status == StatusCode::SERVICE_UNAVAILABLE {
            if UNANSWERED.fetch_add(1, Ordering::Relaxed) == 0 {
                tracing::error!(
                    error = %Chain(&self),
                    "the database is unavailable: answering 503 until it is back"
                );
            }
        } else if status == StatusCode::INSUFFICIENT_STORAGE {
            tracing::error!(
                error = %Chain(&self),
                "out of disk space: the request was refused and nothing of it kept"
            );
        } else if status.is_server_error() {
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
    use crate::store::StoreError;

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

    /// A database locked by another connection (SQLite busy), as a real SQLite file gives it.
    fn sqlite_busy() -> StoreError {
        use sqlx::Connection;
        let dir = tempfile::tempdir().expect("tmp");
        let url = format!("sqlite://{}?mode=rwc", dir.path().join("busy.db").display());
        sqlx::any::install_default_drivers();
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime")
            .block_on(async {
                let mut holder = sqlx::AnyConnection::connect(&url).await.expect("sqlite");
                sqlx::query("CREATE TABLE t (x INTEGER)")
                    .execute(&mut holder)
                    .await
                    .expect("table");
                sqlx::query("BEGIN EXCLUSIVE")
                    .execute(&mut holder)
                    .await
                    .expect("lock");
                let mut other = sqlx::AnyConnection::connect(&url).await.expect("sqlite");
                sqlx::query("PRAGMA busy_timeout = 0")
                    .execute(&mut other)
                    .await
                    .expect("pragma");
                let refused = sqlx::query("INSERT INTO t VALUES (1)")
                    .execute(&mut other)
                    .await
                    .expect_err("the file is locked");
                StoreError::from(refused)
            })
    }

    #[test]
    fn an_unavailable_database_answers_503_with_retry_after_and_is_logged_once() {
        let log = Captured::default();
        let writer = log.clone();
        let subscriber = tracing_subscriber::fmt()
            .with_writer(move || writer.clone())
            .with_ansi(false)
            .finish();
        let busy = sqlite_busy();
        assert!(busy.is_transient(), "{busy}");
        let errors = [
            AppError::Store(busy),
            AppError::Store(StoreError::Database(sqlx::Error::PoolTimedOut)),
            AppError::failed(
                "loading the board",
                StoreError::Database(sqlx::Error::PoolTimedOut),
            ),
        ];
        let responses: Vec<Response> = tracing::subscriber::with_default(subscriber, || {
            let responses = errors
                .into_iter()
                .map(IntoResponse::into_response)
                .collect();
            database_answered();
            responses
        });
        for response in &responses {
            assert_eq!(response.status(), StatusCode::SERVICE_UNAVAILABLE);
            assert_eq!(
                response.headers()[axum::http::header::RETRY_AFTER],
                RETRY_AFTER_UNAVAILABLE_SECS.to_string()
            );
            let body = response.extensions().get::<ErrorBody>().expect("body");
            assert!(body.error.contains("nothing was changed"), "{}", body.error);
        }
        let logged = String::from_utf8(log.0.lock().expect("log buffer").clone()).expect("utf-8");
        assert_eq!(
            logged.matches("answering 503 until it is back").count(),
            1,
            "{logged}"
        );
        assert_eq!(logged.matches("answers again").count(), 1, "{logged}");
        assert!(logged.contains("requests_answered_503=3"), "{logged}");

        // A database that answers with nonsense is a fault, not an outage.
        let corrupt = AppError::Store(StoreError::Corrupt {
            column: "status",
            value: "??".into(),
        });
        assert_eq!(corrupt.status(), StatusCode::INTERNAL_SERVER_ERROR);
    }

    /// A write refused for want of room, as a real SQLite file refuses it: its pages capped
    /// (`max_page_count`), which SQLite reports as it reports a full disk, `SQLITE_FULL`.
    fn sqlite_full() -> StoreError {
        use sqlx::Connection;
        let dir = tempfile::tempdir().expect("tmp");
        let url = format!("sqlite://{}?mode=rwc", dir.path().join("full.db").display());
        sqlx::any::install_default_drivers();
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime")
            .block_on(async {
                let mut conn = sqlx::AnyConnection::connect(&url).await.expect("sqlite");
                for sql in ["CREATE TABLE t (x BLOB)", "PRAGMA max_page_count = 4"] {
                    sqlx::query(sql).execute(&mut conn).await.expect("set-up");
                }
                let refused = sqlx::query("INSERT INTO t VALUES (zeroblob(100000))")
                    .execute(&mut conn)
                    .await
                    .expect_err("the database is full");
                StoreError::from(refused)
            })
    }

    #[test]
    fn a_full_disk_answers_507_saying_nothing_was_stored() {
        let full = sqlite_full();
        assert!(full.is_storage_full() && !full.is_transient(), "{full}");
        let no_space = || std::io::Error::from(std::io::ErrorKind::StorageFull);
        let errors = [
            AppError::Store(full),
            AppError::Io(no_space()),
            AppError::failed("unpacking a zip archive", no_space()),
        ];
        for error in errors {
            let response = error.into_response();
            assert_eq!(response.status(), StatusCode::INSUFFICIENT_STORAGE);
            let body = response.extensions().get::<ErrorBody>().expect("body");
            assert!(body.error.contains("nothing was stored"), "{}", body.error);
            assert!(body.retry_at.is_none());
        }
        // Any other fault of the disk is a fault of the service.
        let other = AppError::Io(std::io::Error::from(std::io::ErrorKind::PermissionDenied));
        assert_eq!(other.status(), StatusCode::INTERNAL_SERVER_ERROR);
    }

    #[test]
    fn a_chain_does_not_repeat_a_cause_its_error_already_says() {
        let error = AppError::Io(std::io::Error::other("broken pipe"));
        assert_eq!(Chain(&error).to_string(), "broken pipe");
    }
}
