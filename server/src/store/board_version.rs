//! The board version: one number in the database, bumped in the same transaction as every
//! change a leaderboard can show, so that every server sharing the database can tell whether
//! the boards it rendered are still current (see `crate::board_cache`). This process's own
//! changes are also counted in memory, so its cache drops stale boards at once instead of at its
//! next look at the database.

use std::sync::atomic::Ordering;

use sqlx::{Any, Row, Transaction};

use super::{Store, StoreResult};

/// Bumps the board version inside `tx`: it becomes visible exactly when the change does. Call
/// [`Store::board_changed`] once `tx` has committed.
pub(crate) async fn bump(tx: &mut Transaction<'static, Any>) -> StoreResult<()> {
    sqlx::query("UPDATE board_version SET version = version + 1 WHERE id = 1")
        .execute(&mut **tx)
        .await?;
    Ok(())
}

impl Store {
    /// The board version as committed in the database.
    pub async fn board_version(&self) -> StoreResult<i64> {
        let row = sqlx::query("SELECT version FROM board_version WHERE id = 1")
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get("version")?)
    }

    /// How many board changes this store (this process) has committed: a cheap first look
    /// before the database is asked.
    pub fn local_board_changes(&self) -> u64 {
        self.board_changes.load(Ordering::Acquire)
    }

    /// Commits `tx`, bumping the board version first when it `changed` something a board
    /// shows; returns `changed`.
    pub(crate) async fn commit_board_change(
        &self,
        mut tx: Transaction<'static, Any>,
        changed: bool,
    ) -> StoreResult<bool> {
        if changed {
            bump(&mut tx).await?;
        }
        tx.commit().await?;
        if changed {
            self.board_changed();
        }
        Ok(changed)
    }

    /// Records that a transaction with [`bump`] committed.
    pub(crate) fn board_changed(&self) {
        self.board_changes.fetch_add(1, Ordering::AcqRel);
    }
}
