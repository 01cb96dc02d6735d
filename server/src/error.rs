//! The service's one error type, shared by the use cases, the app state and the web layer. It
//! says what went wrong in the words of the service (not found, refused, over a limit, an
//! internal fault); the web layer alone turns it into a status and a body (`web::error`), so
//! the use cases stay free of HTTP.

use intake::archive::ArchiveError;
use serde::Serialize;

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
    /// A name in the request that names nothing here, with what there is instead.
    #[error("{0}")]
    Unknown(String),
    /// Something the resource asked about does not have (a 2D submission's targets), with
    /// where to go instead, each link a label and a path of this service: the page answering
    /// it is no dead end.
    #[error("{message}")]
    NotHere {
        message: String,
        links: Vec<(String, String)>,
    },
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
    /// A fault of the service with no error behind it (a rule of the service itself broken).
    #[error("{0}")]
    Internal(String),
    /// A fault of the service caused by another error, kept whole for the logs: `context`
    /// says what the service was doing.
    #[error("{context}")]
    Failed {
        context: String,
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// An error followed by its causes, `what: why: root cause`, as the logs show it. A cause
/// whose words the error above it already says is not repeated.
pub struct Chain<'a>(pub &'a (dyn std::error::Error + 'static));

impl std::fmt::Display for Chain<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut said = self.0.to_string();
        f.write_str(&said)?;
        let mut next = self.0.source();
        while let Some(cause) = next {
            let words = cause.to_string();
            if !said.contains(&words) {
                write!(f, ": {words}")?;
            }
            said = words;
            next = cause.source();
        }
        Ok(())
    }
}

/// An error and its causes, outermost first.
fn causes<'a>(
    e: &'a (dyn std::error::Error + 'static),
) -> impl Iterator<Item = &'a (dyn std::error::Error + 'static)> {
    std::iter::successors(Some(e), |e| e.source())
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

/// A refused archive is an upload that cannot be evaluated, each refused entry one problem
/// of the answer; an I/O fault stays the service's.
impl From<ArchiveError> for AppError {
    fn from(e: ArchiveError) -> Self {
        match e {
            ArchiveError::Invalid(message) => AppError::Invalid {
                message,
                problems: Vec::new(),
            },
            ArchiveError::Refused { message, entries } => AppError::Invalid {
                message,
                problems: entries
                    .into_iter()
                    .map(|entry| LineProblem {
                        file: Some(entry.file),
                        line: 0,
                        message: entry.message,
                    })
                    .collect(),
            },
            ArchiveError::Io(e) => AppError::Io(e),
        }
    }
}

impl AppError {
    /// A fault of the service while doing `context`, caused by `source`.
    pub fn failed(
        context: impl Into<String>,
        source: impl Into<Box<dyn std::error::Error + Send + Sync>>,
    ) -> AppError {
        AppError::Failed {
            context: context.into(),
            source: source.into(),
        }
    }

    /// A fault that passes: the database could not be reached or asked for a retry (a lost
    /// connection, a restarting server, SQLite busy), so the same request may succeed in a
    /// moment. Looked for in the cause of a [`AppError::Failed`] as well.
    pub fn is_unavailable(&self) -> bool {
        match self {
            AppError::Store(e) => e.is_transient(),
            AppError::Failed { source, .. } => causes(source.as_ref())
                .find_map(|e| e.downcast_ref::<StoreError>())
                .is_some_and(StoreError::is_transient),
            _ => false,
        }
    }

    /// Out of disk space: the database's disk (see [`StoreError::is_storage_full`]) or the
    /// data directory's (`ENOSPC` writing an upload's temporary file), looked for in the cause
    /// of a [`AppError::Failed`] as well. The request kept nothing: the write refused was a
    /// transaction, rolled back whole, or a temporary file, removed as the error unwinds.
    pub fn is_storage_full(&self) -> bool {
        match self {
            AppError::Store(e) => e.is_storage_full(),
            AppError::Io(e) => e.kind() == std::io::ErrorKind::StorageFull,
            AppError::Failed { source, .. } => causes(source.as_ref()).any(|e| {
                e.downcast_ref::<StoreError>()
                    .is_some_and(StoreError::is_storage_full)
                    || e.downcast_ref::<std::io::Error>()
                        .is_some_and(|io| io.kind() == std::io::ErrorKind::StorageFull)
            }),
            _ => false,
        }
    }

    /// A fault of the service (database, I/O, a bug), not of the request: logged with its
    /// cause, and never described to the client.
    pub fn is_internal(&self) -> bool {
        matches!(
            self,
            AppError::Store(_) | AppError::Io(_) | AppError::Internal(_) | AppError::Failed { .. }
        )
    }
}
