//! The evaluation workers: they claim queued submissions from the store, evaluate them on the
//! evaluation threads and store the scores. They run in the server process or alone (`poseboard
//! worker`), so they depend on the services and the store, never on the web layer.
//!
//! The queue is the submissions table: a worker claims a row with a lease, renews the lease
//! with a heartbeat that also records progress, and stores the scores, the per-estimate errors
//! and the time the evaluation took in the same transaction that marks the row done. A worker
//! that dies (crash, SIGKILL, restart) stops renewing; once its lease expires any worker, in
//! this process or on another machine sharing the PostgreSQL database, takes the job up again.
//! An idle worker re-scores submissions an older evaluator scored, under a lease of its own.
//! Every poll of the queue and every renewal of a lease is also a beat of the worker (see
//! [`crate::store::worker_beats`]), so that the pages can tell when no worker runs at all.
//!
//! Split by concern: `pool` starts the workers and runs the claim loop, `job` runs one
//! evaluation job and `rescoring` one re-scoring, both evaluating with `evaluation`, holding
//! their row with the one renew/cancel loop of `lease`, and retrying as `retry` says;
//! `preparation` prepares the datasets those evaluations read in the background.
//! `challenge_deadlines` is the server's other background task: the snapshots at the
//! challenges' deadlines.

mod challenge_deadlines;
mod evaluation;
mod job;
mod lease;
mod pool;
mod preparation;
mod rescoring;
mod retry;

pub use challenge_deadlines::spawn_deadline_watch;
pub use pool::spawn_workers;
