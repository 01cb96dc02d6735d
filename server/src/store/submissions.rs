//! Submissions: an uploaded result file for a method and a dataset, with its lifecycle. The
//! submissions of one upload are created in one transaction with their method (get or
//! create), the duplicate checks and the fair-use counts, so that parallel uploads of one user
//! can neither exceed the limit nor trip over each other's new method, and an upload of
//! several files is stored whole or not at all.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use evaluator::protocol::ProtocolName;
use serde::Serialize;
use sqlx::Row;
use sqlx::any::AnyRow;

use super::board_version;
use super::methods::MethodMeta;
use super::{Backend, Store, StoreError, StoreResult, fetch_in, parse_column};
use crate::clock::now_ms;
use crate::domain::{
    DatasetId, Hardware, MethodId, MethodName, SubmissionId, Task, TeamId, UserId, Visibility,
};
use crate::preflight::{Preflight, RedFlag};

/// Lifecycle of a submission (which is also its evaluation job).
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
}

impl FromStr for Status {
    type Err = ();
    fn from_str(s: &str) -> Result<Self, ()> {
        match s {
            "queued" => Ok(Status::Queued),
            "running" => Ok(Status::Running),
            "done" => Ok(Status::Done),
            "failed" => Ok(Status::Failed),
            _ => Err(()),
        }
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Whom a failed evaluation is due to. Failures through the service's fault never count
/// against the user's fair-use limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fault {
    /// The file: shown to the user as the reason.
    User,
    /// The service (a crash, a lost worker, a missing dataset).
    Service,
}

impl Fault {
    pub fn as_str(self) -> &'static str {
        match self {
            Fault::User => "user",
            Fault::Service => "service",
        }
    }
}

impl FromStr for Fault {
    type Err = ();
    fn from_str(s: &str) -> Result<Self, ()> {
        match s {
            "user" => Ok(Fault::User),
            "service" => Ok(Fault::Service),
            _ => Err(()),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SubmissionRow {
    pub id: SubmissionId,
    pub method_id: MethodId,
    pub method: String,
    pub dataset_id: DatasetId,
    pub dataset: String,
    /// The 6D protocols it is evaluated under (none for a task).
    pub protocols: Vec<ProtocolName>,
    /// The BOP'22 2D task or BOP'24 6D detection it is scored for, instead of 6D protocols.
    pub task: Option<Task>,
    pub visibility: Visibility,
    pub file_name: String,
    pub file_sha256: String,
    pub file_size: i64,
    pub estimates_count: i64,
    pub status: Status,
    pub progress: f64,
    pub error: Option<String>,
    pub fault: Option<Fault>,
    pub attempts: i64,
    pub created_at: i64,
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub evaluator_version: Option<String>,
    /// The hardware the reported times come from.
    pub hardware: String,
    /// The uploader.
    #[serde(skip)]
    pub owner_id: Option<UserId>,
    /// The team whose method it is for, if any: its members see it as its uploader does.
    #[serde(skip)]
    pub team_id: Option<TeamId>,
    /// Hidden by an administrator: shown to its owner and the administrators only.
    pub hidden: bool,
    /// Its owner asked for publication, but the pre-flight's red flags hold it back until
    /// they confirm: private meanwhile.
    pub held: bool,
    /// Estimate evaluations the job takes (over all its protocols), and how many are done.
    pub work: i64,
    pub work_done: i64,
    /// How long the evaluation took, once done.
    pub eval_ms: Option<i64>,
    #[serde(skip)]
    pub preflight: Preflight,
}

impl SubmissionRow {
    /// Whether anyone may see it (and the leaderboards count it).
    pub fn is_public(&self) -> bool {
        self.visibility == Visibility::Public && !self.hidden
    }

    /// Whether it is a BOP'22 2D file (its entries are detections, not pose estimates).
    pub fn is_coco(&self) -> bool {
        matches!(self.task, Some(Task::Coco(_)))
    }
}

/// A public finished submission as the recent list names it.
#[derive(Clone, Debug)]
pub struct RecentRow {
    pub submission: SubmissionRow,
    /// The name of the team or account its method belongs to.
    pub owner: String,
    /// Its method is under double-blind review.
    pub anonymous: bool,
    /// Its headline scores: the 6D protocols' (AR, recall), a 2D task's AP, bop24's mAP.
    pub bop19: Option<f64>,
    pub eccv18: Option<f64>,
    pub ap: Option<f64>,
    pub map: Option<f64>,
}

/// A submission to create, with the method it is for.
pub struct NewSubmission<'a> {
    /// The uploader, whose fair-use limit it counts against.
    pub owner_id: UserId,
    /// The team whose method `method` names (created as the team's if new); `None`: the
    /// uploader's own method.
    pub team_id: Option<TeamId>,
    pub method: &'a MethodName,
    pub meta: &'a MethodMeta,
    pub dataset_id: DatasetId,
    pub protocols: &'a [ProtocolName],
    /// A task instead of the protocols.
    pub task: Option<Task>,
    pub visibility: Visibility,
    pub file_name: &'a str,
    pub file_sha256: &'a str,
    pub file_size: i64,
    /// The file itself, gzip-compressed: stored with the submission, for the workers.
    pub file_gzip: &'a [u8],
    pub estimates_count: i64,
    pub hardware: &'a Hardware,
    pub preflight: &'a Preflight,
    /// Publication asked for but held back by red flags.
    pub held: bool,
}

/// Where a queued submission stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct QueuePlace {
    /// Queued submissions that will be evaluated before it.
    pub queued_ahead: i64,
    /// Submissions being evaluated now.
    pub running: i64,
}

/// A fair-use limit: at most `limit` submissions per user and dataset since `since` (epoch ms).
#[derive(Clone, Copy, Debug)]
pub struct FairUse {
    pub limit: usize,
    pub since: i64,
}

/// What [`Store::create_submission`] did.
#[derive(Debug, PartialEq)]
pub enum Created {
    /// A new submission, queued.
    New(SubmissionId),
    /// The same file was already submitted for the method and dataset: that submission.
    Duplicate(SubmissionId),
    /// Over the fair-use limit: nothing was written; the counted submissions' times, oldest first.
    Limited { times: Vec<i64> },
}

/// One submission of an upload that [`Store::create_submissions`] stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CreatedOne {
    /// A new submission, queued.
    New(SubmissionId),
    /// The same file was already submitted for the method and dataset: that submission.
    Duplicate(SubmissionId),
}

impl From<CreatedOne> for Created {
    fn from(one: CreatedOne) -> Created {
        match one {
            CreatedOne::New(id) => Created::New(id),
            CreatedOne::Duplicate(id) => Created::Duplicate(id),
        }
    }
}

/// What [`Store::create_submissions`] did: all of an upload, or nothing.
#[derive(Debug, PartialEq)]
pub enum CreatedAll {
    /// Each one, in order.
    All(Vec<CreatedOne>),
    /// The `index`th was over the fair-use limit, so nothing was written; the counted
    /// submissions' times, oldest first.
    Limited { index: usize, times: Vec<i64> },
}

/// What [`Store::delete_submission`] removed.
#[derive(Debug, PartialEq)]
pub struct Deleted {
    pub file_sha256: String,
    /// No other submission had the same content: its database copy went with it, and a disk
    /// copy an older version kept can go too.
    pub file_unused: bool,
}

/// The `protocols` column: the 6D protocols, comma-separated, or the task alone (so the
/// duplicate check and its unique index tell a detection from a segmentation of one file, and
/// a bop24 upload from a bop19 one of the same CSV file).
fn protocols_to_text(new: &NewSubmission<'_>) -> String {
    match new.task {
        Some(task) => task.as_str().to_string(),
        None => new
            .protocols
            .iter()
            .map(|p| p.as_str())
            .collect::<Vec<_>>()
            .join(","),
    }
}

fn protocols_from_text(s: String) -> StoreResult<(Vec<ProtocolName>, Option<Task>)> {
    if let Ok(task) = Task::from_str(&s) {
        return Ok((Vec::new(), Some(task)));
    }
    let protocols = s
        .split(',')
        .map(|p| {
            ProtocolName::from_str(p).map_err(|_| StoreError::Corrupt {
                column: "protocols",
                value: s.clone(),
            })
        })
        .collect::<StoreResult<_>>()?;
    Ok((protocols, None))
}

pub(crate) const SUBMISSION_COLUMNS: &str = "s.id, s.method_id, m.name AS method, s.dataset_id, \
    d.name AS dataset, s.protocols, s.public, s.file_name, s.file_sha256, s.file_size, \
    s.estimates_count, s.status, s.progress, s.error, s.fault, s.attempts, s.created_at, \
    s.started_at, s.finished_at, s.evaluator_version, s.hardware, s.owner_id, s.hidden, \
    s.held, s.work, s.work_done, s.eval_ms, s.preflight_json, m.team_id \
    FROM submissions s JOIN methods m ON m.id = s.method_id JOIN datasets d ON d.id = s.dataset_id";

pub(crate) fn submission(row: &AnyRow) -> StoreResult<SubmissionRow> {
    let preflight: String = row.try_get("preflight_json")?;
    let preflight = serde_json::from_str(&preflight).map_err(|_| StoreError::Corrupt {
        column: "preflight_json",
        value: preflight,
    })?;
    let (protocols, task) = protocols_from_text(row.try_get("protocols")?)?;
    Ok(SubmissionRow {
        id: row.try_get("id")?,
        method_id: row.try_get("method_id")?,
        method: row.try_get("method")?,
        dataset_id: row.try_get("dataset_id")?,
        dataset: row.try_get("dataset")?,
        protocols,
        task,
        visibility: if row.try_get::<i64, _>("public")? != 0 {
            Visibility::Public
        } else {
            Visibility::Private
        },
        file_name: row.try_get("file_name")?,
        file_sha256: row.try_get("file_sha256")?,
        file_size: row.try_get("file_size")?,
        estimates_count: row.try_get("estimates_count")?,
        status: parse_column("status", row.try_get("status")?)?,
        progress: row.try_get("progress")?,
        error: row.try_get("error")?,
        fault: row
            .try_get::<Option<String>, _>("fault")?
            .map(|f| parse_column("fault", f))
            .transpose()?,
        attempts: row.try_get("attempts")?,
        created_at: row.try_get("created_at")?,
        started_at: row.try_get("started_at")?,
        finished_at: row.try_get("finished_at")?,
        evaluator_version: row.try_get("evaluator_version")?,
        hardware: row.try_get("hardware")?,
        owner_id: row.try_get("owner_id")?,
        team_id: row.try_get("team_id")?,
        hidden: row.try_get::<i64, _>("hidden")? != 0,
        held: row.try_get::<i64, _>("held")? != 0,
        work: row.try_get("work")?,
        work_done: row.try_get("work_done")?,
        eval_ms: row.try_get("eval_ms")?,
        preflight,
    })
}

impl Store {
    /// The red flags of those of the submissions `ids` that have any.
    pub async fn red_flags(
        &self,
        ids: &[SubmissionId],
    ) -> StoreResult<BTreeMap<SubmissionId, Vec<RedFlag>>> {
        let mut out = BTreeMap::new();
        let select = "SELECT id, preflight_json FROM submissions WHERE id IN";
        for r in fetch_in(&self.pool, select, ids).await? {
            let text: String = r.try_get("preflight_json")?;
            let preflight: Preflight =
                serde_json::from_str(&text).map_err(|_| StoreError::Corrupt {
                    column: "preflight_json",
                    value: text,
                })?;
            if !preflight.red_flags.is_empty() {
                out.insert(r.try_get("id")?, preflight.red_flags);
            }
        }
        Ok(out)
    }
    /// Creates one submission; see [`Store::create_submissions`].
    pub async fn create_submission(
        &self,
        new: &NewSubmission<'_>,
        fair_use: Option<FairUse>,
    ) -> StoreResult<Created> {
        Ok(
            match self
                .create_submissions(std::slice::from_ref(new), fair_use)
                .await?
            {
                // One in, one out.
                CreatedAll::All(created) => created
                    .into_iter()
                    .next()
                    .ok_or(StoreError::NotFound)?
                    .into(),
                CreatedAll::Limited { times, .. } => Created::Limited { times },
            },
        )
    }

    /// Creates the submissions of one upload (one per dataset, all of one owner) and, if new,
    /// their method, in ONE transaction, so an upload is stored whole or not at all: a limit
    /// met at the fourth file must not leave the first three behind. For each, in order: the
    /// duplicate check (a re-upload of the same file answers with the existing submission,
    /// whatever the limit), then the fair-use count, then the inserts. Parallel calls for one
    /// user are serialised (SQLite: the write lock; PostgreSQL: the user's row, and the team's
    /// row for a team's method, so two members creating it at once make one), so the count is
    /// exact.
    pub async fn create_submissions(
        &self,
        news: &[NewSubmission<'_>],
        fair_use: Option<FairUse>,
    ) -> StoreResult<CreatedAll> {
        let mut tx = self.write_transaction().await?;
        if self.backend == Backend::Postgres {
            let mut owners: Vec<UserId> = news.iter().map(|n| n.owner_id).collect();
            owners.sort_unstable();
            owners.dedup();
            for owner in owners {
                sqlx::query("SELECT id FROM users WHERE id = $1 FOR UPDATE")
                    .bind(owner)
                    .fetch_optional(&mut *tx)
                    .await?;
            }
            let mut teams: Vec<TeamId> = news.iter().filter_map(|n| n.team_id).collect();
            teams.sort_unstable();
            teams.dedup();
            for team in teams {
                sqlx::query("SELECT id FROM teams WHERE id = $1 FOR UPDATE")
                    .bind(team)
                    .fetch_optional(&mut *tx)
                    .await?;
            }
        }
        let mut created = Vec::with_capacity(news.len());
        let mut meta_changed = false;
        for (index, new) in news.iter().enumerate() {
            match create_one(&mut tx, new, fair_use).await? {
                One::Limited { times } => {
                    tx.rollback().await?;
                    return Ok(CreatedAll::Limited { index, times });
                }
                One::Stored {
                    created: c,
                    meta_changed: changed,
                } => {
                    meta_changed |= changed;
                    created.push(c);
                }
            }
        }
        // A method's training data and input are columns of the boards.
        self.commit_board_change(tx, meta_changed).await?;
        Ok(CreatedAll::All(created))
    }

    pub async fn submission(&self, id: SubmissionId) -> StoreResult<Option<SubmissionRow>> {
        let sql = format!("SELECT {SUBMISSION_COLUMNS} WHERE s.id = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        row.as_ref().map(submission).transpose()
    }

    /// Public submissions of a method, newest first.
    pub async fn public_submissions_of_method(
        &self,
        method_id: MethodId,
    ) -> StoreResult<Vec<SubmissionRow>> {
        let sql = format!(
            "SELECT {SUBMISSION_COLUMNS} WHERE s.method_id = $1 AND s.public = 1 AND s.hidden = 0 ORDER BY s.id DESC"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(submission).collect()
    }

    /// Every submission of a method, private, held and hidden ones included, newest first
    /// (what its owner sees on its page).
    pub async fn submissions_of_method(
        &self,
        method_id: MethodId,
    ) -> StoreResult<Vec<SubmissionRow>> {
        let sql = format!("SELECT {SUBMISSION_COLUMNS} WHERE s.method_id = $1 ORDER BY s.id DESC");
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(method_id)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(submission).collect()
    }

    /// A page of the public finished submissions, newest first: `limit` of them after the
    /// `offset` newest, each with its method's owner and headline scores.
    pub async fn recent_public_finished(
        &self,
        limit: i64,
        offset: i64,
    ) -> StoreResult<Vec<RecentRow>> {
        let sql = format!(
            "SELECT COALESCE(t.name, u.name, '') AS owner, m.anonymous, \
             (SELECT sc.score FROM scores sc WHERE sc.submission_id = s.id \
             AND sc.protocol = 'bop19') AS bop19, \
             (SELECT sc.score FROM scores sc WHERE sc.submission_id = s.id \
             AND sc.protocol = 'eccv18') AS eccv18, \
             (SELECT c.ap FROM coco_scores c WHERE c.submission_id = s.id) AS ap, \
             (SELECT b.map FROM bop24_scores b WHERE b.submission_id = s.id) AS map, \
             {SUBMISSION_COLUMNS} LEFT JOIN users u ON u.id = m.owner_id \
             LEFT JOIN teams t ON t.id = m.team_id \
             WHERE s.public = 1 AND s.hidden = 0 AND s.status = 'done' \
             ORDER BY s.id DESC LIMIT $1 OFFSET $2"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(limit)
            .bind(offset)
            .fetch_all(&self.pool)
            .await?;
        rows.iter()
            .map(|r| {
                Ok(RecentRow {
                    submission: submission(r)?,
                    owner: r.try_get("owner")?,
                    anonymous: r.try_get::<i64, _>("anonymous")? != 0,
                    bop19: r.try_get("bop19")?,
                    eccv18: r.try_get("eccv18")?,
                    ap: r.try_get("ap")?,
                    map: r.try_get("map")?,
                })
            })
            .collect()
    }

    /// Whether any submission exists at all (the demo set-up runs on an empty service only).
    pub async fn has_submissions(&self) -> StoreResult<bool> {
        let row = sqlx::query("SELECT COUNT(*) AS n FROM submissions")
            .fetch_one(&self.pool)
            .await?;
        Ok(row.try_get::<i64, _>("n")? > 0)
    }

    /// When `owner`'s submissions on `dataset` made since `since` (epoch ms) were made, oldest
    /// first: those that count against the fair-use limit, as an upload counts them.
    pub async fn counted_times(
        &self,
        owner: UserId,
        dataset: DatasetId,
        since: i64,
    ) -> StoreResult<Vec<i64>> {
        sqlx::query(COUNTED_TIMES)
            .bind(owner)
            .bind(dataset)
            .bind(since)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(|r| r.try_get("created_at"))
            .collect::<Result<_, _>>()
            .map_err(Into::into)
    }

    /// Where submission `id` stands in the queue: the queued ones before it, and the running
    /// ones (other than itself). `None` asks for a submission about to be created, behind all.
    pub async fn queue_place(&self, id: Option<SubmissionId>) -> StoreResult<QueuePlace> {
        let row = sqlx::query(
            "SELECT CAST(COALESCE(SUM(CASE WHEN status = 'queued' AND id < $1 THEN 1 ELSE 0 END), 0) AS BIGINT) AS queued, \
             CAST(COALESCE(SUM(CASE WHEN status = 'running' AND id <> $1 THEN 1 ELSE 0 END), 0) AS BIGINT) AS running \
             FROM submissions WHERE status IN ('queued', 'running')",
        )
        .bind(id.map_or(i64::MAX, SubmissionId::get))
        .fetch_one(&self.pool)
        .await?;
        Ok(QueuePlace {
            queued_ahead: row.try_get("queued")?,
            running: row.try_get("running")?,
        })
    }

    /// Estimate evaluations still to do before submission `id` can start: what is left of
    /// the running jobs and all of the queued ones before it (rows stored before the work was
    /// counted count their estimates). `None` asks for a submission about to be created.
    pub async fn work_ahead(&self, id: Option<SubmissionId>) -> StoreResult<i64> {
        let row = sqlx::query(
            "SELECT CAST(COALESCE(SUM(CASE WHEN work > 0 THEN work - work_done \
             ELSE estimates_count END), 0) AS BIGINT) AS n FROM submissions \
             WHERE (status = 'queued' AND id < $1) OR (status = 'running' AND id <> $1)",
        )
        .bind(id.map_or(i64::MAX, SubmissionId::get))
        .fetch_one(&self.pool)
        .await?;
        Ok(row.try_get("n")?)
    }

    /// Estimate evaluations per second measured on this service: over the last 20 jobs that
    /// finished with a measured time. `None` before the first.
    pub async fn measured_speed(&self) -> StoreResult<Option<f64>> {
        let row = sqlx::query(
            "SELECT CAST(COALESCE(SUM(work), 0) AS BIGINT) AS work, \
             CAST(COALESCE(SUM(eval_ms), 0) AS BIGINT) AS ms FROM (SELECT work, eval_ms \
             FROM submissions WHERE status = 'done' AND eval_ms > 0 AND work > 0 \
             ORDER BY finished_at DESC LIMIT 20) recent",
        )
        .fetch_one(&self.pool)
        .await?;
        let (work, ms): (i64, i64) = (row.try_get("work")?, row.try_get("ms")?);
        Ok((work > 0 && ms > 0).then(|| work as f64 * 1000.0 / ms as f64))
    }

    /// The finished submissions on a dataset that `viewer` may see (the public ones and its
    /// own), but `except`, newest first, at most `limit`: what a submission can be compared with.
    pub async fn finished_on_dataset(
        &self,
        dataset_id: DatasetId,
        except: SubmissionId,
        viewer: Option<UserId>,
        limit: i64,
    ) -> StoreResult<Vec<SubmissionRow>> {
        let sql = format!(
            "SELECT {SUBMISSION_COLUMNS} WHERE s.dataset_id = $1 AND s.id <> $2 \
             AND s.status = 'done' AND ((s.public = 1 AND s.hidden = 0) OR s.owner_id = $3) \
             ORDER BY s.id DESC LIMIT $4"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(dataset_id)
            .bind(except)
            .bind(viewer.map_or(-1, UserId::get))
            .bind(limit)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(submission).collect()
    }

    /// Every submission of `owner`, private and hidden ones included, newest first.
    pub async fn submissions_of_owner(&self, owner: UserId) -> StoreResult<Vec<SubmissionRow>> {
        let sql = format!("SELECT {SUBMISSION_COLUMNS} WHERE s.owner_id = $1 ORDER BY s.id DESC");
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(owner)
            .fetch_all(&self.pool)
            .await?;
        rows.iter().map(submission).collect()
    }

    /// Hides or shows a submission; false when there is no such submission.
    pub async fn set_hidden(&self, id: SubmissionId, hidden: bool) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query("UPDATE submissions SET hidden = $1 WHERE id = $2")
            .bind(i64::from(hidden))
            .bind(id)
            .execute(&mut *tx)
            .await?;
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Makes a submission public or private, which ends any hold on its publication; false
    /// when there is no such submission.
    pub async fn set_visibility(
        &self,
        id: SubmissionId,
        visibility: Visibility,
    ) -> StoreResult<bool> {
        self.set_publication(id, visibility == Visibility::Public, false)
            .await
    }

    /// Keeps a submission private with its publication held back for red flags; false when
    /// there is no such submission.
    pub async fn hold_publication(&self, id: SubmissionId) -> StoreResult<bool> {
        self.set_publication(id, false, true).await
    }

    async fn set_publication(
        &self,
        id: SubmissionId,
        public: bool,
        held: bool,
    ) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let (public, held) = (i64::from(public), i64::from(held));
        let exists = sqlx::query("SELECT public FROM submissions WHERE id = $1")
            .bind(id)
            .fetch_optional(&mut *tx)
            .await?;
        let Some(row) = exists else {
            tx.rollback().await?;
            return Ok(false);
        };
        let changed = row.try_get::<i64, _>("public")? != public;
        sqlx::query("UPDATE submissions SET public = $1, held = $2 WHERE id = $3")
            .bind(public)
            .bind(held)
            .bind(id)
            .execute(&mut *tx)
            .await?;
        // A published or withdrawn submission enters or leaves the boards.
        self.commit_board_change(tx, changed).await?;
        Ok(true)
    }

    /// Queues a finished submission again (e.g. after an evaluator fix); its old scores stay
    /// until the new ones replace them. False when it is missing or not finished.
    pub async fn rerun(&self, id: SubmissionId) -> StoreResult<bool> {
        let mut tx = self.write_transaction().await?;
        let done = sqlx::query(
            "UPDATE submissions SET status = 'queued', progress = 0, work_done = 0, attempts = 0, error = NULL, \
             fault = NULL, worker = NULL, lease_until = NULL WHERE id = $1 AND status IN ('done', 'failed')",
        )
        .bind(id)
        .execute(&mut *tx)
        .await?;
        // A finished submission leaves the boards until its new scores are in.
        self.commit_board_change(tx, done.rows_affected() == 1)
            .await
    }

    /// Deletes a submission with its scores and errors (and its file, unless another
    /// submission has the same); `None` when there is no such submission.
    pub async fn delete_submission(&self, id: SubmissionId) -> StoreResult<Option<Deleted>> {
        let mut tx = self.write_transaction().await?;
        let Some(row) = sqlx::query("SELECT file_sha256 FROM submissions WHERE id = $1")
            .bind(id)
            .fetch_optional(&mut *tx)
            .await?
        else {
            tx.rollback().await?;
            return Ok(None);
        };
        let sha: String = row.try_get("file_sha256")?;
        for table in [
            "estimate_errors",
            "entry_pins",
            "scores",
            "coco_scores",
            "bop24_scores",
        ] {
            // `table` comes from the list above, never from the request.
            let sql = format!("DELETE FROM {table} WHERE submission_id = $1");
            sqlx::query(sqlx::AssertSqlSafe(sql))
                .bind(id)
                .execute(&mut *tx)
                .await?;
        }
        sqlx::query("DELETE FROM submissions WHERE id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
        let others = sqlx::query("SELECT COUNT(*) AS n FROM submissions WHERE file_sha256 = $1")
            .bind(&sha)
            .fetch_one(&mut *tx)
            .await?;
        let file_unused = others.try_get::<i64, _>("n")? == 0;
        if file_unused {
            sqlx::query("DELETE FROM submission_files WHERE sha256 = $1")
                .bind(&sha)
                .execute(&mut *tx)
                .await?;
        }
        board_version::bump(&mut tx).await?;
        tx.commit().await?;
        self.board_changed();
        Ok(Some(Deleted {
            file_unused,
            file_sha256: sha,
        }))
    }
}

/// The times of one owner's submissions on one dataset since a moment, oldest first, that count
/// against the fair-use limit: all but those that failed through the service's fault. One
/// query for the upload's check and the quota a user is shown, so the two always agree.
const COUNTED_TIMES: &str = "SELECT created_at FROM submissions WHERE owner_id = $1 \
     AND dataset_id = $2 AND created_at >= $3 AND (fault IS NULL OR fault <> 'service') \
     ORDER BY created_at";

/// What [`create_one`] did inside the upload's transaction.
enum One {
    /// Stored (or found stored), and whether that changed the method's metadata.
    Stored {
        created: CreatedOne,
        meta_changed: bool,
    },
    /// Over the fair-use limit: nothing was written (the caller rolls back the whole upload).
    Limited { times: Vec<i64> },
}

/// One submission of [`Store::create_submissions`] inside its transaction.
async fn create_one(
    tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    new: &NewSubmission<'_>,
    fair_use: Option<FairUse>,
) -> StoreResult<One> {
    // A team's method has no owner account, so an account's own methods never include one.
    let (find, whose) = match new.team_id {
        Some(team) => (
            "SELECT id FROM methods WHERE team_id = $1 AND name = $2",
            team.get(),
        ),
        None => (
            "SELECT id FROM methods WHERE owner_id = $1 AND name = $2",
            new.owner_id.get(),
        ),
    };
    let method_id: Option<MethodId> = sqlx::query(find)
        .bind(whose)
        .bind(new.method.as_str())
        .fetch_optional(&mut **tx)
        .await?
        .map(|r| r.try_get("id"))
        .transpose()?;
    if let Some(method_id) = method_id {
        let same = sqlx::query(
            "SELECT id FROM submissions WHERE method_id = $1 AND dataset_id = $2 \
             AND file_sha256 = $3 AND protocols = $4",
        )
        .bind(method_id)
        .bind(new.dataset_id)
        .bind(new.file_sha256)
        .bind(protocols_to_text(new))
        .fetch_optional(&mut **tx)
        .await?;
        if let Some(row) = same {
            return Ok(One::Stored {
                created: CreatedOne::Duplicate(row.try_get("id")?),
                meta_changed: false,
            });
        }
    }
    if let Some(limit) = fair_use {
        let times: Vec<i64> = sqlx::query(COUNTED_TIMES)
            .bind(new.owner_id)
            .bind(new.dataset_id)
            .bind(limit.since)
            .fetch_all(&mut **tx)
            .await?
            .iter()
            .map(|r| r.try_get("created_at"))
            .collect::<Result<_, _>>()?;
        if times.len() >= limit.limit {
            return Ok(One::Limited { times });
        }
    }
    let now = now_ms();
    let mut meta_changed = false;
    let method_id = match method_id {
        Some(id) => {
            meta_changed = update_method_meta(tx, id, new.meta, new.hardware).await?;
            id
        }
        None => sqlx::query(
            "INSERT INTO methods (name, description, paper_url, code_url, training_data, \
             modality, created_at, owner_id, hardware, anonymous, team_id, onboarding, objects) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13) RETURNING id",
        )
        .bind(new.method.as_str())
        .bind(new.meta.description.as_str())
        .bind(new.meta.paper_url.as_str())
        .bind(new.meta.code_url.as_str())
        .bind(new.meta.training_data.map_or("", |t| t.as_str()))
        .bind(new.meta.modality.map_or("", |m| m.as_str()))
        .bind(now)
        .bind(new.team_id.is_none().then_some(new.owner_id))
        .bind(new.hardware.as_str())
        .bind(i64::from(new.meta.anonymous == Some(true)))
        .bind(new.team_id)
        .bind(new.meta.onboarding.map_or("", |o| o.as_str()))
        .bind(new.meta.objects.map_or("", |o| o.as_str()))
        .fetch_one(&mut **tx)
        .await?
        .try_get("id")?,
    };
    let preflight = serde_json::to_string(new.preflight).map_err(|e| StoreError::Corrupt {
        column: "preflight_json",
        value: e.to_string(),
    })?;
    let id: SubmissionId = sqlx::query(
        "INSERT INTO submissions (method_id, dataset_id, protocols, public, file_name, \
         file_sha256, file_size, estimates_count, hardware, preflight_json, status, created_at, \
         owner_id, held, work) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, 'queued', $11, $12, $13, $14) RETURNING id",
    )
    .bind(method_id)
    .bind(new.dataset_id)
    .bind(protocols_to_text(new))
    .bind(i64::from(new.visibility == Visibility::Public))
    .bind(new.file_name)
    .bind(new.file_sha256)
    .bind(new.file_size)
    .bind(new.estimates_count)
    .bind(new.hardware.as_str())
    .bind(preflight)
    .bind(now)
    .bind(new.owner_id)
    .bind(i64::from(new.held))
    .bind(new.preflight.work())
    .fetch_one(&mut **tx)
    .await?
    .try_get("id")?;
    // In the same transaction: no worker can find the job without its file.
    super::files::put_file(tx, new.file_sha256, new.file_size, new.file_gzip).await?;
    Ok(One::Stored {
        created: CreatedOne::New(id),
        meta_changed,
    })
}

/// Updates the metadata fields a new upload gives, hardware included; the others keep their
/// stored values (an upload without `hardware` leaves the method's as it was). True when a
/// field was written.
async fn update_method_meta(
    tx: &mut sqlx::Transaction<'static, sqlx::Any>,
    id: MethodId,
    meta: &MethodMeta,
    hardware: &Hardware,
) -> StoreResult<bool> {
    let mut written = false;
    for (column, value) in [
        ("description", meta.description.as_str()),
        ("paper_url", meta.paper_url.as_str()),
        ("code_url", meta.code_url.as_str()),
        (
            "training_data",
            meta.training_data.map_or("", |t| t.as_str()),
        ),
        ("modality", meta.modality.map_or("", |m| m.as_str())),
        ("onboarding", meta.onboarding.map_or("", |o| o.as_str())),
        ("objects", meta.objects.map_or("", |o| o.as_str())),
        ("hardware", hardware.as_str()),
    ] {
        if !value.is_empty() {
            // `column` comes from the list above, never from the request.
            let sql = format!("UPDATE methods SET {column} = $1 WHERE id = $2");
            sqlx::query(sqlx::AssertSqlSafe(sql))
                .bind(value)
                .bind(id)
                .execute(&mut **tx)
                .await?;
            written = true;
        }
    }
    if let Some(anonymous) = meta.anonymous {
        sqlx::query("UPDATE methods SET anonymous = $1 WHERE id = $2")
            .bind(i64::from(anonymous))
            .bind(id)
            .execute(&mut **tx)
            .await?;
        written = true;
    }
    Ok(written)
}
