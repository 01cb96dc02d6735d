//! Crash recovery: a server killed with SIGKILL in the middle of an evaluation takes the job up
//! again when it restarts, finishing it once, with the scores `poseboard eval` gives and no
//! submission lost or duplicated. Leases and the queue live in the database, so this runs on
//! both.

use crate::common;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    BIN, Db, TestDb, both_databases, cli_report, get_json, start, upload, wait_done,
};
use serde_json::Value;

/// Kills the server with SIGKILL while it evaluates, starts it again, and checks that the
/// job finishes with the scores `poseboard eval` gives, once.
fn crash_and_resume(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = dir.path().join("datasets");
    // A dataset large enough that one evaluation takes a few seconds on one thread.
    let status = Command::new(BIN)
        .args([
            "dataset",
            "synth",
            "--scenes",
            "20",
            "--images-per-scene",
            "10",
        ])
        .arg(datasets.join("synthbig"))
        .stdout(Stdio::null())
        .status()
        .expect("synth runs");
    assert!(status.success());
    let results_dir = dir.path().join("results");
    let status = Command::new(BIN)
        .args(["dataset", "demo-results"])
        .arg(datasets.join("synthbig"))
        .arg(&results_dir)
        .stdout(Stdio::null())
        .status()
        .expect("demo-results runs");
    assert!(status.success());
    let file = std::fs::read_dir(&results_dir)
        .expect("results")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().contains("noisy"))
        .expect("a noisy demo result");

    let db = TestDb::new(kind, "crash");
    let data = dir.path().join("data");
    let args = ["--eval-threads", "1"];
    let id;
    {
        let server = start(&data, &datasets, &db, &args);
        let r = upload(&server, "crashy", "synthbig", &file, None);
        assert_eq!(r.status(), 202);
        id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
        // Wait until a worker has claimed the job (it evaluates from then on), then kill the
        // server hard.
        let start_wait = Instant::now();
        loop {
            let s = get_json(&format!("{}/api/v1/submissions/{id}", server.base));
            if s["status"] == "running" {
                break;
            }
            assert_ne!(
                s["status"], "done",
                "{kind:?}: finished before it could be killed; make the dataset larger"
            );
            assert!(
                start_wait.elapsed() < Duration::from_secs(60),
                "{kind:?}: never ran: {s}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut server = server;
        server.child.kill().expect("SIGKILL");
        server.child.wait().expect("reaped");
    }
    let server = start(&data, &datasets, &db, &args);
    let done = wait_done(&server.base, id, Duration::from_secs(120));
    assert_eq!(done["attempts"], 2, "{kind:?}: taken up again exactly once");
    let want = cli_report(&datasets.join("synthbig"), &file, "bop19");
    assert_eq!(
        done["scores"]["bop19"]["bop19_average_recall"],
        want["bop19_average_recall"]
    );
    let board = get_json(&format!(
        "{}/api/v1/leaderboards/bop19?dataset=synthbig",
        server.base
    ));
    assert_eq!(
        board["rows"].as_array().map(Vec::len),
        Some(1),
        "one score set"
    );
    let listed = get_json(&format!("{}/api/v1/submissions", server.base));
    assert_eq!(
        listed["submissions"].as_array().map(Vec::len),
        Some(1),
        "no submission lost or duplicated"
    );
}
both_databases!(crash_and_resume);

/// A `serve` whose port is taken exits before it starts its workers: a queued job is left
/// alone (not claimed, no attempt spent) for the servers that run.
fn a_server_that_cannot_bind_claims_no_job(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = common::reference_datasets(dir.path());
    let db = TestDb::new(kind, "nobind");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = common::fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "queued", "synthA", &file, None);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(60));
    drop(server);
    // The job queued again, with no server running, and its port held by someone else.
    common::column(
        &db,
        &data,
        "UPDATE submissions SET status = 'queued', attempts = 0, lease_until = NULL",
    );
    let holder = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let taken = holder.local_addr().expect("address").to_string();
    let mut cmd = Command::new(BIN);
    cmd.args(["serve", "--bind", &taken, "--workers", "1"])
        .arg("--data-dir")
        .arg(&data)
        .arg("--datasets")
        .arg(&datasets)
        .env_remove("DATABASE_URL")
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    if let Some(url) = db.url() {
        cmd.env("DATABASE_URL", url);
    }
    let status = cmd.status().expect("serve runs");
    assert!(!status.success(), "{kind:?}: bound a taken port");
    let attempts = common::column(
        &db,
        &data,
        "SELECT CAST(attempts AS TEXT) || ' ' || status FROM submissions",
    );
    assert_eq!(attempts, ["0 queued"], "{kind:?}");
}
both_databases!(a_server_that_cannot_bind_claims_no_job);
