//! Scale-out against real PostgreSQL: `poseboard worker` processes that share nothing with the
//! server but the database (each with a data directory of its own, holding only its prepared
//! datasets, and its own copy of the datasets) evaluate the queue, each job once and with
//! `poseboard eval`'s scores, through worker crashes, a worker whose dataset copy differs,
//! every connection of the database being terminated, and SIGTERM/SIGINT; and `serve --workers
//! 0` evaluates nothing.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{BIN, Db, TestDb, both_databases, cli_report, start, upload_with};
use serde_json::Value;

/// Writes a synthetic dataset `name` into `dir` and returns its folder.
fn synth(dir: &Path, name: &str, scenes: u32, images: u32) -> PathBuf {
    let folder = dir.join(name);
    let status = Command::new(BIN)
        .args(["dataset", "synth", "--scenes"])
        .arg(scenes.to_string())
        .arg("--images-per-scene")
        .arg(images.to_string())
        .arg(&folder)
        .stdout(Stdio::null())
        .status()
        .expect("synth runs");
    assert!(status.success());
    folder
}

/// The demo result files of a dataset (precise, noisy, rough), sorted.
fn demo_results(dataset: &Path, out: &Path) -> Vec<PathBuf> {
    let status = Command::new(BIN)
        .args(["dataset", "demo-results"])
        .arg(dataset)
        .arg(out)
        .stdout(Stdio::null())
        .status()
        .expect("demo-results runs");
    assert!(status.success());
    let mut files: Vec<PathBuf> = std::fs::read_dir(out)
        .expect("results")
        .map(|e| e.expect("entry").path())
        .collect();
    files.sort();
    files
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("folder") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

/// A `poseboard` process killed when this goes away.
struct Proc {
    child: Child,
    log: PathBuf,
}

/// Sends signal `name` (TERM, INT) to process `pid`.
fn signal(pid: u32, name: &str) {
    let status = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .status()
        .expect("kill runs");
    assert!(status.success());
}

/// Waits for `child` to exit on its own, for at most `limit`.
fn exits_within(child: &mut Child, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if child.try_wait().expect("wait").is_some() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

impl Proc {
    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The worker id of this process's first worker, as the queue records it.
    fn worker_id(&self) -> String {
        format!("-{}-0", self.child.id())
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `poseboard worker` on the PostgreSQL database with its own datasets folder and data
/// directory (where it keeps nothing but its prepared datasets).
fn worker(db: &TestDb, datasets: &Path, data: &Path, log: &Path, lease_secs: u32) -> Proc {
    let child = Command::new(BIN)
        .args(["worker", "--eval-threads", "1", "--lease-secs"])
        .arg(lease_secs.to_string())
        .arg("--database-url")
        .arg(db.url().expect("PostgreSQL"))
        .arg("--datasets")
        .arg(datasets)
        .arg("--data-dir")
        .arg(data)
        .env_remove("DATABASE_URL")
        .env("RUST_LOG", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::from(std::fs::File::create(log).expect("log file")))
        .spawn()
        .expect("poseboard worker starts");
    Proc {
        child,
        log: log.to_path_buf(),
    }
}

/// Rows of one text column of the test database.
fn rows(db: &TestDb, data: &Path, sql: &str) -> Vec<String> {
    common::column(db, data, sql)
}

fn status_of(db: &TestDb, data: &Path, id: i64) -> String {
    rows(
        db,
        data,
        &format!(
            "SELECT status || ' ' || CAST(attempts AS TEXT) || ' ' || COALESCE(worker, '-') \
             FROM submissions WHERE id = {id}"
        ),
    )
    .remove(0)
}

/// Polls until `done` holds, panicking with `what` after `limit`.
fn wait_until(what: &str, limit: Duration, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(start.elapsed() < limit, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Uploads `file` for `method` (BOP'19 only) and returns the submission's id.
fn submit(server: &common::Server, method: &str, dataset: &str, file: &Path) -> i64 {
    let r = upload_with(
        server,
        &server.token,
        &[
            ("method", method),
            ("dataset", dataset),
            ("protocol", "bop19"),
        ],
        file,
    );
    assert_eq!(r.status(), 202, "upload of {method}");
    r.json::<Value>().expect("json")["id"].as_i64().expect("id")
}

/// The stored BOP'19 scores of a submission (one row per score set stored).
fn stored_scores(db: &TestDb, data: &Path, id: i64) -> Vec<Value> {
    rows(
        db,
        data,
        &format!("SELECT report_json FROM scores WHERE submission_id = {id}"),
    )
    .iter()
    .map(|j| serde_json::from_str::<Value>(j).expect("report"))
    .map(|r| r["bop19_average_recall"].clone())
    .collect()
}

/// The uploads of a job, taken by a server that then stops and loses its upload folder.
struct Queued {
    dir: tempfile::TempDir,
    db: TestDb,
    data: PathBuf,
    dataset: PathBuf,
    file: PathBuf,
    id: i64,
}

/// One job on a dataset large enough to evaluate for a moment on one thread, queued by a
/// server that is then stopped and whose upload folder is deleted.
fn one_queued_job(name: &str) -> Queued {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = dir.path().join("server-datasets");
    let dataset = synth(&datasets, "synthmid", 6, 6);
    let files = demo_results(&dataset, &dir.path().join("results"));
    let file = files
        .iter()
        .find(|p| p.to_string_lossy().contains("noisy"))
        .expect("a noisy result")
        .clone();
    let db = TestDb::new(Db::Postgres, name);
    let data = dir.path().join("server-data");
    let id = {
        let server = start(&data, &datasets, &db, &["--workers", "0"]);
        submit(&server, "mid", "synthmid", &file)
    };
    std::fs::remove_dir_all(data.join("submissions")).expect("upload folder");
    Queued {
        dir,
        db,
        data,
        dataset,
        file,
        id,
    }
}

impl Queued {
    /// A worker's own copy of the dataset.
    fn copy_for(&self, worker: &str) -> PathBuf {
        let datasets = self.dir.path().join(worker).join("datasets");
        copy_dir(&self.dataset, &datasets.join("synthmid"));
        datasets
    }

    fn start_worker(&self, name: &str, datasets: &Path, lease_secs: u32) -> Proc {
        let base = self.dir.path().join(name);
        std::fs::create_dir_all(&base).expect("mkdir");
        worker(
            &self.db,
            datasets,
            &base.join("data"),
            &base.join("worker.log"),
            lease_secs,
        )
    }

    fn status(&self) -> String {
        status_of(&self.db, &self.data, self.id)
    }

    fn wait_running(&self, by: &Proc) {
        wait_until("the job runs", Duration::from_secs(60), || {
            let s = self.status();
            assert!(
                !s.starts_with("done"),
                "finished too soon to be interrupted: {s}"
            );
            s.starts_with("running") && s.ends_with(&by.worker_id())
        });
    }

    fn wait_done(&self) -> String {
        wait_until("the job is done", Duration::from_secs(120), || {
            let s = self.status();
            assert!(!s.starts_with("failed"), "{s}");
            s.starts_with("done")
        });
        self.status()
    }

    /// The job has exactly one score set, equal to `poseboard eval`'s.
    fn check_scores(&self) {
        let want = cli_report(&self.dataset, &self.file, "bop19");
        assert_eq!(
            stored_scores(&self.db, &self.data, self.id),
            [want["bop19_average_recall"].clone()]
        );
    }
}

/// Three workers with data directories of their own evaluate 60 jobs queued by a server that is gone
/// with its upload folder: each job once, with `poseboard eval`'s scores.
#[test]
fn three_workers_share_the_queue_of_a_stopped_server() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = dir.path().join("server-datasets");
    let dataset = synth(&datasets, "synthS", 1, 2);
    let files = demo_results(&dataset, &dir.path().join("results"));
    let db = TestDb::new(Db::Postgres, "scale_three");
    let data = dir.path().join("server-data");
    let mut jobs = Vec::new();
    {
        let server = start(
            &data,
            &datasets,
            &db,
            &["--workers", "0", "--submissions-per-window", "0"],
        );
        for n in 0..60 {
            let file = &files[n % files.len()];
            jobs.push((submit(&server, &format!("m{n}"), "synthS", file), file));
        }
    }
    std::fs::remove_dir_all(data.join("submissions")).expect("upload folder");

    let workers: Vec<(Proc, PathBuf)> = (0..3)
        .map(|n| {
            let base = dir.path().join(format!("w{n}"));
            copy_dir(&dataset, &base.join("datasets/synthS"));
            let own_data = base.join("data");
            let proc = worker(
                &db,
                &base.join("datasets"),
                &own_data,
                &base.join("worker.log"),
                30,
            );
            (proc, own_data)
        })
        .collect();
    wait_until("every job is done", Duration::from_secs(180), || {
        rows(
            &db,
            &data,
            "SELECT CAST(COUNT(*) AS TEXT) FROM submissions WHERE status <> 'done'",
        ) == ["0"]
    });

    assert_eq!(
        rows(
            &db,
            &data,
            "SELECT CAST(attempts AS TEXT) FROM submissions GROUP BY attempts"
        ),
        ["1"],
        "each job evaluated once"
    );
    let busy = rows(&db, &data, "SELECT DISTINCT worker FROM submissions");
    assert!(busy.len() >= 2, "the workers shared the queue: {busy:?}");
    let mut want = std::collections::HashMap::new();
    for (id, file) in &jobs {
        let expected = want
            .entry(file.to_path_buf())
            .or_insert_with(|| cli_report(&dataset, file, "bop19")["bop19_average_recall"].clone());
        assert_eq!(
            stored_scores(&db, &data, *id),
            std::slice::from_ref(expected),
            "submission {id}"
        );
    }
    for (proc, own_data) in &workers {
        let written: Vec<String> = match std::fs::read_dir(own_data) {
            Ok(entries) => entries
                .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
                .collect(),
            Err(_) => Vec::new(),
        };
        assert!(
            written.iter().all(|name| name == "prepared"),
            "a worker wrote into its data directory more than its prepared datasets: {written:?}"
        );
        assert!(!proc.log().contains("ERROR"), "{}", proc.log());
    }
}

/// A worker killed with SIGKILL mid-job: a worker whose copy of the dataset differs (one depth
/// image changed) refuses the job without spending an attempt, and a worker with a right copy
/// finishes it with the same scores, once.
#[test]
fn a_killed_workers_job_goes_to_a_worker_with_the_right_dataset() {
    let q = one_queued_job("scale_kill");
    let good = q.copy_for("a");
    let mut a = q.start_worker("a", &good, 2);
    q.wait_running(&a);
    a.child.kill().expect("SIGKILL");
    a.child.wait().expect("reaped");

    let differing = q.copy_for("b");
    let depth = std::fs::read_dir(differing.join("synthmid/test/000001/depth"))
        .expect("depth folder")
        .next()
        .expect("a depth image")
        .expect("entry")
        .path();
    let mut bytes = std::fs::read(&depth).expect("png");
    bytes.push(0);
    std::fs::write(&depth, bytes).expect("changed png");
    let b = q.start_worker("b", &differing, 2);
    wait_until(
        "the worker with the differing copy refuses",
        Duration::from_secs(60),
        || {
            b.log()
                .contains("differs from the one the server registered")
        },
    );
    // Given back with the attempt it took returned: only the killed worker's attempt counts.
    wait_until(
        "the refused job is queued again",
        Duration::from_secs(10),
        || q.status() == "queued 1 -",
    );

    let c = q.start_worker("c", &q.copy_for("c"), 2);
    let done = q.wait_done();
    assert!(
        done.starts_with("done 2 ") && done.ends_with(&c.worker_id()),
        "done by the third worker after one lost attempt: {done}"
    );
    q.check_scores();
    assert!(b.log().contains("left to other workers"), "{}", b.log());
}

/// Every backend connection of the database terminated, again and again, while a job runs:
/// the job ends done once with the right scores, no attempt lost.
#[test]
fn terminated_connections_lose_nothing() {
    let q = one_queued_job("scale_terminate");
    let w = q.start_worker("w", &q.copy_for("w"), 10);
    q.wait_running(&w);
    let url = q.db.url().expect("PostgreSQL");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let terminated = rt.block_on(async {
        use sqlx::{Connection, Row};
        let mut conn = sqlx::PgConnection::connect(&url).await.expect("database");
        let mut terminated = 0;
        loop {
            let status: String = sqlx::query("SELECT status FROM submissions WHERE id = $1")
                .bind(q.id)
                .fetch_one(&mut conn)
                .await
                .expect("status")
                .get(0);
            if status != "running" {
                return terminated;
            }
            let n = sqlx::query(
                "SELECT pg_terminate_backend(pid) FROM pg_stat_activity \
                 WHERE datname = current_database() AND pid <> pg_backend_pid()",
            )
            .fetch_all(&mut conn)
            .await
            .expect("terminate")
            .len();
            terminated += n;
            tokio::time::sleep(Duration::from_millis(150)).await;
        }
    });
    assert!(terminated > 0, "no connection was terminated");
    let done = q.wait_done();
    assert!(done.starts_with("done 1 "), "{done}");
    q.check_scores();
}

/// SIGTERM to a worker and SIGINT to a server, each mid-job: the job is released at once
/// (queued, no attempt spent) or finished, never left running, and the process exits.
#[test]
fn a_signal_releases_the_running_job() {
    let q = one_queued_job("scale_signal");
    let mut w = q.start_worker("w", &q.copy_for("w"), 30);
    q.wait_running(&w);
    signal(w.child.id(), "TERM");
    assert!(
        exits_within(&mut w.child, Duration::from_secs(10)),
        "the worker did not exit"
    );
    let after = q.status();
    assert!(
        after == "queued 0 -" || after.starts_with("done 1 "),
        "released or finished, never left running: {after}"
    );
    assert!(w.log().contains("job released"), "{}", w.log());

    // The same with a server evaluating in its own process, stopped with SIGINT.
    let datasets = q.dataset.parent().expect("datasets").to_path_buf();
    let server = start(&q.data, &datasets, &q.db, &["--workers", "1"]);
    let mut server = server;
    let pid = server.child.id();
    wait_until("the server runs the job", Duration::from_secs(60), || {
        let s = q.status();
        s.starts_with("running") && s.ends_with(&format!("-{pid}-0"))
    });
    signal(pid, "INT");
    assert!(
        exits_within(&mut server.child, Duration::from_secs(10)),
        "the server did not exit"
    );
    let after = q.status();
    assert!(
        after == "queued 0 -" || after.starts_with("done 1 "),
        "released or finished, never left running: {after}"
    );

    let _w = q.start_worker("w2", &q.copy_for("w2"), 30);
    let done = q.wait_done();
    assert!(done.starts_with("done 1 "), "{done}");
    q.check_scores();
}

/// `serve --workers 0` takes uploads and evaluates nothing.
fn no_workers_no_evaluation(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = common::reference_datasets(dir.path());
    let db = TestDb::new(kind, "scale_noworkers");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &["--workers", "0"]);
    let file = common::fixtures().join("results/noisesmall_synthA-test.csv");
    let id = submit(&server, "waiting", "synthA", &file);
    // Longer than an idle worker's poll interval (2 s) and the job's evaluation together.
    std::thread::sleep(Duration::from_secs(4));
    assert_eq!(status_of(&db, &data, id), "queued 0 -", "{kind:?}");
    assert!(
        !std::fs::read_to_string(data.join("server.log"))
            .expect("log")
            .contains("worker started")
    );
}
both_databases!(no_workers_no_evaluation);
