//! What is tried again, and how often. Faults of the service are retried, faults of the file
//! never: a database call that fails for a lost connection is tried again with backoff (a
//! finished evaluation's scores are never dropped for that), an evaluation that fails for the
//! service's reasons is tried again in place with backoff, and only then counts as one of a
//! job's attempts; a job out of attempts is failed rather than retried forever.

use std::future::Future;
use std::time::{Duration, Instant};

use super::evaluation::{self, JobError, JobState, Outcome};
use crate::app::AppState;
use crate::shutdown::Shutdown;
use crate::store::StoreResult;
use crate::store::submissions::SubmissionRow;

/// A job failing this many times for the service's reasons (e.g. its worker died each time)
/// is marked failed instead of being retried forever; a re-scoring is given up after as many.
pub(super) const MAX_ATTEMPTS: i64 = 3;
/// Tries of an evaluation within one attempt when it fails for the service's reasons, and the
/// pause before the first retry (doubled each time).
const TRIES_IN_PLACE: u32 = 3;
const FIRST_BACKOFF: Duration = Duration::from_secs(1);
/// Longest pause between two tries of a database call that lost its connection.
const MAX_STORE_BACKOFF: Duration = Duration::from_secs(5);
/// How long a stopping worker keeps trying to give its work back: a stopping process must not
/// hang on a database that is gone (the lease then expires).
pub(super) const RELEASE_GRACE: Duration = Duration::from_secs(5);

/// Runs a database call, trying again with growing pauses while it fails for a lost
/// connection, until it succeeds, fails otherwise, `deadline` passes, or (without a
/// deadline) the process stops.
pub(super) async fn persist<T, F, Fut>(
    shutdown: &Shutdown,
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
                    None => shutdown.is_set(),
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

/// Evaluates, trying again with growing pauses when the service is at fault.
pub(super) async fn evaluate_in_place(
    app: &AppState,
    job: &SubmissionRow,
    state: &JobState,
) -> Result<Outcome, JobError> {
    let mut pause = FIRST_BACKOFF;
    let mut tries = 1;
    loop {
        match evaluation::evaluate(app, job, state).await {
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
