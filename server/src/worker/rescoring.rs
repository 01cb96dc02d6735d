//! One re-scoring: a finished submission evaluated again with this evaluator, as a job is but
//! without publishing progress (its old scores stand meanwhile), under a lease of its own; its
//! scores are swapped for the new ones and the differences recorded. A failed re-scoring only
//! spends one of its attempts: the submission stays done with the scores it had.

use std::sync::atomic::Ordering;
use std::time::Instant;

use super::evaluation::{self, JobError, JobState, Outcome};
use super::lease::{self, Lease};
use super::pool::Worker;
use super::retry::{self, RELEASE_GRACE};
use crate::domain::SubmissionId;
use crate::store::submissions::SubmissionRow;

impl Worker {
    pub(super) async fn run_rescore(&self, job: SubmissionRow) {
        let (app, worker, id) = (&self.app, self.id.as_str(), job.id);
        tracing::info!(%worker, submission = id.get(), from = ?job.evaluator_version, "re-scoring started");
        let state = JobState::new(job.protocols.len(), job.work);
        let held = self.rescore_lease(id, &state);
        let outcome = tokio::select! {
            outcome = evaluation::evaluate(app, &job, &state) => outcome,
            _ = self.shutdown.wait() => Err(JobError::Stopped),
        };
        state.cancel.store(true, Ordering::Relaxed);
        drop(held);
        let let_go = |count: bool| {
            retry::persist(
                &self.shutdown,
                "let go of the re-scoring",
                Some(Instant::now() + RELEASE_GRACE),
                move || app.store.drop_rescore(id, worker, count),
            )
        };
        let stored = match outcome {
            // Never flagged (see `Store::flag_rescoring`); let go, counted, should one be.
            Ok(Outcome::Coco(_) | Outcome::Bop24 { .. }) => let_go(true).await,
            Ok(Outcome::Pose(finished)) => {
                match retry::persist(&self.shutdown, "store the new scores", None, || {
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

    /// Renews the re-scoring lease every third of the lease.
    fn rescore_lease(&self, id: SubmissionId, state: &JobState) -> Lease {
        let (app, worker) = (self.app.clone(), self.id.clone());
        let every = lease::renew_every(app.config.lease_ms());
        lease::keep(
            id,
            every,
            state,
            "re-scoring lease not renewed",
            move || {
                let (app, worker) = (app.clone(), worker.clone());
                async move {
                    app.store
                        .renew_rescore(id, &worker, app.config.lease_ms())
                        .await
                }
            },
        )
    }
}
