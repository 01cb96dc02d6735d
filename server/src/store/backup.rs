//! Backups: a consistent copy of a live database in one SQLite file, and the way back.
//!
//! On SQLite the copy is SQLite's own `VACUUM INTO`: it reads in one transaction, so uploads
//! and evaluations go on while it runs (WAL lets them write meanwhile) and the file holds the
//! database as it was at one instant, compacted. From PostgreSQL the rows go into a new SQLite
//! file through [`Store::copy_into`], read in one repeatable-read snapshot. One format for
//! both means any backup restores into either kind of database; restoring is the same copy in
//! the other direction, in one transaction on the target, so a failed restore changes nothing.

use std::path::Path;

use sqlx::Row;

use super::copy::{CopyReport, TABLES, quoted};
use super::{Backend, Store, StoreError, StoreResult};

impl Store {
    /// Writes a consistent copy of this database into the new SQLite file `path`, which must
    /// not exist yet.
    pub async fn backup_to(&self, path: &Path) -> StoreResult<()> {
        let name = path
            .to_str()
            .ok_or_else(|| StoreError::Url(path.display().to_string()))?;
        match self.backend {
            Backend::Sqlite => {
                sqlx::query("VACUUM INTO $1")
                    .bind(name)
                    .execute(&self.pool)
                    .await?;
            }
            Backend::Postgres => {
                let file = Store::connect(&format!("sqlite://{name}?mode=rwc")).await?;
                self.copy_into(&file, false).await?;
                file.close_as_one_file().await;
            }
        }
        Ok(())
    }

    /// SQLite's integrity check of this database: the problems it lists, none when sound.
    /// PostgreSQL checks its pages itself, so it has nothing to list here.
    pub async fn integrity_problems(&self) -> StoreResult<Vec<String>> {
        if self.backend == Backend::Postgres {
            return Ok(Vec::new());
        }
        let rows = sqlx::query("PRAGMA integrity_check")
            .fetch_all(&self.pool)
            .await?;
        let lines: Vec<String> = rows
            .iter()
            .map(|r| r.try_get::<String, _>(0))
            .collect::<Result<_, _>>()?;
        Ok(lines.into_iter().filter(|l| l != "ok").collect())
    }

    /// Closes every connection, which leaves a SQLite database as one self-contained file:
    /// the last connection to close checkpoints the write-ahead log into the file and removes
    /// the `-wal` and `-shm` files beside it, so the file can be moved or archived alone.
    pub async fn close_as_one_file(self) {
        self.pool.close().await;
    }

    /// The rows of every table a copy carries, in copy order.
    pub async fn row_counts(&self) -> StoreResult<CopyReport> {
        let mut out = Vec::new();
        for table in TABLES {
            let n: i64 = sqlx::query(sqlx::AssertSqlSafe(format!(
                "SELECT COUNT(*) AS n FROM {}",
                quoted(table)
            )))
            .fetch_one(&self.pool)
            .await?
            .try_get("n")?;
            out.push((*table, u64::try_from(n).unwrap_or(0)));
        }
        Ok(out)
    }
}
