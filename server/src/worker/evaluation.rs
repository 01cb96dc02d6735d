//! Evaluating one claimed submission on the evaluation threads, the same for a job and a
//! re-scoring. A worker reads the uploaded file from the database and the dataset from its own
//! copy, which must hash as the copy the server registered did: otherwise the work is refused,
//! not failed, so that a worker with a bad copy spends no attempt of the user's. A 6D file is
//! evaluated from the dataset's prepared form once this process has one complete and current
//! (`datasets::prepared`), with the same scores to the bit; a file of the form refused by its
//! check is computed from the dataset, said in the log, and handed to the preparer to rebuild.
//!
//! A BOP'22 2D file (its `task` a 2D one) is scored by `evaluator::coco` on the dataset's
//! `scene_gt_coco.json`; its report is stored in `coco_scores`. A bop24 file is scored by
//! `evaluator::detection` on the dataset's `test_targets_bop24.json`, with the toolkit's cap of
//! estimates per image for the dataset; its report is stored in `bop24_scores`.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use evaluator::coco;
use evaluator::detection::{self, DetectionReport};
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::{Progress, bootstrap, evaluate_prepared, results};

use crate::app::{AppState, Role};
use crate::datasets;
use crate::datasets::uploaded_file;
use crate::domain::{CocoProtocol, Task};
use crate::error::Chain;
use crate::store::pose_errors::NewErrors;
use crate::store::queue::{Finished, FinishedCoco};
use crate::store::submissions::SubmissionRow;

/// How a job ended for this worker.
pub(super) enum JobError {
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

/// What a job's evaluation gives: a 6D file's reports and errors, a 2D file's report, or a
/// bop24 file's report.
pub(super) enum Outcome {
    Pose(Finished),
    Coco(Box<FinishedCoco>),
    Bop24 {
        report: Box<DetectionReport>,
        /// The bootstrap replicates of its bop24_mAP (empty when none was drawn).
        replicates: Vec<f64>,
        eval_ms: i64,
    },
}

/// Evaluates `job` under `state` (its progress and its cancellation).
pub(super) async fn evaluate(
    app: &AppState,
    job: &SubmissionRow,
    state: &JobState,
) -> Result<Outcome, JobError> {
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
                "this worker has no usable copy of dataset `{}` in {}: {}",
                row.name,
                app.config.datasets_dir().display(),
                Chain(&e)
            )));
        }
        Err(e) => return Err(JobError::Service(Chain(&e).to_string())),
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
    let bytes = uploaded_file::fetch(&app.store, &app.config.submissions_dir(), &job.file_sha256)
        .await
        .map_err(|e| JobError::Service(e.to_string()))?;

    let (dataset, dataset_hash) = (loaded.dataset, loaded.content_hash);
    match job.task {
        Some(Task::Coco(task)) => {
            return evaluate_coco(app, task, dataset.root.clone(), bytes, dataset_hash).await;
        }
        Some(Task::Bop24) => return evaluate_bop24(app, &row, bytes, state).await,
        None => {}
    }
    let prepared = app.prepared.current(row.id, &dataset_hash);
    match &prepared {
        Some(form) => {
            tracing::info!(dataset = %row.name, folder = %form.dir().display(), "evaluating from the prepared form")
        }
        None => {
            tracing::info!(dataset = %row.name, "evaluating from the dataset: no prepared form is ready")
        }
    }
    let protocols: Vec<ProtocolName> = job.protocols.clone();
    let (counter, started, cancel, taken) = (
        state.counter.clone(),
        state.started.clone(),
        state.cancel.clone(),
        state.taken_over.clone(),
    );
    let form = prepared.clone();
    let outcome = on_pool(app, move |clock| {
        let results =
            results::parse_results(&bytes[..]).map_err(|p| JobError::User(p.to_string()))?;
        let mut reports = Vec::with_capacity(protocols.len());
        let mut errors = Vec::with_capacity(protocols.len());
        let mut replicates = BTreeMap::new();
        for name in protocols {
            started.fetch_add(1, Ordering::Relaxed);
            let protocol = Protocol::named(name);
            let mut evaluation = evaluate_prepared(
                &dataset,
                &results,
                &protocol,
                form.as_deref(),
                counter.as_ref(),
                &cancel,
            )
            .map_err(|e| ended(e, &taken))?;
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
            eval_ms: elapsed_ms(clock),
            dataset_hash,
        }))
    })
    .await;
    if let Some(form) = prepared {
        let damaged = form.damaged();
        for problem in &damaged {
            tracing::warn!(dataset = %row.name, "prepared file refused, its image computed from the dataset: {problem}");
        }
        if !damaged.is_empty() {
            app.prepared.report_damaged(row.id);
        }
    }
    outcome
}

/// Runs `work` on the evaluation threads, never on the async ones, handing it the clock its
/// `eval_ms` is measured from; a panic in the evaluator ends the job as the service's fault.
async fn on_pool(
    app: &AppState,
    work: impl FnOnce(Instant) -> Result<Outcome, JobError> + Send + 'static,
) -> Result<Outcome, JobError> {
    let pool_app = app.clone();
    tokio::task::spawn_blocking(move || pool_app.pool.install(|| work(Instant::now())))
        .await
        .unwrap_or_else(|e| Err(JobError::Service(format!("the evaluation crashed: {e}"))))
}

fn elapsed_ms(clock: Instant) -> i64 {
    clock.elapsed().as_millis() as i64
}

/// How an evaluation's error ends the job: a cancellation is a takeover when another worker
/// owns the job now, else this process stopping; anything else is the service's fault.
fn ended(e: evaluator::Error, taken: &AtomicBool) -> JobError {
    match e {
        evaluator::Error::Cancelled if taken.load(Ordering::Relaxed) => JobError::TakenOver,
        evaluator::Error::Cancelled => JobError::Stopped,
        other => JobError::Service(other.to_string()),
    }
}

/// Scores a BOP'22 2D file on the evaluation threads: the dataset's ground truth is read for
/// the job (with the masks for segmentation), COCOeval runs on the pool, and the AP's
/// bootstrap is drawn as a 6D headline's is. COCOeval has no progress to report; a cancelled
/// job's result is dropped by the caller.
async fn evaluate_coco(
    app: &AppState,
    task: CocoProtocol,
    root: std::path::PathBuf,
    bytes: Vec<u8>,
    dataset_hash: String,
) -> Result<Outcome, JobError> {
    on_pool(app, move |clock| {
        let results =
            coco::parse_coco_results(&bytes[..]).map_err(|p| JobError::User(p.to_string()))?;
        let with_masks = task == CocoProtocol::Segmentation;
        let gt = datasets::config::coco_gt(&root, with_masks)
            .map_err(|e| JobError::Service(e.to_string()))?;
        let mut evaluation = coco::evaluation(&gt, &results, task.task()).map_err(|e| match e {
            evaluator::Error::CocoResults(p) => JobError::User(p.to_string()),
            other => JobError::Service(other.to_string()),
        })?;
        let seed = bootstrap::dataset_seed(&evaluation.report.dataset);
        let replicates = evaluation
            .bootstrap(seed, bootstrap::REPLICATES)
            .map_or_else(Vec::new, |b| b.replicates);
        Ok(Outcome::Coco(Box::new(FinishedCoco {
            report: evaluation.report,
            replicates,
            parameters: task.task().parameters(),
            eval_ms: elapsed_ms(clock),
            dataset_hash,
        })))
    })
    .await
}

/// Scores a bop24 file on the evaluation threads, on the dataset loaded with its
/// `test_targets_bop24.json`, keeping the toolkit's number of estimates per image for the
/// dataset, with the job's progress and cancellation.
async fn evaluate_bop24(
    app: &AppState,
    row: &crate::store::datasets::DatasetRow,
    bytes: Vec<u8>,
    state: &JobState,
) -> Result<Outcome, JobError> {
    let dataset = match app.bop24_dataset(row).await {
        Ok(Some(dataset)) => dataset,
        Ok(None) if app.role == Role::Worker => {
            return Err(JobError::Refused(format!(
                "this worker's copy of dataset `{}` has no test_targets_bop24.json",
                row.name
            )));
        }
        Ok(None) => {
            return Err(JobError::Service(format!(
                "dataset `{}` no longer has its test_targets_bop24.json",
                row.name
            )));
        }
        Err(e) => return Err(JobError::Service(Chain(&e).to_string())),
    };
    let (counter, started, cancel, taken) = (
        state.counter.clone(),
        state.started.clone(),
        state.cancel.clone(),
        state.taken_over.clone(),
    );
    on_pool(app, move |clock| {
        let results =
            results::parse_results(&bytes[..]).map_err(|p| JobError::User(p.to_string()))?;
        started.fetch_add(1, Ordering::Relaxed);
        let cap = detection::default_max_estimates_per_image(&dataset.name);
        let mut evaluation =
            detection::evaluation(&dataset, &results, cap, counter.as_ref(), &cancel)
                .map_err(|e| ended(e, &taken))?;
        let seed = bootstrap::dataset_seed(&evaluation.report.dataset);
        let replicates = evaluation
            .bootstrap(seed, bootstrap::REPLICATES)
            .map_or_else(Vec::new, |b| b.replicates);
        Ok(Outcome::Bop24 {
            report: Box::new(evaluation.report),
            replicates,
            eval_ms: elapsed_ms(clock),
        })
    })
    .await
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

/// What the evaluation threads and the lease of one job share.
pub(super) struct JobState {
    pub(super) counter: Arc<Counter>,
    /// Protocols started so far.
    pub(super) started: Arc<AtomicU64>,
    pub(super) protocols: usize,
    /// Estimate evaluations the whole job takes, as the pre-flight counted them (0: unknown).
    pub(super) work: i64,
    /// Set to stop the evaluation at its next image.
    pub(super) cancel: Arc<AtomicBool>,
    /// Set by the lease when another worker owns the job.
    pub(super) taken_over: Arc<AtomicBool>,
}

impl JobState {
    pub(super) fn new(protocols: usize, work: i64) -> JobState {
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
    pub(super) fn reset(&self) {
        self.counter.done.store(0, Ordering::Relaxed);
        self.counter.total.store(0, Ordering::Relaxed);
        self.started.store(0, Ordering::Relaxed);
    }
}

/// Counts evaluated estimates across the protocols of one job.
pub(super) struct Counter {
    pub(super) done: AtomicU64,
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
    pub(super) fn fraction(&self, protocols: usize, started: usize, work: i64) -> f64 {
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
