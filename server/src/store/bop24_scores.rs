//! Scores of BOP'24 6D detection: one row per submission with its mAP (what the board ranks
//! by, NULL when no instance was counted), its parts, its time and the evaluator's whole
//! `DetectionReport` as JSON, read back typed. A method's entry on a dataset follows the 6D
//! rule: the submission its owner pinned, if it is public, finished and scored for bop24;
//! otherwise its best public finished one, the earlier on a tie.

use evaluator::detection::DetectionReport;
use sqlx::Row;

use super::board_rows::{
    EntryHead, HEAD_COLUMNS, HEAD_JOINS, ScoreTable, Whose, ci95, head, report_json,
};
use super::{Store, StoreResult};
use crate::domain::{DatasetId, MethodId, SubmissionId};

/// A method's entry on a dataset's bop24 board.
#[derive(Clone, Debug, PartialEq)]
pub struct Bop24BoardEntry {
    pub head: EntryHead,
    /// The stored score (whose bootstrap replicates an average's interval is made of).
    pub score_id: i64,
    /// The bootstrap 95 % interval of bop24_mAP, for scores stored with replicates.
    pub ci95: Option<[f64; 2]>,
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
            .map(report_json)
            .transpose()
    }

    /// The bop24_mAP of every scored bop24 submission of `whose`, private ones included (a
    /// report that counted nothing has none), by submission.
    pub async fn bop24_maps(&self, whose: Whose) -> StoreResult<Vec<(SubmissionId, f64)>> {
        let table = ScoreTable {
            table: "bop24_scores",
            column: "map",
        };
        self.headline_scores(table, whose).await
    }

    /// The bop24 entry of a method on a dataset: the submission and whether it is pinned.
    pub async fn bop24_entry(
        &self,
        method_id: MethodId,
        dataset_id: DatasetId,
    ) -> StoreResult<Option<(SubmissionId, bool)>> {
        self.entry_by(ENTRY_SQL, &[], method_id, dataset_id).await
    }

    /// The bop24 board, in one query: every method's entry per dataset (optionally one dataset
    /// only), best mAP first.
    pub async fn bop24_leaderboard(
        &self,
        dataset_id: Option<DatasetId>,
    ) -> StoreResult<Vec<Bop24BoardEntry>> {
        let sql = format!(
            "SELECT b.id AS score_id, b.submission_id, b.time_avg, b.report_json, b.ci_low, \
             b.ci_high, {HEAD_COLUMNS} \
             FROM bop24_scores b JOIN submissions s ON s.id = b.submission_id {HEAD_JOINS} \
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
                    head: head(r)?,
                    score_id: r.try_get("score_id")?,
                    ci95: ci95(r)?,
                    time_avg: r.try_get("time_avg")?,
                    report: report_json(r)?,
                })
            })
            .collect()
    }
}
