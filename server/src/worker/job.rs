//! One evaluation job, from its claim to its stored outcome. The lease is renewed by a
//! heartbeat that also records progress (twice a second, so a page following the job moves
//! every second); the scores, the per-estimate errors and the evaluation time are stored in the
//! transaction that marks the job done, only while it is still this worker's. On SIGINT or
//! SIGTERM the running evaluation is cancelled and its job released at once, without spending
//! an attempt.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use super::evaluation::{JobError, JobState, Outcome};
use super::lease::{self, Lease};
use super::pool::Worker;
use super::retry::{self, MAX_ATTEMPTS, RELEASE_GRACE};
use crate::domain::SubmissionId;
use crate::store::StoreResult;
use crate::store::submissions::{Fault, SubmissionRow};

/// Longest pause between two progress records of a running job: pages poll every second.
const PROGRESS_EVERY: Duration = Duration::from_millis(500);

impl Worker {
    pub(super) async fn run_job(&self, job: SubmissionRow) {
        let (app, worker) = (&self.app, self.id.as_str());
        tracing::info!(%worker, submission = job.id.get(), attempt = job.attempts, "evaluation started");
        let timer = crate::ops::metrics::job_started(job.attempts);
        let job_state = JobState::new(job.protocols.len(), job.work);
        let beat = self.heartbeat(job.id, &job_state);
        let outcome = tokio::select! {
            outcome = retry::evaluate_in_place(app, &job, &job_state) => outcome,
            _ = self.shutdown.wait() => Err(JobError::Stopped),
        };
        // Whatever still runs on the evaluation threads stops at its next image.
        job_state.cancel.store(true, Ordering::Relaxed);
        drop(beat);
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
            Ok(Outcome::Coco(finished)) => Some(Some(finished.report.entries_evaluated as u64)),
            Ok(Outcome::Bop24 { report, .. }) => Some(Some(report.estimates_evaluated as u64)),
            Err(JobError::User(_)) => Some(None),
            Err(JobError::Service(_)) if job.attempts >= MAX_ATTEMPTS => Some(None),
            Err(_) => None,
        };
        let shutdown = &self.shutdown;
        let stored = match outcome {
            Ok(Outcome::Pose(finished)) => {
                retry::persist(shutdown, "store the scores", None, || {
                    app.store.finish(id, worker, &finished)
                })
                .await
            }
            Ok(Outcome::Coco(finished)) => {
                retry::persist(shutdown, "store the scores", None, || {
                    app.store.finish_coco(id, worker, &finished)
                })
                .await
            }
            Ok(Outcome::Bop24 {
                report,
                replicates,
                eval_ms,
            }) => {
                retry::persist(shutdown, "store the scores", None, || {
                    app.store
                        .finish_bop24(id, worker, &report, &replicates, eval_ms)
                })
                .await
            }
            Err(JobError::User(msg)) => {
                retry::persist(shutdown, "store the failure", None, || {
                    app.store.fail(id, worker, &msg, Fault::User)
                })
                .await
            }
            Err(JobError::Service(msg)) if job.attempts >= MAX_ATTEMPTS => {
                tracing::error!(submission = id.get(), error = %msg, "evaluation failed");
                retry::persist(shutdown, "store the failure", None, || {
                    app.store.fail(id, worker, &msg, Fault::Service)
                })
                .await
            }
            Err(JobError::Service(msg)) => {
                tracing::error!(submission = id.get(), attempt = job.attempts, error = %msg, "evaluation failed: queued for another attempt");
                let requeued = retry::persist(shutdown, "queue the job again", None, || {
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

    /// Gives the job back without spending an attempt, trying for a short while only.
    async fn release(&self, id: SubmissionId) -> StoreResult<bool> {
        let deadline = Instant::now() + RELEASE_GRACE;
        let released = retry::persist(&self.shutdown, "release the job", Some(deadline), || {
            self.app.store.release(id, &self.id)
        })
        .await;
        self.app.wake.notify_waiters();
        released
    }

    /// Renews the job's lease and publishes its progress in one small update every
    /// [`PROGRESS_EVERY`] (or a third of the lease, if shorter).
    fn heartbeat(&self, id: SubmissionId, state: &JobState) -> Lease {
        let (app, worker) = (self.app.clone(), self.id.clone());
        let (counter, started) = (state.counter.clone(), state.started.clone());
        let (n, work) = (state.protocols, state.work);
        let every = lease::renew_every(app.config.lease_ms()).min(PROGRESS_EVERY);
        lease::keep(id, every, state, "heartbeat failed", move || {
            let progress = counter.fraction(n, started.load(Ordering::Relaxed) as usize, work);
            let done = counter.done.load(Ordering::Relaxed) as i64;
            let (app, worker) = (app.clone(), worker.clone());
            async move {
                app.store
                    .heartbeat(id, &worker, app.config.lease_ms(), progress, done)
                    .await
            }
        })
    }
}
