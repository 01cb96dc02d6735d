//! Scores of BOP'24 6D detection: one row per submission with its mAP (what the board ranks
//! by, NULL when no instance was counted), its parts, its time and the evaluator's whole
//! `DetectionReport` as JSON, read back typed. A method's entry on a dataset follows the 6D
//! rule: the submission its owner pinned, if it is public, finished and scored for bop24;
//! otherwise its best public finished one, the earlier on a tie.

use evaluator::detection::DetectionReport;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::methods::optional_column;
use super::{Store, StoreError, StoreResult};
use crate::domain::{DatasetId, MethodId, Modality, SubmissionId, TrainingData, UserId};

/// A method's entry on a dataset's bop24 board.
#[derive(Clone, Debug, PartialEq)]
pub struct Bop24BoardEntry {
    pub method_id: MethodId,
    pub method: String,
    /// The name of the account the method belongs to.
    pub owner: String,
    pub training_data: Option<TrainingData>,
    pub modality: Option<Modality>,
    pub hardware: String,
    pub dataset_id: DatasetId,
    pub dataset: String,
    pub submission_id: SubmissionId,
    /// Its owner pinned it (otherwise it is the best).
    pub pinned: bool,
    /// Seconds per image; `None` when the file gave no time.
    pub time_avg: Option<f64>,
    pub report: DetectionReport,
}

/// The id of the bop24 entry of the method and dataset of the submission `s`. A mAP of NULL
/// (nothing counted) ranks last on both databases.
const ENTRY_SQL: &str = "COALESCE((SELECT p.submission_id FROM entry_pins p \
     JOIN submissions s3 ON s3.id = p.submission_id \
     JOIN bop24_scores b3 ON b3.submission_id = s3.id \
     WHERE p.method_id = s.method_id AND p.dataset_id = s.dataset_id \
     AND s3.status = 'done' AND s3.public = 1 AND s3.hidden = 0), \
     (SELECT s2.id FROM submissions s2 JOIN bop24_scores b2 ON b2.submission_id = s2.id \
     WHERE s2.method_id = s.method_id AND s2.dataset_id = s.dataset_id \
     AND s2.status = 'done' AND s2.public = 1 AND s2.hidden = 0 \
     ORDER BY COALESCE(b2.map, -1) DESC, s2.id LIMIT 1))";

fn report(row: &AnyRow) -> StoreResult<DetectionReport> {
    let json: String = row.try_get("report_json")?;
    serde_json::from_str(&json).map_err(|_| StoreError::Corrupt {
        column: "report_json",
        value: json,
    })
}

impl Store {
    /// The bop24 report of a submission, once scored.
    pub async fn bop24_report(
        &self,
        submission_id: SubmissionId,
    ) -> StoreResult<Option<DetectionReport>> {
        sqlx::query("SELECT report_json FROM bop24_scores WHERE submission_id = $1")
            .bind(submission_id)
            .fetch_optional(&self.pool)
            .await?
            .as_ref()
            .map(report)
            .transpose()
    }

    /// The bop24_mAP of every scored bop24 submission of `owner`, private ones included.
    pub async fn bop24_scores_of_owner(
        &self,
        owner: UserId,
    ) -> StoreResult<Vec<(SubmissionId, f64)>> {
        self.bop24_scores_where("s.owner_id", owner.get()).await
    }

    /// The bop24_mAP of every scored bop24 submission of method `id`, private ones included.
    pub async fn bop24_scores_of_method(
        &self,
        id: MethodId,
    ) -> StoreResult<Vec<(SubmissionId, f64)>> {
        self.bop24_scores_where("s.method_id", id.get()).await
    }

    /// The bop24_mAP of the scored submissions whose `column` is `value` (a report that
    /// counted nothing has none), by submission.
    async fn bop24_scores_where(
        &self,
        column: &'static str,
        value: i64,
    ) -> StoreResult<Vec<(SubmissionId, f64)>> {
        let sql = format!(
            "SELECT b.submission_id, b.map FROM bop24_scores b \
             JOIN submissions s ON s.id = b.submission_id \
             WHERE {column} = $1 AND b.map IS NOT NULL ORDER BY b.submission_id"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(value)
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| Ok((r.try_get("submission_id")?, r.try_get("map")?)))
            .collect()
    }

    /// The bop24 entry of a method on a dataset: the submission and whether it is pinned.
    pub async fn bop24_entry(
        &self,
        method_id: MethodId,
        dataset_id: DatasetId,
    ) -> StoreResult<Option<(SubmissionId, bool)>> {
        let sql = format!(
            "SELECT {ENTRY_SQL} AS entry, (SELECT p.submission_id FROM entry_pins p \
             WHERE p.method_id = $1 AND p.dataset_id = $2) AS pin \
             FROM (SELECT CAST($1 AS BIGINT) AS method_id, CAST($2 AS BIGINT) AS dataset_id) s"
        );
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .bind(dataset_id)
            .fetch_one(&self.pool)
            .await?;
        let entry: Option<SubmissionId> = row.try_get("entry")?;
        let pin: Option<SubmissionId> = row.try_get("pin")?;
        Ok(entry.map(|id| (id, pin == Some(id))))
    }

    /// The bop24 board, in one query: every method's entry per dataset (optionally one dataset
    /// only), best mAP first.
    pub async fn bop24_leaderboard(
        &self,
        dataset_id: Option<DatasetId>,
    ) -> StoreResult<Vec<Bop24BoardEntry>> {
        let sql = format!(
            "SELECT b.submission_id, b.time_avg, b.report_json, s.method_id, m.name AS method, \
             COALESCE(u.name, '') AS owner, m.training_data, m.modality, m.hardware, \
             s.dataset_id, d.name AS dataset, \
             CAST(CASE WHEN EXISTS (SELECT 1 FROM entry_pins p WHERE p.submission_id = s.id) \
             THEN 1 ELSE 0 END AS BIGINT) AS pinned \
             FROM bop24_scores b JOIN submissions s ON s.id = b.submission_id \
             JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id \
             LEFT JOIN users u ON u.id = m.owner_id \
             WHERE s.status = 'done' AND s.public = 1 AND s.hidden = 0 \
             AND d.retired = 0 AND ($1 < 0 OR s.dataset_id = $1) AND s.id = {ENTRY_SQL} \
             ORDER BY COALESCE(b.map, -1) DESC, m.id, b.id"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(dataset_id.map_or(-1, DatasetId::get))
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| {
                Ok(Bop24BoardEntry {
                    method_id: r.try_get("method_id")?,
                    method: r.try_get("method")?,
                    owner: r.try_get("owner")?,
                    training_data: optional_column(r, "training_data")?,
                    modality: optional_column(r, "modality")?,
                    hardware: r.try_get("hardware")?,
                    dataset_id: r.try_get("dataset_id")?,
                    dataset: r.try_get("dataset")?,
                    submission_id: r.try_get("submission_id")?,
                    pinned: r.try_get::<i64, _>("pinned")? != 0,
                    time_avg: r.try_get("time_avg")?,
                    report: report(r)?,
                })
            })
            .collect()
    }
}
