//! The per-estimate errors behind a submission's scores: every evaluated estimate's errors
//! against each ground-truth instance of its object (the layout of `poseboard eval
//! --errors-out`), kept gzip-compressed, one row per submission and protocol, written in the
//! transaction that stores the scores. Its owner downloads them; comparing two submissions
//! estimate by estimate reads them through [`Store::estimate_errors`].

use std::collections::BTreeMap;
use std::io::Read;

use evaluator::matching::EstimateErrors;
use evaluator::protocol::{Protocol, ProtocolName, columns};
use flate2::read::GzDecoder;
use serde::{Deserialize, Serialize};
use sqlx::Row;

use super::{Store, StoreError, StoreResult, parse_column};
use crate::domain::SubmissionId;

/// One evaluated estimate with its errors, as `poseboard eval --errors-out` writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorRow {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    /// Position among the file's rows for the same scene, image and object.
    pub est_id: u32,
    pub score: f64,
    /// The ground-truth instances of the object in the image.
    pub gt_ids: Vec<u32>,
    /// Per error signature (bop_toolkit's), the error against each of `gt_ids`; `None` where
    /// JSON cannot hold the value (an infinite error).
    pub errors: BTreeMap<String, Vec<Option<f64>>>,
}

/// The stored errors of one submission under one protocol.
#[derive(Clone, Debug)]
pub struct StoredErrors {
    pub submission_id: SubmissionId,
    pub protocol: ProtocolName,
    pub rows_count: i64,
    /// The JSON array of rows, gzip-compressed.
    pub gzip: Vec<u8>,
}

impl StoredErrors {
    /// The JSON text, as `poseboard eval --errors-out` would write it (without its indents).
    pub fn json(&self) -> StoreResult<Vec<u8>> {
        let mut out = Vec::with_capacity(self.gzip.len() * 4);
        GzDecoder::new(&self.gzip[..])
            .read_to_end(&mut out)
            .map_err(|e| self.corrupt(e.to_string()))?;
        Ok(out)
    }

    /// The rows, typed.
    pub fn rows(&self) -> StoreResult<Vec<ErrorRow>> {
        serde_json::from_slice(&self.json()?).map_err(|e| self.corrupt(e.to_string()))
    }

    /// The rows as the evaluator's type, with the errors in the columns of `protocol` (the
    /// one they were computed under): what the outcomes of single targets are made from.
    pub fn estimates(&self, protocol: &Protocol) -> StoreResult<Vec<EstimateErrors>> {
        let columns = columns(protocol);
        self.rows()?
            .into_iter()
            .map(|mut r| {
                let errors = columns
                    .iter()
                    .map(|c| {
                        let values = r.errors.remove(&c.signature).ok_or_else(|| {
                            self.corrupt(format!("no errors under {}", c.signature))
                        })?;
                        Ok(values
                            .into_iter()
                            .map(|v| v.unwrap_or(f64::INFINITY))
                            .collect())
                    })
                    .collect::<StoreResult<_>>()?;
                Ok(EstimateErrors {
                    scene_id: r.scene_id,
                    im_id: r.im_id,
                    obj_id: r.obj_id,
                    est_id: r.est_id,
                    score: r.score,
                    gt_ids: r.gt_ids,
                    errors,
                })
            })
            .collect()
    }

    fn corrupt(&self, reason: String) -> StoreError {
        StoreError::Corrupt {
            column: "estimate_errors.gzip",
            value: format!(
                "submission {} {}: {reason}",
                self.submission_id,
                self.protocol.as_str()
            ),
        }
    }
}

/// The errors of one protocol, ready to be stored with its scores.
pub struct NewErrors {
    pub protocol: ProtocolName,
    pub rows_count: i64,
    pub gzip: Vec<u8>,
}

/// Replaces the stored errors of submission `id` inside the transaction storing its scores.
pub(super) async fn replace(
    tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    id: SubmissionId,
    errors: &[NewErrors],
    now: i64,
) -> StoreResult<()> {
    sqlx::query("DELETE FROM estimate_errors WHERE submission_id = $1")
        .bind(id)
        .execute(&mut **tx)
        .await?;
    for e in errors {
        sqlx::query(
            "INSERT INTO estimate_errors (submission_id, protocol, rows_count, gzip, created_at) \
             VALUES ($1, $2, $3, $4, $5)",
        )
        .bind(id)
        .bind(e.protocol.as_str())
        .bind(e.rows_count)
        .bind(&e.gzip[..])
        .bind(now)
        .execute(&mut **tx)
        .await?;
    }
    Ok(())
}

impl Store {
    /// The errors of submission `id` under `protocol`, if it was evaluated under it.
    pub async fn estimate_errors(
        &self,
        id: SubmissionId,
        protocol: ProtocolName,
    ) -> StoreResult<Option<StoredErrors>> {
        let row = sqlx::query(
            "SELECT submission_id, protocol, rows_count, gzip FROM estimate_errors \
             WHERE submission_id = $1 AND protocol = $2",
        )
        .bind(id)
        .bind(protocol.as_str())
        .fetch_optional(&self.pool)
        .await?;
        row.map(|r| {
            Ok(StoredErrors {
                submission_id: r.try_get("submission_id")?,
                protocol: parse_column("protocol", r.try_get("protocol")?)?,
                rows_count: r.try_get("rows_count")?,
                gzip: r.try_get("gzip")?,
            })
        })
        .transpose()
    }
}
