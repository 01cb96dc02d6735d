//! What is known about submissions once uploaded: where one stands (its place in the queue and
//! when its scores are expected, from the speed measured on this server), its scores and their
//! records, and whether it is its method's entry on the boards; and an owner's list of theirs.
//! One place gathers it so that a submission's page, its JSON twin and its report download
//! read the same facts, checked by [`visibility`] first.

use std::collections::BTreeMap;

use evaluator::Report;
use evaluator::coco::CocoReport;
use evaluator::detection::DetectionReport;
use evaluator::protocol::ProtocolName;
use serde::Serialize;

use crate::app::App;
use crate::clock::now_ms;
use crate::domain::{BoardProtocol, MethodId, SubmissionId, Task};
use crate::error::AppResult;
use crate::service::{methods, submissions, visibility};
use crate::store::accounts::User;
use crate::store::board_rows::Whose;
use crate::store::scores::{ScoreRecord, ScoreRow};
use crate::store::submissions::{QueuePlace, Status, SubmissionRow};

/// What the page of a queued or running submission says when no worker runs: an ETA would
/// be a promise nobody keeps, and the uploader should know the file is not lost.
pub const NO_WORKER: &str = "no evaluation worker is running; your submission is queued and safe";

/// A submission with what its page shows of it.
pub struct Details {
    pub submission: SubmissionRow,
    /// Queued only: its place in the queue.
    pub queue: Option<QueuePlace>,
    /// Queued or running while a worker runs: seconds until the scores are expected.
    pub eta_seconds: Option<f64>,
    /// Queued or running while no worker has been seen for longer than a lease (see
    /// [`workers_running`]): nothing evaluates it now.
    pub no_worker: bool,
    /// The 6D reports, one per protocol scored.
    pub reports: Vec<Report>,
    /// Per protocol scored, how the score can be reproduced.
    pub records: Vec<ScoreRecord>,
    /// A 2D task's report, once scored.
    pub coco: Option<CocoReport>,
    /// A bop24 submission's report, once scored.
    pub bop24: Option<DetectionReport>,
    /// Per board with an entry of its method on its dataset: the entry's submission, and
    /// whether the owner pinned it.
    pub entries: Vec<(BoardProtocol, SubmissionId, bool)>,
    /// Its owner pinned it as the method's entry on this dataset.
    pub pinned: bool,
    /// Why it cannot be pinned, if it cannot (see [`methods::pin_refusal`]).
    pub pin_refusal: Option<String>,
}

/// Submission `id` as `reader` may see it (see [`visibility::submission`]).
pub async fn details(app: &App, id: SubmissionId, reader: Option<&User>) -> AppResult<Details> {
    let submission = visibility::submission(app, id, reader).await?;
    let waiting = matches!(submission.status, Status::Queued | Status::Running);
    let no_worker = waiting && !workers_running(app).await?;
    let speed = submissions::speed(app).await?;
    let (queue, eta_seconds) = match submission.status {
        Status::Queued => {
            let place = app.store.queue_place(Some(id)).await?;
            let eta =
                (app.store.work_ahead(Some(id)).await? + remaining(&submission)) as f64 / speed;
            (Some(place), Some(eta))
        }
        Status::Running => (None, Some(remaining(&submission) as f64 / speed)),
        Status::Done | Status::Failed => (None, None),
    };
    let eta_seconds = eta_seconds.filter(|_| !no_worker);
    let reports = app.store.reports_of_submission(id).await?;
    let mut records = app.store.score_records(id).await?;
    let coco = match submission.task {
        Some(Task::Coco(_)) => {
            records.extend(app.store.coco_record(id).await?);
            app.store.coco_report(id).await?
        }
        Some(Task::Bop24) | None => None,
    };
    let bop24 = match submission.task {
        Some(Task::Bop24) => app.store.bop24_report(id).await?,
        Some(Task::Coco(_)) | None => None,
    };
    let mut entries: Vec<(BoardProtocol, SubmissionId, bool)> = app
        .store
        .entries(submission.method_id, submission.dataset_id)
        .await?
        .into_iter()
        .map(|e| (e.protocol.into(), e.submission_id, e.pinned))
        .collect();
    let (method_id, dataset_id) = (submission.method_id, submission.dataset_id);
    let found = match submission.task {
        Some(Task::Coco(task)) => app.store.coco_entry(task, method_id, dataset_id).await?,
        Some(Task::Bop24) => app.store.bop24_entry(method_id, dataset_id).await?,
        None => None,
    };
    if let Some(task) = submission.task {
        entries.extend(found.map(|(sid, pinned)| (task.board(), sid, pinned)));
    }
    Ok(Details {
        pinned: app.store.is_pinned(id).await?,
        pin_refusal: methods::pin_refusal(&submission),
        submission,
        queue,
        eta_seconds,
        no_worker,
        reports,
        records,
        coco,
        bop24,
        entries,
    })
}

/// Whether any worker, in this process or another sharing the database, has beaten within
/// the last lease: a worker that has not renewed a lease or polled for that long is taken to
/// be dead, as the queue takes it (its job goes to another worker).
pub async fn workers_running(app: &App) -> AppResult<bool> {
    let newest = app.store.newest_beat().await?;
    Ok(newest.is_some_and(|at| now_ms() - at <= app.config.lease_ms()))
}

/// Estimate evaluations the job still has to do.
fn remaining(s: &SubmissionRow) -> i64 {
    if s.work > 0 {
        (s.work - s.work_done).max(0)
    } else {
        s.estimates_count * s.protocols.len().max(1) as i64
    }
}

/// A submission with its headline scores: one of an owner's, or of a method's.
#[derive(Clone, Debug, Serialize)]
pub struct Owned {
    #[serde(flatten)]
    pub submission: SubmissionRow,
    /// Per protocol, the headline score (AR for bop19, recall for eccv18).
    pub scores: BTreeMap<ProtocolName, f64>,
    /// A 2D task's AP or a bop24 submission's bop24_mAP, once scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ap: Option<f64>,
}

impl Owned {
    /// The headline score under `protocol`, once evaluated.
    pub fn score(&self, protocol: ProtocolName) -> Option<f64> {
        self.scores.get(&protocol).copied()
    }
}

/// Every submission of `user`, private ones included, newest first.
pub async fn of_owner(app: &App, user: &User) -> AppResult<Vec<Owned>> {
    let rows = app.store.submissions_of_owner(user.id).await?;
    let scores = app.store.scores_of_owner(user.id).await?;
    let mut aps = app.store.coco_aps(Whose::Owner(user.id)).await?;
    aps.extend(app.store.bop24_maps(Whose::Owner(user.id)).await?);
    Ok(scored(rows, scores, aps))
}

/// `rows`, submissions of method `id` (those the reader may see), with their headline scores.
pub async fn of_method(app: &App, id: MethodId, rows: Vec<SubmissionRow>) -> AppResult<Vec<Owned>> {
    let scores = app.store.scores_of_method(id).await?;
    let mut aps = app.store.coco_aps(Whose::Method(id)).await?;
    aps.extend(app.store.bop24_maps(Whose::Method(id)).await?);
    Ok(scored(rows, scores, aps))
}

/// Each of `rows` with its scores among `scores` and `aps`.
fn scored(
    rows: Vec<SubmissionRow>,
    scores: Vec<ScoreRow>,
    aps: Vec<(SubmissionId, f64)>,
) -> Vec<Owned> {
    let mut by_submission: BTreeMap<SubmissionId, BTreeMap<ProtocolName, f64>> = BTreeMap::new();
    for sc in scores {
        by_submission
            .entry(sc.submission_id)
            .or_default()
            .insert(sc.protocol, sc.score);
    }
    let mut aps: BTreeMap<SubmissionId, f64> = aps.into_iter().collect();
    rows.into_iter()
        .map(|s| Owned {
            scores: by_submission.remove(&s.id).unwrap_or_default(),
            ap: aps.remove(&s.id),
            submission: s,
        })
        .collect()
}
