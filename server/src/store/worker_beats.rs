//! When each evaluation worker was last seen alive. A worker beats when it polls the queue and
//! whenever it renews a lease, so the newest beat says whether any worker, in this process or
//! on another machine sharing the database, is running: the pages stop promising an ETA when
//! none is, and `/metrics` exposes the beat's age for operators to alert on.

use sqlx::Row;

use super::{Store, StoreResult};

impl Store {
    /// Records that `worker` is alive at `now` (epoch ms).
    pub(super) async fn beat(&self, worker: &str, now: i64) -> StoreResult<()> {
        sqlx::query(
            "INSERT INTO worker_beats (worker, beat_at) VALUES ($1, $2) \
             ON CONFLICT (worker) DO UPDATE SET beat_at = excluded.beat_at",
        )
        .bind(worker)
        .bind(now)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// The newest beat of any worker (epoch ms); `None` if no worker ever beat.
    pub async fn newest_beat(&self) -> StoreResult<Option<i64>> {
        let row = sqlx::query("SELECT MAX(beat_at) AS newest FROM worker_beats")
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get("newest")?)
    }

    /// Forgets workers not seen since `before` (epoch ms): each process beats under a name of
    /// its own, so without this every restart would leave a row behind for good. The newest
    /// beat is always kept, so the age of the last sign of life survives the pruning.
    pub async fn forget_beats_before(&self, before: i64) -> StoreResult<()> {
        sqlx::query(
            "DELETE FROM worker_beats WHERE beat_at < $1 \
             AND beat_at < (SELECT MAX(beat_at) FROM worker_beats)",
        )
        .bind(before)
        .execute(&self.pool)
        .await?;
        Ok(())
    }
}
