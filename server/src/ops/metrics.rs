//! The Prometheus metrics of this process: one recorder per process, rendered as text by
//! `GET /metrics` (of `serve`, or of a `worker` given `--metrics-bind`). Counters live in the
//! process and start at zero with it; Prometheus' `rate()` and `increase()` are made for that.
//! The queue depth and the age of the newest worker beat are the database's truth, so they are
//! read at scrape time rather than counted.

use std::sync::OnceLock;
use std::time::Instant;

use metrics::{
    Unit, counter, describe_counter, describe_gauge, describe_histogram, gauge, histogram,
};
use metrics_exporter_prometheus::{BuildError, Matcher, PrometheusBuilder, PrometheusHandle};

use crate::store::submissions::Status;

const JOBS_STARTED: &str = "poseboard_jobs_started_total";
const JOBS_DONE: &str = "poseboard_jobs_done_total";
const JOBS_FAILED: &str = "poseboard_jobs_failed_total";
const JOBS_RETRIED: &str = "poseboard_jobs_retried_total";
const JOB_DURATION: &str = "poseboard_job_duration_seconds";
const ESTIMATES: &str = "poseboard_estimates_evaluated_total";
const QUEUE_DEPTH: &str = "poseboard_queue_depth";
const HEARTBEAT_AGE: &str = "poseboard_worker_heartbeat_age_seconds";
const HTTP_REQUESTS: &str = "poseboard_http_requests_total";
const HTTP_DURATION: &str = "poseboard_http_request_duration_seconds";

/// Every state a submission can be in, so that an empty state shows as 0 rather than vanishing.
const STATES: [Status; 4] = [
    Status::Queued,
    Status::Running,
    Status::Done,
    Status::Failed,
];

/// Jobs take from a fraction of a second (a miniature) to an hour (a paper-sized set).
const JOB_BUCKETS: &[f64] = &[
    0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0,
];
/// Pages answer in milliseconds; uploads of large files take seconds.
const HTTP_BUCKETS: &[f64] = &[
    0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
];

static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();

/// Installs the process's recorder (once; later calls do nothing) and makes every job series
/// exist at zero, so a dashboard sees `0` rather than no data before the first job.
pub fn install() -> Result<(), BuildError> {
    if HANDLE.get().is_some() {
        return Ok(());
    }
    let handle = PrometheusBuilder::new()
        .set_buckets_for_metric(Matcher::Full(JOB_DURATION.into()), JOB_BUCKETS)?
        .set_buckets_for_metric(Matcher::Full(HTTP_DURATION.into()), HTTP_BUCKETS)?
        .install_recorder()?;
    if HANDLE.set(handle).is_err() {
        return Ok(());
    }
    describe_counter!(
        JOBS_STARTED,
        "Evaluation jobs claimed by this process's workers"
    );
    describe_counter!(JOBS_DONE, "Jobs this process finished with scores");
    describe_counter!(JOBS_FAILED, "Jobs this process marked failed");
    describe_counter!(
        JOBS_RETRIED,
        "Jobs claimed again after an earlier attempt (its worker died or gave it up)"
    );
    describe_histogram!(
        JOB_DURATION,
        Unit::Seconds,
        "Time from claim to stored outcome"
    );
    describe_counter!(
        ESTIMATES,
        "Pose estimates evaluated (summed over protocols); rate() gives estimates per second"
    );
    describe_gauge!(QUEUE_DEPTH, "Submissions per state, read from the database");
    describe_gauge!(
        HEARTBEAT_AGE,
        Unit::Seconds,
        "Age of the newest beat of any evaluation worker sharing the database (+Inf: none ever \
         beat); above the lease, no worker is running and queued submissions wait"
    );
    describe_counter!(HTTP_REQUESTS, "HTTP requests by route template and status");
    describe_histogram!(HTTP_DURATION, Unit::Seconds, "HTTP request latency");
    for name in [
        JOBS_STARTED,
        JOBS_DONE,
        JOBS_FAILED,
        JOBS_RETRIED,
        ESTIMATES,
    ] {
        counter!(name).absolute(0);
    }
    Ok(())
}

/// The exposition text of every metric of this process (empty before [`install`]).
pub fn render() -> String {
    HANDLE.get().map_or_else(String::new, |h| {
        h.run_upkeep();
        h.render()
    })
}

/// Records the number of submissions in each state (states absent from `counts` are 0).
pub fn set_queue_depth(counts: &[(Status, i64)]) {
    for state in STATES {
        let n = counts
            .iter()
            .find(|(s, _)| *s == state)
            .map_or(0, |(_, n)| *n);
        gauge!(QUEUE_DEPTH, "state" => state.as_str()).set(n as f64);
    }
}

/// Records the age in seconds of the newest worker beat; `None` (no worker ever beat) is
/// +Inf, so that an alert on the age fires for a service that never had a worker.
pub fn set_heartbeat_age(seconds: Option<f64>) {
    gauge!(HEARTBEAT_AGE).set(seconds.unwrap_or(f64::INFINITY));
}

/// A job this process's worker has claimed, timed until its outcome is stored.
pub struct JobTimer {
    started: Instant,
}

/// Counts a claimed job: `attempt` is its attempt number (the claim counts it), so anything
/// above 1 is a retry.
pub fn job_started(attempt: i64) -> JobTimer {
    counter!(JOBS_STARTED).increment(1);
    if attempt > 1 {
        counter!(JOBS_RETRIED).increment(1);
    }
    JobTimer {
        started: Instant::now(),
    }
}

impl JobTimer {
    /// Counts the stored outcome: `Some(estimates evaluated)` when the job is done, `None`
    /// when it failed. A job taken over by another worker is not ended here (that worker
    /// counts it).
    pub fn ended(self, evaluated: Option<u64>) {
        let secs = self.started.elapsed().as_secs_f64();
        let outcome = match evaluated {
            Some(n) => {
                counter!(JOBS_DONE).increment(1);
                counter!(ESTIMATES).increment(n);
                "done"
            }
            None => {
                counter!(JOBS_FAILED).increment(1);
                "failed"
            }
        };
        histogram!(JOB_DURATION, "outcome" => outcome).record(secs);
    }
}

/// Counts an answered HTTP request under its route template (`/submissions/{id}`, not the
/// address asked for, which would make a series per id).
pub fn http_request(method: &str, route: &str, status: u16, secs: f64) {
    let labels = [
        ("method", method.to_string()),
        ("route", route.to_string()),
        ("status", status.to_string()),
    ];
    counter!(HTTP_REQUESTS, &labels).increment(1);
    histogram!(HTTP_DURATION, &labels).record(secs);
}
