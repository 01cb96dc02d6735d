//! Scores: one row per submission and protocol, with the evaluator's full report kept as JSON
//! (read back as a `Report`) and the per-object numbers in a table of their own for the
//! leaderboards.

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::protocol::ProtocolName;
use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::methods::optional_column;
use super::{Store, StoreError, StoreResult, parse_column};
use crate::domain::{Modality, TrainingData};

/// One protocol's headline numbers of a submission.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoreRow {
    pub id: i64,
    pub submission_id: i64,
    pub protocol: ProtocolName,
    pub score: f64,
    pub recall: Option<f64>,
    pub ar_vsd: Option<f64>,
    pub ar_mssd: Option<f64>,
    pub ar_mspd: Option<f64>,
    pub time_avg: Option<f64>,
    pub estimates_evaluated: i64,
    pub estimates_ignored: i64,
}

/// A leaderboard entry: the latest finished public submission of a method on a dataset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoardEntry {
    pub method_id: i64,
    pub method: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub hardware: String,
    pub dataset_id: i64,
    pub dataset: String,
    pub submission_id: i64,
    pub submitted_at: i64,
    pub score: ScoreRow,
    pub object_scores: BTreeMap<i64, f64>,
}

fn score(row: &AnyRow) -> StoreResult<ScoreRow> {
    Ok(ScoreRow {
        id: row.try_get("score_id")?,
        submission_id: row.try_get("submission_id")?,
        protocol: parse_column("protocol", row.try_get("protocol")?)?,
        score: row.try_get("score")?,
        recall: row.try_get("recall")?,
        ar_vsd: row.try_get("ar_vsd")?,
        ar_mssd: row.try_get("ar_mssd")?,
        ar_mspd: row.try_get("ar_mspd")?,
        time_avg: row.try_get("time_avg")?,
        estimates_evaluated: row.try_get("estimates_evaluated")?,
        estimates_ignored: row.try_get("estimates_ignored")?,
    })
}

impl Store {
    /// The headline scores of every submission of `owner`, by submission, then protocol.
    pub async fn scores_of_owner(&self, owner: i64) -> StoreResult<Vec<ScoreRow>> {
        let rows = sqlx::query(
            "SELECT sc.id AS score_id, sc.submission_id, sc.protocol, sc.score, sc.recall, \
             sc.ar_vsd, sc.ar_mssd, sc.ar_mspd, sc.time_avg, sc.estimates_evaluated, \
             sc.estimates_ignored FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             WHERE s.owner_id = $1 ORDER BY sc.submission_id, sc.protocol",
        )
        .bind(owner)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(score).collect()
    }

    /// The reports of a submission, one per protocol it was evaluated under.
    pub async fn reports_of_submission(&self, id: i64) -> StoreResult<Vec<Report>> {
        let rows = sqlx::query(
            "SELECT report_json FROM scores WHERE submission_id = $1 ORDER BY protocol",
        )
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                let json: String = r.try_get("report_json")?;
                serde_json::from_str(&json).map_err(|_| StoreError::Corrupt {
                    column: "report_json",
                    value: json,
                })
            })
            .collect()
    }

    /// The leaderboard of a protocol, in one query: for every method and dataset, the latest
    /// finished public submission's scores with its per-object scores, best score first
    /// (optionally for one dataset only).
    pub async fn leaderboard(
        &self,
        protocol: ProtocolName,
        dataset_id: Option<i64>,
    ) -> StoreResult<Vec<BoardEntry>> {
        let rows = sqlx::query(
            "SELECT sc.id AS score_id, sc.submission_id, sc.protocol, sc.score, sc.recall, sc.ar_vsd, \
             sc.ar_mssd, sc.ar_mspd, sc.time_avg, sc.estimates_evaluated, sc.estimates_ignored, \
             s.method_id, m.name AS method, m.training_data, m.modality, s.hardware, \
             s.dataset_id, d.name AS dataset, s.finished_at, os.obj_id, os.value AS obj_value \
             FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id \
             LEFT JOIN object_scores os ON os.score_id = sc.id \
             WHERE sc.protocol = $1 AND s.status = 'done' AND s.public = 1 AND s.hidden = 0 AND d.retired = 0 \
             AND ($2 < 0 OR s.dataset_id = $2) \
             AND s.id = (SELECT MAX(s2.id) FROM submissions s2 JOIN scores sc2 ON sc2.submission_id = s2.id \
                 WHERE s2.method_id = s.method_id AND s2.dataset_id = s.dataset_id \
                 AND s2.status = 'done' AND s2.public = 1 AND s2.hidden = 0 AND sc2.protocol = $1) \
             ORDER BY sc.score DESC, m.name, sc.id, os.obj_id",
        )
        .bind(protocol.as_str())
        .bind(dataset_id.unwrap_or(-1))
        .fetch_all(&self.pool)
        .await?;
        let mut entries: Vec<BoardEntry> = Vec::new();
        for r in &rows {
            let score_id: i64 = r.try_get("score_id")?;
            if entries.last().is_none_or(|e| e.score.id != score_id) {
                entries.push(BoardEntry {
                    method_id: r.try_get("method_id")?,
                    method: r.try_get("method")?,
                    training_data: optional_column(r, "training_data")?,
                    modality: optional_column(r, "modality")?,
                    hardware: r.try_get("hardware")?,
                    dataset_id: r.try_get("dataset_id")?,
                    dataset: r.try_get("dataset")?,
                    submission_id: r.try_get("submission_id")?,
                    submitted_at: r
                        .try_get::<Option<i64>, _>("finished_at")?
                        .unwrap_or_default(),
                    score: score(r)?,
                    object_scores: BTreeMap::new(),
                });
            }
            if let (Some(obj), Some(value), Some(entry)) = (
                r.try_get::<Option<i64>, _>("obj_id")?,
                r.try_get::<Option<f64>, _>("obj_value")?,
                entries.last_mut(),
            ) {
                entry.object_scores.insert(obj, value);
            }
        }
        Ok(entries)
    }
}
