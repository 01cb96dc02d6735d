//! `poseboard submit` run as a researcher runs it, against the real server: it prints the
//! scores `poseboard eval` prints for the same file (and the final submission as JSON on its
//! last line), refuses a malformed file before uploading anything, and fails with the server's
//! own message when the server refuses. One database is enough here: the CLI only speaks HTTP,
//! and the store is tested on both elsewhere.

mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};

use common::{
    BIN, Db, Server, TestDb, cli_report, client, column, fixtures, get_as, reference_datasets,
    start,
};
use serde_json::Value;

/// `poseboard submit FILE` for the method `cli` on `synthA`, with `extra` arguments; the token
/// comes from the environment like a script's would.
fn submit(server: &Server, token: &str, file: &Path, extra: &[&str]) -> Output {
    Command::new(BIN)
        .arg("submit")
        .arg(file)
        .args(["--method", "cli", "--dataset", "synthA"])
        .args(extra)
        .env("POSEBOARD_SERVER", &server.base)
        .env("POSEBOARD_TOKEN", token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs")
}

/// What `poseboard eval` prints on stdout for a file.
fn eval_stdout(dataset: &Path, file: &Path, protocol: &str) -> String {
    let out = Command::new(BIN)
        .args(["eval", "--protocol", protocol, "--threads", "1"])
        .arg("--dataset")
        .arg(dataset)
        .arg("--results")
        .arg(file)
        .output()
        .expect("poseboard eval runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

fn submissions_in_database(db: &TestDb, data: &Path) -> String {
    column(db, data, "SELECT CAST(COUNT(*) AS TEXT) FROM submissions").concat()
}

#[test]
fn submit_prints_the_scores_eval_prints() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/noisemedium_synthA-test.csv");

    let out = submit(&server, &server.token, &file, &["--json"]);
    let stdout = String::from_utf8(out.stdout).expect("utf-8");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "submit failed: {stderr}");

    // The tables, as `poseboard eval` prints them on the same file and dataset.
    let synth_a = datasets.join("synthA");
    for protocol in ["bop19", "eccv18"] {
        let table = eval_stdout(&synth_a, &file, protocol);
        assert!(
            stdout.contains(&table),
            "submit's output lacks eval's {protocol} table:\n{table}\n--- submit printed:\n{stdout}"
        );
    }

    // The last line is the submission as the server has it, with its id and scores.
    let last = stdout.lines().last().expect("a last line");
    let printed: Value = serde_json::from_str(last).expect("the last line is JSON");
    let id = printed["id"].as_i64().expect("an id");
    assert_eq!(printed["status"], "done");
    let on_server: Value = get_as(
        &format!("{}/api/v1/submissions/{id}", server.base),
        &server.token,
    )
    .json()
    .expect("json");
    assert_eq!(printed["scores"], on_server["scores"]);
    for protocol in ["bop19", "eccv18"] {
        let report = cli_report(&synth_a, &file, protocol);
        for key in [
            "bop19_average_recall",
            "bop19_average_recall_vsd",
            "bop19_average_recall_mssd",
            "bop19_average_recall_mspd",
            "obj_average_recalls",
            "localization",
        ] {
            assert_eq!(
                printed["scores"][protocol][key], report[key],
                "{protocol} {key}"
            );
        }
    }
}

#[test]
fn a_malformed_file_is_refused_before_any_upload() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    for (file, message) in [
        (
            "wrong-columns_synthA-test.csv",
            "line 6 has 6 fields, expected 7",
        ),
        ("nan_synthA-test.csv", "non-finite number on line 4"),
        (
            "not-rotation_synthA-test.csv",
            "R on line 5 is not a rotation matrix",
        ),
        ("bad-header_synthA-test.csv", "bad header on line 1"),
    ] {
        let path = fixtures().join("results/malformed").join(file);
        let out = submit(&server, &server.token, &path, &["--json"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{file} was accepted");
        assert!(stderr.contains(message), "{file}: {stderr}");
        assert!(out.stdout.is_empty(), "{file}: printed a submission");
    }
    assert_eq!(submissions_in_database(&db, &data), "0");
    // The request traces name every request the server saw (the one made below as well): no
    // upload among them.
    let traced = |method: &str, path: &str| {
        std::fs::read_to_string(data.join("server.log"))
            .expect("server log")
            .lines()
            .any(|l| l.contains(method) && l.contains(path))
    };
    assert!(
        !traced("POST", "/api/v1/submissions"),
        "an upload reached the server"
    );
    get_as(&format!("{}/api/v1/datasets", server.base), "");
    assert!(traced("GET", "/api/v1/datasets"), "requests are not traced");
}

#[test]
fn a_refused_upload_fails_with_the_servers_message() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "submit_cli");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let file = fixtures().join("results/noisesmall_synthA-test.csv");

    // What the server says to a token it does not know.
    let said: Value = client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth("not-a-token")
        .send()
        .expect("answered")
        .json()
        .expect("a JSON error");
    let message = said["error"].as_str().expect("a message");
    let out = submit(&server, "not-a-token", &file, &["--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains(message), "{stderr}");
    assert!(stderr.contains("401"), "{stderr}");

    // A dataset the server does not serve: refused by the server, with its reason.
    let out = Command::new(BIN)
        .arg("submit")
        .arg(&file)
        .args(["--method", "cli", "--dataset", "nosuch"])
        .args(["--server", &server.base, "--token", &server.token])
        .env_remove("POSEBOARD_SERVER")
        .env_remove("POSEBOARD_TOKEN")
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("the server answered 4"), "{stderr}");
    assert_eq!(submissions_in_database(&db, &data), "0");

    // No server at all.
    let out = Command::new(BIN)
        .arg("submit")
        .arg(&file)
        .args(["--method", "cli", "--dataset", "synthA"])
        .args(["--server", "http://127.0.0.1:9", "--token", "t"])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("cannot upload to http://127.0.0.1:9"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
