//! The evaluation workers. The queue is the submissions table: a worker claims a row with a
//! lease, renews the lease with a heartbeat that also records progress, and stores the scores
//! in the same transaction that marks the row done. A worker that dies (crash, SIGKILL,
//! restart) stops renewing; once its lease expires any worker, in this process or on another
//! machine sharing the PostgreSQL database, takes the job up again. The in-process `Notify`
//! only wakes idle workers early.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::{Progress, Report, evaluate, results};
use tokio::task::JoinHandle;
use tracing::Instrument;

use crate::app::AppState;
use crate::store::submissions::{Fault, SubmissionRow};

/// How often an idle worker looks at the queue without being woken.
const POLL: Duration = Duration::from_secs(2);
/// A job failing this many times for the service's reasons (e.g. its worker died each time)
/// is marked failed instead of being retried forever.
const MAX_ATTEMPTS: i64 = 3;

pub fn spawn_workers(app: &AppState) -> Vec<JoinHandle<()>> {
    (0..app.config.workers.max(1))
        .map(|n| {
            let app = app.clone();
            let id = format!("{}-{}-{n}", host_name(), std::process::id());
            tokio::spawn(async move { worker_loop(app, id).await })
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

async fn worker_loop(app: AppState, worker: String) {
    tracing::info!(%worker, "worker started");
    loop {
        // Register interest before looking, so a wake-up between the two is not lost.
        let notified = app.wake.notified();
        tokio::pin!(notified);
        notified.as_mut().enable();
        match app
            .store
            .claim(&worker, app.config.lease_ms(), MAX_ATTEMPTS)
            .await
        {
            Ok(Some(job)) => {
                let span = tracing::info_span!("job", submission = job.id, attempt = job.attempts);
                run_job(&app, &worker, job).instrument(span).await
            }
            Ok(None) => {
                tokio::select! {
                    _ = &mut notified => {}
                    _ = tokio::time::sleep(POLL) => {}
                }
            }
            Err(e) => {
                tracing::error!(%worker, error = %e, "cannot read the queue");
                tokio::time::sleep(POLL).await;
            }
        }
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
    fn fraction(&self, protocols: usize, started: usize) -> f64 {
        // Later protocols have not announced their totals yet: count each protocol equally.
        let (done, total) = (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        );
        let current = if total == 0 {
            0.0
        } else {
            done as f64 / total as f64
        };
        let finished_share = started.saturating_sub(1) as f64 / protocols.max(1) as f64;
        (finished_share + current / protocols.max(1) as f64).clamp(0.0, 0.99)
    }
}

async fn run_job(app: &AppState, worker: &str, job: SubmissionRow) {
    tracing::info!(%worker, submission = job.id, attempt = job.attempts, "evaluation started");
    let timer = crate::metrics::job_started(job.attempts);
    let outcome = evaluate_job(app, worker, &job).await;
    let evaluated = (outcome.as_ref().ok())
        .map(|reports| reports.iter().map(|r| r.estimates_evaluated as u64).sum());
    let stored = match outcome {
        Ok(reports) => app.store.finish(job.id, worker, &reports).await,
        Err(JobError::User(msg)) => app.store.fail(job.id, worker, &msg, Fault::User).await,
        Err(JobError::Service(msg)) => {
            tracing::error!(submission = job.id, error = %msg, "evaluation failed");
            app.store.fail(job.id, worker, &msg, Fault::Service).await
        }
    };
    if let Ok(true) = stored {
        timer.ended(evaluated);
    }
    match stored {
        Ok(true) => tracing::info!(submission = job.id, "evaluation finished"),
        Ok(false) => tracing::warn!(submission = job.id, "job was taken over; result discarded"),
        Err(e) => tracing::error!(submission = job.id, error = %e, "cannot store the outcome"),
    }
}

enum JobError {
    /// The file's fault: shown to the user as the reason.
    User(String),
    /// The service's fault: does not count against the user.
    Service(String),
}

async fn evaluate_job(
    app: &AppState,
    worker: &str,
    job: &SubmissionRow,
) -> Result<Vec<Report>, JobError> {
    let row = app
        .store
        .dataset(job.dataset_id)
        .await
        .map_err(|e| JobError::Service(e.to_string()))?
        .ok_or_else(|| JobError::Service("the dataset is no longer served".into()))?;
    let dataset = app
        .dataset(&row)
        .await
        .map_err(|e| JobError::Service(e.to_string()))?;
    let path = app.stored_file(&job.file_sha256);
    let protocols: Vec<ProtocolName> = job.protocols.clone();

    let counter = Arc::new(Counter {
        done: AtomicU64::new(0),
        total: AtomicU64::new(0),
    });
    let started = Arc::new(AtomicU64::new(0));
    let cancel = Arc::new(AtomicBool::new(false));

    // Heartbeat: renew the lease and publish progress until the evaluation ends.
    let beat = {
        let (app, worker, counter, started, cancel) = (
            app.clone(),
            worker.to_string(),
            counter.clone(),
            started.clone(),
            cancel.clone(),
        );
        let (id, n) = (job.id, protocols.len());
        tokio::spawn(async move {
            let every =
                Duration::from_millis((app.config.lease_ms() / 3).clamp(200, 10_000) as u64);
            loop {
                tokio::time::sleep(every).await;
                let progress = counter.fraction(n, started.load(Ordering::Relaxed) as usize);
                match app
                    .store
                    .heartbeat(id, &worker, app.config.lease_ms(), progress)
                    .await
                {
                    Ok(true) => {}
                    Ok(false) => {
                        // Someone else owns the job now: stop wasting the CPU on it.
                        cancel.store(true, Ordering::Relaxed);
                        return;
                    }
                    Err(e) => tracing::warn!(submission = id, error = %e, "heartbeat failed"),
                }
            }
        })
    };

    let pool_app = app.clone();
    let result = tokio::task::spawn_blocking(move || {
        pool_app.pool.install(|| {
            let results = results::load_results(&path).map_err(|e| match e {
                evaluator::Error::Results(p) => JobError::User(p.to_string()),
                other => JobError::Service(other.to_string()),
            })?;
            let mut reports = Vec::with_capacity(protocols.len());
            for name in protocols {
                started.fetch_add(1, Ordering::Relaxed);
                let protocol = Protocol::named(name);
                let report = evaluate(&dataset, &results, &protocol, counter.as_ref(), &cancel)
                    .map_err(|e| match e {
                        evaluator::Error::Cancelled => {
                            JobError::Service("evaluation taken over by another worker".into())
                        }
                        other => JobError::Service(other.to_string()),
                    })?
                    .report;
                reports.push(report);
            }
            Ok(reports)
        })
    })
    .await
    .unwrap_or_else(|e| Err(JobError::Service(format!("the evaluation crashed: {e}"))));
    beat.abort();
    result
}
