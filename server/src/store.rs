//! Storage of datasets, methods, submissions (which are also the evaluation jobs) and scores,
//! in SQLite by default or PostgreSQL. One store over `sqlx::Any`, with the SQL kept common
//! (`$N` placeholders, `RETURNING`) and a backend switch only where the dialects differ (the
//! job claim, connection setup, migrations). Times are epoch milliseconds; booleans 0/1.

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;
use std::time::{SystemTime, UNIX_EPOCH};

use evaluator::protocol::ProtocolName;
use evaluator::report::Report;
use serde::Serialize;
use sqlx::any::{AnyPoolOptions, AnyRow};
use sqlx::migrate::Migrator;
use sqlx::{AnyPool, Row};

use crate::error::{AppError, AppResult};

pub mod accounts;

static SQLITE_MIGRATIONS: Migrator = sqlx::migrate!("../migrations/sqlite");
static POSTGRES_MIGRATIONS: Migrator = sqlx::migrate!("../migrations/postgres");

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

#[derive(Clone)]
pub struct Store {
    pool: AnyPool,
    backend: Backend,
}

pub fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// The default database: a SQLite file in the data directory.
pub fn sqlite_url(data_dir: &Path) -> String {
    format!(
        "sqlite://{}?mode=rwc",
        data_dir.join("poseboard.db").display()
    )
}

#[derive(Clone, Debug, Serialize)]
pub struct DatasetRow {
    pub id: i64,
    pub name: String,
    #[serde(skip)]
    pub path: String,
    pub objects_count: i64,
    pub scenes_count: i64,
    pub images_count: i64,
    pub targets_count: i64,
    pub instances_count: i64,
    pub image_width: i64,
    pub image_height: i64,
    pub added_at: i64,
}

#[derive(Clone, Debug, Serialize)]
pub struct MethodRow {
    pub id: i64,
    pub name: String,
    pub description: String,
    pub paper_url: String,
    pub code_url: String,
    /// `synthetic`, `real` or `both` (empty: not given).
    pub training_data: String,
    /// `rgb`, `depth` or `rgb-d` (empty: not given).
    pub modality: String,
    pub created_at: i64,
}

/// What a submitter says about their method; empty fields leave stored values as they are.
#[derive(Clone, Debug, Default)]
pub struct MethodMeta {
    pub description: String,
    pub paper_url: String,
    pub code_url: String,
    pub training_data: String,
    pub modality: String,
}

/// Lifecycle of a submission.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Queued,
    Running,
    Done,
    Failed,
}

impl Status {
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Queued => "queued",
            Status::Running => "running",
            Status::Done => "done",
            Status::Failed => "failed",
        }
    }

    fn parse(s: &str) -> Status {
        match s {
            "running" => Status::Running,
            "done" => Status::Done,
            "failed" => Status::Failed,
            _ => Status::Queued,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct SubmissionRow {
    pub id: i64,
    pub method_id: i64,
    pub method: String,
    pub dataset_id: i64,
    pub dataset: String,
    pub protocols: Vec<ProtocolName>,
    pub public: bool,
    pub file_name: String,
    pub file_sha256: String,
    pub file_size: i64,
    pub estimates_count: i64,
    pub status: Status,
    pub progress: f64,
    pub error: Option<String>,
    /// Who a failure is due to: `user` (the file) or `service` (never counted against the user).
    pub fault: Option<String>,
    pub attempts: i64,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub evaluator_version: Option<String>,
    /// The hardware the reported times come from.
    pub hardware: String,
    #[serde(skip)]
    pub owner_id: Option<i64>,
    /// Hidden by an administrator: shown to its owner and the administrators only.
    pub hidden: bool,
    #[serde(skip)]
    pub preflight_json: String,
}

pub struct NewSubmission<'a> {
    pub method_id: i64,
    pub dataset_id: i64,
    pub protocols: &'a [ProtocolName],
    pub public: bool,
    pub file_name: &'a str,
    pub file_sha256: &'a str,
    pub file_size: i64,
    pub estimates_count: i64,
    pub hardware: &'a str,
    pub preflight_json: &'a str,
    pub owner_id: i64,
}

#[derive(Clone, Debug, Serialize)]
pub struct AuditEntry {
    pub actor: String,
    pub action: String,
    pub target: String,
    pub at: i64,
}

/// One protocol's scores of a submission, as stored.
#[derive(Clone, Debug, Serialize)]
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
#[derive(Clone, Debug, Serialize)]
pub struct BoardEntry {
    pub method_id: i64,
    pub method: String,
    pub training_data: String,
    pub modality: String,
    pub hardware: String,
    pub dataset_id: i64,
    pub dataset: String,
    pub submission_id: i64,
    pub submitted_at: i64,
    pub score: ScoreRow,
    pub object_scores: BTreeMap<i64, f64>,
}

fn protocols_to_text(p: &[ProtocolName]) -> String {
    p.iter().map(|p| p.as_str()).collect::<Vec<_>>().join(",")
}

fn protocols_from_text(s: &str) -> Vec<ProtocolName> {
    s.split(',')
        .filter_map(|p| ProtocolName::from_str(p).ok())
        .collect()
}

const SUBMISSION_COLUMNS: &str = "s.id, s.method_id, m.name AS method, s.dataset_id, d.name AS dataset, \
    s.protocols, s.public, s.file_name, s.file_sha256, s.file_size, s.estimates_count, s.status, \
    s.progress, s.error, s.fault, s.attempts, s.created_at, s.started_at, s.finished_at, \
    s.evaluator_version, s.hardware, s.owner_id, s.hidden, s.preflight_json \
    FROM submissions s JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id";

fn submission(row: &AnyRow) -> Result<SubmissionRow, sqlx::Error> {
    Ok(SubmissionRow {
        id: row.try_get("id")?,
        method_id: row.try_get("method_id")?,
        method: row.try_get("method")?,
        dataset_id: row.try_get("dataset_id")?,
        dataset: row.try_get("dataset")?,
        protocols: protocols_from_text(&row.try_get::<String, _>("protocols")?),
        public: row.try_get::<i64, _>("public")? != 0,
        file_name: row.try_get("file_name")?,
        file_sha256: row.try_get("file_sha256")?,
        file_size: row.try_get("file_size")?,
        estimates_count: row.try_get("estimates_count")?,
        status: Status::parse(&row.try_get::<String, _>("status")?),
        progress: row.try_get("progress")?,
        error: row.try_get("error")?,
        fault: row.try_get("fault")?,
        attempts: row.try_get("attempts")?,
        created_at: row.try_get("created_at")?,
        started_at: row.try_get("started_at")?,
        finished_at: row.try_get("finished_at")?,
        evaluator_version: row.try_get("evaluator_version")?,
        hardware: row.try_get("hardware")?,
        owner_id: row.try_get("owner_id")?,
        hidden: row.try_get::<i64, _>("hidden")? != 0,
        preflight_json: row.try_get("preflight_json")?,
    })
}

fn dataset(row: &AnyRow) -> Result<DatasetRow, sqlx::Error> {
    Ok(DatasetRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        path: row.try_get("path")?,
        objects_count: row.try_get("objects_count")?,
        scenes_count: row.try_get("scenes_count")?,
        images_count: row.try_get("images_count")?,
        targets_count: row.try_get("targets_count")?,
        instances_count: row.try_get("instances_count")?,
        image_width: row.try_get("image_width")?,
        image_height: row.try_get("image_height")?,
        added_at: row.try_get("added_at")?,
    })
}

fn method(row: &AnyRow) -> Result<MethodRow, sqlx::Error> {
    Ok(MethodRow {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        description: row.try_get("description")?,
        paper_url: row.try_get("paper_url")?,
        code_url: row.try_get("code_url")?,
        training_data: row.try_get("training_data")?,
        modality: row.try_get("modality")?,
        created_at: row.try_get("created_at")?,
    })
}

fn score(row: &AnyRow) -> Result<ScoreRow, sqlx::Error> {
    Ok(ScoreRow {
        id: row.try_get("score_id")?,
        submission_id: row.try_get("submission_id")?,
        protocol: ProtocolName::from_str(&row.try_get::<String, _>("protocol")?)
            .unwrap_or(ProtocolName::Bop19),
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
    /// Connects to `url` (`sqlite://...` or `postgres://...`); a SQLite file is created when
    /// missing and put in WAL mode so that pages read while a worker writes.
    pub async fn connect(url: &str) -> AppResult<Store> {
        sqlx::any::install_default_drivers();
        let backend = if url.starts_with("postgres") {
            Backend::Postgres
        } else if url.starts_with("sqlite") {
            Backend::Sqlite
        } else {
            return Err(AppError::Config(format!(
                "unsupported database URL `{url}`: use sqlite://... or postgres://..."
            )));
        };
        let mut options =
            AnyPoolOptions::new().max_connections(if backend == Backend::Sqlite { 4 } else { 10 });
        if backend == Backend::Sqlite {
            options = options.after_connect(|conn, _| {
                Box::pin(async move {
                    for pragma in [
                        "PRAGMA journal_mode = WAL",
                        "PRAGMA busy_timeout = 10000",
                        "PRAGMA foreign_keys = ON",
                        "PRAGMA synchronous = NORMAL",
                    ] {
                        sqlx::query(pragma).execute(&mut *conn).await?;
                    }
                    Ok(())
                })
            });
        }
        let pool = options.connect(url).await?;
        Ok(Store { pool, backend })
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    pub async fn migrate(&self) -> AppResult<()> {
        let migrator = match self.backend {
            Backend::Sqlite => &SQLITE_MIGRATIONS,
            Backend::Postgres => &POSTGRES_MIGRATIONS,
        };
        migrator
            .run(&self.pool)
            .await
            .map_err(|e| AppError::Internal(e.to_string()))
    }

    // ---- datasets --------------------------------------------------------------------------

    /// Registers a dataset, or refreshes its description (and un-retires it) if one of that
    /// name exists.
    pub async fn upsert_dataset(&self, d: &DatasetRow) -> AppResult<i64> {
        let row = sqlx::query(
            "INSERT INTO datasets (name, path, objects_count, scenes_count, images_count, \
             targets_count, instances_count, image_width, image_height, added_at) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10) \
             ON CONFLICT (name) DO UPDATE SET path = excluded.path, \
             objects_count = excluded.objects_count, scenes_count = excluded.scenes_count, \
             images_count = excluded.images_count, targets_count = excluded.targets_count, \
             instances_count = excluded.instances_count, image_width = excluded.image_width, \
             image_height = excluded.image_height, retired = 0 \
             RETURNING id",
        )
        .bind(&d.name)
        .bind(&d.path)
        .bind(d.objects_count)
        .bind(d.scenes_count)
        .bind(d.images_count)
        .bind(d.targets_count)
        .bind(d.instances_count)
        .bind(d.image_width)
        .bind(d.image_height)
        .bind(now_ms())
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    pub async fn datasets(&self) -> AppResult<Vec<DatasetRow>> {
        let rows = sqlx::query("SELECT * FROM datasets WHERE retired = 0 ORDER BY name")
            .fetch_all(&self.pool)
            .await?;
        Ok(rows.iter().map(dataset).collect::<Result<_, _>>()?)
    }

    pub async fn dataset_by_name(&self, name: &str) -> AppResult<Option<DatasetRow>> {
        let row = sqlx::query("SELECT * FROM datasets WHERE name = $1 AND retired = 0")
            .bind(name)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.as_ref().map(dataset).transpose()?)
    }

    pub async fn dataset(&self, id: i64) -> AppResult<Option<DatasetRow>> {
        let row = sqlx::query("SELECT * FROM datasets WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.as_ref().map(dataset).transpose()?)
    }

    // ---- methods ---------------------------------------------------------------------------

    /// The method of that name, created with the given metadata if new; the metadata of an
    /// existing method is updated where new values are given.
    /// The owner's method of that name, created with the given metadata if new (names are
    /// unique per account, so another account's methods stay invisible).
    pub async fn ensure_method(
        &self,
        name: &str,
        meta: &MethodMeta,
        owner_id: i64,
    ) -> AppResult<i64> {
        let existing = sqlx::query("SELECT id FROM methods WHERE owner_id = $1 AND name = $2")
            .bind(owner_id)
            .bind(name)
            .fetch_optional(&self.pool)
            .await?;
        if let Some(row) = existing {
            let id: i64 = row.try_get("id")?;
            for (column, value) in [
                ("description", &meta.description),
                ("paper_url", &meta.paper_url),
                ("code_url", &meta.code_url),
                ("training_data", &meta.training_data),
                ("modality", &meta.modality),
            ] {
                if !value.is_empty() {
                    // `column` comes from the list above, never from the request.
                    let sql = format!("UPDATE methods SET {column} = $1 WHERE id = $2");
                    sqlx::query(sqlx::AssertSqlSafe(sql))
                        .bind(value)
                        .bind(id)
                        .execute(&self.pool)
                        .await?;
                }
            }
            return Ok(id);
        }
        let row = sqlx::query(
            "INSERT INTO methods (name, description, paper_url, code_url, training_data, modality, \
             created_at, owner_id) VALUES ($1, $2, $3, $4, $5, $6, $7, $8) RETURNING id",
        )
        .bind(name)
        .bind(&meta.description)
        .bind(&meta.paper_url)
        .bind(&meta.code_url)
        .bind(&meta.training_data)
        .bind(&meta.modality)
        .bind(now_ms())
        .bind(owner_id)
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    pub async fn method(&self, id: i64) -> AppResult<Option<MethodRow>> {
        let row = sqlx::query("SELECT * FROM methods WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.as_ref().map(method).transpose()?)
    }

    /// Methods with at least one public submission.
    pub async fn methods(&self) -> AppResult<Vec<MethodRow>> {
        let rows = sqlx::query(
            "SELECT * FROM methods m WHERE EXISTS \
             (SELECT 1 FROM submissions s WHERE s.method_id = m.id AND s.public = 1 AND s.hidden = 0) ORDER BY m.name",
        )
        .fetch_all(&self.pool)
        .await?;
        Ok(rows.iter().map(method).collect::<Result<_, _>>()?)
    }

    // ---- submissions -----------------------------------------------------------------------

    pub async fn find_same_file(
        &self,
        method_id: i64,
        dataset_id: i64,
        sha256: &str,
        protocols: &[ProtocolName],
    ) -> AppResult<Option<SubmissionRow>> {
        let sql = format!(
            "SELECT {SUBMISSION_COLUMNS} WHERE s.method_id = $1 AND s.dataset_id = $2 \
             AND s.file_sha256 = $3 AND s.protocols = $4"
        );
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .bind(dataset_id)
            .bind(sha256)
            .bind(protocols_to_text(protocols))
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.as_ref().map(submission).transpose()?)
    }

    pub async fn insert_submission(&self, s: &NewSubmission<'_>) -> AppResult<i64> {
        let row = sqlx::query(
            "INSERT INTO submissions (method_id, dataset_id, protocols, public, file_name, \
             file_sha256, file_size, estimates_count, hardware, preflight_json, status, created_at, \
             owner_id) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, 'queued', $11, $12) RETURNING id",
        )
        .bind(s.method_id)
        .bind(s.dataset_id)
        .bind(protocols_to_text(s.protocols))
        .bind(s.public as i64)
        .bind(s.file_name)
        .bind(s.file_sha256)
        .bind(s.file_size)
        .bind(s.estimates_count)
        .bind(s.hardware)
        .bind(s.preflight_json)
        .bind(now_ms())
        .bind(s.owner_id)
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("id")?)
    }

    pub async fn submission(&self, id: i64) -> AppResult<Option<SubmissionRow>> {
        let sql = format!("SELECT {SUBMISSION_COLUMNS} WHERE s.id = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        Ok(row.as_ref().map(submission).transpose()?)
    }

    /// Public submissions of a method, newest first.
    pub async fn submissions_of_method(&self, method_id: i64) -> AppResult<Vec<SubmissionRow>> {
        let sql = format!(
            "SELECT {SUBMISSION_COLUMNS} WHERE s.method_id = $1 AND s.public = 1 AND s.hidden = 0 ORDER BY s.id DESC"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .fetch_all(&self.pool)
            .await?;
        Ok(rows.iter().map(submission).collect::<Result<_, _>>()?)
    }

    /// Public submissions, newest first.
    pub async fn recent_submissions(&self, limit: i64) -> AppResult<Vec<SubmissionRow>> {
        let sql = format!(
            "SELECT {SUBMISSION_COLUMNS} WHERE s.public = 1 AND s.hidden = 0 ORDER BY s.id DESC LIMIT $1"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(limit)
            .fetch_all(&self.pool)
            .await?;
        Ok(rows.iter().map(submission).collect::<Result<_, _>>()?)
    }

    /// Creation times of the user's submissions on a dataset since `since` (epoch ms), oldest
    /// first, not counting those that failed through the service's fault.
    pub async fn recent_submission_times(
        &self,
        owner_id: i64,
        dataset_id: i64,
        since: i64,
    ) -> AppResult<Vec<i64>> {
        let rows = sqlx::query(
            "SELECT created_at FROM submissions WHERE owner_id = $1 AND dataset_id = $2 \
             AND created_at >= $3 AND (fault IS NULL OR fault <> 'service') ORDER BY created_at",
        )
        .bind(owner_id)
        .bind(dataset_id)
        .bind(since)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(|r| Ok(r.try_get("created_at")?)).collect()
    }

    /// How many submissions wait before this one (0 = it is next or running).
    pub async fn queue_position(&self, id: i64) -> AppResult<i64> {
        let row = sqlx::query(
            "SELECT COUNT(*) AS n FROM submissions WHERE status = 'queued' AND id < $1",
        )
        .bind(id)
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("n")?)
    }

    /// Estimates waiting or being evaluated, for the pre-flight time estimate.
    pub async fn estimates_ahead(&self, id: i64) -> AppResult<i64> {
        let row = sqlx::query(
            "SELECT CAST(COALESCE(SUM(estimates_count), 0) AS BIGINT) AS n FROM submissions \
             WHERE status IN ('queued', 'running') AND id < $1",
        )
        .bind(id)
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("n")?)
    }

    // ---- the job queue ---------------------------------------------------------------------

    /// Takes the oldest queued submission, or one whose worker's lease expired (the worker
    /// died), for `worker` until `lease_until`. Submissions that failed `max_attempts` times
    /// for the service's reasons are marked failed instead of being retried forever.
    pub async fn claim(
        &self,
        worker: &str,
        lease_ms: i64,
        max_attempts: i64,
    ) -> AppResult<Option<SubmissionRow>> {
        let now = now_ms();
        sqlx::query(
            "UPDATE submissions SET status = 'failed', fault = 'service', finished_at = $1, \
             error = 'the evaluation was interrupted too many times' \
             WHERE status = 'running' AND lease_until < $1 AND attempts >= $2",
        )
        .bind(now)
        .bind(max_attempts)
        .execute(&self.pool)
        .await?;
        let lock = match self.backend {
            Backend::Postgres => " FOR UPDATE SKIP LOCKED",
            // SQLite runs one writer at a time, so the subquery and the update are atomic.
            Backend::Sqlite => "",
        };
        let sql = format!(
            "UPDATE submissions SET status = 'running', worker = $1, lease_until = $2, \
             attempts = attempts + 1, started_at = COALESCE(started_at, $3), progress = 0 \
             WHERE id = (SELECT id FROM submissions WHERE status = 'queued' \
             OR (status = 'running' AND lease_until < $3) ORDER BY id LIMIT 1{lock}) \
             RETURNING id"
        );
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(worker)
            .bind(now + lease_ms)
            .bind(now)
            .fetch_optional(&self.pool)
            .await?;
        match row {
            Some(row) => self.submission(row.try_get("id")?).await,
            None => Ok(None),
        }
    }

    /// Extends the lease and records progress; false when the job is no longer this worker's.
    pub async fn heartbeat(
        &self,
        id: i64,
        worker: &str,
        lease_ms: i64,
        progress: f64,
    ) -> AppResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET lease_until = $1, progress = $2 \
             WHERE id = $3 AND worker = $4 AND status = 'running'",
        )
        .bind(now_ms() + lease_ms)
        .bind(progress)
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Stores the scores and marks the submission done, in one transaction that only commits
    /// if the job is still this worker's: a job taken over after a lost lease never ends up
    /// with two score sets.
    pub async fn finish(&self, id: i64, worker: &str, reports: &[Report]) -> AppResult<bool> {
        let mut tx = self.pool.begin().await?;
        let now = now_ms();
        let updated = sqlx::query(
            "UPDATE submissions SET status = 'done', progress = 1, finished_at = $1, \
             lease_until = NULL, error = NULL, fault = NULL, evaluator_version = $2 \
             WHERE id = $3 AND worker = $4 AND status = 'running'",
        )
        .bind(now)
        .bind(evaluator::report::EVALUATOR_VERSION)
        .bind(id)
        .bind(worker)
        .execute(&mut *tx)
        .await?;
        if updated.rows_affected() != 1 {
            tx.rollback().await?;
            return Ok(false);
        }
        sqlx::query("DELETE FROM scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        for report in reports {
            let (time_avg, recall) = match report.protocol {
                ProtocolName::Eccv18 => (
                    report.average_time_per_target,
                    report.localization.as_ref().map(|l| l.recall),
                ),
                ProtocolName::Bop19 => (report.bop19_average_time_per_image, None),
            };
            let loc = report.localization.as_ref();
            let json =
                serde_json::to_string(report).map_err(|e| AppError::Internal(e.to_string()))?;
            let row = sqlx::query(
                "INSERT INTO scores (submission_id, protocol, score, recall, ar_vsd, ar_mssd, \
                 ar_mspd, time_avg, targets_count, tp_count, estimates_evaluated, estimates_ignored, \
                 report_json, created_at) \
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14) RETURNING id",
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
            .fetch_one(&mut *tx)
            .await?;
            let score_id: i64 = row.try_get("id")?;
            let (objects, scenes) = match (report.protocol, loc) {
                (ProtocolName::Eccv18, Some(l)) => (l.obj_recalls.clone(), l.scene_recalls.clone()),
                _ => (
                    report.obj_average_recalls.clone(),
                    report.scene_average_recalls.clone(),
                ),
            };
            for (obj, value) in objects {
                sqlx::query(
                    "INSERT INTO object_scores (score_id, obj_id, value) VALUES ($1, $2, $3)",
                )
                .bind(score_id)
                .bind(obj as i64)
                .bind(value)
                .execute(&mut *tx)
                .await?;
            }
            for (scene, value) in scenes {
                sqlx::query(
                    "INSERT INTO scene_scores (score_id, scene_id, value) VALUES ($1, $2, $3)",
                )
                .bind(score_id)
                .bind(scene as i64)
                .bind(value)
                .execute(&mut *tx)
                .await?;
            }
            for (curve, series, x, y) in curve_points(report) {
                sqlx::query(
                    "INSERT INTO curve_points (score_id, curve, series, x, y) VALUES ($1, $2, $3, $4, $5)",
                )
                .bind(score_id)
                .bind(curve)
                .bind(series)
                .bind(x)
                .bind(y)
                .execute(&mut *tx)
                .await?;
            }
        }
        tx.commit().await?;
        Ok(true)
    }

    /// Marks the job failed with a reason; `fault` says whether the file or the service is to blame.
    pub async fn fail(&self, id: i64, worker: &str, error: &str, fault: &str) -> AppResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET status = 'failed', error = $1, fault = $2, finished_at = $3, \
             lease_until = NULL WHERE id = $4 AND worker = $5 AND status = 'running'",
        )
        .bind(error)
        .bind(fault)
        .bind(now_ms())
        .bind(id)
        .bind(worker)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    // ---- administration --------------------------------------------------------------------

    pub async fn set_hidden(&self, id: i64, hidden: bool) -> AppResult<bool> {
        let done = sqlx::query("UPDATE submissions SET hidden = $1 WHERE id = $2")
            .bind(hidden as i64)
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Queues a finished submission again (e.g. after an evaluator fix); its old scores stay
    /// until the new ones replace them.
    pub async fn rerun(&self, id: i64) -> AppResult<bool> {
        let done = sqlx::query(
            "UPDATE submissions SET status = 'queued', progress = 0, attempts = 0, error = NULL, \
             fault = NULL, worker = NULL, lease_until = NULL WHERE id = $1 AND status IN ('done', 'failed')",
        )
        .bind(id)
        .execute(&self.pool)
        .await?;
        Ok(done.rows_affected() == 1)
    }

    /// Deletes a submission and its scores; returns the file's hash when no other submission
    /// uses the same file, so the caller can remove it.
    pub async fn delete_submission(&self, id: i64) -> AppResult<Option<Option<String>>> {
        let Some(sub) = self.submission(id).await? else {
            return Ok(None);
        };
        let mut tx = self.pool.begin().await?;
        sqlx::query("DELETE FROM scores WHERE submission_id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        sqlx::query("DELETE FROM submissions WHERE id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        let others = sqlx::query("SELECT COUNT(*) AS n FROM submissions WHERE file_sha256 = $1")
            .bind(&sub.file_sha256)
            .fetch_one(&mut *tx)
            .await?;
        tx.commit().await?;
        let unused = others.try_get::<i64, _>("n")? == 0;
        Ok(Some(unused.then_some(sub.file_sha256)))
    }

    pub async fn retire_dataset(&self, name: &str) -> AppResult<bool> {
        let done = sqlx::query("UPDATE datasets SET retired = 1 WHERE name = $1 AND retired = 0")
            .bind(name)
            .execute(&self.pool)
            .await?;
        Ok(done.rows_affected() == 1)
    }

    pub async fn audit(&self, actor_id: i64, action: &str, target: &str) -> AppResult<()> {
        sqlx::query("INSERT INTO audit_log (actor_id, action, target, at) VALUES ($1, $2, $3, $4)")
            .bind(actor_id)
            .bind(action)
            .bind(target)
            .bind(now_ms())
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// The latest administrator actions: (who, action, target, when).
    pub async fn audit_log(&self, limit: i64) -> AppResult<Vec<AuditEntry>> {
        let rows = sqlx::query(
            "SELECT u.name AS actor, a.action, a.target, a.at FROM audit_log a \
             JOIN users u ON u.id = a.actor_id ORDER BY a.id DESC LIMIT $1",
        )
        .bind(limit)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok(AuditEntry {
                    actor: r.try_get("actor")?,
                    action: r.try_get("action")?,
                    target: r.try_get("target")?,
                    at: r.try_get("at")?,
                })
            })
            .collect()
    }

    // ---- scores ----------------------------------------------------------------------------

    pub async fn scores_of_submission(&self, id: i64) -> AppResult<Vec<(ScoreRow, String)>> {
        let rows = sqlx::query(
            "SELECT id AS score_id, submission_id, protocol, score, recall, ar_vsd, ar_mssd, ar_mspd, \
             time_avg, estimates_evaluated, estimates_ignored, report_json \
             FROM scores WHERE submission_id = $1 ORDER BY protocol",
        )
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| Ok((score(r)?, r.try_get::<String, _>("report_json")?)))
            .collect()
    }

    /// The curve points of one score: (curve, series, x, y) ordered for plotting.
    pub async fn curve_points(&self, score_id: i64) -> AppResult<Vec<(String, f64, f64, f64)>> {
        let rows = sqlx::query(
            "SELECT curve, series, x, y FROM curve_points WHERE score_id = $1 ORDER BY curve, series, x",
        )
        .bind(score_id)
        .fetch_all(&self.pool)
        .await?;
        rows.iter()
            .map(|r| {
                Ok((
                    r.try_get("curve")?,
                    r.try_get("series")?,
                    r.try_get("x")?,
                    r.try_get("y")?,
                ))
            })
            .collect()
    }

    /// The leaderboard of a protocol: for every method and dataset, the latest finished public
    /// submission's scores (optionally for one dataset only).
    pub async fn leaderboard(
        &self,
        protocol: ProtocolName,
        dataset_id: Option<i64>,
    ) -> AppResult<Vec<BoardEntry>> {
        let rows = sqlx::query(
            "SELECT sc.id AS score_id, sc.submission_id, sc.protocol, sc.score, sc.recall, sc.ar_vsd, \
             sc.ar_mssd, sc.ar_mspd, sc.time_avg, sc.estimates_evaluated, sc.estimates_ignored, \
             s.method_id, m.name AS method, m.training_data, m.modality, s.hardware, \
             s.dataset_id, d.name AS dataset, s.finished_at \
             FROM scores sc JOIN submissions s ON s.id = sc.submission_id \
             JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id \
             WHERE sc.protocol = $1 AND s.status = 'done' AND s.public = 1 AND s.hidden = 0 AND d.retired = 0 \
             AND ($2 < 0 OR s.dataset_id = $2) \
             AND s.id = (SELECT MAX(s2.id) FROM submissions s2 JOIN scores sc2 ON sc2.submission_id = s2.id \
                 WHERE s2.method_id = s.method_id AND s2.dataset_id = s.dataset_id \
                 AND s2.status = 'done' AND s2.public = 1 AND s2.hidden = 0 AND sc2.protocol = $1) \
             ORDER BY sc.score DESC, m.name",
        )
        .bind(protocol.as_str())
        .bind(dataset_id.unwrap_or(-1))
        .fetch_all(&self.pool)
        .await?;
        let mut entries = Vec::with_capacity(rows.len());
        for r in &rows {
            let score = score(r)?;
            let objects =
                sqlx::query("SELECT obj_id, value FROM object_scores WHERE score_id = $1")
                    .bind(score.id)
                    .fetch_all(&self.pool)
                    .await?
                    .iter()
                    .map(|o| Ok((o.try_get("obj_id")?, o.try_get("value")?)))
                    .collect::<Result<BTreeMap<i64, f64>, sqlx::Error>>()?;
            entries.push(BoardEntry {
                method_id: r.try_get("method_id")?,
                method: r.try_get("method")?,
                training_data: r.try_get("training_data")?,
                modality: r.try_get("modality")?,
                hardware: r.try_get("hardware")?,
                dataset_id: r.try_get("dataset_id")?,
                dataset: r.try_get("dataset")?,
                submission_id: score.submission_id,
                submitted_at: r
                    .try_get::<Option<i64>, _>("finished_at")?
                    .unwrap_or_default(),
                score,
                object_scores: objects,
            });
        }
        Ok(entries)
    }
}

/// The curves of a report as rows: recall vs theta per tau (eccv18), recall vs visible
/// fraction (eccv18, x = bin start), recall vs threshold per error type (bop19).
fn curve_points(report: &Report) -> Vec<(&'static str, f64, f64, f64)> {
    let mut points = Vec::new();
    for curve in &report.recall_vs_theta {
        for &(theta, recall) in &curve.points {
            points.push(("recall_vs_theta", curve.tau, theta, recall));
        }
    }
    for bin in report.recall_vs_visib.iter().filter(|b| b.instances > 0) {
        points.push(("recall_vs_visib", 0.0, bin.visib_from, bin.recall));
    }
    if report.protocol == ProtocolName::Bop19 {
        // Per error type and threshold, the recall averaged over the error's other settings
        // (the VSD taus): the curves behind AR_VSD, AR_MSSD and AR_MSPD.
        let mut by: BTreeMap<(&'static str, String), Vec<f64>> = BTreeMap::new();
        for (sig, ths) in &report.per_error_recall_per_threshold {
            let curve = if sig.starts_with("error=vsd") {
                "recall_vs_th_vsd"
            } else if sig.starts_with("error=mssd") {
                "recall_vs_th_mssd"
            } else if sig.starts_with("error=mspd") {
                "recall_vs_th_mspd"
            } else {
                continue;
            };
            for (th, recall) in ths {
                by.entry((curve, th.clone())).or_default().push(*recall);
            }
        }
        for ((curve, th), recalls) in by {
            let x = th
                .strip_prefix("th=")
                .and_then(|t| t.split('_').next())
                .and_then(|t| t.parse::<f64>().ok())
                .unwrap_or(0.0);
            points.push((curve, 0.0, x, evaluator::score::mean(&recalls)));
        }
    }
    points
}
