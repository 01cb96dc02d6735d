//! Dated snapshots of the leaderboards: the rendered boards of one moment, kept as bytes
//! (gzip-compressed) so that what a paper cites is served back exactly, whatever changes later
//! (scores, templates, the evaluator).

use serde::Serialize;
use sqlx::{Any, Row, Transaction};

use super::{Store, StoreResult, parse_column};
use crate::domain::{BoardProtocol, SnapshotId, UserId};

/// Which rendering of a board a snapshot holds: the page and its JSON twin, and the exports
/// (CSV, JSON) its page offers. Snapshots taken before the exports were kept hold the first
/// two only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardFormat {
    Html,
    Json,
    Csv,
    ExportJson,
}

impl BoardFormat {
    pub fn as_str(self) -> &'static str {
        match self {
            BoardFormat::Html => "html",
            BoardFormat::Json => "json",
            BoardFormat::Csv => "csv",
            BoardFormat::ExportJson => "export.json",
        }
    }
}

/// One stored board: which one, and its bytes gzip-compressed.
pub struct SnapshotBoard {
    pub protocol: BoardProtocol,
    /// Empty for the board of all datasets.
    pub dataset: String,
    pub format: BoardFormat,
    pub gzip: Vec<u8>,
}

/// A complete snapshot, without its bytes.
#[derive(Clone, Debug, Serialize)]
pub struct SnapshotRow {
    pub id: SnapshotId,
    pub taken_at: i64,
    /// The administrator who took it.
    pub taken_by: String,
    /// The boards it holds, as (protocol, dataset; empty for all datasets), each in every format.
    pub boards: Vec<(BoardProtocol, String)>,
}

/// Stores every board of snapshot `id` and marks it complete, in the caller's transaction (a
/// challenge's snapshot is recorded with the challenge in the same one).
pub(super) async fn insert_boards(
    tx: &mut Transaction<'static, Any>,
    id: SnapshotId,
    boards: &[SnapshotBoard],
) -> StoreResult<()> {
    for b in boards {
        sqlx::query(
            "INSERT INTO snapshot_boards (snapshot_id, protocol, dataset, format, gzip) \
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(id)
        .bind(b.protocol.as_str())
        .bind(&b.dataset)
        .bind(b.format.as_str())
        .bind(&b.gzip)
        .execute(&mut **tx)
        .await?;
    }
    sqlx::query("UPDATE snapshots SET complete = 1 WHERE id = $1")
        .bind(id)
        .execute(&mut **tx)
        .await?;
    Ok(())
}

impl Store {
    /// Starts a snapshot: its id (which its pages name) before its boards are rendered. It is
    /// shown nowhere until [`Store::complete_snapshot`].
    pub async fn begin_snapshot(&self, taken_by: UserId, taken_at: i64) -> StoreResult<SnapshotId> {
        let row = sqlx::query(
            "INSERT INTO snapshots (taken_at, taken_by, complete) VALUES ($1, $2, 0) RETURNING id",
        )
        .bind(taken_at)
        .bind(taken_by)
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    /// Stores every board of snapshot `id` and makes it visible, all at once.
    pub async fn complete_snapshot(
        &self,
        id: SnapshotId,
        boards: &[SnapshotBoard],
    ) -> StoreResult<()> {
        let mut tx = self.write_transaction().await?;
        insert_boards(&mut tx, id, boards).await?;
        tx.commit().await?;
        Ok(())
    }

    /// Drops a snapshot whose boards could not all be rendered.
    pub async fn discard_snapshot(&self, id: SnapshotId) -> StoreResult<()> {
        sqlx::query("DELETE FROM snapshots WHERE id = $1 AND complete = 0")
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// Every complete snapshot, newest first.
    pub async fn snapshots(&self) -> StoreResult<Vec<SnapshotRow>> {
        let rows = sqlx::query(
            "SELECT s.id, s.taken_at, u.name FROM snapshots s JOIN users u ON u.id = s.taken_by \
             WHERE s.complete = 1 ORDER BY s.id DESC",
        )
        .fetch_all(&self.pool)
        .await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            let id: SnapshotId = r.try_get("id")?;
            out.push(SnapshotRow {
                id,
                taken_at: r.try_get("taken_at")?,
                taken_by: r.try_get("name")?,
                boards: self.snapshot_boards(id).await?,
            });
        }
        Ok(out)
    }

    /// A complete snapshot.
    pub async fn snapshot(&self, id: SnapshotId) -> StoreResult<Option<SnapshotRow>> {
        let row = sqlx::query(
            "SELECT s.id, s.taken_at, u.name FROM snapshots s JOIN users u ON u.id = s.taken_by \
             WHERE s.id = $1 AND s.complete = 1",
        )
        .bind(id)
        .fetch_optional(&self.pool)
        .await?;
        let Some(r) = row else {
            return Ok(None);
        };
        Ok(Some(SnapshotRow {
            id,
            taken_at: r.try_get("taken_at")?,
            taken_by: r.try_get("name")?,
            boards: self.snapshot_boards(id).await?,
        }))
    }

    async fn snapshot_boards(&self, id: SnapshotId) -> StoreResult<Vec<(BoardProtocol, String)>> {
        let rows = sqlx::query(
            "SELECT DISTINCT protocol, dataset FROM snapshot_boards WHERE snapshot_id = $1 \
             ORDER BY protocol, dataset",
        )
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok((
                    parse_column("protocol", r.try_get("protocol")?)?,
                    r.try_get("dataset")?,
                ))
            })
            .collect()
    }

    /// The stored bytes (gzip-compressed) of one board of a complete snapshot.
    pub async fn snapshot_board(
        &self,
        id: SnapshotId,
        protocol: BoardProtocol,
        dataset: &str,
        format: BoardFormat,
    ) -> StoreResult<Option<Vec<u8>>> {
        let row = sqlx::query(
            "SELECT b.gzip FROM snapshot_boards b \
             JOIN snapshots s ON s.id = b.snapshot_id AND s.complete = 1 \
             WHERE b.snapshot_id = $1 AND b.protocol = $2 AND b.dataset = $3 AND b.format = $4",
        )
        .bind(id)
        .bind(protocol.as_str())
        .bind(dataset)
        .bind(format.as_str())
        .fetch_optional(&self.pool)
        .await?;
        row.map(|r| Ok(r.try_get("gzip")?)).transpose()
    }
}
