//! Scores: one row per submission and protocol, with the evaluator's full report kept as JSON
//! (read back as a `Report`) and the per-object numbers in a table of their own for the
//! leaderboards.

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::CocoParameters;
use evaluator::protocol::ProtocolName;
use evaluator::report::Parameters;
use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::board_rows::{EntryHead, HEAD_COLUMNS, HEAD_JOINS, head};
use super::queue::replicates_from;
use super::{Store, StoreError, StoreResult, fetch_in, parse_column};
use crate::domain::{BoardProtocol, DatasetId, MethodId, SubmissionId, UserId};

/// One protocol's headline numbers of a submission.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoreRow {
    pub id: i64,
    pub submission_id: SubmissionId,
    pub protocol: ProtocolName,
    pub score: f64,
    pub recall: Option<f64>,
    pub ar_vsd: Option<f64>,
    pub ar_mssd: Option<f64>,
    pub ar_mspd: Option<f64>,
    pub time_avg: Option<f64>,
    pub estimates_evaluated: i64,
    pub estimates_ignored: i64,
    pub record: ScoreRecord,
    /// The bootstrap 95 % interval of `score`, for scores stored with replicates.
    pub ci95: Option<[f64; 2]>,
}

/// What it takes to reproduce a score: the evaluator, the protocol with its parameters, and
/// the content hashes of the two inputs. Scores stored before records were kept have no
/// dataset hash (the worker's copy was not recorded then).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoreRecord {
    pub evaluator_version: Option<String>,
    pub protocol: BoardProtocol,
    pub parameters: Option<RecordParameters>,
    /// The content hash of the dataset copy the score was computed on.
    pub dataset_hash: Option<String>,
    /// SHA-256 of the uploaded result file.
    pub file_sha256: String,
}

/// The parameters a score was computed with: a 6D protocol's, or COCOeval's for a 2D task.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum RecordParameters {
    Pose(Parameters),
    Coco(CocoParameters),
}

impl ScoreRecord {
    /// A 6D score's parameters (for the page, which lays the two kinds out differently).
    pub fn pose_parameters(&self) -> Option<&Parameters> {
        match &self.parameters {
            Some(RecordParameters::Pose(p)) => Some(p),
            _ => None,
        }
    }

    /// A 2D score's parameters.
    pub fn coco_parameters(&self) -> Option<&CocoParameters> {
        match &self.parameters {
            Some(RecordParameters::Coco(p)) => Some(p),
            _ => None,
        }
    }
}

/// The parameters stored in `parameters_json`, parsed as `T`.
pub(super) fn stored_parameters<T: serde::de::DeserializeOwned>(
    row: &AnyRow,
) -> StoreResult<Option<T>> {
    row.try_get::<Option<String>, _>("parameters_json")?
        .map(|json| {
            serde_json::from_str::<T>(&json).map_err(|_| StoreError::Corrupt {
                column: "parameters_json",
                value: json,
            })
        })
        .transpose()
}

/// The columns [`score`] reads, for a query joining `scores sc` and `submissions s`.
const SCORE_COLUMNS: &str = "sc.id AS score_id, sc.submission_id, sc.protocol, sc.score, \
     sc.recall, sc.ar_vsd, sc.ar_mssd, sc.ar_mspd, sc.time_avg, sc.estimates_evaluated, \
     sc.estimates_ignored, sc.evaluator_version, sc.parameters_json, sc.dataset_hash, \
     s.file_sha256, sc.ci_low, sc.ci_high";

/// A leaderboard entry: a method's entry on a dataset (see [`entry_sql`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BoardEntry {
    pub head: EntryHead,
    pub score: ScoreRow,
    pub object_scores: BTreeMap<i64, f64>,
}

/// Which submission is a method's entry on a dataset under a protocol.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Entry {
    pub protocol: ProtocolName,
    pub submission_id: SubmissionId,
    /// Pinned by the method's owner; otherwise the best.
    pub pinned: bool,
}

/// The id of the entry of the method and dataset of the submission `s` under the protocol
/// `protocol` (an SQL expression): the submission its owner pinned, if it is public, finished
/// and scored under the protocol; otherwise its best public finished submission there, the
/// earlier one on a tie.
fn entry_sql(protocol: &str) -> String {
    format!(
        "COALESCE((SELECT p.submission_id FROM entry_pins p \
         JOIN submissions s3 ON s3.id = p.submission_id \
         JOIN scores sc3 ON sc3.submission_id = s3.id AND sc3.protocol = {protocol} \
         WHERE p.method_id = s.method_id AND p.dataset_id = s.dataset_id \
         AND s3.status = 'done' AND s3.public = 1 AND s3.hidden = 0), \
         (SELECT s2.id FROM submissions s2 JOIN scores sc2 ON sc2.submission_id = s2.id \
         WHERE s2.method_id = s.method_id AND s2.dataset_id = s.dataset_id \
         AND s2.status = 'done' AND s2.public = 1 AND s2.hidden = 0 AND sc2.protocol = {protocol} \
         ORDER BY sc2.score DESC, s2.id LIMIT 1))"
    )
}

/// Whether the submission `s` is pinned, as 0 or 1 on both databases.
const PINNED_SQL: &str = "CAST(CASE WHEN EXISTS (SELECT 1 FROM entry_pins p \
     WHERE p.submission_id = s.id) THEN 1 ELSE 0 END AS BIGINT)";

fn score(row: &AnyRow) -> StoreResult<ScoreRow> {
    let protocol = parse_column("protocol", row.try_get("protocol")?)?;
    // A record is read by people: its numbers as the protocol defines them, whenever scored.
    let parameters =
        stored_parameters::<Parameters>(row)?.map(|p| RecordParameters::Pose(p.as_defined()));
    Ok(ScoreRow {
        id: row.try_get("score_id")?,
        submission_id: row.try_get("submission_id")?,
        protocol,
        score: row.try_get("score")?,
        recall: row.try_get("recall")?,
        ar_vsd: row.try_get("ar_vsd")?,
        ar_mssd: row.try_get("ar_mssd")?,
        ar_mspd: row.try_get("ar_mspd")?,
        time_avg: row.try_get("time_avg")?,
        estimates_evaluated: row.try_get("estimates_evaluated")?,
        estimates_ignored: row.try_get("estimates_ignored")?,
        record: ScoreRecord {
            evaluator_version: row.try_get("evaluator_version")?,
            protocol: protocol.into(),
            parameters,
            dataset_hash: row.try_get("dataset_hash")?,
            file_sha256: row.try_get("file_sha256")?,
        },
        ci95: match (row.try_get("ci_low")?, row.try_get("ci_high")?) {
            (Some(low), Some(high)) => Some([low, high]),
            _ => None,
        },
    })
}

impl Store {
    /// The headline scores of every submission of `owner`, by submission, then protocol.
    pub async fn scores_of_owner(&self, owner: UserId) -> StoreResult<Vec<ScoreRow>> {
        self.scores_of_submissions_where("s.owner_id", owner.get())
            .await
    }

    /// The headline scores of every submission of method `id`, private ones included, by
    /// submission, then protocol.
    pub async fn scores_of_method(&self, id: MethodId) -> StoreResult<Vec<ScoreRow>> {
        self.scores_of_submissions_where("s.method_id", id.get())
            .await
    }

    /// The scores of the submissions whose `column` is `value`.
    async fn scores_of_submissions_where(
        &self,
        column: &'static str,
        value: i64,
    ) -> StoreResult<Vec<ScoreRow>> {
        let sql = format!(
            "SELECT {SCORE_COLUMNS} FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             WHERE {column} = $1 ORDER BY sc.submission_id, sc.protocol"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(value)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(score).collect()
    }

    /// The reproducibility records of a submission's scores, one per protocol.
    pub async fn score_records(&self, id: SubmissionId) -> StoreResult<Vec<ScoreRecord>> {
        let sql = format!(
            "SELECT {SCORE_COLUMNS} FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             WHERE sc.submission_id = $1 ORDER BY sc.protocol"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(id)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(|r| Ok(score(r)?.record)).collect()
    }

    /// The reports of a submission, one per protocol it was evaluated under.
    pub async fn reports_of_submission(&self, id: SubmissionId) -> StoreResult<Vec<Report>> {
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

    /// The leaderboard of a protocol, in one query: for every method and dataset, its entry's
    /// scores with its per-object scores, best score first (optionally for one dataset only).
    pub async fn leaderboard(
        &self,
        protocol: ProtocolName,
        dataset_id: Option<DatasetId>,
    ) -> StoreResult<Vec<BoardEntry>> {
        let sql = format!(
            "SELECT {SCORE_COLUMNS}, {HEAD_COLUMNS}, \
             os.obj_id, os.value AS obj_value \
             FROM scores sc JOIN submissions s ON s.id = sc.submission_id {HEAD_JOINS} \
             LEFT JOIN object_scores os ON os.score_id = sc.id \
             WHERE sc.protocol = $1 AND s.status = 'done' AND s.public = 1 AND s.hidden = 0 AND d.retired = 0 \
             AND ($2 < 0 OR s.dataset_id = $2) AND s.id = {} \
             ORDER BY sc.score DESC, m.id, sc.id, os.obj_id",
            entry_sql("$1")
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(protocol.as_str())
            .bind(dataset_id.map_or(-1, DatasetId::get))
            .fetch_all(&self.pool)
            .await?;
        let mut entries: Vec<BoardEntry> = Vec::new();
        for r in &rows {
            let score_id: i64 = r.try_get("score_id")?;
            if entries.last().is_none_or(|e| e.score.id != score_id) {
                entries.push(BoardEntry {
                    head: head(r)?,
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

    /// The bootstrap replicates of the scores `ids` (those stored with some), by score id, of
    /// the table `protocol`'s board ranks (each table's ids are its own).
    pub async fn replicates(
        &self,
        ids: &[i64],
        protocol: BoardProtocol,
    ) -> StoreResult<BTreeMap<i64, Vec<f64>>> {
        let select = match protocol {
            BoardProtocol::Pose(_) => {
                "SELECT id, replicates FROM scores WHERE replicates IS NOT NULL AND id IN"
            }
            BoardProtocol::Coco(_) => {
                "SELECT id, replicates FROM coco_scores WHERE replicates IS NOT NULL AND id IN"
            }
            BoardProtocol::Bop24 => {
                "SELECT id, replicates FROM bop24_scores WHERE replicates IS NOT NULL AND id IN"
            }
        };
        let mut out = BTreeMap::new();
        for r in fetch_in(&self.pool, select, ids).await? {
            let bytes: Vec<u8> = r.try_get("replicates")?;
            let values = replicates_from(&bytes).ok_or(StoreError::Corrupt {
                column: "replicates",
                value: format!("{} bytes", bytes.len()),
            })?;
            if !values.is_empty() {
                out.insert(r.try_get("id")?, values);
            }
        }
        Ok(out)
    }

    /// The entries, per protocol, of a method on a dataset.
    pub async fn entries(
        &self,
        method_id: MethodId,
        dataset_id: DatasetId,
    ) -> StoreResult<Vec<Entry>> {
        let sql = format!(
            "SELECT sc.protocol, s.id AS submission_id, {PINNED_SQL} AS pinned \
             FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             WHERE s.method_id = $1 AND s.dataset_id = $2 AND s.id = {} ORDER BY sc.protocol",
            entry_sql("sc.protocol")
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .bind(dataset_id)
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| {
                Ok(Entry {
                    protocol: parse_column("protocol", r.try_get("protocol")?)?,
                    submission_id: r.try_get("submission_id")?,
                    pinned: r.try_get::<i64, _>("pinned")? != 0,
                })
            })
            .collect()
    }

    /// Whether the submission is pinned as its method's entry on its dataset.
    pub async fn is_pinned(&self, submission_id: SubmissionId) -> StoreResult<bool> {
        let row = sqlx::query("SELECT submission_id FROM entry_pins WHERE submission_id = $1")
            .bind(submission_id)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.is_some())
    }

    /// Pins a submission as its method's entry on its dataset (`pin`), or removes that pin if
    /// it is this submission's; true when the boards change.
    pub async fn set_pinned(&self, submission_id: SubmissionId, pin: bool) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = if pin {
            sqlx::query(
                "INSERT INTO entry_pins (method_id, dataset_id, submission_id) \
                 SELECT method_id, dataset_id, id FROM submissions WHERE id = $1 \
                 ON CONFLICT (method_id, dataset_id) DO UPDATE SET submission_id = excluded.submission_id",
            )
            .bind(submission_id)
            .execute(&mut *tx)
            .await?
        } else {
            sqlx::query("DELETE FROM entry_pins WHERE submission_id = $1")
                .bind(submission_id)
                .execute(&mut *tx)
                .await?
        };
        self.commit_board_change(tx, done.rows_affected() > 0).await
    }
}
