//! The workers of a process and the loop each runs: claim a queued job, else a re-scoring,
//! else wait. The in-process `Notify` only wakes idle workers early; the database stays the
//! truth, so workers on other machines find the same jobs by polling.
//!
//! A worker whose copy of a dataset differs from the registered one (or is missing) gives the
//! job back and leaves that dataset's jobs to others for a while; the refusal is shared by
//! the workers of the process, which read the same copy.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::task::JoinHandle;
use tracing::Instrument;

use super::lease;
use super::retry::MAX_ATTEMPTS;
use crate::app::AppState;
use crate::clock::now_ms;
use crate::domain::DatasetId;
use crate::shutdown::Shutdown;

/// How often an idle worker looks at the queue without being woken; more often under a lease
/// of a few seconds, since each look is a beat and a worker unseen for a lease counts as dead.
const POLL: Duration = Duration::from_secs(2);
/// How long a worker leaves the jobs of a dataset it refused before it looks at its copy again.
const REFUSAL_PAUSE: Duration = Duration::from_secs(300);
/// How long the beats of workers no longer seen are kept (a starting worker forgets older ones).
const BEATS_KEPT_MS: i64 = 7 * 24 * 3600 * 1000;

/// Starts `app.config.workers` workers (none for `serve --workers 0`), and the preparer of
/// the datasets they evaluate; each ends once `shutdown` is set, a worker after giving back the
/// job it was running.
pub fn spawn_workers(app: &AppState, shutdown: &Shutdown) -> Vec<JoinHandle<()>> {
    if app.config.workers == 0 {
        return Vec::new();
    }
    let refused = Arc::new(Refused::default());
    let mut handles: Vec<JoinHandle<()>> = (0..app.config.workers)
        .map(|n| {
            let worker = Worker {
                app: app.clone(),
                id: format!("{}-{}-{n}", host_name(), std::process::id()),
                refused: refused.clone(),
                shutdown: shutdown.clone(),
            };
            tokio::spawn(async move { worker.run().await })
        })
        .collect();
    handles.extend(super::preparation::spawn(app, shutdown));
    handles
}

/// This machine's name, which worker ids and the preparations' records carry.
pub(super) fn host_name() -> String {
    std::fs::read_to_string("/etc/hostname")
        .map(|h| h.trim().to_string())
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "worker".to_string())
}

/// Datasets this process's workers refused, with when: their jobs are not claimed until
/// [`REFUSAL_PAUSE`] has passed.
#[derive(Default)]
pub(super) struct Refused(Mutex<HashMap<DatasetId, Instant>>);

impl Refused {
    pub(super) fn add(&self, dataset_id: DatasetId) {
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

/// One worker: what its job and its re-scorings run with.
pub(super) struct Worker {
    pub(super) app: AppState,
    /// The name its leases are held under: host, process and number, unique among workers.
    pub(super) id: String,
    pub(super) refused: Arc<Refused>,
    pub(super) shutdown: Shutdown,
}

impl Worker {
    async fn run(self) {
        let worker = &self.id;
        tracing::info!(%worker, "worker started");
        let app = &self.app;
        if let Err(e) = app
            .store
            .forget_beats_before(now_ms() - BEATS_KEPT_MS)
            .await
        {
            tracing::warn!(%worker, error = %e, "old worker beats not pruned");
        }
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
                    let poll = POLL.min(lease::renew_every(app.config.lease_ms()));
                    tokio::select! {
                        _ = &mut notified => {}
                        _ = tokio::time::sleep(poll) => {}
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
}
