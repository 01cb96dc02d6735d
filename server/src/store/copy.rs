//! Moving house: every row of one poseboard database copied into another, of either kind,
//! keeping ids, so that a grown SQLite installation moves to PostgreSQL (or back) with its
//! accounts, password and token hashes, sessions, methods, submissions, scores, rate counters
//! and audit log intact.
//!
//! The copy is driven by [`TABLES`] and the databases' own catalogues: the columns and their
//! kinds are read from the source, checked against the target, and copied by name. A new table
//! is one line in [`TABLES`]; a database holding a table missing there is refused rather than
//! copied in part. The source is read in one snapshot (a running server may stay up); the
//! target is written in one transaction, so a failed copy leaves it as it was.

use futures_util::TryStreamExt;
use sqlx::any::AnyRow;
use sqlx::{Any, Row, Transaction};

use super::{Backend, Store, StoreError, StoreResult};

/// Every table of the schema, parents before children (foreign keys are checked as rows go in).
pub(super) const TABLES: &[&str] = &[
    "users",
    "teams",
    "team_members",
    "team_invitations",
    "datasets",
    "dataset_preparations",
    "methods",
    "submissions",
    "submission_files",
    "scores",
    "object_scores",
    "coco_scores",
    "bop24_scores",
    "entry_pins",
    "estimate_errors",
    "api_tokens",
    "sessions",
    "audit_log",
    "rate_counters",
    "sign_in_addresses",
    "snapshots",
    "snapshot_boards",
    "challenges",
    "challenge_entries",
    "challenge_award_overrides",
    "score_changes",
    "worker_beats",
    "dataset_groups",
    "dataset_group_members",
];

/// Tables the migrations seed with defaults (BOP's dataset groups): a fresh target holds those
/// rows, which the copy replaces with the source's, so they do not make the target "filled".
const SEEDED: &[&str] = &["dataset_groups", "dataset_group_members"];

/// Tables the migrations create and seed themselves, holding no data of their own: not copied.
/// The board version is bumped on the target instead, so servers already running on it drop
/// the boards they rendered before the copy.
const BOOKKEEPING: &[&str] = &["board_version"];

/// The value kinds `sqlx::Any` carries; every column of the schema is one of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Int,
    Real,
    Text,
    Bytes,
}

impl Kind {
    /// The kind of a declared SQLite type or a PostgreSQL `data_type`.
    fn of(declared: &str) -> Option<Kind> {
        match declared.to_ascii_lowercase().as_str() {
            "integer" | "bigint" | "int" | "int8" | "smallint" => Some(Kind::Int),
            "real" | "double precision" | "float8" => Some(Kind::Real),
            "text" | "character varying" | "varchar" => Some(Kind::Text),
            "blob" | "bytea" => Some(Kind::Bytes),
            _ => None,
        }
    }
}

/// Rows copied per table, in copy order.
pub type CopyReport = Vec<(&'static str, u64)>;

impl Store {
    /// Copies every row of this database into `target` (migrated first), in one transaction
    /// on the target. A target holding any row is refused unless `force`, which replaces its
    /// contents. Both databases must be at this binary's migrations.
    pub async fn copy_into(&self, target: &Store, force: bool) -> StoreResult<CopyReport> {
        let state = self.migration_state().await?;
        if !state.is_current() {
            return Err(StoreError::Schema(format!(
                "the source database is not at this version's migrations (not applied: {:?}, \
                 unknown here: {:?}): run `poseboard migrate` with this version on it first",
                state.pending, state.unknown
            )));
        }
        target.migrate().await?;
        let mut columns = Vec::with_capacity(TABLES.len());
        for table in TABLES {
            let src = self.columns(table).await?;
            let dst = target.columns(table).await?;
            if src != dst {
                return Err(StoreError::Schema(format!(
                    "table {table} differs: source columns {src:?}, target columns {dst:?}"
                )));
            }
            columns.push(src);
        }
        for store in [self, target] {
            let extra: Vec<String> = store
                .tables()
                .await?
                .into_iter()
                .filter(|t| !TABLES.contains(&t.as_str()) && !BOOKKEEPING.contains(&t.as_str()))
                .collect();
            if !extra.is_empty() {
                return Err(StoreError::Schema(format!(
                    "the {} database holds tables this version cannot copy: {}",
                    store.backend.name(),
                    extra.join(", ")
                )));
            }
        }

        let mut source = match self.backend {
            // One snapshot of every table, even while a server writes.
            Backend::Postgres => {
                self.pool
                    .begin_with("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY")
                    .await?
            }
            Backend::Sqlite => self.pool.begin().await?,
        };
        let mut tx = target.write_transaction().await?;
        let mut filled = Vec::new();
        for table in TABLES.iter().filter(|t| !SEEDED.contains(t)) {
            let any = sqlx::query(sqlx::AssertSqlSafe(format!(
                "SELECT 1 FROM {} LIMIT 1",
                quoted(table)
            )))
            .fetch_optional(&mut *tx)
            .await?;
            if any.is_some() {
                filled.push(table.to_string());
            }
        }
        if !filled.is_empty() && !force {
            return Err(StoreError::NotEmpty(filled));
        }
        for table in TABLES.iter().rev() {
            sqlx::query(sqlx::AssertSqlSafe(format!(
                "DELETE FROM {}",
                quoted(table)
            )))
            .execute(&mut *tx)
            .await?;
        }

        let mut report = Vec::with_capacity(TABLES.len());
        for (table, cols) in TABLES.iter().zip(&columns) {
            let n = copy_table(&mut source, &mut tx, table, cols).await?;
            if target.backend == Backend::Postgres && cols.iter().any(|(c, _)| c == "id") {
                // Ids were given, so the serial sequence did not move: new rows continue after
                // the copied ones.
                sqlx::query(sqlx::AssertSqlSafe(format!(
                    "SELECT setval(pg_get_serial_sequence('{table}', 'id'), MAX(id)) \
                     FROM {} HAVING MAX(id) IS NOT NULL",
                    quoted(table)
                )))
                .execute(&mut *tx)
                .await?;
            }
            report.push((*table, n));
        }
        super::board_version::bump(&mut tx).await?;
        tx.commit().await?;
        source.rollback().await?;
        Ok(report)
    }

    /// The tables of the schema, without the migrations' own table.
    async fn tables(&self) -> StoreResult<Vec<String>> {
        let sql = match self.backend {
            Backend::Sqlite => {
                "SELECT name FROM sqlite_master WHERE type = 'table' \
                 AND name NOT LIKE 'sqlite_%' AND name <> '_sqlx_migrations' ORDER BY name"
            }
            Backend::Postgres => {
                "SELECT table_name::text AS name FROM information_schema.tables \
                 WHERE table_schema = current_schema() AND table_type = 'BASE TABLE' \
                 AND table_name <> '_sqlx_migrations' ORDER BY table_name"
            }
        };
        let rows = sqlx::query(sql).fetch_all(&self.pool).await?;
        rows.iter()
            .map(|r| Ok(r.try_get::<String, _>("name")?))
            .collect()
    }

    /// The columns of `table` with their kinds, sorted by name (the two backends order
    /// columns added by later migrations differently).
    async fn columns(&self, table: &str) -> StoreResult<Vec<(String, Kind)>> {
        let sql = match self.backend {
            Backend::Sqlite => "SELECT name, type AS kind FROM pragma_table_info($1)",
            Backend::Postgres => {
                "SELECT column_name::text AS name, data_type::text AS kind \
                 FROM information_schema.columns \
                 WHERE table_schema = current_schema() AND table_name = $1"
            }
        };
        let rows = sqlx::query(sql).bind(table).fetch_all(&self.pool).await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            let name: String = r.try_get("name")?;
            let declared: String = r.try_get("kind")?;
            let kind = Kind::of(&declared).ok_or_else(|| {
                StoreError::Schema(format!(
                    "column {table}.{name} has the type {declared}, which the copy does not carry"
                ))
            })?;
            out.push((name, kind));
        }
        if out.is_empty() {
            return Err(StoreError::Schema(format!(
                "the {} database has no table {table}",
                self.backend.name()
            )));
        }
        out.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(out)
    }
}

pub(super) fn quoted(identifier: &str) -> String {
    format!("\"{}\"", identifier.replace('"', "\"\""))
}

/// Streams the rows of `table` from the source snapshot into the target transaction.
async fn copy_table(
    source: &mut Transaction<'static, Any>,
    target: &mut Transaction<'static, Any>,
    table: &str,
    columns: &[(String, Kind)],
) -> StoreResult<u64> {
    let names: Vec<String> = columns.iter().map(|(c, _)| quoted(c)).collect();
    let select = format!(
        "SELECT {} FROM {} ORDER BY 1",
        names.join(", "),
        quoted(table)
    );
    let params: Vec<String> = (1..=columns.len()).map(|i| format!("${i}")).collect();
    let insert = format!(
        "INSERT INTO {} ({}) VALUES ({})",
        quoted(table),
        names.join(", "),
        params.join(", ")
    );
    let mut rows = sqlx::query(sqlx::AssertSqlSafe(select)).fetch(&mut **source);
    let mut n = 0;
    while let Some(row) = rows.try_next().await? {
        // Not cached: a column's NULL and its values would otherwise share one prepared type.
        let mut q = sqlx::query(sqlx::AssertSqlSafe(insert.clone())).persistent(false);
        for (i, (_, kind)) in columns.iter().enumerate() {
            q = bind(q, &row, i, *kind)?;
        }
        q.execute(&mut **target).await?;
        n += 1;
    }
    Ok(n)
}

type Query<'q> = sqlx::query::Query<'q, Any, sqlx::any::AnyArguments>;

fn bind<'q>(q: Query<'q>, row: &AnyRow, i: usize, kind: Kind) -> StoreResult<Query<'q>> {
    Ok(match kind {
        Kind::Int => q.bind(row.try_get::<Option<i64>, _>(i)?),
        Kind::Real => q.bind(row.try_get::<Option<f64>, _>(i)?),
        Kind::Text => q.bind(row.try_get::<Option<String>, _>(i)?),
        Kind::Bytes => q.bind(row.try_get::<Option<Vec<u8>>, _>(i)?),
    })
}
