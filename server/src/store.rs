//! Storage of datasets, methods, submissions (which are also the evaluation jobs), scores,
//! accounts and the audit log, in SQLite by default or PostgreSQL. One store over `sqlx::Any`,
//! with the SQL kept common (`$N` placeholders, `RETURNING`) and a backend switch only where
//! the dialects differ (the job claim, write transactions, connection setup, migrations).
//! Times are epoch milliseconds; booleans 0/1.
//!
//! The store speaks in types: rows come back as structs and enums, and a stored value that no
//! longer parses (an unknown status, say) is a [`StoreError::Corrupt`], never a silent default.
//! It knows nothing of HTTP; the service maps [`StoreError`] to statuses in one place.

use std::path::Path;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;

use sqlx::any::AnyPoolOptions;
use sqlx::migrate::Migrator;
use sqlx::{Any, AnyPool, Connection as _, Transaction};

pub mod accounts;
pub mod audit;
pub mod backup;
pub mod board_rows;
pub mod board_version;
pub mod bop24_scores;
pub mod challenges;
pub mod coco_scores;
pub mod copy;
pub mod datasets;
pub mod files;
pub mod groups;
pub mod health;
pub mod methods;
pub mod pose_errors;
pub mod preparations;
pub mod queue;
pub mod rescoring;
pub mod scores;
pub mod snapshots;
pub mod submissions;
pub mod teams;
pub mod worker_beats;

static SQLITE_MIGRATIONS: Migrator = sqlx::migrate!("../migrations/sqlite");
static POSTGRES_MIGRATIONS: Migrator = sqlx::migrate!("../migrations/postgres");

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

#[derive(Clone)]
pub struct Store {
    pool: AnyPool,
    backend: Backend,
    /// Board changes committed through this store (shared by its clones).
    board_changes: Arc<AtomicU64>,
}

#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    #[error("not found")]
    NotFound,
    /// A row that would break a unique constraint; PostgreSQL names the constraint, SQLite not.
    #[error("already exists ({})", constraint.as_deref().unwrap_or("unique constraint"))]
    Unique { constraint: Option<String> },
    /// A stored value that does not parse: the database was changed behind the service's back
    /// or by a newer version of it.
    #[error("stored value {value:?} in `{column}` is not valid")]
    Corrupt { column: &'static str, value: String },
    #[error("unsupported database URL `{0}`: use sqlite://... or postgres://...")]
    Url(String),
    #[error("migrations: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    #[error("database: {0}")]
    Database(sqlx::Error),
    /// The two databases of a copy do not have the same tables and columns.
    #[error("{0}")]
    Schema(String),
    /// A copy target that already holds data, which a copy would mix with the source's.
    #[error("the target database is not empty (rows in {}): copy into an empty database, or pass --force to replace its contents", .0.join(", "))]
    NotEmpty(Vec<String>),
}

impl From<sqlx::Error> for StoreError {
    fn from(e: sqlx::Error) -> Self {
        match e.as_database_error() {
            Some(d) if d.is_unique_violation() => StoreError::Unique {
                constraint: d.constraint().map(str::to_string),
            },
            _ => StoreError::Database(e),
        }
    }
}

impl StoreError {
    /// Whether trying again may succeed: the connection was lost or refused (a restarting or
    /// failing-over database, `pg_terminate_backend`), the pool ran dry, or the database asked
    /// for a retry (serialization failure, deadlock, SQLite busy).
    pub fn is_transient(&self) -> bool {
        let StoreError::Database(e) = self else {
            return false;
        };
        match e {
            sqlx::Error::Io(_)
            | sqlx::Error::Tls(_)
            | sqlx::Error::Protocol(_)
            | sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::WorkerCrashed => true,
            sqlx::Error::Database(d) => d.code().is_some_and(|code| {
                // PostgreSQL: connection exceptions (08), operator intervention such as
                // admin_shutdown (57P), serialization failure and deadlock (40001, 40P01).
                // SQLite (codes of at most 4 digits, where PostgreSQL's have 5 characters):
                // SQLITE_BUSY (5) and SQLITE_LOCKED (6), with their extended codes.
                code.starts_with("08")
                    || code.starts_with("57P")
                    || code == "40001"
                    || code == "40P01"
                    || (code.len() <= 4
                        && code.parse::<i64>().is_ok_and(|n| matches!(n & 0xff, 5 | 6)))
            }),
            _ => false,
        }
    }

    /// Whether the database's disk is full: PostgreSQL's `disk_full` (SQLSTATE 53100) or
    /// SQLite's `SQLITE_FULL` (13). Not transient, since trying again at once fails the same
    /// way, and not a bug: the write was refused whole (the transaction rolled back), so the
    /// service answers that it is out of room rather than that it broke.
    pub fn is_storage_full(&self) -> bool {
        let StoreError::Database(sqlx::Error::Database(d)) = self else {
            return false;
        };
        d.code().is_some_and(|code| {
            code == "53100"
                || (code.len() <= 4 && code.parse::<i64>().is_ok_and(|n| n & 0xff == 13))
        })
    }
}

pub type StoreResult<T> = Result<T, StoreError>;

/// Parses a stored text column into its type; a value that does not parse is corruption.
pub(crate) fn parse_column<T: FromStr>(column: &'static str, value: String) -> StoreResult<T> {
    value
        .parse()
        .map_err(|_| StoreError::Corrupt { column, value })
}

/// The rows of `select` (a statement ending in `IN`) for each of `ids`, asked in slices of 500:
/// no database takes an unbounded number of parameters, and a board may ask for thousands.
/// Only the placeholders' count comes from the caller, never a value.
pub(crate) async fn fetch_in<'a, I>(
    pool: &AnyPool,
    select: &'static str,
    ids: &'a [I],
) -> StoreResult<Vec<sqlx::any::AnyRow>>
where
    I: sqlx::Encode<'a, Any> + sqlx::Type<Any> + Sync,
{
    let mut rows = Vec::new();
    for chunk in ids.chunks(500) {
        let marks: Vec<String> = (1..=chunk.len()).map(|i| format!("${i}")).collect();
        let sql = format!("{select} ({})", marks.join(", "));
        let mut query = sqlx::query(sqlx::AssertSqlSafe(sql));
        for id in chunk {
            query = query.bind(id);
        }
        rows.extend(query.fetch_all(pool).await?);
    }
    Ok(rows)
}

/// The default database: a SQLite file in the data directory.
pub fn sqlite_url(data_dir: &Path) -> String {
    format!(
        "sqlite://{}?mode=rwc",
        data_dir.join("poseboard.db").display()
    )
}

impl Store {
    /// Connects to `url` (`sqlite://...` or `postgres://...`); a SQLite file is created when
    /// missing and put in WAL mode so that pages read while a worker writes.
    pub async fn connect(url: &str) -> StoreResult<Store> {
        sqlx::any::install_default_drivers();
        let backend = if url.starts_with("postgres") {
            Backend::Postgres
        } else if url.starts_with("sqlite") {
            Backend::Sqlite
        } else {
            return Err(StoreError::Url(url.to_string()));
        };
        let mut options = AnyPoolOptions::new()
            .max_connections(if backend == Backend::Sqlite { 4 } else { 10 })
            // SQLite rolls a transaction back by itself when its COMMIT fails for want of disk
            // (SQLITE_FULL); sqlx then still counts the connection as inside it, its own
            // ROLLBACK failing, and every later `begin` on that connection fails. Such a
            // connection is closed when next taken from the pool rather than handed out: the
            // request after a full disk was made room for succeeds instead of a 500.
            .before_acquire(|conn, _| Box::pin(async move { Ok(!conn.is_in_transaction()) }));
        if backend == Backend::Sqlite {
            options = options.after_connect(|conn, _| {
                Box::pin(async move {
                    for pragma in [
                        "PRAGMA journal_mode = WAL",
                        "PRAGMA busy_timeout = 10000",
                        "PRAGMA foreign_keys = ON",
                        "PRAGMA synchronous = NORMAL",
                    ] {
                        sqlx::query(pragma).execute(&mut *conn).await?;
                    }
                    Ok(())
                })
            });
        }
        let pool = options.connect(url).await?;
        Ok(Store {
            pool,
            backend,
            board_changes: Arc::new(AtomicU64::new(0)),
        })
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    pub async fn migrate(&self) -> StoreResult<()> {
        self.migrator().run(&self.pool).await?;
        Ok(())
    }

    /// The migrations of this backend, as built into the binary.
    fn migrator(&self) -> &'static Migrator {
        match self.backend {
            Backend::Sqlite => &SQLITE_MIGRATIONS,
            Backend::Postgres => &POSTGRES_MIGRATIONS,
        }
    }

    /// A transaction that will write: on SQLite it takes the write lock at once (`BEGIN
    /// IMMEDIATE`), so that reading then writing cannot fail half-way with `SQLITE_BUSY` when
    /// another writer got in between; PostgreSQL locks rows as the statements ask.
    async fn write_transaction(&self) -> StoreResult<Transaction<'static, Any>> {
        Ok(match self.backend {
            Backend::Sqlite => self.pool.begin_with("BEGIN IMMEDIATE").await?,
            Backend::Postgres => self.pool.begin().await?,
        })
    }
}
