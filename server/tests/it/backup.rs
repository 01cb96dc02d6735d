//! Backups that restore (issue 29, point 5): `poseboard backup` copies a live installation
//! into one file while uploads go on and the worker evaluates; `poseboard restore` brings a
//! backup back into an empty database, after which every view is the same as when the backup
//! was taken, the boards' pages byte for byte, with the same accounts and tokens. The backup
//! file is never changed by a restore, an existing file is not overwritten, a filled database
//! is not replaced without `--force`, and a file that is no backup is refused by name. On
//! PostgreSQL the README's `pg_dump`/`pg_restore` commands are run as written too.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use crate::common::{
    BIN, Db, TestDb, admin_token, both_databases, client, column, fixtures, reference_datasets,
    start, upload, wait_done,
};
use crate::copy_db::{move_data_dir, views};
use serde_json::Value;

/// Runs `poseboard backup|restore FILE` against the database of `data` (and `db`'s URL).
fn run(command: &str, file: &Path, data: &Path, db: &TestDb, extra: &[&str]) -> (bool, String) {
    let mut cmd = Command::new(BIN);
    cmd.arg(command)
        .arg(file)
        .arg("--data-dir")
        .arg(data)
        .args(extra)
        .env_remove("DATABASE_URL");
    if let Some(url) = db.url() {
        cmd.env("DATABASE_URL", url);
    }
    let out = cmd.output().expect("poseboard runs");
    (
        out.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
    )
}

/// The boards' pages as a reader gets them.
fn pages(base: &str) -> Vec<(String, String)> {
    [
        "/leaderboards/bop19",
        "/leaderboards/eccv18",
        "/leaderboards/bop19?dataset=synthA",
    ]
    .iter()
    .map(|p| {
        let r = client().get(format!("{base}{p}")).send().expect("page");
        assert!(r.status().is_success(), "{p}: {}", r.status());
        (p.to_string(), r.text().expect("html"))
    })
    .collect()
}

fn submit(server: &crate::common::Server, name: &str) -> i64 {
    let file = fixtures().join(format!("results/{name}_synthA-test.csv"));
    let r = upload(server, name, "synthA", &file, None);
    assert_eq!(r.status(), 202, "{name}");
    r.json::<Value>().expect("json")["id"].as_i64().expect("id")
}

fn a_backup_restores_the_installation_it_was_taken_of(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "backup");
    let root = admin_token(&data, &db, "root");
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let base = server.base.clone();
    let mut ids: Vec<i64> = ["noisesmall", "noisemedium"]
        .iter()
        .map(|n| submit(&server, n))
        .collect();
    for id in &ids {
        wait_done(&base, *id, Duration::from_secs(120));
    }

    // Online: the backup runs while three more uploads arrive and are evaluated.
    let online = dir.path().join("online.db");
    let (more, (ok, printed)) = std::thread::scope(|s| {
        let uploads = s.spawn(|| {
            ["gtexact", "symflip", "noiselarge"]
                .iter()
                .map(|n| submit(&server, n))
                .collect::<Vec<i64>>()
        });
        let backup = run("backup", &online, &data, &db, &[]);
        (uploads.join().expect("uploads"), backup)
    });
    assert!(ok, "online backup: {printed}");
    assert!(printed.contains("submissions"), "{printed}");
    ids.extend(more);
    for id in &ids {
        wait_done(&base, *id, Duration::from_secs(120));
    }

    // Quiet: the views at the time of this backup are what a restore must give back.
    let before = views(&base, &root, &ids);
    let before_pages = pages(&base);
    let backup = dir.path().join("poseboard-backup.db");
    let (ok, printed) = run("backup", &backup, &data, &db, &[]);
    assert!(ok, "backup: {printed}");
    assert!(printed.contains("submissions  5 rows"), "{printed}");
    let (ok, printed) = run("backup", &backup, &data, &db, &[]);
    assert!(!ok && printed.contains("exists"), "{printed}");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .expect("dir")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().contains(".partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    drop(server);
    let backup_bytes = std::fs::read(&backup).expect("backup");

    // Restored into an empty database of the same kind, the service is the same.
    let data2 = dir.path().join("data2");
    move_data_dir(&data, &data2);
    let db2 = TestDb::new(kind, "restored");
    let (ok, printed) = run("restore", &backup, &data2, &db2, &[]);
    assert!(ok, "restore: {printed}");
    assert!(printed.contains("submissions  5 rows"), "{printed}");
    assert_eq!(
        std::fs::read(&backup).expect("backup"),
        backup_bytes,
        "a restore leaves the backup as it was"
    );
    let server = start(&data2, &datasets, &db2, &["--no-demo"]);
    let after = views(&server.base, &root, &ids);
    for ((path, a), (_, b)) in before.iter().zip(&after) {
        assert_eq!(a, b, "{path} differs after the restore");
    }
    for ((path, a), (_, b)) in before_pages.iter().zip(&pages(&server.base)) {
        assert_eq!(a, b, "the page {path} differs after the restore");
    }
    drop(server);

    // A filled database is replaced only when asked; a file that is no backup is named.
    let (ok, printed) = run("restore", &backup, &data2, &db2, &[]);
    assert!(!ok && printed.contains("not empty"), "{printed}");
    let (ok, printed) = run("restore", &backup, &data2, &db2, &["--force"]);
    assert!(ok, "{printed}");
    let csv = fixtures().join("results/noisesmall_synthA-test.csv");
    let (ok, printed) = run("restore", &csv, &data2, &db2, &["--force"]);
    assert!(
        !ok && printed.contains("is not a poseboard backup"),
        "{printed}"
    );

    // The online backup holds a consistent moment: every submission in it has its file.
    let data3 = dir.path().join("data3");
    move_data_dir(&data, &data3);
    let db3 = TestDb::new(kind, "online");
    let (ok, printed) = run("restore", &online, &data3, &db3, &[]);
    assert!(ok, "restore of the online backup: {printed}");
    let submitted = column(
        &db3,
        &data3,
        "SELECT file_sha256 FROM submissions ORDER BY id",
    );
    assert!(submitted.len() >= 2, "{submitted:?}");
    let files = column(&db3, &data3, "SELECT sha256 FROM submission_files");
    for sha in &submitted {
        assert!(files.contains(sha), "submission file {sha} missing");
    }

    if matches!(kind, Db::Postgres) {
        pg_dump_and_restore(&db, &data, &datasets, &root, &ids, &before, &before_pages);
    }
}
both_databases!(a_backup_restores_the_installation_it_was_taken_of);

/// The README's PostgreSQL commands, run as written: `pg_dump --format=custom` of the live
/// database and `pg_restore --no-owner` into an empty one give the same service, its boards'
/// pages the same byte for byte.
fn pg_dump_and_restore(
    db: &TestDb,
    data: &Path,
    datasets: &Path,
    root: &str,
    ids: &[i64],
    before: &[(String, Value)],
    before_pages: &[(String, String)],
) {
    let dump = data.join("poseboard.dump");
    let url = db.url().expect("PostgreSQL");
    let out = Command::new("pg_dump")
        .args(["--format=custom", "--file"])
        .arg(&dump)
        .arg(&url)
        .output()
        .expect("pg_dump runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let target = TestDb::new(Db::Postgres, "pg_restore");
    let out = Command::new("pg_restore")
        .args(["--no-owner", "--dbname"])
        .arg(target.url().expect("PostgreSQL"))
        .arg(&dump)
        .output()
        .expect("pg_restore runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let server = start(data, datasets, &target, &["--no-demo"]);
    let after = views(&server.base, root, ids);
    for ((path, a), (_, b)) in before.iter().zip(&after) {
        assert_eq!(a, b, "{path} differs after pg_restore");
    }
    for ((path, a), (_, b)) in before_pages.iter().zip(&pages(&server.base)) {
        assert_eq!(a, b, "the page {path} differs after pg_restore");
    }
}
