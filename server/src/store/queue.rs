//! The job queue is the submissions table: a worker claims a row with a lease, renews it with
//! a heartbeat that also records progress, and stores the scores in the same transaction that
//! marks the row done, only while the job is still its own. A job whose lease expired (its
//! worker died) is claimed again by any worker; after `max_attempts` it is failed instead.

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::{CocoParameters, CocoReport};
use evaluator::detection::DetectionReport;
use evaluator::protocol::ProtocolName;
use sqlx::{Any, Row, Transaction};

use super::board_version;
use super::pose_errors::{self, NewErrors};
use super::submissions::{Fault, SubmissionRow};
use super::{Backend, Store, StoreError, StoreResult};
use crate::clock::now_ms;
use crate::domain::{DatasetId, SubmissionId};

/// A finished evaluation, as [`Store::finish`] stores it.
pub struct Finished {
    /// One report per protocol.
    pub reports: Vec<Report>,
    /// The per-estimate errors of each protocol.
    pub errors: Vec<NewErrors>,
    /// Per protocol, the bootstrap replicates of its headline score (whose interval the
    /// report's `bootstrap` records).
    pub replicates: BTreeMap<ProtocolName, Vec<f64>>,
    /// How long the evaluation took: with the estimates it evaluated, the speed of this
    /// service that waiting times are estimated from.
    pub eval_ms: i64,
    /// The content hash of the dataset copy the scores were computed on (the scores'
    /// reproducibility record).
    pub dataset_hash: String,
}

/// A finished 2D evaluation, as [`Store::finish_coco`] stores it.
pub struct FinishedCoco {
    pub report: CocoReport,
    /// The bootstrap replicates of the AP (whose interval the report's `bootstrap` records);
    /// empty when there was nothing to resample.
    pub replicates: Vec<f64>,
    /// COCOeval's parameters, for the reproducibility record.
    pub parameters: CocoParameters,
    pub eval_ms: i64,
    /// The content hash of the dataset copy the score was computed on.
    pub dataset_hash: String,
}

impl Store {
    /// Takes the oldest queued submission, or one whose worker's lease expired, for `worker`
    /// for `lease_ms`, leaving those of the datasets in `skip` (which this worker cannot serve)
    /// to others. Submissions that failed `max_attempts` times for the service's reasons are
    /// marked failed instead of being retried forever. Every poll is a beat of `worker`.
    pub async fn claim(
        &self,
        worker: &str,
        lease_ms: i64,
        max_attempts: i64,
        skip: &[DatasetId],
    ) -> StoreResult<Option<SubmissionRow>> {
        let now = now_ms();
        self.beat(worker, now).await?;
        sqlx::query(
            "UPDATE submissions SET status = 'failed', fault = 'service', finished_at = $1, \
             error = 'the evaluation was interrupted too many times' \
             WHERE status = 'running' AND lease_until < $1 AND attempts >= $2",
        )
        .bind(now)
        .bind(max_attempts)
        .execute(&self.pool)
        .await?;
        let claimed = Claim {
            set: "status = 'running', worker = $1, lease_until = $2, attempts = attempts + 1, \
                  started_at = COALESCE(started_at, $3), progress = 0, work_done = 0",
            available: "(status = 'queued' OR (status = 'running' AND lease_until < $3))",
            worker,
            numbers: &[now + lease_ms, now],
            skip,
        }
        .run(self)
        .await?;
        match claimed {
            Some(id) => self.submission(id).await,
            None => Ok(None),
        }
    }

    /// Extends the lease and records progress (the fraction done, and the estimate
    /// evaluations done); false when the job is no longer this worker's. A beat of `worker`
    /// too: a worker busy with a long job polls no queue.
    pub async fn heartbeat(
        &self,
        id: SubmissionId,
        worker: &str,
        lease_ms: i64,
        progress: f64,
        work_done: i64,
    ) -> StoreResult<bool> {
        let now = now_ms();
        self.beat(worker, now).await?;
        let done = sqlx::query(
            "UPDATE submissions SET lease_until = $1, progress = $2, work_done = $3 \
             WHERE id = $4 AND worker = $5 AND status = 'running'",
        )
        .bind(now + lease_ms)
        .bind(progress)
        .bind(work_done)
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Stores the scores and the per-estimate errors and marks the submission done, in one
    /// transaction that only commits if the job is still this worker's: a job taken over after
    /// a lost lease never ends up with two score sets. The same transaction bumps the board
    /// version. (A failed job needs no bump: it was running, so no board showed it.)
    pub async fn finish(
        &self,
        id: SubmissionId,
        worker: &str,
        finished: &Finished,
    ) -> StoreResult<bool> {
        let reports = &finished.reports;
        let work: i64 = reports.iter().map(|r| r.estimates_evaluated as i64).sum();
        let mut tx = self.write_transaction().await?;
        let now = now_ms();
        if !mark_done(&mut tx, id, worker, work, finished.eval_ms, now).await? {
            // Done by this very worker already: an earlier try committed, but its answer was
            // lost with the connection.
            let mine = done_by(&mut tx, id, worker).await?;
            tx.rollback().await?;
            return Ok(mine);
        }
        sqlx::query("DELETE FROM scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        pose_errors::replace(&mut tx, id, &finished.errors, now).await?;
        insert_scores(&mut tx, id, finished, now).await?;
        board_version::bump(&mut tx).await?;
        tx.commit().await?;
        self.board_changed();
        Ok(true)
    }

    /// [`Store::finish`] for a 2D task: its report goes to `coco_scores`, with its AP for the
    /// boards, its interval and replicates and its reproducibility record, in the transaction
    /// that marks the job done and bumps the board version.
    pub async fn finish_coco(
        &self,
        id: SubmissionId,
        worker: &str,
        finished: &FinishedCoco,
    ) -> StoreResult<bool> {
        let report = &finished.report;
        let mut tx = self.write_transaction().await?;
        let now = now_ms();
        let work = report.entries_evaluated as i64;
        if !mark_done(&mut tx, id, worker, work, finished.eval_ms, now).await? {
            let mine = done_by(&mut tx, id, worker).await?;
            tx.rollback().await?;
            return Ok(mine);
        }
        let json = serde_json::to_string(report).map_err(|e| StoreError::Corrupt {
            column: "report_json",
            value: e.to_string(),
        })?;
        sqlx::query("DELETE FROM coco_scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        let parameters =
            serde_json::to_string(&finished.parameters).map_err(|e| StoreError::Corrupt {
                column: "parameters_json",
                value: e.to_string(),
            })?;
        let ci95 = report.bootstrap.as_ref().map(|b| b.ci95);
        sqlx::query(
            "INSERT INTO coco_scores (submission_id, task, ap, time_avg, entries_evaluated, \
             report_json, created_at, ci_low, ci_high, replicates, evaluator_version, \
             parameters_json, dataset_hash) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13)",
        )
        // The time and the interval are NULL or numbers; a cached statement would keep the
        // first one's types.
        .persistent(false)
        .bind(id)
        .bind(report.protocol.as_str())
        .bind(report.ap)
        // A negative time (the toolkit's -1) means the file gave none.
        .bind(Some(report.average_time_per_image).filter(|t| *t >= 0.0))
        .bind(work)
        .bind(json)
        .bind(now)
        .bind(ci95.map(|c| c[0]))
        .bind(ci95.map(|c| c[1]))
        .bind(replicates_bytes(&finished.replicates))
        .bind(&report.evaluator_version)
        .bind(parameters)
        .bind(&finished.dataset_hash)
        .execute(&mut *tx)
        .await?;
        board_version::bump(&mut tx).await?;
        tx.commit().await?;
        self.board_changed();
        Ok(true)
    }

    /// [`Store::finish`] for BOP'24 6D detection: its report goes to `bop24_scores`, with its
    /// mAP and parts for the board (NULL where no instance was counted: SQLite stores a NaN as
    /// NULL anyway, so both databases say it the same way), in the transaction that marks the
    /// job done and bumps the board version.
    pub async fn finish_bop24(
        &self,
        id: SubmissionId,
        worker: &str,
        report: &DetectionReport,
        replicates: &[f64],
        eval_ms: i64,
    ) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let now = now_ms();
        let work = report.estimates_evaluated as i64;
        if !mark_done(&mut tx, id, worker, work, eval_ms, now).await? {
            let mine = done_by(&mut tx, id, worker).await?;
            tx.rollback().await?;
            return Ok(mine);
        }
        let json = serde_json::to_string(report).map_err(|e| StoreError::Corrupt {
            column: "report_json",
            value: e.to_string(),
        })?;
        sqlx::query("DELETE FROM bop24_scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        let number = |v: f64| Some(v).filter(|v| v.is_finite());
        sqlx::query(
            "INSERT INTO bop24_scores (submission_id, map, map_mssd, map_mssd_mm, map_mspd, \
             time_avg, estimates_evaluated, report_json, created_at, ci_low, ci_high, replicates) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)",
        )
        // Each number is NULL or not; a cached statement would keep the first one's types.
        .persistent(false)
        .bind(id)
        .bind(number(report.bop24_map))
        .bind(number(report.bop24_map_mssd))
        .bind(number(report.bop24_map_mssd_mm))
        .bind(number(report.bop24_map_mspd))
        // A negative time (the toolkit's -1) means the file gave none.
        .bind(Some(report.bop24_average_time_per_image).filter(|t| *t >= 0.0))
        .bind(work)
        .bind(json)
        .bind(now)
        .bind(report.bootstrap.as_ref().map(|b| b.ci95[0]))
        .bind(report.bootstrap.as_ref().map(|b| b.ci95[1]))
        .bind(Some(replicates_bytes(replicates)).filter(|b| !b.is_empty()))
        .execute(&mut *tx)
        .await?;
        board_version::bump(&mut tx).await?;
        tx.commit().await?;
        self.board_changed();
        Ok(true)
    }

    /// Marks the job failed with a reason; false when it is no longer this worker's.
    pub async fn fail(
        &self,
        id: SubmissionId,
        worker: &str,
        error: &str,
        fault: Fault,
    ) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET status = 'failed', error = $1, fault = $2, finished_at = $3, \
             lease_until = NULL WHERE id = $4 AND worker = $5 AND status = 'running'",
        )
        .bind(error)
        .bind(fault.as_str())
        .bind(now_ms())
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Gives the job back to the queue without counting the attempt (this worker stops for
    /// its own reasons: it is shutting down, or its copy of the dataset differs); false when it
    /// is no longer this worker's.
    pub async fn release(&self, id: SubmissionId, worker: &str) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET status = 'queued', worker = NULL, lease_until = NULL, \
             progress = 0, work_done = 0, attempts = attempts - 1, \
             started_at = CASE WHEN attempts <= 1 THEN NULL ELSE started_at END \
             WHERE id = $1 AND worker = $2 AND status = 'running'",
        )
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Puts the job back to the queue for another try, the attempt counted (a failure of the
    /// service that retrying in place did not cure); false when it is no longer this worker's.
    pub async fn requeue(&self, id: SubmissionId, worker: &str, error: &str) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET status = 'queued', worker = NULL, lease_until = NULL, \
             progress = 0, work_done = 0, error = $1 WHERE id = $2 AND worker = $3 AND status = 'running'",
        )
        .bind(error)
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }
}

/// The one way a worker takes something from the submissions table, shared by the job queue
/// and the re-scoring: the oldest row that `available` admits, outside the datasets in `skip`,
/// is changed by `set` and its id returned. Two workers never take the same row: PostgreSQL
/// locks the row the subquery picks and skips rows other workers hold (`SKIP LOCKED`); SQLite
/// runs one writer at a time, so the subquery and the update are atomic there.
pub(super) struct Claim<'a> {
    /// The assignments; `$1` is the worker, `$2`.. are `numbers`.
    pub set: &'static str,
    /// The condition a row must meet, over the same parameters.
    pub available: &'static str,
    pub worker: &'a str,
    pub numbers: &'a [i64],
    /// Datasets this worker cannot serve.
    pub skip: &'a [DatasetId],
}

impl Claim<'_> {
    /// The statement, with one placeholder per skipped dataset after the fixed parameters
    /// (only their count comes from the caller, never their values).
    fn sql(&self, backend: Backend) -> String {
        let lock = match backend {
            Backend::Postgres => " FOR UPDATE SKIP LOCKED",
            Backend::Sqlite => "",
        };
        let first = self.numbers.len() + 2;
        let skipped = if self.skip.is_empty() {
            String::new()
        } else {
            let marks: Vec<String> = (0..self.skip.len())
                .map(|i| format!("${}", i + first))
                .collect();
            format!(" AND dataset_id NOT IN ({})", marks.join(", "))
        };
        format!(
            "UPDATE submissions SET {} WHERE id = (SELECT id FROM submissions WHERE {}{skipped} \
             ORDER BY id LIMIT 1{lock}) RETURNING id",
            self.set, self.available
        )
    }

    /// The id of the row taken, if any.
    pub async fn run(self, store: &Store) -> StoreResult<Option<SubmissionId>> {
        let sql = self.sql(store.backend);
        let mut query = sqlx::query(sqlx::AssertSqlSafe(sql)).bind(self.worker);
        for n in self.numbers {
            query = query.bind(*n);
        }
        for id in self.skip {
            query = query.bind(*id);
        }
        match query.fetch_optional(&store.pool).await? {
            Some(row) => Ok(Some(row.try_get("id")?)),
            None => Ok(None),
        }
    }
}

/// Inserts the scores of `finished` for submission `id` (whose old scores are gone): one row
/// per protocol with its report, interval and replicates, and its per-object scores.
pub(crate) async fn insert_scores(
    tx: &mut Transaction<'static, Any>,
    id: SubmissionId,
    finished: &Finished,
    now: i64,
) -> StoreResult<()> {
    for report in &finished.reports {
        let loc = report.localization.as_ref();
        let (time_avg, recall) = match report.protocol {
            ProtocolName::Eccv18 => (report.average_time_per_target, loc.map(|l| l.recall)),
            // A negative time (bop_toolkit's -1) means the file gave none.
            ProtocolName::Bop19 => (
                report.bop19_average_time_per_image.filter(|t| *t >= 0.0),
                None,
            ),
        };
        let json = serde_json::to_string(report).map_err(|e| StoreError::Corrupt {
            column: "report_json",
            value: e.to_string(),
        })?;
        // Empty when there was nothing to resample: NULL is left to scores stored before
        // replicates were, which re-scoring fills in.
        let replicates = finished
            .replicates
            .get(&report.protocol)
            .map_or(&[][..], Vec::as_slice);
        let ci95 = report.bootstrap.as_ref().map(|b| b.ci95);
        let parameters =
            serde_json::to_string(&report.parameters).map_err(|e| StoreError::Corrupt {
                column: "parameters_json",
                value: e.to_string(),
            })?;
        let row = sqlx::query(
            "INSERT INTO scores (submission_id, protocol, score, recall, ar_vsd, ar_mssd, \
             ar_mspd, time_avg, targets_count, tp_count, estimates_evaluated, estimates_ignored, \
             report_json, created_at, ci_low, ci_high, replicates, evaluator_version, \
             parameters_json, dataset_hash) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17, \
             $18, $19, $20) \
             RETURNING id",
        )
        // The optional columns are NULL for one protocol and numbers for the other; a
        // cached statement would keep the parameter types of its first use.
        .persistent(false)
        .bind(id)
        .bind(report.protocol.as_str())
        .bind(report.headline())
        .bind(recall)
        .bind(report.bop19_average_recall_vsd)
        .bind(report.bop19_average_recall_mssd)
        .bind(report.bop19_average_recall_mspd)
        .bind(time_avg)
        .bind(loc.map(|l| l.targets_count as i64))
        .bind(loc.map(|l| l.tp_count as i64))
        .bind(report.estimates_evaluated as i64)
        .bind(report.estimates_ignored as i64)
        .bind(json)
        .bind(now)
        .bind(ci95.map(|c| c[0]))
        .bind(ci95.map(|c| c[1]))
        .bind(replicates_bytes(replicates))
        .bind(&report.evaluator_version)
        .bind(parameters)
        .bind(&finished.dataset_hash)
        .fetch_one(&mut **tx)
        .await?;
        let score_id: i64 = row.try_get("id")?;
        let objects = match (report.protocol, loc) {
            (ProtocolName::Eccv18, Some(l)) => &l.obj_recalls,
            _ => &report.obj_average_recalls,
        };
        for (&obj, &value) in objects {
            sqlx::query("INSERT INTO object_scores (score_id, obj_id, value) VALUES ($1, $2, $3)")
                .bind(score_id)
                .bind(i64::from(obj))
                .bind(value)
                .execute(&mut **tx)
                .await?;
        }
    }
    Ok(())
}

/// Replicates as stored: little-endian f64s in replicate order.
fn replicates_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Replicates as read back; `None` for a length that is no whole number of f64s.
pub(crate) fn replicates_from(bytes: &[u8]) -> Option<Vec<f64>> {
    bytes.len().is_multiple_of(8).then(|| {
        bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or_default()))
            .collect()
    })
}

/// Marks a running job of `worker` done; false when it is not (or no longer) its.
async fn mark_done(
    tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    id: SubmissionId,
    worker: &str,
    work: i64,
    eval_ms: i64,
    now: i64,
) -> StoreResult<bool> {
    let updated = sqlx::query(
        "UPDATE submissions SET status = 'done', progress = 1, finished_at = $1, \
         lease_until = NULL, error = NULL, fault = NULL, evaluator_version = $2, \
         work = $3, work_done = $3, eval_ms = $4, rescore = 0, rescore_worker = NULL, \
         rescore_lease_until = NULL, rescore_attempts = 0 \
         WHERE id = $5 AND worker = $6 AND status = 'running'",
    )
    .bind(now)
    .bind(evaluator::report::EVALUATOR_VERSION)
    .bind(work)
    .bind(eval_ms)
    .bind(id)
    .bind(worker)
    .execute(&mut **tx)
    .await?;
    Ok(updated.rows_affected() == 1)
}

/// Whether the job is done by `worker` already.
async fn done_by(
    tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    id: SubmissionId,
    worker: &str,
) -> StoreResult<bool> {
    Ok(
        sqlx::query("SELECT id FROM submissions WHERE id = $1 AND worker = $2 AND status = 'done'")
            .bind(id)
            .bind(worker)
            .fetch_optional(&mut **tx)
            .await?
            .is_some(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_claim_numbers_the_skipped_datasets_after_its_parameters_and_locks_on_postgres() {
        let claim = Claim {
            set: "rescore_worker = $1, rescore_lease_until = $2",
            available: "rescore = 1 AND rescore_attempts < $4",
            worker: "w",
            numbers: &[10, 5, 3],
            skip: &[DatasetId::new(7), DatasetId::new(9)],
        };
        assert_eq!(
            claim.sql(Backend::Postgres),
            "UPDATE submissions SET rescore_worker = $1, rescore_lease_until = $2 WHERE id = \
             (SELECT id FROM submissions WHERE rescore = 1 AND rescore_attempts < $4 AND \
             dataset_id NOT IN ($5, $6) ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING id"
        );
        let none = Claim { skip: &[], ..claim };
        assert_eq!(
            none.sql(Backend::Sqlite),
            "UPDATE submissions SET rescore_worker = $1, rescore_lease_until = $2 WHERE id = \
             (SELECT id FROM submissions WHERE rescore = 1 AND rescore_attempts < $4 \
             ORDER BY id LIMIT 1) RETURNING id"
        );
    }
}
