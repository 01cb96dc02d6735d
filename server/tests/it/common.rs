//! The harness every service test shares: a fresh database of either kind, the real
//! `poseboard serve` started on a free port against it, and the HTTP and CLI helpers the
//! tests drive it with.
//!
//! The tests only talk to the `poseboard` binary (over HTTP and its command line) and to the
//! database it uses, never to the server's library internals, so they hold across refactors.
//!
//! PostgreSQL: `POSEBOARD_TEST_POSTGRES` (default `postgres://postgres@127.0.0.1:5432/test`)
//! is used to create a uniquely named database per test, dropped afterwards.
//!
//! The tests run on threads of one process: nothing here changes process-wide state, and
//! every name it makes (databases, folders) is unique within the process as well as across
//! processes.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use reqwest::blocking::{Client, multipart};
use serde_json::Value;

/// Turns `fn name(kind: Db)` into two tests, `name::sqlite` and `name::postgres`; written
/// right after the function as `both_databases!(name);`.
///
/// The tests live in a module named after the function (modules and functions do not share a
/// namespace), so `cargo test name` runs both cases and `cargo test postgres` runs every
/// PostgreSQL case.
macro_rules! both_databases {
    ($name:ident) => {
        mod $name {
            #[test]
            fn sqlite() {
                super::$name($crate::common::Db::Sqlite);
            }

            #[test]
            fn postgres() {
                super::$name($crate::common::Db::Postgres);
            }
        }
    };
}
pub(crate) use both_databases;

/// The bundled reference fixture: a small dataset, result files and bop_toolkit's scores.
pub fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

/// The `poseboard` binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_poseboard");

/// The database kinds the service runs on.
#[derive(Clone, Copy, Debug)]
pub enum Db {
    Sqlite,
    Postgres,
}

/// A database for one test; a PostgreSQL one is dropped when this goes away.
///
/// A SQLite one has no URL: the server then makes a fresh `poseboard.db` in its (temporary)
/// data directory.
pub struct TestDb {
    url: Option<String>,
    drop_sql: Option<(String, String)>,
}

/// The PostgreSQL databases this process has created so far (see [`TestDb::new`]).
static DATABASES: AtomicU64 = AtomicU64::new(0);

/// The PostgreSQL database tests create their databases from.
pub fn admin_url() -> String {
    std::env::var("POSEBOARD_TEST_POSTGRES")
        .unwrap_or_else(|_| "postgres://postgres@127.0.0.1:5432/test".to_string())
}

/// Runs one statement on the PostgreSQL database at `url`.
pub fn pg_exec(url: &str, sql: &str) {
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
    /// The PostgreSQL database's URL; `None` for SQLite (a file in the data directory).
    pub fn url(&self) -> Option<String> {
        self.url.clone()
    }

    /// A database the test made elsewhere (a PostgreSQL cluster of its own, a SQLite file on a
    /// disk of its own), reached at `url` and left as it is afterwards: its owner removes it.
    pub fn at(url: String) -> TestDb {
        TestDb {
            url: Some(url),
            drop_sql: None,
        }
    }

    pub fn new(kind: Db, name: &str) -> TestDb {
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
                // The process id tells apart concurrent test processes, the count the tests
                // of this one (two may start within a clock tick under the same name), and
                // the time a process whose id an earlier, killed run had used. The count
                // comes before the time: PostgreSQL cuts names at 63 bytes.
                let n = DATABASES.fetch_add(1, Ordering::Relaxed);
                let db = format!("poseboard_{name}_{}_{n}_{nanos}", std::process::id());
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

/// A running `poseboard serve`, killed when this goes away.
pub struct Server {
    pub child: Child,
    /// `http://127.0.0.1:<port>`.
    pub base: String,
    /// An API token of the account `tester`.
    pub token: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `poseboard admin ...` against the server's database.
pub fn admin(data_dir: &Path, db: &TestDb, args: &[&str]) -> String {
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
pub fn account(data_dir: &Path, db: &TestDb, name: &str) -> String {
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
pub fn start(data_dir: &Path, datasets: &Path, db: &TestDb, extra: &[&str]) -> Server {
    start_with_env(data_dir, datasets, db, extra, &[])
}

/// [`start`] with environment variables set for the server (settings read from the
/// environment, which a server without them ignores).
pub fn start_with_env(
    data_dir: &Path,
    datasets: &Path,
    db: &TestDb,
    extra: &[&str],
    env: &[(&str, &str)],
) -> Server {
    launch(data_dir, Some(datasets), db, extra, env)
}

/// The server as a new operator first starts it: no datasets directory given, so it makes the
/// demo dataset and submits the demo files, with every other setting at its default.
pub fn start_first_time(data_dir: &Path, db: &TestDb) -> Server {
    launch(data_dir, None, db, &[], &[])
}

fn launch(
    data_dir: &Path,
    datasets: Option<&Path>,
    db: &TestDb,
    extra: &[&str],
    env: &[(&str, &str)],
) -> Server {
    let token = account(data_dir, db, "tester");
    let mut cmd = Command::new(BIN);
    cmd.envs(env.iter().copied());
    cmd.args(["serve", "--bind", "127.0.0.1:0", "--lease-secs", "2"])
        .arg("--data-dir")
        .arg(data_dir);
    if let Some(datasets) = datasets {
        cmd.arg("--datasets").arg(datasets);
    }
    cmd.args(extra)
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
pub fn reference_datasets(dir: &Path) -> PathBuf {
    let datasets = dir.join("datasets");
    std::fs::create_dir_all(&datasets).expect("mkdir");
    std::os::unix::fs::symlink(
        fixtures().join("dataset").canonicalize().expect("fixture"),
        datasets.join("synthA"),
    )
    .expect("symlink");
    datasets
}

/// A plain HTTP client without cookies.
pub fn client() -> Client {
    Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client")
}

/// Uploads `file` as the account `tester`, optionally for one `protocol`, asking for it to be
/// published (the API's default is private; the tests using this follow the public boards).
pub fn upload(
    server: &Server,
    method: &str,
    dataset: &str,
    file: &Path,
    protocol: Option<&str>,
) -> reqwest::blocking::Response {
    let mut fields = vec![
        ("method", method),
        ("dataset", dataset),
        ("visibility", "public"),
    ];
    if let Some(p) = protocol {
        fields.push(("protocol", p));
    }
    upload_with(server, &server.token, &fields, file)
}

/// Uploads through the API with `token` (none when empty).
pub fn upload_with(
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
pub fn browser(server: &Server, name: &str) -> (Client, String) {
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

/// A cookie client signed in through the login form as `name`, an account [`account`] made
/// (its password is the one that function wrote), for pages that show the owner's controls.
pub fn signed_in(server: &Server, name: &str) -> Client {
    let b = Client::builder()
        .cookie_store(true)
        .timeout(Duration::from_secs(60))
        .build()
        .expect("client");
    let password = format!("{name}-secret-password");
    let r = b
        .post(format!("{}/login", server.base))
        .form(&[
            ("name", name),
            ("password", password.as_str()),
            ("next", "/account"),
        ])
        .send()
        .expect("login");
    assert!(r.status().is_success(), "login {name}: {}", r.status());
    b
}

/// The CSRF token a page's forms carry.
pub fn csrf_of(page: &str) -> String {
    let needle = "name=\"csrf\" value=\"";
    let at = page.find(needle).expect("a CSRF field") + needle.len();
    page[at..].split('"').next().expect("value").to_string()
}

/// GETs `url` without credentials, asserting success, and returns the JSON answer.
pub fn get_json(url: &str) -> Value {
    let r = client().get(url).send().expect("answered");
    assert!(r.status().is_success(), "{url}: {}", r.status());
    r.json().expect("JSON")
}

/// The methods of a leaderboard's JSON rows, in their order.
pub fn board_methods(board: &Value) -> Vec<String> {
    board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| r["method"].as_str().expect("method").to_string())
        .collect()
}

/// Polls submission `id` until it is done (panicking if it fails or takes over `limit`).
pub fn wait_done(base: &str, id: i64, limit: Duration) -> Value {
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

/// Uploads `file` publicly to `dataset` as `method` (under `protocol`, else as its kind's
/// default) and waits until it is scored: the upload's answer (`id`, `submission`).
pub fn upload_scored(
    server: &Server,
    method: &str,
    dataset: &str,
    file: &Path,
    protocol: Option<&str>,
) -> Value {
    let r = upload(server, method, dataset, file, protocol);
    assert_eq!(r.status().as_u16(), 202, "{method}: {}", r.text().unwrap());
    let body: Value = r.json().expect("JSON");
    let id = body["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
    body
}

/// A synthetic dataset `synthdemo` with the demo's 6D and 2D result files, made by
/// `poseboard dataset synth` and `dataset demo-results` in a temporary folder.
pub struct SynthDemo {
    pub dir: tempfile::TempDir,
    /// The folder of datasets the server serves (holding `synthdemo`).
    pub datasets: PathBuf,
    pub dataset: PathBuf,
    pub results: PathBuf,
}

impl SynthDemo {
    pub fn new() -> SynthDemo {
        let dir = tempfile::tempdir().expect("tmp");
        let datasets = dir.path().join("datasets");
        let dataset = datasets.join("synthdemo");
        let results = dir.path().join("results");
        let path = |p: &Path| p.to_str().expect("path").to_string();
        let (dataset_arg, results_arg) = (path(&dataset), path(&results));
        for args in [
            &["dataset", "synth", &dataset_arg][..],
            &["dataset", "demo-results", &dataset_arg, &results_arg],
            &[
                "dataset",
                "demo-results",
                "--coco",
                &dataset_arg,
                &results_arg,
            ],
        ] {
            assert!(poseboard(args).status.success(), "{args:?}");
        }
        SynthDemo {
            dir,
            datasets,
            dataset,
            results,
        }
    }

    /// The demo's result file `name`.
    pub fn file(&self, name: &str) -> PathBuf {
        self.results.join(name)
    }

    /// The service's data folder for this set.
    pub fn data(&self) -> PathBuf {
        self.dir.path().join("data")
    }
}

/// What `poseboard eval` reports for a file.
pub fn cli_report(dataset: &Path, results: &Path, protocol: &str) -> Value {
    eval_report(
        dataset,
        results,
        &["--protocol", protocol, "--threads", "1"],
    )
    .1
}

/// `poseboard` run with `args`, as a user runs it.
pub fn poseboard(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .output()
        .expect("poseboard runs")
}

/// `poseboard eval` of `results` on `dataset` with `extra` arguments, which must succeed: its
/// output and the JSON report it wrote.
pub fn eval_report(dataset: &Path, results: &Path, extra: &[&str]) -> (Output, Value) {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("report.json");
    let utf8 = |p: &'_ Path| p.to_str().expect("utf-8 path").to_owned();
    let (dataset, results, out_arg) = (utf8(dataset), utf8(results), utf8(&out));
    let mut args = vec![
        "eval",
        "--dataset",
        &dataset,
        "--results",
        &results,
        "--out",
        &out_arg,
    ];
    args.extend_from_slice(extra);
    let output = poseboard(&args);
    assert!(
        output.status.success(),
        "poseboard eval failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report = serde_json::from_str(&std::fs::read_to_string(&out).expect("report written"))
        .expect("report is JSON");
    (output, report)
}

/// An upload request without a body: authentication is decided before any body is read, and
/// with nothing to send the answer can never race the request.
pub fn post_without_file(server: &Server, token: &str) -> u16 {
    let mut r = client().post(format!("{}/api/v1/submissions", server.base));
    if !token.is_empty() {
        r = r.bearer_auth(token);
    }
    r.send().expect("answered").status().as_u16()
}

/// GETs `url` with `token` (none when empty).
pub fn get_as(url: &str, token: &str) -> reqwest::blocking::Response {
    let mut r = client().get(url);
    if !token.is_empty() {
        r = r.bearer_auth(token);
    }
    r.send().expect("answered")
}

/// The URL of the server's database (its SQLite file when the test has no PostgreSQL one).
pub fn database_url(db: &TestDb, data_dir: &Path) -> String {
    db.url
        .clone()
        .unwrap_or_else(|| format!("sqlite://{}", data_dir.join("poseboard.db").display()))
}

/// A connection to the server's database, with a runtime to drive it.
fn connect(db: &TestDb, data_dir: &Path) -> (tokio::runtime::Runtime, sqlx::AnyConnection) {
    use sqlx::Connection;
    let url = database_url(db, data_dir);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    sqlx::any::install_default_drivers();
    let conn = rt
        .block_on(sqlx::AnyConnection::connect(&url))
        .expect("database");
    (rt, conn)
}

/// Runs one statement on the server's database.
pub fn execute(db: &TestDb, data_dir: &Path, sql: &str) {
    let (rt, mut conn) = connect(db, data_dir);
    rt.block_on(sqlx::query(sqlx::AssertSqlSafe(sql.to_string())).execute(&mut conn))
        .expect("statement runs");
}

/// Reads one column of every row of a table of the server's database.
pub fn column(db: &TestDb, data_dir: &Path, sql: &str) -> Vec<String> {
    use sqlx::Row;
    let (rt, mut conn) = connect(db, data_dir);
    rt.block_on(sqlx::query(sqlx::AssertSqlSafe(sql.to_string())).fetch_all(&mut conn))
        .expect("query")
        .iter()
        .map(|r| r.try_get::<String, _>(0).expect("text column"))
        .collect()
}

/// POSTs to `url` with `token`, and a JSON body if given.
pub fn post_as(url: &str, token: &str, json: Option<Value>) -> reqwest::blocking::Response {
    let mut r = client().post(url).bearer_auth(token);
    if let Some(body) = json {
        r = r.json(&body);
    }
    r.send().expect("answered")
}

/// Creates the administrator `name` and returns an API token for it.
pub fn admin_token(data_dir: &Path, db: &TestDb, name: &str) -> String {
    std::fs::create_dir_all(data_dir).expect("mkdir");
    let pw = data_dir.join(format!("{name}.pw"));
    std::fs::write(&pw, format!("{name}-secret-password\n")).expect("pw");
    admin(
        data_dir,
        db,
        &[
            "create-user",
            name,
            "--password-file",
            pw.to_str().expect("path"),
            "--admin",
        ],
    );
    admin(data_dir, db, &["create-token", name])
}

/// A synthetic dataset `name` of `scenes` scenes of `images` images each, made by `poseboard
/// dataset synth` in `dir/datasets`, with the result files `dataset demo-results` writes for it
/// in `dir/results`: returns the datasets folder and the result files.
pub fn synth_with_results(
    dir: &Path,
    name: &str,
    scenes: u32,
    images: u32,
) -> (PathBuf, Vec<PathBuf>) {
    let datasets = dir.join("datasets");
    let dataset = datasets.join(name);
    let results = dir.join("results");
    let (scenes, images) = (scenes.to_string(), images.to_string());
    let status = Command::new(BIN)
        .args(["dataset", "synth", "--scenes", &scenes])
        .args(["--images-per-scene", &images])
        .arg(&dataset)
        .stdout(Stdio::null())
        .status()
        .expect("synth runs");
    assert!(status.success(), "dataset synth");
    let status = Command::new(BIN)
        .args(["dataset", "demo-results"])
        .arg(&dataset)
        .arg(&results)
        .stdout(Stdio::null())
        .status()
        .expect("demo-results runs");
    assert!(status.success(), "dataset demo-results");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&results)
        .expect("results")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .collect();
    files.sort();
    (datasets, files)
}

/// What a reader got for one request: the path, the status, whether `Retry-After` came with
/// it, and the body.
pub struct Answer {
    pub path: String,
    pub status: u16,
    pub retry_after: bool,
    pub text: String,
}

/// Asks for `paths` in turn from `base`, starting at the `first`, `pause` apart, until `stop`,
/// keeping every answer in `answers`. A request that got no answer at all (a connection refused
/// while a database restart keeps the server from accepting, say) is not kept: the database
/// fault tests judge what the service answered.
pub fn read_until(
    base: &str,
    paths: &[String],
    first: usize,
    pause: Duration,
    stop: &std::sync::atomic::AtomicBool,
    answers: &std::sync::Mutex<Vec<Answer>>,
) {
    let c = client();
    let mut i = first;
    while !stop.load(Ordering::Relaxed) {
        let path = &paths[i % paths.len()];
        i += 1;
        let Ok(r) = c.get(format!("{base}{path}")).send() else {
            continue;
        };
        let status = r.status().as_u16();
        let retry_after = r.headers().contains_key("retry-after");
        let text = r.text().unwrap_or_default();
        answers.lock().expect("answers").push(Answer {
            path: path.clone(),
            status,
            retry_after,
            text,
        });
        std::thread::sleep(pause);
    }
}

/// Every answer is a 200 or a 503 that says when to try again and that nothing was changed:
/// a database fault is never a 500.
pub fn assert_200_or_503(answers: &[Answer]) {
    for a in answers {
        assert!(
            a.status == 200 || a.status == 503,
            "{} answered {}: {}",
            a.path,
            a.status,
            a.text
        );
        if a.status == 503 {
            assert!(a.retry_after, "{}: a 503 without Retry-After", a.path);
            assert!(
                a.text.contains("nothing was changed"),
                "{}: {}",
                a.path,
                a.text
            );
        }
    }
}

/// `poseboard submit FILE --method METHOD --dataset DATASET --json` as the account `tester`
/// of `server`, which waits for the scores; its last line, the submission as it ended.
pub fn submit_and_wait(server: &Server, file: &Path, method: &str, dataset: &str) -> Value {
    let out = Command::new(BIN)
        .arg("submit")
        .arg(file)
        .args(["--method", method, "--dataset", dataset, "--json"])
        .env("POSEBOARD_SERVER", &server.base)
        .env("POSEBOARD_TOKEN", &server.token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "submit {method}: {}{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let last = stdout.lines().last().expect("a last line");
    serde_json::from_str(last).expect("JSON")
}
