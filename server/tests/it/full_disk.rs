//! A full disk refuses an upload with `507` and keeps nothing of it (issue 29, point 4): with
//! the data directory's disk full (a small tmpfs mounted on it and filled), and with the disk of
//! a SQLite database full while the data directory has room, an upload through the API gets
//! `507` with a JSON message and one through the site's form a `507` page, both sent as
//! clients send them (the body streamed after the headers); no submission, no stored file
//! and no temporary file stays, and once there is room again the same service takes uploads
//! (on SQLite, a connection whose commit failed for want of room is not handed out again).
//! The server's log is on the full disk too in the first case: lines it cannot write are lost
//! without taking the requests down.
//! PostgreSQL's `disk_full` (SQLSTATE 53100), raised by a real PostgreSQL, and SQLite's
//! `SQLITE_FULL` answer `507` as well.
//!
//! Mounting needs root (as the tests run here and on CI); where this process may not mount,
//! the disk tests say they are skipped and why, rather than pass without looking.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::{
    Db, Server, TestDb, both_databases, browser, column, csrf_of, execute, fixtures,
    reference_datasets, start, upload, upload_with, wait_done,
};
use reqwest::blocking::{Client, multipart};
use serde_json::Value;

/// A tmpfs of a given size mounted on a folder for as long as this lives.
struct Tmpfs {
    at: PathBuf,
}

impl Tmpfs {
    /// Mounts a tmpfs of `size` (as `mount -o size=` takes it) on `at`, made if missing;
    /// `None`, having said why, when this process may not mount.
    fn mount(at: &Path, size: &str) -> Option<Tmpfs> {
        std::fs::create_dir_all(at).expect("mount point");
        let out = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(at)
            .output();
        match out {
            Ok(out) if out.status.success() => Some(Tmpfs {
                at: at.to_path_buf(),
            }),
            Ok(out) => {
                eprintln!(
                    "SKIPPED: cannot mount a tmpfs on {} to fill its disk (mount needs root): {}",
                    at.display(),
                    String::from_utf8_lossy(&out.stderr).trim()
                );
                None
            }
            Err(e) => {
                eprintln!("SKIPPED: cannot run mount to make a small disk: {e}");
                None
            }
        }
    }

    /// Writes `name` on this disk until no byte more fits: the disk is full.
    fn fill(&self, name: &str) {
        let mut file = std::fs::File::create(self.at.join(name)).expect("filler");
        let block = vec![0x5a_u8; 64 * 1024];
        loop {
            match file.write(&block) {
                Ok(0) => panic!("a disk that takes no byte without an error"),
                Ok(_) => {}
                Err(e) => {
                    assert_eq!(e.kind(), std::io::ErrorKind::StorageFull, "{e}");
                    break;
                }
            }
        }
        // Whatever the last page of the filler still held is taken too.
        assert!(file.write(&[0]).is_err(), "the disk is full");
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        // Lazily, so that a test failing with its server still up leaves no mount behind.
        let _ = Command::new("umount").arg("-l").arg(&self.at).status();
    }
}

/// The temporary files of uploads left in the data directory.
fn temporaries(data: &Path) -> Vec<String> {
    std::fs::read_dir(data.join("submissions"))
        .expect("submissions folder")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect()
}

/// Rows of `table` in the server's database.
fn rows(db: &TestDb, data: &Path, table: &str) -> String {
    let counted = column(
        db,
        data,
        &format!("SELECT CAST(COUNT(*) AS TEXT) FROM {table}"),
    );
    counted.concat()
}

/// The API's refusal of an upload for want of room, sent as clients send it: the headers
/// first, the body streamed after them. The service reads such a body to its end before it
/// answers, so the client sees the answer rather than a connection closed while it sends.
fn assert_refused_by_the_api(server: &Server, file: &Path, what: &str) {
    let fields = [("method", "full"), ("dataset", "synthA")];
    let r = upload_with(server, &server.token, &fields, file);
    let status = r.status();
    let body = r.text().expect("body");
    assert_eq!(status, 507, "{what}: {body}");
    let body: Value = serde_json::from_str(&body).expect("JSON");
    let error = body["error"].as_str().expect("error");
    assert!(
        error.contains("out of disk space") && error.contains("nothing was stored"),
        "{what}: {error}"
    );
}

/// The site form's refusal of an upload for want of room, sent as a browser sends it (the
/// body streamed after the headers): an error page with status `507` that says why.
fn assert_refused_by_the_form(browser: &Client, server: &Server, file: &Path, what: &str) {
    let page = browser
        .get(format!("{}/submit", server.base))
        .send()
        .expect("form");
    assert_eq!(page.status(), 200, "{what}: the form");
    let csrf = csrf_of(&page.text().expect("page"));
    let form = multipart::Form::new()
        .text("csrf", csrf)
        .text("method", "full-form")
        .text("dataset", "synthA")
        .file("file", file)
        .expect("file");
    let r = browser
        .post(format!("{}/submit", server.base))
        .multipart(form)
        .send()
        .unwrap_or_else(|e| panic!("{what}: the form's upload got no answer: {e:?}"));
    assert_eq!(r.status(), 507, "{what}");
    let page = r.text().expect("page");
    assert!(
        page.contains("out of disk space") && page.contains("nothing was stored"),
        "{what}: {page}"
    );
}

fn an_upload_to_a_full_data_directory_is_refused_with_507(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    // SQLite's database is in the data directory, so its disk fills too; PostgreSQL's is not.
    let Some(disk) = Tmpfs::mount(&data, "24m") else {
        return;
    };
    let db = TestDb::new(kind, "fulldata");
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let (site, _) = browser(&server, "formuser");
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    if matches!(kind, Db::Sqlite) {
        // SQLite's small writes (the token's last use) go on reusing its write-ahead log's
        // room once it is checkpointed, so this upload is refused where the data directory is
        // needed: receiving the file.
        execute(&db, &data, "PRAGMA wal_checkpoint(RESTART)");
    }
    disk.fill("filler");

    assert_refused_by_the_api(&server, &file, "API");
    assert_refused_by_the_form(&site, &server, &file, "form");
    // Nothing half-written: no submission, no method, no stored file, no temporary file.
    for table in ["submissions", "methods", "submission_files"] {
        assert_eq!(rows(&db, &data, table), "0", "{kind:?}: rows in {table}");
    }
    assert_eq!(temporaries(&data), Vec::<String>::new(), "{kind:?}");

    // With room again, the same service takes the upload and scores it.
    std::fs::remove_file(data.join("filler")).expect("room made");
    let r = upload(&server, "full", "synthA", &file, None);
    assert_eq!(
        r.status(),
        202,
        "{kind:?}: {}",
        r.text().unwrap_or_default()
    );
    let id = r.json::<Value>().expect("JSON")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
    drop(server);
    drop(disk);
}
both_databases!(an_upload_to_a_full_data_directory_is_refused_with_507);

/// A valid result file of about `rows` estimates for the reference dataset's targets that
/// hardly compresses (scores and translations of random digits), so that storing it needs
/// room in proportion to its size.
fn incompressible_results(path: &Path, rows: usize) {
    let fixture = std::fs::read_to_string(fixtures().join("results/noisesmall_synthA-test.csv"))
        .expect("fixture");
    let mut lines = fixture.lines();
    let header = lines.next().expect("header");
    let lines: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // xorshift64: enough disorder for a compressor, the same file at every run.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut digits = |n: usize| -> String {
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                char::from(b'0' + (state % 10) as u8)
            })
            .collect()
    };
    let mut out = String::with_capacity(rows * 260);
    out.push_str(header);
    out.push('\n');
    for i in 0..rows {
        let l = &lines[i % lines.len()];
        let t = format!(
            "{}.{} {}.{} {}.{}",
            digits(2),
            digits(12),
            digits(2),
            digits(12),
            digits(3),
            digits(12)
        );
        let score = format!("0.{}", digits(12));
        out.push_str(&[l[0], l[1], l[2], &score, l[4], &t, l[6]].join(","));
        out.push('\n');
    }
    std::fs::write(path, out).expect("results written");
}

/// The database's disk full, the data directory's not: the upload is received into its
/// temporary file, checked, and refused when its transaction cannot be written.
#[test]
fn an_upload_to_a_full_sqlite_disk_is_refused_with_507() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let Some(disk) = Tmpfs::mount(&dir.path().join("database"), "24m") else {
        return;
    };
    let db_file = disk.at.join("poseboard.db");
    let db = TestDb::at(format!("sqlite://{}?mode=rwc", db_file.display()));
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let (site, _) = browser(&server, "formuser");
    let big = dir.path().join("big_synthA-test.csv");
    incompressible_results(&big, 20_000);

    // SQLite appends its writes to the write-ahead log, which keeps its size once grown: it is
    // emptied first, so that a write needs new room on the disk. Then the disk is filled but
    // for a little room, enough for the small writes of signing in, not for the file.
    let wal = disk.at.join("poseboard.db-wal");
    for _ in 0..50 {
        execute(&db, &data, "PRAGMA wal_checkpoint(TRUNCATE)");
        if std::fs::metadata(&wal).map_or(0, |m| m.len()) == 0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(
        std::fs::metadata(&wal).map_or(0, |m| m.len()),
        0,
        "the log was emptied"
    );
    std::fs::write(disk.at.join("room"), vec![0_u8; 256 * 1024]).expect("room kept");
    disk.fill("filler");
    std::fs::remove_file(disk.at.join("room")).expect("room made");

    assert_refused_by_the_api(&server, &big, "SQLite's disk full");
    assert_refused_by_the_form(&site, &server, &big, "SQLite's disk full, the form");
    for table in ["submissions", "methods", "submission_files"] {
        assert_eq!(rows(&db, &data, table), "0", "rows in {table}");
    }
    assert_eq!(temporaries(&data), Vec::<String>::new());
    // The log (in the data directory, which has room) names the cause for the operator.
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    assert!(
        log.contains("out of disk space: the request was refused")
            && log.contains("database or disk is full"),
        "{log}"
    );

    std::fs::remove_file(disk.at.join("filler")).expect("room made");
    let r = upload(&server, "big", "synthA", &big, None);
    let status = r.status();
    let body = r.text().unwrap_or_default();
    let log = std::fs::read_to_string(data.join("server.log")).unwrap_or_default();
    assert_eq!(status, 202, "{body}\n{log}");
    drop(server);
    drop(disk);
}

/// The database refusing a write for want of room is `507` on both kinds: PostgreSQL's
/// `disk_full`, raised by the server itself with that SQLSTATE, and SQLite's `SQLITE_FULL`, from
/// a database file capped at its pages.
fn a_full_database_is_insufficient_storage(kind: Db) {
    use server::error::AppError;
    use server::store::StoreError;
    use sqlx::Connection;

    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "diskfull");
    let (url, statements) = match db.url() {
        Some(url) => (
            url,
            vec![
                "DO $$ BEGIN RAISE EXCEPTION 'could not extend file: No space left on device' \
                 USING ERRCODE = 'disk_full'; END $$",
            ],
        ),
        None => (
            format!("sqlite://{}?mode=rwc", dir.path().join("full.db").display()),
            vec![
                "CREATE TABLE t (x BLOB)",
                "PRAGMA max_page_count = 4",
                "INSERT INTO t VALUES (zeroblob(100000))",
            ],
        ),
    };
    sqlx::any::install_default_drivers();
    let refused = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
        .block_on(async {
            let mut conn = sqlx::AnyConnection::connect(&url).await.expect("database");
            let (last, set_up) = statements.split_last().expect("statements");
            for sql in set_up {
                sqlx::query(*sql).execute(&mut conn).await.expect("set-up");
            }
            sqlx::query(*last)
                .execute(&mut conn)
                .await
                .expect_err("no room")
        });
    let error = StoreError::from(refused);
    assert!(error.is_storage_full(), "{kind:?}: {error}");
    assert!(!error.is_transient(), "{kind:?}: {error}");
    let app = AppError::from(error);
    assert_eq!(app.status().as_u16(), 507, "{kind:?}");
    assert!(app.body().error.contains("nothing was stored"));
}
both_databases!(a_full_database_is_insufficient_storage);
