//! The evaluation workers. The queue is the submissions table: a worker claims a row with a
//! lease, renews the lease with a heartbeat that also records progress (twice a second, so a
//! page following the job moves every second), and stores the scores, the per-estimate errors
//! and the time the evaluation took in the same transaction that marks the row done. A worker that dies (crash, SIGKILL,
//! restart) stops renewing; once its lease expires any worker, in this process or on another
//! machine sharing the PostgreSQL database, takes the job up again. The in-process `Notify`
//! only wakes idle workers early.
//!
//! A worker reads the uploaded file from the database and the dataset from its own copy, which
//! must hash as the copy the server registered did: a worker whose copy differs (or is missing)
//! gives the job back without spending an attempt and leaves that dataset's jobs to others for
//! a while. Faults of the service are retried: a database call that fails for a lost connection
//! is tried again with backoff (a finished evaluation's scores are never dropped for that), an
//! evaluation that fails for the service's reasons is tried again in place with backoff, and
//! only then counts as an attempt. On SIGINT or SIGTERM the running evaluation is cancelled and
//! its job released at once.
//!
//! A BOP'22 2D job (its `task` set) is scored the same way, by `evaluator::coco` on the
//! dataset's `scene_gt_coco.json`, and its report stored in `coco_scores`.

use std::collections::{BTreeMap, HashMap};
use std::future::Future;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use evaluator::coco::{self, CocoReport};
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::{Progress, bootstrap, evaluate, results};
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::app::{AppState, Role};
use crate::datasets;
use crate::datasets::uploaded_file;
use crate::domain::{CocoProtocol, DatasetId, SubmissionId};
use crate::shutdown::Shutdown;
use crate::store::StoreResult;
use crate::store::pose_errors::NewErrors;
use crate::store::queue::Finished;
use crate::store::submissions::{Fault, SubmissionRow};

/// How often an idle worker looks at the queue without being woken.
const POLL: Duration = Duration::from_secs(2);
/// A job failing this many times for the service's reasons (e.g. its worker died each time)
/// is marked failed instead of being retried forever.
const MAX_ATTEMPTS: i64 = 3;
/// Tries of an evaluation within one attempt when it fails for the service's reasons, and the
/// pause before the first retry (doubled each time).
const TRIES_IN_PLACE: u32 = 3;
const FIRST_BACKOFF: Duration = Duration::from_secs(1);
/// Longest pause between two tries of a database call that lost its connection.
const MAX_STORE_BACKOFF: Duration = Duration::from_secs(5);
/// How long a worker leaves the jobs of a dataset it refused before it looks at its copy again.
const REFUSAL_PAUSE: Duration = Duration::from_secs(300);
/// How long a stopping worker keeps trying to give its job back.
const RELEASE_GRACE: Duration = Duration::from_secs(5);
/// Longest pause between two progress records of a running job: pages poll every second.
const PROGRESS_EVERY: Duration = Duration::from_millis(500);

/// Starts `app.config.workers` workers (none for `serve --workers 0`); each ends once
/// `shutdown` is set, after giving back the job it was running.
pub fn spawn_workers(app: &AppState, shutdown: &Shutdown) -> Vec<JoinHandle<()>> {
    let refused = Arc::new(Refused::default());
    (0..app.config.workers)
        .map(|n| {
            let worker = Worker {
                app: app.clone(),
                id: format!("{}-{}-{n}", host_name(), std::process::id()),
                refused: refused.clone(),
                shutdown: shutdown.clone(),
            };
            tokio::spawn(async move { worker.run().await })
        })
        .collect()
}

fn host_name() -> String {
    std::fs::read_to_string("/etc/hostname")
        .map(|h| h.trim().to_string())
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "worker".to_string())
}

/// Datasets this process's workers refused, with when: their jobs are not claimed until
/// [`REFUSAL_PAUSE`] has passed.
#[derive(Default)]
struct Refused(Mutex<HashMap<DatasetId, Instant>>);

impl Refused {
    fn add(&self, dataset_id: DatasetId) {
        if let Ok(mut map) = self.0.lock() {
            map.insert(dataset_id, Instant::now());
        }
    }

    /// The datasets to leave alone now.
    fn current(&self) -> Vec<DatasetId> {
        let Ok(mut map) = self.0.lock() else {
            return Vec::new();
        };
        map.retain(|_, at| at.elapsed() < REFUSAL_PAUSE);
        map.keys().copied().collect()
    }
}

struct Worker {
    app: AppState,
    id: String,
    refused: Arc<Refused>,
    shutdown: Shutdown,
}

/// How a job ended for this worker.
enum JobError {
    /// The file's fault: shown to the user as the reason.
    User(String),
    /// The service's fault: does not count against the user.
    Service(String),
    /// This worker cannot serve the job's dataset (its copy differs or is missing).
    Refused(String),
    /// Another worker owns the job now.
    TakenOver,
    /// The process is stopping.
    Stopped,
}

impl Worker {
    async fn run(self) {
        let worker = &self.id;
        tracing::info!(%worker, "worker started");
        let app = &self.app;
        while !self.shutdown.is_set() {
            // Register interest before looking, so a wake-up between the two is not lost.
            let notified = app.wake.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            let skip = self.refused.current();
            match app
                .store
                .claim(worker, app.config.lease_ms(), MAX_ATTEMPTS, &skip)
                .await
            {
                Ok(Some(job)) => {
                    let span = tracing::info_span!(
                        "job",
                        submission = job.id.get(),
                        attempt = job.attempts
                    );
                    self.run_job(job).instrument(span).await
                }
                Ok(None) => {
                    // Nothing uploaded waits: re-score a submission an older evaluator scored.
                    match app
                        .store
                        .claim_rescore(worker, app.config.lease_ms(), MAX_ATTEMPTS, &skip)
                        .await
                    {
                        Ok(Some(job)) => {
                            let span = tracing::info_span!("rescore", submission = job.id.get());
                            self.run_rescore(job).instrument(span).await;
                            continue;
                        }
                        Ok(None) => {}
                        Err(e) => {
                            tracing::error!(%worker, error = %e, "cannot read the re-scoring queue")
                        }
                    }
                    tokio::select! {
                        _ = &mut notified => {}
                        _ = tokio::time::sleep(POLL) => {}
                        _ = self.shutdown.wait() => {}
                    }
                }
                Err(e) => {
                    tracing::error!(%worker, error = %e, "cannot read the queue");
                    tokio::select! {
                        _ = tokio::time::sleep(POLL) => {}
                        _ = self.shutdown.wait() => {}
                    }
                }
            }
        }
        tracing::info!(%worker, "worker stopped");
    }

    async fn run_job(&self, job: SubmissionRow) {
        let (app, worker) = (&self.app, self.id.as_str());
        tracing::info!(%worker, submission = job.id.get(), attempt = job.attempts, "evaluation started");
        let timer = crate::ops::metrics::job_started(job.attempts);
        let job_state = JobState::new(job.protocols.len(), job.work);
        let beat = self.heartbeat(job.id, &job_state);
        let outcome = tokio::select! {
            outcome = self.evaluate_with_retries(&job, &job_state) => outcome,
            _ = self.shutdown.wait() => Err(JobError::Stopped),
        };
        // Whatever still runs on the evaluation threads stops at its next image.
        job_state.cancel.store(true, Ordering::Relaxed);
        beat.abort();
        let id = job.id;
        // What the metrics count once stored: estimates evaluated for a done job, nothing for
        // a failed one; a job handed back to the queue has not ended.
        let ending = match &outcome {
            Ok(Outcome::Pose(finished)) => Some(Some(
                finished
                    .reports
                    .iter()
                    .map(|r| r.estimates_evaluated as u64)
                    .sum(),
            )),
            Ok(Outcome::Coco { report, .. }) => Some(Some(report.entries_evaluated as u64)),
            Err(JobError::User(_)) => Some(None),
            Err(JobError::Service(_)) if job.attempts >= MAX_ATTEMPTS => Some(None),
            Err(_) => None,
        };
        let stored = match outcome {
            Ok(Outcome::Pose(finished)) => {
                self.persist("store the scores", None, || {
                    app.store.finish(id, worker, &finished)
                })
                .await
            }
            Ok(Outcome::Coco { report, eval_ms }) => {
                self.persist("store the scores", None, || {
                    app.store.finish_coco(id, worker, &report, eval_ms)
                })
                .await
            }
            Err(JobError::User(msg)) => {
                self.persist("store the failure", None, || {
                    app.store.fail(id, worker, &msg, Fault::User)
                })
                .await
            }
            Err(JobError::Service(msg)) if job.attempts >= MAX_ATTEMPTS => {
                tracing::error!(submission = id.get(), error = %msg, "evaluation failed");
                self.persist("store the failure", None, || {
                    app.store.fail(id, worker, &msg, Fault::Service)
                })
                .await
            }
            Err(JobError::Service(msg)) => {
                tracing::error!(submission = id.get(), attempt = job.attempts, error = %msg, "evaluation failed: queued for another attempt");
                let requeued = self
                    .persist("queue the job again", None, || {
                        app.store.requeue(id, worker, &msg)
                    })
                    .await;
                app.wake.notify_waiters();
                requeued
            }
            Err(JobError::Refused(msg)) => {
                tracing::warn!(%worker, submission = id.get(), dataset = %job.dataset, "{msg}; the job is left to other workers");
                self.refused.add(job.dataset_id);
                // The copy may be fixed by the time the pause is over: read it again then.
                app.forget_dataset(job.dataset_id).await;
                self.release(id).await
            }
            Err(JobError::Stopped) => {
                let released = self.release(id).await;
                if matches!(released, Ok(true)) {
                    tracing::info!(submission = id.get(), "stopping: job released to the queue");
                }
                return;
            }
            Err(JobError::TakenOver) => Ok(false),
        };
        if let (Ok(true), Some(evaluated)) = (&stored, ending) {
            timer.ended(evaluated);
        }
        match stored {
            Ok(true) => tracing::info!(submission = id.get(), "job ended"),
            Ok(false) => tracing::warn!(
                submission = id.get(),
                "job was taken over; result discarded"
            ),
            Err(e) => {
                tracing::error!(submission = id.get(), error = %e, "cannot store the outcome")
            }
        }
    }

    /// Re-scores a finished submission with this evaluator: evaluated as a job is (without
    /// publishing progress, as its scores stand meanwhile), its scores swapped for the new ones
    /// and the differences recorded.
    async fn run_rescore(&self, job: SubmissionRow) {
        let (app, worker, id) = (&self.app, self.id.as_str(), job.id);
        tracing::info!(%worker, submission = id.get(), from = ?job.evaluator_version, "re-scoring started");
        let state = JobState::new(job.protocols.len(), job.work);
        let beat = self.rescore_lease(id, &state);
        let outcome = tokio::select! {
            outcome = self.evaluate_job(&job, &state) => outcome,
            _ = self.shutdown.wait() => Err(JobError::Stopped),
        };
        state.cancel.store(true, Ordering::Relaxed);
        beat.abort();
        let let_go = |count: bool| {
            self.persist(
                "let go of the re-scoring",
                Some(Instant::now() + RELEASE_GRACE),
                move || app.store.drop_rescore(id, worker, count),
            )
        };
        let stored = match outcome {
            // Never flagged (see `Store::flag_rescoring`); let go, counted, should one be.
            Ok(Outcome::Coco { .. }) => let_go(true).await,
            Ok(Outcome::Pose(finished)) => {
                match self
                    .persist("store the new scores", None, || {
                        app.store.finish_rescore(id, worker, &finished)
                    })
                    .await
                {
                    Ok(Some(changes)) => {
                        tracing::info!(submission = id.get(), changes, "re-scored");
                        Ok(true)
                    }
                    Ok(None) => Ok(false),
                    Err(e) => Err(e),
                }
            }
            Err(JobError::Refused(msg)) => {
                tracing::warn!(%worker, submission = id.get(), "{msg}; the re-scoring is left to other workers");
                self.refused.add(job.dataset_id);
                app.forget_dataset(job.dataset_id).await;
                let_go(false).await
            }
            Err(JobError::Stopped) => let_go(false).await,
            Err(JobError::User(msg) | JobError::Service(msg)) => {
                tracing::error!(submission = id.get(), error = %msg, "re-scoring failed");
                let_go(true).await
            }
            Err(JobError::TakenOver) => Ok(false),
        };
        if let Err(e) = stored {
            tracing::error!(submission = id.get(), error = %e, "cannot store the re-scoring");
        }
    }

    /// Renews the re-scoring lease until aborted; cancels the evaluation when it is no longer
    /// this worker's.
    fn rescore_lease(&self, id: SubmissionId, state: &JobState) -> JoinHandle<()> {
        let (app, worker) = (self.app.clone(), self.id.clone());
        let (cancel, taken) = (state.cancel.clone(), state.taken_over.clone());
        tokio::spawn(async move {
            let every =
                Duration::from_millis((app.config.lease_ms() / 3).clamp(200, 10_000) as u64);
            loop {
                tokio::time::sleep(every).await;
                match app
                    .store
                    .renew_rescore(id, &worker, app.config.lease_ms())
                    .await
                {
                    Ok(true) => {}
                    Ok(false) => {
                        taken.store(true, Ordering::Relaxed);
                        cancel.store(true, Ordering::Relaxed);
                        return;
                    }
                    Err(e) => {
                        tracing::warn!(submission = id.get(), error = %e, "re-scoring lease not renewed")
                    }
                }
            }
        })
    }

    /// Gives the job back without spending an attempt, trying for a short while only: a
    /// stopping process must not hang on a database that is gone (the lease then expires).
    async fn release(&self, id: SubmissionId) -> StoreResult<bool> {
        let deadline = Instant::now() + RELEASE_GRACE;
        let released = self
            .persist("release the job", Some(deadline), || {
                self.app.store.release(id, &self.id)
            })
            .await;
        self.app.wake.notify_waiters();
        released
    }

    /// Runs a database call, trying again with growing pauses while it fails for a lost
    /// connection, until it succeeds, fails otherwise, `deadline` passes, or (without a
    /// deadline) the process stops.
    async fn persist<T, F, Fut>(
        &self,
        what: &str,
        deadline: Option<Instant>,
        mut call: F,
    ) -> StoreResult<T>
    where
        F: FnMut() -> Fut,
        Fut: Future<Output = StoreResult<T>>,
    {
        let mut pause = Duration::from_millis(100);
        loop {
            match call().await {
                Err(e) if e.is_transient() => {
                    let out_of_time = match deadline {
                        Some(d) => Instant::now() + pause > d,
                        None => self.shutdown.is_set(),
                    };
                    if out_of_time {
                        return Err(e);
                    }
                    tracing::warn!(error = %e, retry_in_ms = pause.as_millis() as u64, "cannot {what}: trying again");
                    tokio::time::sleep(pause).await;
                    pause = (pause * 2).min(MAX_STORE_BACKOFF);
                }
                other => return other,
            }
        }
    }

    /// Renews the lease and publishes progress until aborted, in one small update every
    /// [`PROGRESS_EVERY`] (or a third of the lease, if shorter); cancels the evaluation when
    /// the job turns out to be another worker's.
    fn heartbeat(&self, id: SubmissionId, state: &JobState) -> JoinHandle<()> {
        let (app, worker) = (self.app.clone(), self.id.clone());
        let (counter, started, cancel, taken) = (
            state.counter.clone(),
            state.started.clone(),
            state.cancel.clone(),
            state.taken_over.clone(),
        );
        let (n, work) = (state.protocols, state.work);
        tokio::spawn(async move {
            let every =
                Duration::from_millis((app.config.lease_ms() / 3).clamp(200, 10_000) as u64)
                    .min(PROGRESS_EVERY);
            loop {
                tokio::time::sleep(every).await;
                let progress = counter.fraction(n, started.load(Ordering::Relaxed) as usize, work);
                let done = counter.done.load(Ordering::Relaxed) as i64;
                match app
                    .store
                    .heartbeat(id, &worker, app.config.lease_ms(), progress, done)
                    .await
                {
                    Ok(true) => {}
                    Ok(false) => {
                        // Someone else owns the job now: stop wasting the CPU on it.
                        taken.store(true, Ordering::Relaxed);
                        cancel.store(true, Ordering::Relaxed);
                        return;
                    }
                    // The next beat tries again; a lease outlives two missed beats.
                    Err(e) => tracing::warn!(submission = id.get(), error = %e, "heartbeat failed"),
                }
            }
        })
    }

    /// Evaluates, trying again with growing pauses when the service is at fault.
    async fn evaluate_with_retries(
        &self,
        job: &SubmissionRow,
        state: &JobState,
    ) -> Result<Outcome, JobError> {
        let mut pause = FIRST_BACKOFF;
        let mut tries = 1;
        loop {
            match self.evaluate_job(job, state).await {
                Err(JobError::Service(msg)) if tries < TRIES_IN_PLACE => {
                    tracing::warn!(submission = job.id.get(), error = %msg, retry_in_ms = pause.as_millis() as u64, "evaluation failed: trying again");
                    tokio::time::sleep(pause).await;
                    pause *= 2;
                    tries += 1;
                    state.reset();
                }
                other => return other,
            }
        }
    }

    async fn evaluate_job(
        &self,
        job: &SubmissionRow,
        state: &JobState,
    ) -> Result<Outcome, JobError> {
        let app = &self.app;
        let row = app
            .store
            .dataset(job.dataset_id)
            .await
            .map_err(|e| JobError::Service(e.to_string()))?
            .ok_or_else(|| JobError::Service("the dataset is no longer registered".into()))?;
        let loaded = match app.loaded(&row).await {
            Ok(loaded) => loaded,
            Err(e) if app.role == Role::Worker => {
                return Err(JobError::Refused(format!(
                    "this worker has no usable copy of dataset `{}` in {}: {e}",
                    row.name,
                    app.config.datasets_dir().display()
                )));
            }
            Err(e) => return Err(JobError::Service(e.to_string())),
        };
        match &row.content_hash {
            Some(registered) if *registered != loaded.content_hash => {
                return Err(JobError::Refused(format!(
                    "this worker's copy of dataset `{}` differs from the one the server \
                     registered (content hash {} here, {registered} registered)",
                    row.name, loaded.content_hash
                )));
            }
            None if app.role == Role::Worker => {
                return Err(JobError::Refused(format!(
                    "dataset `{}` has no recorded content hash to check this worker's copy \
                     against: start the server once so that it registers the dataset again",
                    row.name
                )));
            }
            _ => {}
        }
        let bytes =
            uploaded_file::fetch(&app.store, &app.config.submissions_dir(), &job.file_sha256)
                .await
                .map_err(|e| JobError::Service(e.to_string()))?;

        let (dataset, dataset_hash) = (loaded.dataset, loaded.content_hash);
        if let Some(task) = job.task {
            return evaluate_coco(app, task, dataset.root.clone(), bytes).await;
        }
        let protocols: Vec<ProtocolName> = job.protocols.clone();
        let (counter, started, cancel, taken) = (
            state.counter.clone(),
            state.started.clone(),
            state.cancel.clone(),
            state.taken_over.clone(),
        );
        let pool_app = app.clone();
        tokio::task::spawn_blocking(move || {
            pool_app.pool.install(|| {
                let clock = Instant::now();
                let results = results::parse_results(&bytes[..])
                    .map_err(|p| JobError::User(p.to_string()))?;
                let mut reports = Vec::with_capacity(protocols.len());
                let mut errors = Vec::with_capacity(protocols.len());
                let mut replicates = BTreeMap::new();
                for name in protocols {
                    started.fetch_add(1, Ordering::Relaxed);
                    let protocol = Protocol::named(name);
                    let mut evaluation =
                        evaluate(&dataset, &results, &protocol, counter.as_ref(), &cancel)
                            .map_err(|e| match e {
                                evaluator::Error::Cancelled if taken.load(Ordering::Relaxed) => {
                                    JobError::TakenOver
                                }
                                evaluator::Error::Cancelled => JobError::Stopped,
                                other => JobError::Service(other.to_string()),
                            })?;
                    errors.push(error_rows(name, &evaluation)?);
                    let seed = bootstrap::dataset_seed(&evaluation.report.dataset);
                    if let Some(b) = evaluation.bootstrap(seed, bootstrap::REPLICATES) {
                        replicates.insert(name, b.replicates);
                    }
                    reports.push(evaluation.report);
                }
                Ok(Outcome::Pose(Finished {
                    reports,
                    errors,
                    replicates,
                    eval_ms: clock.elapsed().as_millis() as i64,
                    dataset_hash,
                }))
            })
        })
        .await
        .unwrap_or_else(|e| Err(JobError::Service(format!("the evaluation crashed: {e}"))))
    }
}

/// What a job's evaluation gives: a 6D file's reports and errors, or a 2D file's report.
enum Outcome {
    Pose(Finished),
    Coco {
        report: Box<CocoReport>,
        eval_ms: i64,
    },
}

/// Scores a BOP'22 2D file on the evaluation threads: the dataset's ground truth is read for
/// the job (with the masks for segmentation) and COCOeval runs on the pool. COCOeval has no
/// progress to report; a cancelled job's result is dropped by the caller.
async fn evaluate_coco(
    app: &AppState,
    task: CocoProtocol,
    root: std::path::PathBuf,
    bytes: Vec<u8>,
) -> Result<Outcome, JobError> {
    let pool_app = app.clone();
    tokio::task::spawn_blocking(move || {
        pool_app.pool.install(|| {
            let clock = Instant::now();
            let results =
                coco::parse_coco_results(&bytes[..]).map_err(|p| JobError::User(p.to_string()))?;
            let with_masks = task == CocoProtocol::Segmentation;
            let gt = datasets::config::coco_gt(&root, with_masks).map_err(JobError::Service)?;
            let report = coco::evaluate(&gt, &results, task.task()).map_err(|e| match e {
                evaluator::Error::CocoResults(p) => JobError::User(p.to_string()),
                other => JobError::Service(other.to_string()),
            })?;
            Ok(Outcome::Coco {
                report: Box::new(report),
                eval_ms: clock.elapsed().as_millis() as i64,
            })
        })
    })
    .await
    .unwrap_or_else(|e| Err(JobError::Service(format!("the evaluation crashed: {e}"))))
}

/// The per-estimate errors of one protocol, compressed for the store.
fn error_rows(
    protocol: ProtocolName,
    evaluation: &evaluator::Evaluation,
) -> Result<NewErrors, JobError> {
    let rows = evaluation.error_rows();
    let json = serde_json::to_vec(&rows)
        .map_err(|e| JobError::Service(format!("cannot write the errors: {e}")))?;
    let gzip = uploaded_file::compress(&json)
        .map_err(|e| JobError::Service(format!("cannot compress the errors: {e}")))?;
    Ok(NewErrors {
        protocol,
        rows_count: rows.len() as i64,
        gzip,
    })
}

/// What the evaluation threads and the heartbeat of one job share.
struct JobState {
    counter: Arc<Counter>,
    /// Protocols started so far.
    started: Arc<AtomicU64>,
    protocols: usize,
    /// Estimate evaluations the whole job takes, as the pre-flight counted them (0: unknown).
    work: i64,
    /// Set to stop the evaluation at its next image.
    cancel: Arc<AtomicBool>,
    /// Set by the heartbeat when another worker owns the job.
    taken_over: Arc<AtomicBool>,
}

impl JobState {
    fn new(protocols: usize, work: i64) -> JobState {
        JobState {
            counter: Arc::new(Counter {
                done: AtomicU64::new(0),
                total: AtomicU64::new(0),
            }),
            started: Arc::new(AtomicU64::new(0)),
            protocols,
            work,
            cancel: Arc::new(AtomicBool::new(false)),
            taken_over: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Progress starts again for another try.
    fn reset(&self) {
        self.counter.done.store(0, Ordering::Relaxed);
        self.counter.total.store(0, Ordering::Relaxed);
        self.started.store(0, Ordering::Relaxed);
    }
}

/// Counts evaluated estimates across the protocols of one job.
struct Counter {
    done: AtomicU64,
    total: AtomicU64,
}

impl Progress for Counter {
    fn start(&self, total: u64) {
        self.total.fetch_add(total, Ordering::Relaxed);
    }
    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
}

impl Counter {
    fn fraction(&self, protocols: usize, started: usize, work: i64) -> f64 {
        let (done, total) = (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        );
        if work > 0 {
            return (done as f64 / work as f64).clamp(0.0, 0.99);
        }
        // Later protocols have not announced their totals yet: count each protocol equally.
        let current = if total == 0 {
            0.0
        } else {
            done as f64 / total as f64
        };
        let finished_share = started.saturating_sub(1) as f64 / protocols.max(1) as f64;
        (finished_share + current / protocols.max(1) as f64).clamp(0.0, 0.99)
    }
}
