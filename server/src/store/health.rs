//! What an operator asks of the database: is it there, is its schema the one this binary
//! expects, and how many submissions wait in each state.

use std::collections::BTreeSet;

use sqlx::Row;

use super::submissions::Status;
use super::{Backend, Store, StoreResult, parse_column};

/// How the applied migrations compare with the ones this binary carries.
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct MigrationState {
    /// Carried here but not applied to the database.
    pub pending: Vec<i64>,
    /// Applied to the database by another (newer) version of poseboard.
    pub unknown: Vec<i64>,
}

impl MigrationState {
    pub fn is_current(&self) -> bool {
        self.pending.is_empty() && self.unknown.is_empty()
    }
}

impl Store {
    /// One round trip to the database.
    pub async fn ping(&self) -> StoreResult<()> {
        sqlx::query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    /// Compares the database's migrations table with this binary's migrations.
    pub async fn migration_state(&self) -> StoreResult<MigrationState> {
        let applied: BTreeSet<i64> =
            sqlx::query("SELECT version FROM _sqlx_migrations WHERE success = $1")
                .bind(true)
                .fetch_all(&self.pool)
                .await?
                .iter()
                .map(|r| r.try_get::<i64, _>("version"))
                .collect::<Result<_, _>>()?;
        let known: BTreeSet<i64> = self.migrator().iter().map(|m| m.version).collect();
        Ok(MigrationState {
            pending: known.difference(&applied).copied().collect(),
            unknown: applied.difference(&known).copied().collect(),
        })
    }

    /// The number of submissions in each state that has any.
    pub async fn queue_depth(&self) -> StoreResult<Vec<(Status, i64)>> {
        let rows = sqlx::query("SELECT status, COUNT(*) AS n FROM submissions GROUP BY status")
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| {
                Ok((
                    parse_column("status", r.try_get("status")?)?,
                    r.try_get("n")?,
                ))
            })
            .collect()
    }
}

impl Backend {
    /// The name this backend goes by in messages.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Sqlite => "SQLite",
            Backend::Postgres => "PostgreSQL",
        }
    }
}
