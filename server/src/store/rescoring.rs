//! Background re-scoring: finished submissions whose scores an older evaluator computed (or
//! that have no bootstrap replicates yet) are flagged, taken one at a time by idle workers with
//! a lease of their own, and their scores swapped for the new ones in one transaction that
//! records every number that changed. The submission stays done, and on the boards with its
//! old scores, until then; the lease (not the job's) lets workers on many machines share the
//! flagged submissions without doing one twice, as the job queue does.

use std::collections::BTreeMap;

use evaluator::protocol::ProtocolName;
use serde::Serialize;
use sqlx::{Any, Row, Transaction};

use super::pose_errors;
use super::queue::{Claim, Finished, insert_scores};
use super::submissions::SubmissionRow;
use super::{Store, StoreResult, parse_column};
use crate::clock::now_ms;
use crate::domain::{DatasetId, SubmissionId, UserId};

/// One number a re-scoring changed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoreChange {
    pub submission_id: SubmissionId,
    pub method: String,
    pub dataset: String,
    pub protocol: ProtocolName,
    /// `score` (the headline), `recall`, `ar_vsd`, `ar_mssd`, `ar_mspd`, `time`, or `obj_N`.
    pub key: String,
    /// `None`: the number was absent before (or is absent after).
    pub before: Option<f64>,
    pub after: Option<f64>,
    pub old_version: String,
    pub new_version: String,
    pub changed_at: i64,
}

/// Who reads the changes: anyone sees those of public submissions, a user also those of their
/// own, an administrator all.
#[derive(Clone, Copy, Debug)]
pub struct Reader {
    pub user_id: Option<UserId>,
    pub admin: bool,
}

/// The numbers of a submission's scores as stored, by protocol and key, and its intervals.
#[derive(Default, PartialEq)]
struct Stored {
    values: BTreeMap<(String, String), f64>,
    intervals: BTreeMap<String, (Option<f64>, Option<f64>)>,
}

async fn stored(tx: &mut Transaction<'static, Any>, id: SubmissionId) -> StoreResult<Stored> {
    let mut out = Stored::default();
    let rows = sqlx::query(
        "SELECT protocol, score, recall, ar_vsd, ar_mssd, ar_mspd, time_avg, ci_low, ci_high \
         FROM scores WHERE submission_id = $1",
    )
    .bind(id)
    .fetch_all(&mut **tx)
    .await?;
    for r in &rows {
        let protocol: String = r.try_get("protocol")?;
        for (column, key) in [
            ("score", "score"),
            ("recall", "recall"),
            ("ar_vsd", "ar_vsd"),
            ("ar_mssd", "ar_mssd"),
            ("ar_mspd", "ar_mspd"),
            ("time_avg", "time"),
        ] {
            if let Some(v) = r.try_get::<Option<f64>, _>(column)? {
                out.values.insert((protocol.clone(), key.to_string()), v);
            }
        }
        out.intervals
            .insert(protocol, (r.try_get("ci_low")?, r.try_get("ci_high")?));
    }
    let objects = sqlx::query(
        "SELECT sc.protocol, os.obj_id, os.value FROM object_scores os \
         JOIN scores sc ON sc.id = os.score_id WHERE sc.submission_id = $1",
    )
    .bind(id)
    .fetch_all(&mut **tx)
    .await?;
    for r in &objects {
        let obj: i64 = r.try_get("obj_id")?;
        out.values.insert(
            (r.try_get("protocol")?, format!("obj_{obj}")),
            r.try_get("value")?,
        );
    }
    Ok(out)
}

/// The keys whose numbers differ (bit for bit) between `old` and `new`.
fn differences(old: &Stored, new: &Stored) -> Vec<(String, String, Option<f64>, Option<f64>)> {
    let mut keys: Vec<&(String, String)> = old.values.keys().chain(new.values.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter_map(|k| {
            let (a, b) = (old.values.get(k).copied(), new.values.get(k).copied());
            (a.map(f64::to_bits) != b.map(f64::to_bits)).then(|| (k.0.clone(), k.1.clone(), a, b))
        })
        .collect()
}

impl Store {
    /// The evaluator versions finished submissions' scores were computed with (`None`: not
    /// recorded).
    pub async fn finished_evaluator_versions(&self) -> StoreResult<Vec<Option<String>>> {
        let rows =
            sqlx::query("SELECT DISTINCT evaluator_version FROM submissions WHERE status = 'done'")
                .fetch_all(&self.pool)
                .await?;
        rows.iter()
            .map(|r| Ok(r.try_get("evaluator_version")?))
            .collect()
    }

    /// Flags for re-scoring the finished submissions scored by one of the `stale` versions (or
    /// by an unrecorded one), or with a score that has no bootstrap replicates; how many. The 2D
    /// tasks' and bop24's submissions are left alone: their scores have no intervals, and
    /// re-scoring runs the 6D localization protocols only.
    pub async fn flag_rescoring(&self, stale: &[String]) -> StoreResult<u64> {
        // One placeholder per stale version; only their count comes from the caller.
        let marks: Vec<String> = (1..=stale.len()).map(|i| format!("${i}")).collect();
        let in_stale = if marks.is_empty() {
            String::new()
        } else {
            format!(" OR evaluator_version IN ({})", marks.join(", "))
        };
        let sql = format!(
            "UPDATE submissions SET rescore = 1, rescore_attempts = 0, rescore_worker = NULL, \
             rescore_lease_until = NULL WHERE status = 'done' AND rescore = 0 AND \
             (evaluator_version IS NULL{in_stale} OR EXISTS (SELECT 1 FROM scores sc \
             WHERE sc.submission_id = submissions.id AND sc.replicates IS NULL)) \
             AND NOT EXISTS (SELECT 1 FROM coco_scores c WHERE c.submission_id = submissions.id) \
             AND NOT EXISTS (SELECT 1 FROM bop24_scores b WHERE b.submission_id = submissions.id)"
        );
        let mut query = sqlx::query(sqlx::AssertSqlSafe(sql));
        for v in stale {
            query = query.bind(v.as_str());
        }
        Ok(query.execute(&self.pool).await?.rows_affected())
    }

    /// Takes the oldest flagged submission whose re-scoring no live worker holds, for `worker`
    /// for `lease_ms`, leaving those of the datasets in `skip` to others and those tried
    /// `max_attempts` times alone.
    pub async fn claim_rescore(
        &self,
        worker: &str,
        lease_ms: i64,
        max_attempts: i64,
        skip: &[DatasetId],
    ) -> StoreResult<Option<SubmissionRow>> {
        let now = now_ms();
        let claimed = Claim {
            set: "rescore_worker = $1, rescore_lease_until = $2, \
                  rescore_attempts = rescore_attempts + 1",
            available: "rescore = 1 AND status = 'done' \
                        AND (rescore_lease_until IS NULL OR rescore_lease_until < $3) \
                        AND rescore_attempts < $4",
            worker,
            numbers: &[now + lease_ms, now, max_attempts],
            skip,
        }
        .run(self)
        .await?;
        match claimed {
            Some(id) => self.submission(id).await,
            None => Ok(None),
        }
    }

    /// Extends the re-scoring lease; false when it is no longer this worker's (taken over, or
    /// the submission was re-run or deleted meanwhile). A beat of `worker` too.
    pub async fn renew_rescore(
        &self,
        id: SubmissionId,
        worker: &str,
        lease_ms: i64,
    ) -> StoreResult<bool> {
        let now = now_ms();
        self.beat(worker, now).await?;
        let done = sqlx::query(
            "UPDATE submissions SET rescore_lease_until = $1 \
             WHERE id = $2 AND rescore_worker = $3 AND rescore = 1 AND status = 'done'",
        )
        .bind(now + lease_ms)
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Lets go of a re-scoring: `count` says whether the try counts as one of its attempts
    /// (it failed) or not (this worker stops or cannot serve the dataset).
    pub async fn drop_rescore(
        &self,
        id: SubmissionId,
        worker: &str,
        count: bool,
    ) -> StoreResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET rescore_worker = NULL, rescore_lease_until = NULL, \
             rescore_attempts = rescore_attempts - $1 WHERE id = $2 AND rescore_worker = $3",
        )
        .bind(i64::from(!count))
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Swaps a re-scored submission's scores and errors for `finished`, records the evaluator
    /// version, and records every number that changed, in one transaction that commits only
    /// while the re-scoring is this worker's. The boards change (and their version is bumped)
    /// when a number or an interval did. The changes recorded, or `None` when it was no longer
    /// this worker's.
    pub async fn finish_rescore(
        &self,
        id: SubmissionId,
        worker: &str,
        finished: &Finished,
    ) -> StoreResult<Option<usize>> {
        let new_version = evaluator::report::EVALUATOR_VERSION;
        let mut tx = self.write_transaction().await?;
        let old_version: Option<String> = sqlx::query(
            "SELECT evaluator_version FROM submissions \
             WHERE id = $1 AND rescore_worker = $2 AND rescore = 1 AND status = 'done'",
        )
        .bind(id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?
        .map(|r| r.try_get::<Option<String>, _>("evaluator_version"))
        .transpose()?
        .flatten();
        let updated = sqlx::query(
            "UPDATE submissions SET evaluator_version = $1, rescore = 0, rescore_worker = NULL, \
             rescore_lease_until = NULL, rescore_attempts = 0 \
             WHERE id = $2 AND rescore_worker = $3 AND rescore = 1 AND status = 'done'",
        )
        .bind(new_version)
        .bind(id)
        .bind(worker)
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() != 1 {
            tx.rollback().await?;
            return Ok(None);
        }
        let now = now_ms();
        let before = stored(&mut tx, id).await?;
        sqlx::query("DELETE FROM scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        pose_errors::replace(&mut tx, id, &finished.errors, now).await?;
        insert_scores(&mut tx, id, finished, now).await?;
        let after = stored(&mut tx, id).await?;
        let changes = differences(&before, &after);
        let old_version = old_version.unwrap_or_default();
        for (protocol, key, old, new) in &changes {
            sqlx::query(
                "INSERT INTO score_changes (submission_id, protocol, score_key, old_value, \
                 new_value, old_version, new_version, changed_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
            )
            // `old_value` or `new_value` may be NULL: keep no parameter types between uses.
            .persistent(false)
            .bind(id)
            .bind(protocol.as_str())
            .bind(key.as_str())
            .bind(*old)
            .bind(*new)
            .bind(old_version.as_str())
            .bind(new_version)
            .bind(now)
            .execute(&mut *tx)
            .await?;
        }
        let shown = !changes.is_empty() || before.intervals != after.intervals;
        self.commit_board_change(tx, shown).await?;
        Ok(Some(changes.len()))
    }

    /// The recorded changes `reader` may see, newest first (at most `limit`).
    pub async fn score_changes(&self, reader: Reader, limit: i64) -> StoreResult<Vec<ScoreChange>> {
        let rows = sqlx::query(
            "SELECT c.submission_id, m.name AS method, d.name AS dataset, c.protocol, \
             c.score_key, c.old_value, c.new_value, c.old_version, c.new_version, c.changed_at \
             FROM score_changes c JOIN submissions s ON s.id = c.submission_id \
             JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id \
             WHERE (s.public = 1 AND s.hidden = 0) OR $1 = 1 OR s.owner_id = $2 \
             ORDER BY c.id DESC LIMIT $3",
        )
        .bind(i64::from(reader.admin))
        .bind(reader.user_id.map_or(-1, UserId::get))
        .bind(limit)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(ScoreChange {
                    submission_id: r.try_get("submission_id")?,
                    method: r.try_get("method")?,
                    dataset: r.try_get("dataset")?,
                    protocol: parse_column("protocol", r.try_get("protocol")?)?,
                    key: r.try_get("score_key")?,
                    before: r.try_get("old_value")?,
                    after: r.try_get("new_value")?,
                    old_version: r.try_get("old_version")?,
                    new_version: r.try_get("new_version")?,
                    changed_at: r.try_get("changed_at")?,
                })
            })
            .collect()
    }
}
