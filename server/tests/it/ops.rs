//! Operations over real HTTP on both databases: `/healthz` and `/readyz` answer 200 on a
//! healthy server; `/readyz` answers 503 naming what is not ready (a migration applied by a
//! newer version, one that failed half-way, a served dataset whose folder is gone, on
//! PostgreSQL a database that refuses connections); `/metrics` counts the jobs the test ran and
//! reads the queue from the database; logs come as JSON lines with a span per job; a worker
//! serves the same endpoints; with no worker running, a queued submission promises no ETA and
//! the age of the newest worker beat is exposed.

use crate::common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    BIN, Db, TestDb, admin_url, both_databases, client, execute, fixtures, get_json, pg_exec,
    reference_datasets, start, upload, wait_done,
};
use serde_json::Value;

/// The samples of a Prometheus exposition: (name, labels) -> value.
fn samples(text: &str) -> BTreeMap<(String, BTreeSet<(String, String)>), f64> {
    let mut out = BTreeMap::new();
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let (series, value) = line.rsplit_once(' ').expect("series and value");
        let (name, labels) = match series.split_once('{') {
            Some((name, rest)) => (name, rest.strip_suffix('}').expect("closing brace")),
            None => (series, ""),
        };
        let labels: BTreeSet<(String, String)> = labels
            .split("\",")
            .filter(|l| !l.is_empty())
            .map(|l| {
                let (k, v) = l.split_once("=\"").expect("label=\"value\"");
                (k.to_string(), v.trim_end_matches('"').to_string())
            })
            .collect();
        let value: f64 = value.parse().expect("a number");
        assert!(
            out.insert((name.to_string(), labels), value).is_none(),
            "one sample per series: {line}"
        );
    }
    out
}

/// The value of one series (`labels` exactly), if present.
fn sample(text: &str, name: &str, labels: &[(&str, &str)]) -> Option<f64> {
    let want: BTreeSet<(String, String)> = labels
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    samples(text).get(&(name.to_string(), want)).copied()
}

fn scrape(base: &str) -> String {
    let r = client()
        .get(format!("{base}/metrics"))
        .send()
        .expect("metrics");
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .expect("type")
            .starts_with("text/plain")
    );
    r.text().expect("text")
}

/// GETs `/readyz`: its status and body.
fn readyz(base: &str) -> (u16, Value) {
    let r = client()
        .get(format!("{base}/readyz"))
        .send()
        .expect("readyz");
    let status = r.status().as_u16();
    (status, r.json().expect("JSON"))
}

/// Polls `/readyz` until it answers `status` (the pool notices a change on its next use).
fn readyz_becomes(base: &str, status: u16) -> Value {
    let start = Instant::now();
    loop {
        let (s, body) = readyz(base);
        if s == status {
            return body;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "readyz stays {s}: {body}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn not_ready_checks(body: &Value) -> Vec<String> {
    body["not_ready"]
        .as_array()
        .expect("not_ready")
        .iter()
        .map(|c| c["check"].as_str().expect("check").to_string())
        .collect()
}

fn health_readiness_and_job_metrics(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "ops");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &["--log-format", "json"]);
    let base = server.base.clone();

    let health = client()
        .get(format!("{base}/healthz"))
        .send()
        .expect("healthz");
    assert_eq!(health.status(), 200);
    let (status, body) = readyz(&base);
    assert_eq!(status, 200, "{kind:?}: {body}");
    assert_eq!(body["ready"], true);

    // Before any job: every job counter exists at 0, the queue is empty.
    let before = scrape(&base);
    for name in [
        "poseboard_jobs_started_total",
        "poseboard_jobs_done_total",
        "poseboard_jobs_failed_total",
        "poseboard_jobs_retried_total",
        "poseboard_estimates_evaluated_total",
    ] {
        assert_eq!(sample(&before, name, &[]), Some(0.0), "{kind:?}: {name}");
    }
    assert_eq!(
        sample(&before, "poseboard_queue_depth", &[("state", "queued")]),
        Some(0.0)
    );

    let files = ["noisesmall", "noisemedium", "gtexact"];
    let mut ids = Vec::new();
    for name in files {
        let file = fixtures().join(format!("results/{name}_synthA-test.csv"));
        let r = upload(&server, name, "synthA", &file, None);
        assert_eq!(r.status(), 202, "{kind:?}");
        ids.push(r.json::<Value>().expect("json")["id"].as_i64().expect("id"));
    }
    let mut estimates = 0;
    for id in &ids {
        let done = wait_done(&base, *id, Duration::from_secs(120));
        for (_, score) in done["scores"].as_object().expect("scores") {
            estimates += score["estimates_evaluated"].as_u64().expect("evaluated");
        }
    }
    assert!(estimates > 0);
    let missing = client()
        .get(format!("{base}/no/such/page"))
        .send()
        .expect("answered");
    assert_eq!(missing.status(), 404);

    let text = scrape(&base);
    let n = files.len() as f64;
    let value = |name: &str, labels: &[(&str, &str)]| {
        sample(&text, name, labels).unwrap_or_else(|| panic!("{kind:?}: no {name} {labels:?}"))
    };
    assert_eq!(value("poseboard_jobs_started_total", &[]), n, "{kind:?}");
    assert_eq!(value("poseboard_jobs_done_total", &[]), n);
    assert_eq!(value("poseboard_jobs_failed_total", &[]), 0.0);
    assert_eq!(value("poseboard_jobs_retried_total", &[]), 0.0);
    assert_eq!(
        value("poseboard_estimates_evaluated_total", &[]),
        estimates as f64
    );
    assert_eq!(
        value(
            "poseboard_job_duration_seconds_count",
            &[("outcome", "done")]
        ),
        n
    );
    assert!(value("poseboard_job_duration_seconds_sum", &[("outcome", "done")]) > 0.0);
    for (state, count) in [
        ("queued", 0.0),
        ("running", 0.0),
        ("done", n),
        ("failed", 0.0),
    ] {
        assert_eq!(
            value("poseboard_queue_depth", &[("state", state)]),
            count,
            "{kind:?}: {state}"
        );
    }
    // Requests by route template, method and status, with their latencies.
    let upload_labels = [
        ("method", "POST"),
        ("route", "/api/v1/submissions"),
        ("status", "202"),
    ];
    assert_eq!(value("poseboard_http_requests_total", &upload_labels), n);
    assert_eq!(
        value(
            "poseboard_http_request_duration_seconds_count",
            &upload_labels
        ),
        n
    );
    let polled = [
        ("method", "GET"),
        ("route", "/api/v1/submissions/{id}"),
        ("status", "200"),
    ];
    assert!(value("poseboard_http_requests_total", &polled) >= n);
    assert_eq!(
        value(
            "poseboard_http_requests_total",
            &[("method", "GET"), ("route", "unmatched"), ("status", "404")]
        ),
        1.0
    );
    assert!(
        !text.contains(&format!("route=\"/api/v1/submissions/{}\"", ids[0])),
        "no series per address"
    );

    // JSON logs, one object per line, with the job's span and its submission.
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    let lines: Vec<Value> = log
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    for id in &ids {
        assert!(
            lines
                .iter()
                .any(|l| l["span"]["name"] == "job" && l["span"]["submission"] == *id),
            "{kind:?}: no log line in the span of job {id}"
        );
    }
    assert!(
        lines.iter().any(|l| l["span"]["name"] == "request"),
        "request spans"
    );

    // A worker serves the same endpoints on --metrics-bind; its counters are its own, the
    // queue is the database's.
    let (mut worker, worker_base) = start_worker(&data, &datasets, &db);
    let health = client()
        .get(format!("{worker_base}/healthz"))
        .send()
        .expect("healthz");
    assert_eq!(health.status(), 200);
    assert_eq!(readyz(&worker_base).0, 200);
    let text = scrape(&worker_base);
    assert_eq!(
        sample(&text, "poseboard_queue_depth", &[("state", "done")]),
        Some(n)
    );
    assert_eq!(
        sample(&text, "poseboard_jobs_started_total", &[]),
        Some(0.0)
    );
    let _ = worker.kill();
    let _ = worker.wait();
}
both_databases!(health_readiness_and_job_metrics);

/// Starts `poseboard worker --metrics-bind 127.0.0.1:0` and reads the address it prints.
fn start_worker(data: &Path, datasets: &Path, db: &TestDb) -> (Child, String) {
    let mut cmd = Command::new(BIN);
    cmd.args(["worker", "--metrics-bind", "127.0.0.1:0"])
        .arg("--data-dir")
        .arg(data.join("worker"))
        .arg("--datasets")
        .arg(datasets)
        .env_remove("DATABASE_URL")
        .env("DATABASE_URL", common::database_url(db, data))
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let mut child = cmd.spawn().expect("worker starts");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let line = lines.next().expect("an address").expect("stdout");
    let base = line
        .strip_prefix("poseboard worker metrics on ")
        .unwrap_or_else(|| panic!("unexpected first line: {line}"))
        .to_string();
    std::thread::spawn(move || for _ in lines {});
    (child, base)
}

fn readiness_names_what_is_missing(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "ready");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    assert_eq!(readyz(&base).0, 200, "{kind:?}");

    // A newer version of poseboard migrated the shared database: this one is out of date.
    let checksum = match kind {
        Db::Sqlite => "X'00'",
        Db::Postgres => "decode('00', 'hex')",
    };
    execute(
        &db,
        &data,
        &format!(
            "INSERT INTO _sqlx_migrations (version, description, success, checksum, \
             execution_time) VALUES (99990101000000, 'from a newer poseboard', true, {checksum}, 0)"
        ),
    );
    let (status, body) = readyz(&base);
    assert_eq!(status, 503, "{kind:?}: {body}");
    assert_eq!(body["ready"], false);
    assert_eq!(not_ready_checks(&body), ["migrations"]);
    assert!(
        body["not_ready"][0]["reason"]
            .as_str()
            .expect("reason")
            .contains("99990101000000"),
        "{body}"
    );
    assert_eq!(
        client()
            .get(format!("{base}/healthz"))
            .send()
            .expect("healthz")
            .status(),
        200,
        "alive all the same"
    );
    execute(
        &db,
        &data,
        "DELETE FROM _sqlx_migrations WHERE version = 99990101000000",
    );
    assert_eq!(readyz(&base).0, 200);

    // The latest migration failed half-way (sqlx records it unsuccessful): it is pending.
    let latest = "(SELECT MAX(version) FROM _sqlx_migrations)";
    execute(
        &db,
        &data,
        &format!("UPDATE _sqlx_migrations SET success = false WHERE version = {latest}"),
    );
    let (status, body) = readyz(&base);
    assert_eq!(status, 503, "{kind:?}: {body}");
    assert_eq!(not_ready_checks(&body), ["migrations"]);
    assert!(
        body["not_ready"][0]["reason"]
            .as_str()
            .expect("reason")
            .contains("not applied"),
        "{body}"
    );
    execute(
        &db,
        &data,
        "UPDATE _sqlx_migrations SET success = true WHERE success = false",
    );
    assert_eq!(readyz(&base).0, 200);

    if let (Db::Postgres, Some(url)) = (kind, db.url()) {
        // The database refuses every connection: not ready, until it takes them again.
        let name = url.rsplit('/').next().expect("database name").to_string();
        pg_exec(
            &admin_url(),
            &format!("ALTER DATABASE {name} ALLOW_CONNECTIONS false"),
        );
        pg_exec(
            &admin_url(),
            &format!(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = '{name}'"
            ),
        );
        let body = readyz_becomes(&base, 503);
        assert_eq!(not_ready_checks(&body), ["database"], "{body}");
        pg_exec(
            &admin_url(),
            &format!("ALTER DATABASE {name} ALLOW_CONNECTIONS true"),
        );
        readyz_becomes(&base, 200);
    }

    // Restarted with a served dataset's folder gone (an unmounted volume, say).
    drop(server);
    std::fs::remove_file(datasets.join("synthA")).expect("unlink the dataset");
    let server = start(&data, &datasets, &db, &[]);
    let (status, body) = readyz(&server.base);
    assert_eq!(status, 503, "{kind:?}: {body}");
    assert_eq!(not_ready_checks(&body), ["datasets"]);
    assert!(
        body["not_ready"][0]["reason"]
            .as_str()
            .expect("reason")
            .contains("synthA"),
        "{body}"
    );
    assert!(get_json(&format!("{}/healthz", server.base))["status"] == "ok");
}
both_databases!(readiness_names_what_is_missing);

/// The wait is honest: with no evaluation worker (`serve --workers 0`, none elsewhere) a queued
/// submission is promised no ETA; its page and its JSON say that no worker runs and that the
/// submission is queued and safe, and `/metrics` gives the age of the newest worker beat (+Inf:
/// none ever beat). Once a worker starts on the same database it beats, takes the job, and the
/// age becomes that of a real beat.
fn no_worker_means_an_honest_wait(kind: Db) {
    const NO_WORKER: &str = "no evaluation worker is running; your submission is queued and safe";
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "noworker");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &["--workers", "0"]);
    let base = server.base.clone();
    let age = |text: &str| sample(text, "poseboard_worker_heartbeat_age_seconds", &[]);
    assert_eq!(age(&scrape(&base)), Some(f64::INFINITY), "{kind:?}");

    let r = upload(
        &server,
        "patient-net",
        "synthA",
        &fixtures().join("results/noisesmall_synthA-test.csv"),
        None,
    );
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let s = get_json(&format!("{base}/api/v1/submissions/{id}"));
    assert_eq!(s["status"], "queued", "{kind:?}: {s}");
    assert_eq!(s["progress_text"], NO_WORKER, "{kind:?}: {s}");
    assert_eq!(s["no_worker"], true, "{kind:?}: {s}");
    assert!(s["eta_seconds"].is_null(), "{kind:?}: {s}");
    let page = client()
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains(NO_WORKER), "{kind:?}: {page}");
    assert!(!page.contains("scores expected"), "{kind:?}: {page}");
    assert_eq!(age(&scrape(&base)), Some(f64::INFINITY), "{kind:?}");

    // A worker on the same database beats and evaluates the waiting submission.
    let (mut worker, _) = start_worker(&data, &datasets, &db);
    let done = wait_done(&base, id, Duration::from_secs(120));
    assert_eq!(done["no_worker"], false, "{kind:?}: {done}");
    assert!(done["progress_text"].is_null(), "{kind:?}: {done}");
    let seen = age(&scrape(&base)).expect("the age of the newest beat");
    assert!(seen.is_finite() && seen >= 0.0, "{kind:?}: {seen}");
    let _ = worker.kill();
    let _ = worker.wait();
}
both_databases!(no_worker_means_an_honest_wait);
