//! Moving house: a SQLite installation populated through the real service (accounts, tokens,
//! public, private and hidden submissions with their scores, the audit log, rate counters) is
//! copied by `poseboard copy-db` into an empty PostgreSQL database; a server on the copy shows
//! the same boards and submission pages, lets the same user sign in with the same password and
//! accepts the same API tokens, and gives a new upload the next id. A filled target is refused
//! without `--force`; and the copy goes back from PostgreSQL into a new SQLite file.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use crate::common::{
    BIN, Db, TestDb, admin, browser, column, fixtures, get_as, post_as, reference_datasets, start,
    upload, upload_with, wait_done,
};
use serde_json::Value;

fn copy_db(from: &str, to: &str, force: bool) -> std::process::Output {
    let mut cmd = Command::new(BIN);
    cmd.args(["copy-db", "--from", from, "--to", to]);
    if force {
        cmd.arg("--force");
    }
    cmd.output().expect("copy-db runs")
}

/// Everything a visitor and an administrator see, as JSON, keyed by address.
pub(crate) fn views(base: &str, admin_token: &str, ids: &[i64]) -> Vec<(String, Value)> {
    let mut paths: Vec<String> = [
        "/api/v1/leaderboards/bop19",
        "/api/v1/leaderboards/eccv18",
        "/api/v1/leaderboards/bop19?dataset=synthA",
        "/api/v1/leaderboards/eccv18?dataset=synthA",
        "/api/v1/methods",
        "/api/v1/submissions",
        "/api/v1/datasets",
        "/api/v1/admin/audit",
    ]
    .iter()
    .map(|p| p.to_string())
    .collect();
    paths.extend(ids.iter().map(|id| format!("/api/v1/submissions/{id}")));
    paths
        .into_iter()
        .map(|p| {
            let r = get_as(&format!("{base}{p}"), admin_token);
            assert!(r.status().is_success(), "{p}: {}", r.status());
            let mut view: Value = r.json().expect("JSON");
            // How far each host has prepared the datasets is that host's, not the
            // installation's: a moved installation prepares them again where it now runs.
            if p == "/api/v1/datasets" {
                for dataset in view["datasets"].as_array_mut().expect("datasets") {
                    dataset
                        .as_object_mut()
                        .expect("a dataset")
                        .remove("prepared");
                }
            }
            (p, view)
        })
        .collect()
}

/// Gives a new data directory the password files `common::account` looks for (so it does not
/// create the accounts again) and the uploaded files, as the README says to move them.
pub(crate) fn move_data_dir(from: &Path, to: &Path) {
    // Only the password files the test wrote: the uploads travel inside the database.
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("data dir") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "pw") {
            std::fs::copy(&path, to.join(path.file_name().expect("name"))).expect("copy");
        }
    }
}

/// Polls a private submission as its owner until it is done.
fn wait_private(base: &str, id: i64, token: &str) {
    let start = std::time::Instant::now();
    loop {
        let s: Value = get_as(&format!("{base}/api/v1/submissions/{id}"), token)
            .json()
            .expect("JSON");
        match s["status"].as_str() {
            Some("done") => return,
            Some("failed") => panic!("submission {id} failed: {s}"),
            _ => {}
        }
        assert!(start.elapsed() < Duration::from_secs(120), "not done: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn sign_in(base: &str, name: &str, password: &str) -> u16 {
    reqwest::blocking::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .expect("client")
        .post(format!("{base}/login"))
        .form(&[("name", name), ("password", password)])
        .send()
        .expect("sign-in")
        .status()
        .as_u16()
}

#[test]
fn a_sqlite_installation_moves_to_postgresql_and_back() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let sqlite = TestDb::new(Db::Sqlite, "copy_source");
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).expect("mkdir");
    std::fs::write(data.join("root.pw"), "root-secret-password\n").expect("pw");
    let root_pw = data.join("root.pw");
    admin(
        &data,
        &sqlite,
        &[
            "create-user",
            "root",
            "--password-file",
            root_pw.to_str().expect("path"),
            "--admin",
        ],
    );
    let root = admin(&data, &sqlite, &["create-token", "root"]);

    // Populate through the service: uploads public and private, by two accounts, one hidden.
    let server = start(&data, &datasets, &sqlite, &[]);
    let base = server.base.clone();
    let _alice_browser = browser(&server, "alice");
    let alice = admin(&data, &sqlite, &["create-token", "alice"]);
    let result = |name: &str| fixtures().join(format!("results/{name}_synthA-test.csv"));
    let mut ids = Vec::new();
    for name in ["noisesmall", "noisemedium"] {
        let r = upload(&server, name, "synthA", &result(name), None);
        assert_eq!(r.status(), 202);
        ids.push(r.json::<Value>().expect("json")["id"].as_i64().expect("id"));
    }
    let private = upload_with(
        &server,
        &alice,
        &[
            ("method", "alices"),
            ("dataset", "synthA"),
            ("visibility", "private"),
        ],
        &result("gtexact"),
    );
    assert_eq!(private.status(), 202);
    let private = private.json::<Value>().expect("json")["id"]
        .as_i64()
        .expect("id");
    ids.push(private);
    for id in &ids[..2] {
        wait_done(&base, *id, Duration::from_secs(120));
    }
    wait_private(&base, private, &alice);
    let hide = post_as(
        &format!("{base}/api/v1/admin/submissions/{}/hide", ids[1]),
        &root,
        None,
    );
    assert!(hide.status().is_success());
    // A failed sign-in leaves rate counters behind.
    assert_eq!(sign_in(&base, "alice", "not her password"), 401);
    let before = views(&base, &root, &ids);
    drop(server);

    // Copy into an empty PostgreSQL database, and start a server on it.
    let pg = TestDb::new(Db::Postgres, "copy_target");
    let pg_url = pg.url().expect("PostgreSQL");
    let source_url = format!("sqlite://{}", data.join("poseboard.db").display());
    let out = copy_db(&source_url, &pg_url, false);
    assert!(
        out.status.success(),
        "copy-db: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = String::from_utf8_lossy(&out.stdout);
    assert!(printed.contains("submissions  3 rows"), "{printed}");
    assert!(
        printed.contains("uploaded result files included"),
        "{printed}"
    );
    let files = |db: &TestDb, dir: &Path| {
        column(
            db,
            dir,
            "SELECT sha256 || ':' || CAST(size AS TEXT) FROM submission_files ORDER BY sha256",
        )
    };
    assert!(!files(&sqlite, &data).is_empty());
    assert_eq!(files(&sqlite, &data), files(&pg, &data), "uploaded files");
    for table in [
        "users",
        "api_tokens",
        "scores",
        "audit_log",
        "rate_counters",
    ] {
        let count = |db: &TestDb, dir: &Path| {
            column(
                db,
                dir,
                &format!("SELECT CAST(COUNT(*) AS TEXT) FROM {table}"),
            )
        };
        assert_eq!(count(&sqlite, &data), count(&pg, &data), "{table}");
    }
    let data2 = dir.path().join("data2");
    move_data_dir(&data, &data2);
    let server = start(&data2, &datasets, &pg, &[]);
    let base = server.base.clone();
    let after = views(&base, &root, &ids);
    for ((path, a), (_, b)) in before.iter().zip(&after) {
        assert_eq!(a, b, "{path} differs after the copy");
    }

    // The same password signs in, the same token works (on a private submission), and the
    // next upload continues after the copied ids.
    assert_eq!(sign_in(&base, "alice", "correct horse battery"), 303);
    assert_eq!(sign_in(&base, "alice", "wrong horse battery"), 401);
    let url = format!("{base}/api/v1/submissions/{private}");
    assert_eq!(get_as(&url, &alice).status(), 200);
    assert_eq!(get_as(&url, "").status(), 404);
    let r = upload(&server, "symflip", "synthA", &result("symflip"), None);
    assert_eq!(r.status(), 202, "{}", r.text().unwrap_or_default());
    let new = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    assert_eq!(new, ids.iter().max().expect("ids") + 1);
    wait_done(&base, new, Duration::from_secs(120));
    let hidden = post_as(
        &format!("{base}/api/v1/admin/submissions/{new}/hide"),
        &root,
        None,
    );
    assert!(hidden.status().is_success(), "audit ids continue too");
    drop(server);

    // A target with data is refused, and replaced with --force.
    let refused = copy_db(&source_url, &pg_url, false);
    assert!(!refused.status.success());
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("not empty"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );
    assert_eq!(
        column(
            &pg,
            &data2,
            "SELECT CAST(COUNT(*) AS TEXT) FROM submissions"
        ),
        ["4"],
        "a refused copy leaves the target as it was"
    );
    let forced = copy_db(&source_url, &pg_url, true);
    assert!(
        forced.status.success(),
        "{}",
        String::from_utf8_lossy(&forced.stderr)
    );
    assert_eq!(
        column(
            &pg,
            &data2,
            "SELECT CAST(COUNT(*) AS TEXT) FROM submissions"
        ),
        ["3"]
    );

    // And back: PostgreSQL into a new SQLite file, with the same boards.
    let data3 = dir.path().join("data3");
    move_data_dir(&data, &data3);
    let back = format!("sqlite://{}?mode=rwc", data3.join("poseboard.db").display());
    let out = copy_db(&pg_url, &back, false);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let server = start(&data3, &datasets, &TestDb::new(Db::Sqlite, "back"), &[]);
    let again = views(&server.base, &root, &ids);
    for ((path, a), (_, b)) in before.iter().zip(&again) {
        assert_eq!(a, b, "{path} differs after the copy back");
    }
    assert_eq!(sign_in(&server.base, "alice", "correct horse battery"), 303);
}
