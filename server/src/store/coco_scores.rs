//! Scores of the BOP'22 2D tasks: one row per submission with its AP (what the boards rank
//! by), its time and the evaluator's whole `CocoReport` as JSON, read back typed. A method's
//! entry on a dataset follows the 6D rule: the submission its owner pinned, if it is public,
//! finished and scored for the task; otherwise its best public finished one, the earlier on a
//! tie.

use evaluator::coco::{CocoParameters, CocoReport};
use evaluator::report::as_defined;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::board_rows::{
    EntryHead, HEAD_COLUMNS, HEAD_JOINS, ScoreTable, Whose, ci95, head, report_json,
};
use super::scores::{RecordParameters, ScoreRecord, stored_parameters};
use super::{Store, StoreResult, parse_column};
use crate::domain::{BoardProtocol, CocoProtocol, DatasetId, MethodId, SubmissionId};

/// A method's entry on a dataset's board of a 2D task.
#[derive(Clone, Debug, PartialEq)]
pub struct CocoBoardEntry {
    pub head: EntryHead,
    /// Seconds per image; `None` when the file gave no time.
    pub time_avg: Option<f64>,
    pub report: CocoReport,
    /// The stored score (whose bootstrap replicates an average's interval is made of).
    pub score_id: i64,
    /// The bootstrap 95 % interval of the AP, for scores stored with replicates.
    pub ci95: Option<[f64; 2]>,
    pub record: ScoreRecord,
}

/// The columns [`record`] and [`ci95`] read, for a query joining `coco_scores c` and
/// `submissions s`.
const RECORD_COLUMNS: &str = "c.task, c.evaluator_version, c.parameters_json, c.dataset_hash, \
     s.file_sha256, c.ci_low, c.ci_high";

fn record(row: &AnyRow) -> StoreResult<ScoreRecord> {
    let task: CocoProtocol = parse_column("task", row.try_get("task")?)?;
    Ok(ScoreRecord {
        evaluator_version: row.try_get("evaluator_version")?,
        protocol: BoardProtocol::Coco(task),
        // Read back as the protocol defines them, as a 6D record is.
        parameters: stored_parameters::<CocoParameters>(row)?.map(|mut p| {
            p.iou_thresholds = p.iou_thresholds.into_iter().map(as_defined).collect();
            RecordParameters::Coco(p)
        }),
        dataset_hash: row.try_get("dataset_hash")?,
        file_sha256: row.try_get("file_sha256")?,
    })
}

/// The id of the entry, for the task `$1`, of the method and dataset of the submission `s`.
const ENTRY_SQL: &str = "COALESCE((SELECT p.submission_id FROM entry_pins p \
     JOIN submissions s3 ON s3.id = p.submission_id \
     JOIN coco_scores c3 ON c3.submission_id = s3.id AND c3.task = $1 \
     WHERE p.method_id = s.method_id AND p.dataset_id = s.dataset_id \
     AND s3.status = 'done' AND s3.public = 1 AND s3.hidden = 0), \
     (SELECT s2.id FROM submissions s2 JOIN coco_scores c2 ON c2.submission_id = s2.id \
     WHERE s2.method_id = s.method_id AND s2.dataset_id = s.dataset_id \
     AND s2.status = 'done' AND s2.public = 1 AND s2.hidden = 0 AND c2.task = $1 \
     ORDER BY c2.ap DESC, s2.id LIMIT 1))";

impl Store {
    /// The report of a submission of a 2D task, once scored.
    pub async fn coco_report(
        &self,
        submission_id: SubmissionId,
    ) -> StoreResult<Option<CocoReport>> {
        sqlx::query("SELECT report_json FROM coco_scores WHERE submission_id = $1")
            .bind(submission_id)
            .fetch_optional(&self.pool)
            .await?
            .as_ref()
            .map(report_json)
            .transpose()
    }

    /// The reproducibility record of a submission's 2D score, once scored.
    pub async fn coco_record(
        &self,
        submission_id: SubmissionId,
    ) -> StoreResult<Option<ScoreRecord>> {
        let sql = format!(
            "SELECT {RECORD_COLUMNS} FROM coco_scores c JOIN submissions s \
             ON s.id = c.submission_id WHERE c.submission_id = $1"
        );
        sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(submission_id)
            .fetch_optional(&self.pool)
            .await?
            .as_ref()
            .map(record)
            .transpose()
    }

    /// The AP of every scored 2D submission of `whose`, private ones included, by submission.
    pub async fn coco_aps(&self, whose: Whose) -> StoreResult<Vec<(SubmissionId, f64)>> {
        let table = ScoreTable {
            table: "coco_scores",
            column: "ap",
        };
        self.headline_scores(table, whose).await
    }

    /// The entry, for `task`, of a method on a dataset: the submission and whether it is pinned.
    pub async fn coco_entry(
        &self,
        task: CocoProtocol,
        method_id: MethodId,
        dataset_id: DatasetId,
    ) -> StoreResult<Option<(SubmissionId, bool)>> {
        self.entry_by(ENTRY_SQL, &[task.as_str()], method_id, dataset_id)
            .await
    }

    /// The board of a 2D task, in one query: every method's entry per dataset (optionally one
    /// dataset only), best AP first.
    pub async fn coco_leaderboard(
        &self,
        task: CocoProtocol,
        dataset_id: Option<DatasetId>,
    ) -> StoreResult<Vec<CocoBoardEntry>> {
        let sql = format!(
            "SELECT c.id AS score_id, c.submission_id, c.time_avg, c.report_json, {RECORD_COLUMNS}, \
             {HEAD_COLUMNS} \
             FROM coco_scores c JOIN submissions s ON s.id = c.submission_id {HEAD_JOINS} \
             WHERE c.task = $1 AND s.status = 'done' AND s.public = 1 AND s.hidden = 0 \
             AND d.retired = 0 AND ($2 < 0 OR s.dataset_id = $2) AND s.id = {ENTRY_SQL} \
             ORDER BY c.ap DESC, m.id, c.id"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(task.as_str())
            .bind(dataset_id.map_or(-1, DatasetId::get))
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| {
                Ok(CocoBoardEntry {
                    head: head(r)?,
                    time_avg: r.try_get("time_avg")?,
                    report: report_json(r)?,
                    score_id: r.try_get("score_id")?,
                    ci95: ci95(r)?,
                    record: record(r)?,
                })
            })
            .collect()
    }
}
