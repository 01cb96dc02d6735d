//! The service as users meet it: the real `poseboard serve` started on an ephemeral port, once
//! with a fresh SQLite file and once with a fresh PostgreSQL database, driven over HTTP.
//!
//! PostgreSQL: `POSEBOARD_TEST_POSTGRES` (default `postgres://postgres@127.0.0.1:5432/test`)
//! is used to create a uniquely named database per test, dropped afterwards.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use reqwest::blocking::{Client, multipart};
use serde_json::Value;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

const BIN: &str = env!("CARGO_BIN_EXE_poseboard");

#[derive(Clone, Copy, Debug)]
enum Db {
    Sqlite,
    Postgres,
}

/// A database for one test; a PostgreSQL one is dropped when this goes away.
struct TestDb {
    url: Option<String>,
    drop_sql: Option<(String, String)>,
}

fn admin_url() -> String {
    std::env::var("POSEBOARD_TEST_POSTGRES")
        .unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/test".to_string())
}

fn pg_exec(url: &str, sql: &str) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        use sqlx::Connection;
        let mut conn = sqlx::PgConnection::connect(url)
            .await
            .expect("PostgreSQL is reachable");
        sqlx::query(sqlx::AssertSqlSafe(sql.to_string()))
            .execute(&mut conn)
            .await
            .expect("statement runs");
    });
}

impl TestDb {
    fn new(kind: Db, name: &str) -> TestDb {
        match kind {
            Db::Sqlite => TestDb {
                url: None,
                drop_sql: None,
            },
            Db::Postgres => {
                let nanos = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .expect("clock")
                    .as_nanos();
                let db = format!("poseboard_{name}_{}_{nanos}", std::process::id());
                let admin = admin_url();
                pg_exec(&admin, &format!("CREATE DATABASE {db}"));
                let base = admin
                    .rsplit_once('/')
                    .map_or(admin.as_str(), |(b, _)| b)
                    .to_string();
                TestDb {
                    url: Some(format!("{base}/{db}")),
                    drop_sql: Some((admin, format!("DROP DATABASE IF EXISTS {db} WITH (FORCE)"))),
                }
            }
        }
    }
}

impl Drop for TestDb {
    fn drop(&mut self) {
        if let Some((admin, sql)) = &self.drop_sql {
            pg_exec(admin, sql);
        }
    }
}

struct Server {
    child: Child,
    base: String,
    /// An API token of the account `tester`.
    token: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `poseboard admin ...` against the server's database.
fn admin(data_dir: &Path, db: &TestDb, args: &[&str]) -> String {
    let mut cmd = Command::new(BIN);
    cmd.arg("admin")
        .arg("--data-dir")
        .arg(data_dir)
        .args(args)
        .env_remove("DATABASE_URL");
    if let Some(url) = &db.url {
        cmd.env("DATABASE_URL", url);
    }
    let out = cmd.output().expect("poseboard admin runs");
    assert!(
        out.status.success(),
        "admin {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .expect("utf-8")
        .trim()
        .to_string()
}

/// Creates an account (if new) and returns a fresh API token for it.
fn account(data_dir: &Path, db: &TestDb, name: &str) -> String {
    let pw = data_dir.join(format!("{name}.pw"));
    std::fs::create_dir_all(data_dir).expect("mkdir");
    if !pw.exists() {
        std::fs::write(&pw, format!("{name}-secret-password\n")).expect("password file");
        admin(
            data_dir,
            db,
            &[
                "create-user",
                name,
                "--password-file",
                pw.to_str().expect("path"),
            ],
        );
    }
    admin(data_dir, db, &["create-token", name])
}

/// Starts `poseboard serve` on port 0 and waits for the line that tells its address.
fn start(data_dir: &Path, datasets: &Path, db: &TestDb, extra: &[&str]) -> Server {
    let token = account(data_dir, db, "tester");
    let mut cmd = Command::new(BIN);
    cmd.args(["serve", "--bind", "127.0.0.1:0", "--lease-secs", "2"])
        .arg("--data-dir")
        .arg(data_dir)
        .arg("--datasets")
        .arg(datasets)
        .args(extra)
        // Request traces included, so tests can check that no secret ever reaches the log.
        .env("RUST_LOG", "info,tower_http=debug")
        .env_remove("DATABASE_URL")
        .stdout(Stdio::piped())
        .stderr(Stdio::from(
            std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(data_dir.join("server.log"))
                .expect("log file"),
        ));
    if let Some(url) = &db.url {
        cmd.env("DATABASE_URL", url);
    }
    let mut child = cmd.spawn().expect("poseboard serve starts");
    let stdout = child.stdout.take().expect("stdout");
    let mut lines = BufReader::new(stdout).lines();
    let line = lines
        .next()
        .expect("the server prints its address")
        .expect("readable stdout");
    let base = line
        .strip_prefix("poseboard listening on ")
        .unwrap_or_else(|| panic!("unexpected first line: {line}"))
        .to_string();
    // Keep draining stdout so the server never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    Server { child, base, token }
}

/// A datasets directory holding the reference dataset under the name `synthA`.
fn reference_datasets(dir: &Path) -> PathBuf {
    let datasets = dir.join("datasets");
    std::fs::create_dir_all(&datasets).expect("mkdir");
    std::os::unix::fs::symlink(
        fixtures().join("dataset").canonicalize().expect("fixture"),
        datasets.join("synthA"),
    )
    .expect("symlink");
    datasets
}

fn client() -> Client {
    Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client")
}

fn upload(
    server: &Server,
    method: &str,
    dataset: &str,
    file: &Path,
    protocol: Option<&str>,
) -> reqwest::blocking::Response {
    let mut fields = vec![("method", method), ("dataset", dataset)];
    if let Some(p) = protocol {
        fields.push(("protocol", p));
    }
    upload_with(server, &server.token, &fields, file)
}

/// Uploads through the API with `token` (none when empty).
fn upload_with(
    server: &Server,
    token: &str,
    fields: &[(&str, &str)],
    file: &Path,
) -> reqwest::blocking::Response {
    let mut form = multipart::Form::new()
        .file("file", file)
        .expect("result file");
    for (k, v) in fields {
        form = form.text(k.to_string(), v.to_string());
    }
    let mut request = client()
        .post(format!("{}/api/v1/submissions", server.base))
        .multipart(form);
    if !token.is_empty() {
        request = request.bearer_auth(token);
    }
    request.send().expect("upload answered")
}

/// A browser with its own cookies, signed up as `name`; returns it and the CSRF token its
/// forms carry.
fn browser(server: &Server, name: &str) -> (Client, String) {
    let b = Client::builder()
        .cookie_store(true)
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client");
    let r = b
        .post(format!("{}/register", server.base))
        .form(&[
            ("name", name),
            ("password", "correct horse battery"),
            ("next", "/account"),
        ])
        .send()
        .expect("register");
    assert!(r.status().is_success(), "register {name}: {}", r.status());
    let page = r.text().expect("account page");
    (b, csrf_of(&page))
}

fn csrf_of(page: &str) -> String {
    let needle = "name=\"csrf\" value=\"";
    let at = page.find(needle).expect("a CSRF field") + needle.len();
    page[at..].split('"').next().expect("value").to_string()
}

fn get_json(url: &str) -> Value {
    let r = client().get(url).send().expect("answered");
    assert!(r.status().is_success(), "{url}: {}", r.status());
    r.json().expect("JSON")
}

fn wait_done(base: &str, id: i64, limit: Duration) -> Value {
    let start = Instant::now();
    loop {
        let s = get_json(&format!("{base}/api/v1/submissions/{id}"));
        match s["status"].as_str() {
            Some("done") => return s,
            Some("failed") => panic!("submission {id} failed: {}", s["error"]),
            _ => {}
        }
        assert!(
            start.elapsed() < limit,
            "submission {id} not done in {limit:?}: {s}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// What `poseboard eval` reports for a file.
fn cli_report(dataset: &Path, results: &Path, protocol: &str) -> Value {
    let out = tempfile::NamedTempFile::new().expect("tmp");
    let status = Command::new(BIN)
        .args(["eval", "--protocol", protocol, "--threads", "1"])
        .arg("--dataset")
        .arg(dataset)
        .arg("--results")
        .arg(results)
        .arg("--out")
        .arg(out.path())
        .stdout(Stdio::null())
        .status()
        .expect("poseboard eval runs");
    assert!(status.success());
    serde_json::from_str(&std::fs::read_to_string(out.path()).expect("report")).expect("json")
}

fn upload_evaluate_and_rank(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "rank");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisemedium_synthA-test.csv");

    let meta = [
        ("method", "noisy-net"),
        ("dataset", "synthA"),
        ("training_data", "synthetic"),
        ("modality", "rgb-d"),
        ("hardware", "test rig, 2 cores"),
    ];
    let r = upload_with(&server, &server.token, &meta, &file);
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    let id = body["id"].as_i64().expect("id");
    assert_eq!(body["preflight"]["targets"], 28);
    let done = wait_done(&base, id, Duration::from_secs(60));

    let bop19 = cli_report(&datasets.join("synthA"), &file, "bop19");
    let eccv18 = cli_report(&datasets.join("synthA"), &file, "eccv18");
    for key in [
        "bop19_average_recall",
        "bop19_average_recall_vsd",
        "bop19_average_recall_mssd",
        "bop19_average_recall_mspd",
    ] {
        assert_eq!(done["scores"]["bop19"][key], bop19[key], "{kind:?} {key}");
    }
    for key in [
        "recall",
        "obj_recalls",
        "scene_recalls",
        "mean_obj_recall",
        "targets_count",
        "tp_count",
    ] {
        assert_eq!(done["scores"]["eccv18"][key], eccv18[key], "{kind:?} {key}");
    }

    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"));
    let row = &board["rows"][0];
    assert_eq!(row["method"], "noisy-net");
    assert_eq!(
        row["scores"]["synthA"]["score"],
        bop19["bop19_average_recall"]
    );
    for (obj, ar) in bop19["obj_average_recalls"].as_object().expect("objects") {
        assert_eq!(&row["objects"][obj], ar, "object {obj}");
    }
    let board = get_json(&format!("{base}/api/v1/leaderboards/eccv18"));
    assert_eq!(
        board["rows"][0]["scores"]["synthA"]["score"],
        eccv18["recall"]
    );

    let html = client()
        .get(format!("{base}/leaderboards/bop19?dataset=synthA"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    let shown = format!(
        "{:.1}",
        bop19["bop19_average_recall"].as_f64().expect("ar") * 100.0
    );
    assert!(
        html.contains("noisy-net") && html.contains(&shown),
        "{kind:?}: {shown} not on the page"
    );
    let page = client()
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains("<svg"), "curves are drawn");

    // The same file again for the same method is recognised.
    let again = upload(&server, "noisy-net", "synthA", &file, None);
    assert_eq!(again.status(), 200);
    let again: Value = again.json().expect("json");
    assert_eq!(again["duplicate"], true);
    assert_eq!(again["id"], id);
}

#[test]
fn upload_evaluate_and_rank_on_sqlite() {
    upload_evaluate_and_rank(Db::Sqlite);
}

#[test]
fn upload_evaluate_and_rank_on_postgres() {
    upload_evaluate_and_rank(Db::Postgres);
}

fn malformed_upload_leaves_nothing(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "bad");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    for (file, needle) in [
        (
            "wrong-columns_synthA-test.csv",
            "line 6 has 6 fields, expected 7",
        ),
        (
            "not-rotation_synthA-test.csv",
            "R on line 5 is not a rotation matrix",
        ),
        ("nan_synthA-test.csv", "non-finite number on line 4"),
    ] {
        let r = upload(
            &server,
            "broken",
            "synthA",
            &fixtures().join("results/malformed").join(file),
            None,
        );
        assert_eq!(r.status(), 422, "{kind:?} {file}");
        let body: Value = r.json().expect("json");
        let problems = body["problems"].as_array().expect("problems");
        assert!(
            problems
                .iter()
                .any(|p| p["message"].as_str().is_some_and(|m| m.contains(needle))),
            "{kind:?} {file}: {body}"
        );
        assert!(problems.iter().all(|p| p["line"].as_u64().is_some()));
    }
    // The browser form shows the problems too.
    let (b, csrf) = browser(&server, "formuser");
    let form = multipart::Form::new()
        .text("csrf", csrf)
        .text("method", "broken")
        .text("dataset", "synthA")
        .file(
            "file",
            fixtures().join("results/malformed/wrong-columns_synthA-test.csv"),
        )
        .expect("file");
    let r = b
        .post(format!("{}/submit", server.base))
        .multipart(form)
        .send()
        .expect("form");
    assert_eq!(r.status(), 422);
    assert!(
        r.text()
            .expect("html")
            .contains("line 6 has 6 fields, expected 7")
    );

    let listed = get_json(&format!("{}/api/v1/submissions", server.base));
    assert_eq!(
        listed["submissions"].as_array().map(Vec::len),
        Some(0),
        "{kind:?}: no submission row"
    );
    let stored: Vec<_> = std::fs::read_dir(data.join("submissions"))
        .expect("dir")
        .collect();
    assert!(stored.is_empty(), "{kind:?}: no stored file: {stored:?}");

    // Unknown datasets and missing fields are refused with a clear 4xx.
    let r = upload(
        &server,
        "x",
        "nope",
        &fixtures().join("results/gtexact_synthA-test.csv"),
        None,
    );
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("unknown dataset"));
}

#[test]
fn malformed_upload_leaves_nothing_on_sqlite() {
    malformed_upload_leaves_nothing(Db::Sqlite);
}

#[test]
fn malformed_upload_leaves_nothing_on_postgres() {
    malformed_upload_leaves_nothing(Db::Postgres);
}

#[test]
fn an_upload_over_the_size_bound_is_refused_with_413() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "big");
    let server = start(
        &dir.path().join("data"),
        &datasets,
        &db,
        &["--max-upload-mb", "1"],
    );
    // Announce a 50 MiB body and send none of it: the answer must come without the body.
    let addr = server.base.trim_start_matches("http://");
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    write!(
        stream,
        "POST /api/v1/submissions HTTP/1.1\r\nHost: {addr}\r\nContent-Type: multipart/form-data; boundary=x\r\nContent-Length: {}\r\n\r\n",
        50u64 << 20
    )
    .expect("headers sent");
    let mut answer = [0u8; 64];
    let n = stream.read(&mut answer).expect("an answer before the body");
    let head = String::from_utf8_lossy(&answer[..n]);
    assert!(head.starts_with("HTTP/1.1 413"), "{head}");

    // A streamed (chunked) upload that grows past the bound is cut off with 413 as well.
    let big = dir.path().join("big.csv");
    let csv =
        std::fs::read_to_string(fixtures().join("results/gtexact_synthA-test.csv")).expect("csv");
    let mut text = String::new();
    while text.len() < 3 << 20 {
        text.push_str(&csv);
    }
    std::fs::write(&big, text).expect("write");
    let file = std::fs::File::open(&big).expect("open");
    let part = multipart::Part::reader(file).file_name("big.csv");
    let form = multipart::Form::new()
        .text("method", "huge")
        .text("dataset", "synthA")
        .part("file", part);
    match client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
    {
        Ok(r) => assert_eq!(r.status(), 413),
        // The server may close the connection before the client finishes sending.
        Err(e) => assert!(e.is_body() || e.is_request(), "{e}"),
    }
    let stored: Vec<_> = std::fs::read_dir(dir.path().join("data/submissions"))
        .expect("dir")
        .collect();
    assert!(stored.is_empty(), "nothing kept: {stored:?}");
}

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
            "12",
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
        // Wait until the job runs and has made progress, then kill the server hard.
        let start_wait = Instant::now();
        loop {
            let s = get_json(&format!("{}/api/v1/submissions/{id}", server.base));
            if s["status"] == "running" && s["progress"].as_f64().unwrap_or(0.0) > 0.0 {
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
            std::thread::sleep(Duration::from_millis(20));
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

#[test]
fn crash_and_resume_on_sqlite() {
    crash_and_resume(Db::Sqlite);
}

#[test]
fn crash_and_resume_on_postgres() {
    crash_and_resume(Db::Postgres);
}

/// An upload request without a body: authentication is decided before any body is read, and
/// with nothing to send the answer can never race the request.
fn post_without_file(server: &Server, token: &str) -> u16 {
    let mut r = client().post(format!("{}/api/v1/submissions", server.base));
    if !token.is_empty() {
        r = r.bearer_auth(token);
    }
    r.send().expect("answered").status().as_u16()
}

fn get_as(url: &str, token: &str) -> reqwest::blocking::Response {
    let mut r = client().get(url);
    if !token.is_empty() {
        r = r.bearer_auth(token);
    }
    r.send().expect("answered")
}

/// Reads one column of every row of a table of the server's database.
fn column(db: &TestDb, data_dir: &Path, sql: &str) -> Vec<String> {
    let url = db
        .url
        .clone()
        .unwrap_or_else(|| format!("sqlite://{}", data_dir.join("poseboard.db").display()));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        use sqlx::{Connection, Row};
        sqlx::any::install_default_drivers();
        let mut conn = sqlx::AnyConnection::connect(&url).await.expect("database");
        sqlx::query(sqlx::AssertSqlSafe(sql.to_string()))
            .fetch_all(&mut conn)
            .await
            .expect("query")
            .iter()
            .map(|r| r.try_get::<String, _>(0).expect("text column"))
            .collect()
    })
}

fn accounts_privacy_and_tokens(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "acct");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let fields = [
        ("method", "secret-net"),
        ("dataset", "synthA"),
        ("visibility", "private"),
    ];

    // No credentials, or a token that is not one: 401 before the body is read.
    for token in ["", "pbt_0000"] {
        assert_eq!(
            post_without_file(&server, token),
            401,
            "{kind:?}: token {token:?}"
        );
    }

    // A private submission is visible to its owner only.
    let r = upload_with(&server, &server.token, &fields, &file);
    assert_eq!(r.status(), 202, "{kind:?}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let url = format!("{base}/api/v1/submissions/{id}");
    let start_wait = Instant::now();
    while get_as(&url, &server.token).json::<Value>().expect("json")["status"] != "done" {
        assert!(start_wait.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(100));
    }
    let bob = account(&data, &db, "bob");
    let missing = format!("{base}/api/v1/submissions/999999");
    for token in ["", bob.as_str()] {
        let hidden = get_as(&url, token);
        assert_eq!(hidden.status(), 404, "{kind:?}: private submission leaked");
        assert_eq!(
            hidden.text().expect("body"),
            get_as(&missing, token).text().expect("body")
        );
        let page = get_as(&format!("{base}/submissions/{id}"), token);
        assert_eq!(page.status(), 404);
        assert!(!page.text().expect("html").contains("secret-net"));
    }
    for listing in [
        format!("{base}/api/v1/submissions"),
        format!("{base}/api/v1/methods"),
        format!("{base}/api/v1/leaderboards/bop19"),
        format!("{base}/api/v1/leaderboards/eccv18?dataset=synthA"),
        format!("{base}/leaderboards/bop19"),
    ] {
        let text = get_as(&listing, &bob).text().expect("body");
        assert!(
            !text.contains("secret-net"),
            "{kind:?}: {listing} lists a private method"
        );
    }
    // Method names are per account: the same name elsewhere is a different method, and
    // nothing tells bob that a private one of that name exists.
    let own = upload_with(
        &server,
        &bob,
        &[("method", "secret-net"), ("dataset", "synthA")],
        &file,
    );
    assert_eq!(own.status(), 202, "{kind:?}");
    let own: Value = own.json().expect("json");
    assert_eq!(
        own["duplicate"], false,
        "not matched to the other account's submission"
    );
    assert_ne!(
        own["submission"]["method_id"],
        get_as(&url, &server.token).json::<Value>().expect("json")["method_id"]
    );

    // Forms need the session's CSRF token: missing or forged ones change nothing.
    let (carol, csrf) = browser(&server, "carol");
    for sent in [None, Some("forged")] {
        let mut form = vec![("name", "script")];
        if let Some(c) = sent {
            form.push(("csrf", c));
        }
        let r = carol
            .post(format!("{base}/account/tokens"))
            .form(&form)
            .send()
            .expect("post");
        assert_eq!(r.status(), 403, "{kind:?}: CSRF {sent:?}");
    }
    let tokens_page = carol
        .get(format!("{base}/account"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        !tokens_page.contains("<td>script</td>"),
        "{kind:?}: a token was created"
    );
    let page = carol
        .post(format!("{base}/account/tokens"))
        .form(&[("name", "script"), ("csrf", csrf.as_str())])
        .send()
        .expect("post")
        .text()
        .expect("html");
    let at = page
        .find("<code id=\"new-token\">")
        .expect("the new token is shown")
        + 21;
    let token = page[at..].split('<').next().expect("token").to_string();
    let r = upload_with(
        &server,
        &token,
        &[("method", "carol-net"), ("dataset", "synthA")],
        &file,
    );
    assert_eq!(r.status(), 202);
    // Revoked, it gets 401.
    let token_id = page
        .split("/account/tokens/")
        .nth(1)
        .and_then(|s| s.split('/').next())
        .expect("a revoke form")
        .to_string();
    let r = carol
        .post(format!("{base}/account/tokens/{token_id}/revoke"))
        .form(&[("csrf", csrf.as_str())])
        .send()
        .expect("revoke");
    assert!(r.status().is_success());
    assert_eq!(
        post_without_file(&server, &token),
        401,
        "{kind:?}: revoked token accepted"
    );

    // Secrets never reach the log, and are never stored in clear.
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    assert!(
        log.contains("/api/v1/submissions"),
        "the log has the requests"
    );
    for secret in [
        token.as_str(),
        server.token.as_str(),
        bob.as_str(),
        "correct horse battery",
    ] {
        assert!(!log.contains(secret), "{kind:?}: a secret is in the log");
    }
    let hashes = column(
        &db,
        &data,
        "SELECT password_hash FROM users WHERE name = 'carol'",
    );
    assert!(hashes[0].starts_with("$argon2id$") && !hashes[0].contains("correct horse"));
    let tokens = column(&db, &data, "SELECT token_hash FROM api_tokens");
    assert!(
        tokens
            .iter()
            .all(|t| t.len() == 64 && !token.contains(t.as_str()))
    );
    assert!(!tokens.contains(&token));
}

#[test]
fn accounts_privacy_and_tokens_on_sqlite() {
    accounts_privacy_and_tokens(Db::Sqlite);
}

#[test]
fn accounts_privacy_and_tokens_on_postgres() {
    accounts_privacy_and_tokens(Db::Postgres);
}

fn fair_use_limit(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "limit");
    let args = ["--submissions-per-window", "1", "--limit-window-secs", "3"];
    let server = start(&dir.path().join("data"), &datasets, &db, &args);
    let first = fixtures().join("results/noisesmall_synthA-test.csv");
    let second = fixtures().join("results/noisemedium_synthA-test.csv");
    assert_eq!(
        upload(&server, "limited", "synthA", &first, None).status(),
        202
    );
    let refused = upload(&server, "limited", "synthA", &second, None);
    assert_eq!(refused.status(), 429, "{kind:?}");
    assert!(refused.headers().contains_key("retry-after"));
    let body: Value = refused.json().expect("json");
    let retry_at = body["retry_at"].as_i64().expect("retry_at");
    // Re-sending an identical file is not a new submission and is not limited.
    assert_eq!(
        upload(&server, "limited", "synthA", &first, None).status(),
        200
    );
    // Once the window has passed, the next one is accepted.
    let now = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .expect("clock")
            .as_millis() as i64
    };
    while now() < retry_at {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(
        upload(&server, "limited", "synthA", &second, None).status(),
        202,
        "{kind:?}"
    );
}

#[test]
fn fair_use_limit_on_sqlite() {
    fair_use_limit(Db::Sqlite);
}

#[test]
fn fair_use_limit_on_postgres() {
    fair_use_limit(Db::Postgres);
}

fn login_attempts_are_limited(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "login");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    browser(&server, "dave");
    browser(&server, "erin");
    let login = |name: &str, password: &str| {
        Client::builder()
            .redirect(reqwest::redirect::Policy::none())
            .build()
            .expect("client")
            .post(format!("{}/login", server.base))
            .form(&[("name", name), ("password", password)])
            .send()
            .expect("login")
            .status()
            .as_u16()
    };
    for _ in 0..5 {
        assert_eq!(login("dave", "wrong password!"), 401, "{kind:?}");
    }
    // The account is now locked for a while, even with the right password.
    assert_eq!(login("dave", "correct horse battery"), 429, "{kind:?}");
    // A sign-in posted from another site's page is refused.
    let cross = client()
        .post(format!("{}/login", server.base))
        .header("Origin", "http://evil.example")
        .form(&[("name", "erin"), ("password", "correct horse battery")])
        .send()
        .expect("login");
    assert_eq!(cross.status(), 403, "{kind:?}");
    // Other accounts from the same address are not locked.
    assert_eq!(login("erin", "correct horse battery"), 303, "{kind:?}");
}

#[test]
fn login_attempts_are_limited_on_sqlite() {
    login_attempts_are_limited(Db::Sqlite);
}

#[test]
fn login_attempts_are_limited_on_postgres() {
    login_attempts_are_limited(Db::Postgres);
}

fn post_as(url: &str, token: &str, json: Option<Value>) -> reqwest::blocking::Response {
    let mut r = client().post(url).bearer_auth(token);
    if let Some(body) = json {
        r = r.json(&body);
    }
    r.send().expect("answered")
}

fn administration(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "admin");
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).expect("mkdir");
    std::fs::write(data.join("root.pw"), "root-secret-password\n").expect("pw");
    admin(
        &data,
        &db,
        &[
            "create-user",
            "root",
            "--password-file",
            data.join("root.pw").to_str().expect("path"),
            "--admin",
        ],
    );
    let root = admin(&data, &db, &["create-token", "root"]);
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "moderated", "synthA", &file, None);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let done = wait_done(&base, id, Duration::from_secs(60));
    let action = |token: &str, what: &str| {
        post_as(
            &format!("{base}/api/v1/admin/submissions/{id}/{what}"),
            token,
            None,
        )
    };

    // Not an administrator: the routes do not exist.
    assert_eq!(action(&server.token, "hide").status(), 404, "{kind:?}");
    assert_eq!(
        get_as(&format!("{base}/api/v1/admin/audit"), &server.token).status(),
        404
    );

    assert!(action(&root, "hide").status().is_success());
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), "").status(),
        404,
        "{kind:?}: hidden"
    );
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), &server.token).status(),
        200,
        "owner still sees it"
    );
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board["rows"].as_array().map(Vec::len), Some(0));
    assert!(action(&root, "unhide").status().is_success());
    assert_eq!(
        get_json(&format!("{base}/api/v1/leaderboards/bop19"))["rows"]
            .as_array()
            .map(Vec::len),
        Some(1)
    );

    // A re-run evaluates again, to the same scores.
    assert!(action(&root, "rerun").status().is_success());
    let again = wait_done(&base, id, Duration::from_secs(60));
    assert_eq!(again["scores"], done["scores"], "{kind:?}");

    // Datasets can be retired and added back (by folder name only).
    let retire = post_as(
        &format!("{base}/api/v1/admin/datasets/synthA/retire"),
        &root,
        None,
    );
    assert!(retire.status().is_success());
    assert!(
        !get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );
    let bad = post_as(
        &format!("{base}/api/v1/admin/datasets"),
        &root,
        Some(serde_json::json!({ "name": "../etc" })),
    );
    assert_eq!(bad.status(), 400);
    let add = post_as(
        &format!("{base}/api/v1/admin/datasets"),
        &root,
        Some(serde_json::json!({ "name": "synthA" })),
    );
    assert!(
        add.status().is_success(),
        "{}",
        add.text().unwrap_or_default()
    );
    assert!(
        get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );

    // The same from the datasets page, in an administrator's browser.
    let b = Client::builder()
        .cookie_store(true)
        .build()
        .expect("client");
    let page = b
        .post(format!("{base}/login"))
        .form(&[
            ("name", "root"),
            ("password", "root-secret-password"),
            ("next", "/datasets"),
        ])
        .send()
        .expect("login")
        .text()
        .expect("html");
    let csrf = csrf_of(&page);
    let r = b
        .post(format!("{base}/admin/datasets/synthA/retire"))
        .form(&[("csrf", csrf.as_str())])
        .send()
        .expect("retire");
    assert!(r.status().is_success());
    assert!(
        !get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );
    let forged = b
        .post(format!("{base}/admin/datasets"))
        .form(&[("csrf", "forged"), ("name", "synthA")])
        .send()
        .expect("add");
    assert_eq!(forged.status(), 403);
    let r = b
        .post(format!("{base}/admin/datasets"))
        .form(&[("csrf", csrf.as_str()), ("name", "synthA")])
        .send()
        .expect("add");
    assert!(r.status().is_success());
    assert!(
        get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );

    // Deleted: gone for everyone, with its file.
    assert!(action(&root, "delete").status().is_success());
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), &root).status(),
        404
    );
    assert_eq!(
        std::fs::read_dir(data.join("submissions"))
            .expect("dir")
            .count(),
        0
    );

    let audit = get_as(&format!("{base}/api/v1/admin/audit"), &root)
        .json::<Value>()
        .expect("json");
    let actions: Vec<&str> = audit["audit"]
        .as_array()
        .expect("entries")
        .iter()
        .filter_map(|e| {
            assert_eq!(e["actor"], "root");
            e["action"].as_str()
        })
        .collect();
    assert_eq!(
        actions,
        [
            "delete",
            "add dataset",
            "retire dataset",
            "add dataset",
            "retire dataset",
            "rerun",
            "unhide",
            "hide"
        ],
        "{kind:?}"
    );
}

#[test]
fn administration_on_sqlite() {
    administration(Db::Sqlite);
}

#[test]
fn administration_on_postgres() {
    administration(Db::Postgres);
}

fn hostile_input(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "hostile");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let script = "<script>alert(1)</script>";
    let method = "x'); DROP TABLE users; --<script>alert(1)</script>";
    // A file name with path separators and `..` is kept as its last component.
    let tricky = dir.path().join("evil.csv");
    std::fs::copy(fixtures().join("results/gtexact_synthA-test.csv"), &tricky).expect("copy");
    let form = multipart::Form::new()
        .text("method", method)
        .text("dataset", "synthA")
        .text(
            "description",
            format!("{script}<img src=x onerror=alert(2)>"),
        )
        .text("hardware", "\"><script>alert(3)</script>")
        .part(
            "file",
            multipart::Part::file(&tricky)
                .expect("file")
                .file_name("../../etc/passwd"),
        );
    let r = client()
        .post(format!("{base}/api/v1/submissions"))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
        .expect("upload");
    assert_eq!(r.status(), 202, "{kind:?}");
    let sub: Value = r.json().expect("json");
    assert_eq!(sub["submission"]["file_name"], "passwd");
    assert_eq!(sub["submission"]["method"], method, "stored as given");
    let id = sub["id"].as_i64().expect("id");
    wait_done(&base, id, Duration::from_secs(60));
    // Shown harmlessly: escaped on every page.
    let method_id = sub["submission"]["method_id"].as_i64().expect("method id");
    for page in [
        format!("{base}/submissions/{id}"),
        format!("{base}/methods/{method_id}"),
        format!("{base}/leaderboards/bop19"),
    ] {
        let html = get_as(&page, "").text().expect("html");
        assert!(
            !html.contains("<script>alert"),
            "{kind:?}: {page} runs the script"
        );
        assert!(
            html.contains("&lt;script&gt;") || html.contains("&#60;script&#62;"),
            "{kind:?}: {page}"
        );
    }
    // The database is intact: accounts still work.
    assert_eq!(post_without_file(&server, &server.token), 400);
    // Giant fields are refused with a clear 4xx.
    let giant = "a".repeat(20_000);
    let r = upload_with(
        &server,
        &server.token,
        &[
            ("method", "big"),
            ("dataset", "synthA"),
            ("description", giant.as_str()),
        ],
        &tricky,
    );
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("longer than"));
    let r = upload_with(
        &server,
        &server.token,
        &[("method", &"m".repeat(500)), ("dataset", "synthA")],
        &tricky,
    );
    assert_eq!(r.status(), 400);
    // Nothing escaped the data directory.
    assert!(!dir.path().join("etc").exists());
}

#[test]
fn hostile_input_on_sqlite() {
    hostile_input(Db::Sqlite);
}

#[test]
fn hostile_input_on_postgres() {
    hostile_input(Db::Postgres);
}
