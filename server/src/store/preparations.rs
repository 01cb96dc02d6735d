//! How far each evaluating host has prepared each dataset. The prepared forms live on the
//! workers' disks, which no server can see, and the datasets page may be served by any server:
//! so the workers record their progress here and the page reads it. A row is one prepared
//! folder of one host, so several workers on one machine sharing a data directory share a row,
//! and workers on several machines each have their own.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;
use sqlx::Row;

use super::{Store, StoreResult, parse_column};
use crate::clock::now_ms;
use crate::domain::DatasetId;

/// Where a host's preparation of a dataset stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PreparationState {
    /// Under way (or waiting for another process preparing the same folder): evaluations read
    /// the dataset meanwhile.
    Preparing,
    /// Complete and current: evaluations read it.
    Ready,
    /// Could not be made (the reason is in `detail`): evaluations read the dataset.
    Failed,
}

impl PreparationState {
    pub fn as_str(self) -> &'static str {
        match self {
            PreparationState::Preparing => "preparing",
            PreparationState::Ready => "ready",
            PreparationState::Failed => "failed",
        }
    }
}

impl FromStr for PreparationState {
    type Err = ();
    fn from_str(s: &str) -> Result<Self, ()> {
        match s {
            "preparing" => Ok(PreparationState::Preparing),
            "ready" => Ok(PreparationState::Ready),
            "failed" => Ok(PreparationState::Failed),
            _ => Err(()),
        }
    }
}

impl fmt::Display for PreparationState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One host's preparation of one dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PreparationRow {
    #[serde(skip)]
    pub dataset_id: DatasetId,
    /// The machine's name.
    pub host: String,
    /// The folder its prepared forms are kept in, on that machine.
    pub folder: String,
    pub state: PreparationState,
    /// Target images prepared (or found intact) so far, of `images_total` (0 while unknown).
    pub images_done: i64,
    pub images_total: i64,
    /// Why it failed, or what a preparation under way waits for.
    pub detail: Option<String>,
    /// When it was last written (epoch ms).
    pub updated_at: i64,
}

impl Store {
    /// Records a host's preparation of a dataset as it stands now.
    pub async fn save_preparation(&self, p: &PreparationRow) -> StoreResult<()> {
        sqlx::query(
            "INSERT INTO dataset_preparations (dataset_id, host, folder, state, images_done, \
             images_total, detail, updated_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) \
             ON CONFLICT (dataset_id, host, folder) DO UPDATE SET state = excluded.state, \
             images_done = excluded.images_done, images_total = excluded.images_total, \
             detail = excluded.detail, updated_at = excluded.updated_at",
        )
        .bind(p.dataset_id)
        .bind(&p.host)
        .bind(&p.folder)
        .bind(p.state.as_str())
        .bind(p.images_done)
        .bind(p.images_total)
        .bind(&p.detail)
        .bind(now_ms())
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// Every recorded preparation, by dataset, host and folder.
    pub async fn preparations(&self) -> StoreResult<Vec<PreparationRow>> {
        let rows =
            sqlx::query("SELECT * FROM dataset_preparations ORDER BY dataset_id, host, folder")
                .fetch_all(&self.pool)
                .await?;
        rows.iter()
            .map(|r| {
                Ok(PreparationRow {
                    dataset_id: r.try_get("dataset_id")?,
                    host: r.try_get("host")?,
                    folder: r.try_get("folder")?,
                    state: parse_column("state", r.try_get("state")?)?,
                    images_done: r.try_get("images_done")?,
                    images_total: r.try_get("images_total")?,
                    detail: r.try_get("detail")?,
                    updated_at: r.try_get("updated_at")?,
                })
            })
            .collect()
    }
}
