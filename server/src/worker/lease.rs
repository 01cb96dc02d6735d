//! Holding a claimed row: a job and a re-scoring each keep their lease alive the same way, so
//! the rule lives once. The lease is renewed a few times per lease period, so it outlives a
//! missed renewal or two; when a renewal finds the row no longer this worker's (its lease
//! expired and another worker took it, or the submission changed meanwhile), the evaluation is
//! cancelled at once rather than finished for nothing.

use std::future::Future;
use std::sync::atomic::Ordering;
use std::time::Duration;

use tokio::task::JoinHandle;

use super::evaluation::JobState;
use crate::domain::SubmissionId;
use crate::store::StoreResult;

/// A lease being renewed in the background; dropping it stops the renewals.
pub(super) struct Lease(JoinHandle<()>);

impl Drop for Lease {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// How often a lease of `lease_ms` is renewed: a third of it, within 0.2 s and 10 s.
pub(super) fn renew_every(lease_ms: i64) -> Duration {
    Duration::from_millis((lease_ms / 3).clamp(200, 10_000) as u64)
}

/// Renews the lease of `submission` with `renew` every `every` until dropped. When `renew`
/// answers false the row is another worker's: the evaluation of `state` is marked taken over
/// and cancelled, and the renewals end. A renewal that fails is logged as `failed` and tried
/// again at the next beat.
pub(super) fn keep<F, Fut>(
    submission: SubmissionId,
    every: Duration,
    state: &JobState,
    failed: &'static str,
    mut renew: F,
) -> Lease
where
    F: FnMut() -> Fut + Send + 'static,
    Fut: Future<Output = StoreResult<bool>> + Send + 'static,
{
    let (cancel, taken) = (state.cancel.clone(), state.taken_over.clone());
    Lease(tokio::spawn(async move {
        loop {
            tokio::time::sleep(every).await;
            match renew().await {
                Ok(true) => {}
                Ok(false) => {
                    // Someone else owns it now: stop wasting the CPU on it.
                    taken.store(true, Ordering::Relaxed);
                    cancel.store(true, Ordering::Relaxed);
                    return;
                }
                Err(e) => tracing::warn!(submission = submission.get(), error = %e, "{failed}"),
            }
        }
    }))
}
