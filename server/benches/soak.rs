//! Soak benchmark (issue 29): the real release `poseboard serve` under mixed load for an hour,
//! watched for leaks. Users upload valid files (BOP CSV, BOP'22 JSON, a zip) and malformed ones
//! (bad lines, NaN, a zip of garbage, random bytes named `.zip`, a broken JSON entry, a body
//! over the size limit) while a worker evaluates throughout; one user keeps uploading past the
//! fair-use limit; 50 readers cycle over every board (page and JSON), compare pages, target
//! pictures, exports, pages and the API; browsers sign in through the form and out with its
//! CSRF token; someone keeps guessing a password and sending a made-up API token.
//!
//! Every sample interval it records the server's (and on PostgreSQL the worker's) resident
//! memory and open files, the database connections (PostgreSQL: `pg_stat_activity` rows of the
//! service's database; SQLite: the server's descriptors of the database files; both counted
//! as the least of a few readings, see [`READINGS`]), and the requests done, refused as
//! intended (422, 413, 429, 401) and failed, per kind. It prints them, writes `soak.csv`,
//! `kinds.csv`, `failures.txt` and the plot `soak.svg`, and at the end checks that memory and
//! open files are within 10 % of the reference sample (the tenth minute, or 1/6 of a shorter
//! run) and connections at most 10 % above it, that nothing failed other than the intended
//! refusals, and that evaluations finished in every interval; it exits non-zero otherwise.
//!
//! What the service holds stays the same size, so that growth in the figures is the service's
//! and not the data's: each uploader deletes its older submissions (keeping two per dataset),
//! and the user past the limit those that left the fair-use window.
//!
//! `cargo bench -p server --bench soak` runs on SQLite, the server evaluating in-process as it
//! does alone; with `POSEBOARD_BENCH_POSTGRES=postgres://...` (a database the benchmark may
//! create others from) on PostgreSQL, as deployed to scale out: `serve --workers 0` and one
//! `poseboard worker`. `POSEBOARD_SOAK_MINUTES` (60) is the length, `POSEBOARD_SOAK_SAMPLE_SECS`
//! (60) the sampling interval, `POSEBOARD_SOAK_PAUSE_MS` (500) each reader's pause between
//! requests, `POSEBOARD_SOAK_OUT` the folder of the files and the logs (default
//! `target/soak/sqlite` or `target/soak/postgres`).

mod common;

use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use reqwest::Client;
use reqwest::header::{ACCEPT_ENCODING, CONTENT_TYPE, LOCATION, ORIGIN, RETRY_AFTER};
use reqwest::multipart::{Form, Part};
use serde_json::Value;
use server::demo::{SynthOptions, write_dataset, write_demo_coco_results, write_demo_results};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use common::{PgDb, Res, Server, env_num};

const BIN: &str = env!("CARGO_BIN_EXE_poseboard");
const READERS: usize = 50;
const UPLOADERS: [&str; 4] = ["uploader1", "uploader2", "uploader3", "uploader4"];
const CURATOR: &str = "curator";
const GREEDY: &str = "greedy";
/// The account whose password is guessed; it never signs in.
const VICTIM: &str = "victim";
/// The synthetic dataset: large enough that a job takes seconds, so the worker is busy.
const SYNTH: &str = "synthsoak";
/// Fair use, small so that the greedy user meets it at once and again after each window.
const PER_WINDOW: u64 = 4;
const WINDOW_SECS: u64 = 120;
const MAX_UPLOAD_MB: u64 = 4;
/// Submissions an uploader keeps per dataset; older ones are deleted.
const KEEP: usize = 2;
/// Generous, as the machine is shared: a slow answer is not a failure, a missing one is.
const CLIENT_TIMEOUT: Duration = Duration::from_secs(120);
/// How long an upload may wait for its scores before that counts as a failure.
const EVALUATION_TIMEOUT: Duration = Duration::from_secs(600);
const TOLERANCE: f64 = 0.10;

fn main() -> Res<()> {
    // `cargo bench` passes `--bench`; a plain `cargo test` of the benches passes nothing and
    // must not run for an hour.
    if !std::env::args().any(|a| a == "--bench") {
        println!(
            "soak: run with `cargo bench -p server --bench soak` (POSEBOARD_SOAK_MINUTES, \
             POSEBOARD_SOAK_SAMPLE_SECS, POSEBOARD_BENCH_POSTGRES; see server/benches/soak.rs)"
        );
        return Ok(());
    }
    let minutes = env_num("POSEBOARD_SOAK_MINUTES", 60).max(1);
    let settings = Settings {
        length: Duration::from_secs(minutes * 60),
        every: Duration::from_secs(env_num("POSEBOARD_SOAK_SAMPLE_SECS", 60).max(1)),
        pause: Duration::from_millis(env_num("POSEBOARD_SOAK_PAUSE_MS", 500)),
    };
    let postgres = std::env::var("POSEBOARD_BENCH_POSTGRES").ok();
    let out = std::env::var_os("POSEBOARD_SOAK_OUT")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../target/soak")
                .join(if postgres.is_some() {
                    "postgres"
                } else {
                    "sqlite"
                })
        });
    std::fs::create_dir_all(&out)?;
    let work = tempfile::tempdir()?;
    let files = Files::write(work.path())?;
    let pg = match &postgres {
        Some(admin) => Some(PgDb::create(admin, "soak")?),
        None => None,
    };
    let data = work.path().join("data");
    std::fs::create_dir_all(&data)?;
    let db_url = pg.as_ref().map(|p| p.url.as_str());
    let mut tokens = BTreeMap::new();
    for user in UPLOADERS.iter().chain(&[CURATOR, GREEDY, VICTIM]) {
        tokens.insert(*user, account(&data, db_url, user)?);
    }
    let processes = Processes::start(&data, &files.datasets, db_url, &out)?;
    println!(
        "poseboard soak: {}, {minutes} min, a sample every {} s, {READERS} readers ({} ms \
         between requests), {} uploaders and one past the fair-use limit, {} cores",
        if pg.is_some() {
            "PostgreSQL (serve --workers 0 and one poseboard worker)"
        } else {
            "SQLite (the server's own worker)"
        },
        settings.every.as_secs(),
        settings.pause.as_millis(),
        UPLOADERS.len(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let watched = Watched {
        server: processes.server.child.id(),
        worker: processes.worker.as_ref().map(|w| w.0.id()),
        postgres: postgres.clone().zip(pg.as_ref().map(|p| p.name.clone())),
    };
    let run = rt.block_on(drive(
        processes.server.addr,
        Arc::new(files),
        Arc::new(tokens),
        &settings,
        &watched,
    ))?;
    drop(processes);
    drop(pg);
    let reasons = report(&run, &settings, &out)?;
    for (name, file) in [("server", "server.log"), ("worker", "worker.log")] {
        if let Ok(log) = std::fs::read_to_string(out.join(file)) {
            let errors = log.lines().filter(|l| l.contains("ERROR")).count();
            let warnings = log.lines().filter(|l| l.contains("WARN")).count();
            println!("{name} log: {errors} error and {warnings} warning lines ({file})");
        }
    }
    println!("figures in {}", out.display());
    if reasons.is_empty() {
        println!("PASS");
        Ok(())
    } else {
        println!("FAIL");
        for r in &reasons {
            println!("  - {r}");
        }
        std::process::exit(1);
    }
}

struct Settings {
    length: Duration,
    every: Duration,
    pause: Duration,
}

/// The datasets and the files the users send.
struct Files {
    datasets: PathBuf,
    /// The reference fixture's results, on `synthA`.
    reference_csv: String,
    reference_medium_csv: String,
    synth_csv: String,
    synth_precise_csv: String,
    synth_masks_json: String,
    synth_boxes_json: String,
    bad_lines_csv: Vec<u8>,
    nan_csv: Vec<u8>,
}

impl Files {
    /// The reference fixture as `synthA` and a synthetic dataset with its demo results.
    fn write(dir: &Path) -> Res<Files> {
        let datasets = dir.join("datasets");
        std::fs::create_dir_all(&datasets)?;
        let reference = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference");
        std::os::unix::fs::symlink(
            reference.join("dataset").canonicalize()?,
            datasets.join("synthA"),
        )?;
        let synth = datasets.join(SYNTH);
        write_dataset(
            &synth,
            &SynthOptions {
                scenes: 12,
                images_per_scene: 8,
                ..SynthOptions::default()
            },
        )?;
        let results = dir.join("results");
        let mut demo = BTreeMap::new();
        for d in write_demo_results(&synth, &results, 11)?
            .into_iter()
            .chain(write_demo_coco_results(&synth, &results, 11)?)
        {
            demo.insert(d.method, std::fs::read_to_string(&d.path)?);
        }
        let mut demo_file = |name: &str| demo.remove(name).ok_or(format!("no demo file {name}"));
        let fixture = |name: &str| std::fs::read(reference.join("results").join(name));
        Ok(Files {
            datasets,
            reference_csv: String::from_utf8(fixture("noisesmall_synthA-test.csv")?)?,
            reference_medium_csv: String::from_utf8(fixture("noisemedium_synthA-test.csv")?)?,
            synth_csv: demo_file("demo-noisy")?,
            synth_precise_csv: demo_file("demo-precise")?,
            synth_masks_json: demo_file("demo-segmenter")?,
            synth_boxes_json: demo_file("demo-detector")?,
            bad_lines_csv: fixture("malformed/wrong-columns_synthA-test.csv")?,
            nan_csv: fixture("malformed/nan_synthA-test.csv")?,
        })
    }

    /// The `kind`-th valid upload (by rotation), made a new file by `n`: its dataset (for the
    /// quota), form fields and file.
    fn valid(&self, kind: usize, n: u64) -> Upload {
        match kind % 4 {
            0 => Upload::new(
                "synthA",
                "csv",
                "soak_synthA-test.csv",
                vary_csv(&self.reference_csv, n),
            ),
            1 => Upload::new(
                SYNTH,
                "csv",
                "soak_synthsoak-test.csv",
                vary_csv(&self.synth_csv, n),
            ),
            2 => Upload::new(
                SYNTH,
                "masks",
                "soak_synthsoak-test.json",
                vary_json(&self.synth_masks_json, n),
            ),
            _ => {
                let mut upload = Upload::new(
                    "synthA",
                    "zip",
                    "soak-zip.zip",
                    zip_of("soak_synthA-test.csv", &vary_csv(&self.reference_csv, n)),
                );
                // A zip names its datasets in its entries.
                upload.dataset_field = false;
                upload
            }
        }
    }

    /// The `kind`-th malformed upload: its name and its file (the oversize one is not a file:
    /// see [`oversize`]).
    fn malformed(&self, kind: usize) -> Option<Upload> {
        let garbage: Vec<u8> = (0..4096).map(|_| rand::random::<u8>()).collect();
        Some(match kind % 6 {
            0 => Upload::new("synthA", "bad", "soak_synthA-test.csv", self.bad_lines_csv.clone()),
            1 => Upload::new("synthA", "bad", "soak_synthA-test.csv", self.nan_csv.clone()),
            2 => {
                let mut upload = Upload::new(
                    "synthA",
                    "bad",
                    "soak-garbage.zip",
                    zip_of("soak_synthA-test.csv", &garbage),
                );
                upload.dataset_field = false;
                upload
            }
            3 => Upload::new("synthA", "bad", "soak_synthA-test.zip", garbage),
            4 => Upload::new(
                SYNTH,
                "bad",
                "soak_synthsoak-test.json",
                br#"[{"scene_id": 1, "image_id": 0, "category_id": "one", "score": 0.5, "bbox": [1, 2, 3, 4], "time": 0.1}]"#.to_vec(),
            ),
            _ => return None,
        })
    }
}

/// One upload: the dataset it is for, the suffix of its method's name, and its file.
struct Upload {
    dataset: &'static str,
    method: &'static str,
    file_name: &'static str,
    bytes: Vec<u8>,
    /// Whether the form names the dataset (a zip's entries do instead).
    dataset_field: bool,
}

impl Upload {
    fn new(
        dataset: &'static str,
        method: &'static str,
        file_name: &'static str,
        bytes: Vec<u8>,
    ) -> Upload {
        Upload {
            dataset,
            method,
            file_name,
            bytes,
            dataset_field: true,
        }
    }

    /// The upload as `token` sends it through the API, for the method `method`.
    fn request(
        self,
        client: &Client,
        base: &str,
        token: &str,
        method: &str,
    ) -> reqwest::RequestBuilder {
        let mut form = Form::new()
            .text("method", method.to_string())
            .text("visibility", "public");
        if self.dataset_field {
            form = form.text("dataset", self.dataset);
        }
        let part = Part::bytes(self.bytes).file_name(self.file_name);
        client
            .post(format!("{base}/api/v1/submissions"))
            .bearer_auth(token)
            .multipart(form.part("file", part))
    }
}

/// `csv` with the score of its first estimate changed to one only `n` gives: a new file, as a
/// re-sent one would be answered with the submission it made before.
fn vary_csv(csv: &str, n: u64) -> Vec<u8> {
    let first = csv.find('\n').map_or(0, |i| i + 1);
    let end = first + csv[first..].find('\n').unwrap_or(csv.len() - first);
    let mut cols: Vec<&str> = csv[first..end].split(',').collect();
    let score = format!("0.{:09}", n + 1);
    if cols.len() > 3 {
        cols[3] = &score;
    }
    format!("{}{}{}", &csv[..first], cols.join(","), &csv[end..]).into_bytes()
}

/// `json` (BOP'22 entries) with its first entry's score changed to one only `n` gives.
fn vary_json(json: &str, n: u64) -> Vec<u8> {
    let mut entries: Value = serde_json::from_str(json).unwrap_or(Value::Null);
    if let Some(first) = entries.get_mut(0) {
        first["score"] = Value::from(0.5 + (n + 1) as f64 * 1e-9);
    }
    serde_json::to_vec(&entries).unwrap_or_default()
}

/// A zip archive of one entry.
fn zip_of(name: &str, bytes: &[u8]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    let written = w
        .start_file(name, options)
        .and_then(|()| w.write_all(bytes).map_err(Into::into));
    match written.and_then(|()| w.finish()) {
        Ok(cursor) => cursor.into_inner(),
        Err(_) => Vec::new(),
    }
}

fn password(user: &str) -> String {
    format!("{user}-soak-password")
}

/// Creates `user` with `poseboard admin`, as an operator would, and returns an API token of it.
fn account(data: &Path, db_url: Option<&str>, user: &str) -> Res<String> {
    let file = data.join(format!("{user}.pw"));
    std::fs::write(&file, password(user))?;
    let file = file.to_str().ok_or("a UTF-8 path")?;
    admin(
        data,
        db_url,
        &["create-user", user, "--password-file", file],
    )?;
    admin(data, db_url, &["create-token", user])
}

fn admin(data: &Path, db_url: Option<&str>, args: &[&str]) -> Res<String> {
    let mut cmd = Command::new(BIN);
    cmd.arg("admin")
        .arg("--data-dir")
        .arg(data)
        .args(args)
        .env_remove("DATABASE_URL");
    if let Some(url) = db_url {
        cmd.env("DATABASE_URL", url);
    }
    let out = cmd.output()?;
    if !out.status.success() {
        return Err(format!(
            "poseboard admin {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        )
        .into());
    }
    Ok(String::from_utf8(out.stdout)?.trim().to_string())
}

/// The service's processes: the server, and on PostgreSQL a separate worker.
struct Processes {
    server: Server,
    worker: Option<Worker>,
}

/// A `poseboard worker`, killed when dropped.
struct Worker(Child);

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Processes {
    fn start(data: &Path, datasets: &Path, db_url: Option<&str>, out: &Path) -> Res<Processes> {
        let log = |name: &str| -> Res<Stdio> { Ok(std::fs::File::create(out.join(name))?.into()) };
        let per_window = PER_WINDOW.to_string();
        let window = WINDOW_SECS.to_string();
        let max_upload = MAX_UPLOAD_MB.to_string();
        let mut cmd = Command::new(BIN);
        cmd.args(["serve", "--bind", "127.0.0.1:0"])
            .args(["--submissions-per-window", &per_window])
            .args(["--limit-window-secs", &window])
            .args(["--max-upload-mb", &max_upload])
            .arg("--data-dir")
            .arg(data)
            .arg("--datasets")
            .arg(datasets)
            .env("RUST_LOG", "warn")
            .env_remove("DATABASE_URL")
            .stderr(log("server.log")?);
        if let Some(url) = db_url {
            cmd.args(["--workers", "0"]).env("DATABASE_URL", url);
        }
        let server = Server::spawn(&mut cmd)?;
        let worker = match db_url {
            Some(url) => Some(Worker(
                Command::new(BIN)
                    // One evaluation thread: it shares the machine with the server, as the
                    // server's own worker does.
                    .args(["worker", "--eval-threads", "1"])
                    .arg("--data-dir")
                    .arg(data)
                    .arg("--datasets")
                    .arg(datasets)
                    .env("RUST_LOG", "warn")
                    .env("DATABASE_URL", url)
                    .stdout(Stdio::null())
                    .stderr(log("worker.log")?)
                    .spawn()?,
            )),
            None => None,
        };
        Ok(Processes { server, worker })
    }
}

/// What is sampled: the processes and, on PostgreSQL, the admin URL and the service's database.
struct Watched {
    server: u32,
    worker: Option<u32>,
    postgres: Option<(String, String)>,
}

/// Requests of one kind.
#[derive(Clone, Copy, Debug, Default)]
struct Counts {
    done: u64,
    /// Intended refusals: the service said no, as it should.
    refused: u64,
    failed: u64,
}

impl Counts {
    fn total(&self) -> u64 {
        self.done + self.refused + self.failed
    }
}

/// The outcome of every request so far, shared by the clients.
struct Tally {
    start: Instant,
    kinds: Mutex<BTreeMap<&'static str, Counts>>,
    /// What failed, as told (the first thousand).
    failures: Mutex<Vec<String>>,
    /// Uploads seen scored.
    evaluated: AtomicU64,
}

const KEPT_FAILURES: usize = 1000;

impl Tally {
    fn count(&self, kind: &'static str, f: impl FnOnce(&mut Counts)) {
        if let Ok(mut kinds) = self.kinds.lock() {
            f(kinds.entry(kind).or_default());
        }
    }

    fn done(&self, kind: &'static str) {
        self.count(kind, |c| c.done += 1);
    }

    fn refused(&self, kind: &'static str) {
        self.count(kind, |c| c.refused += 1);
    }

    fn failed(&self, kind: &'static str, what: String) {
        self.count(kind, |c| c.failed += 1);
        if let Ok(mut failures) = self.failures.lock()
            && failures.len() < KEPT_FAILURES
        {
            failures.push(format!(
                "{:>7.1} s  {kind}: {what}",
                self.start.elapsed().as_secs_f64()
            ));
        }
    }

    fn kinds(&self) -> BTreeMap<&'static str, Counts> {
        self.kinds.lock().map(|k| k.clone()).unwrap_or_default()
    }
}

/// An answer that was expected (done or an intended refusal).
struct Answer {
    status: u16,
    headers: reqwest::header::HeaderMap,
    body: Vec<u8>,
}

impl Answer {
    fn json(&self) -> Option<Value> {
        serde_json::from_slice(&self.body).ok()
    }
}

/// Sends `request` and counts its answer under `kind`: done when its status is in `ok`, an
/// intended refusal when in `refused`, otherwise (another status, no answer, a cut body) a
/// failure, told with the request and what came back. Returns the expected answers.
async fn exchange(
    tally: &Tally,
    client: &Client,
    kind: &'static str,
    request: reqwest::RequestBuilder,
    ok: &[u16],
    refused: &[u16],
) -> Option<Answer> {
    let request = match request.build() {
        Ok(r) => r,
        Err(e) => {
            tally.failed(kind, format!("request not built: {e}"));
            return None;
        }
    };
    let what = format!(
        "{} {}{}",
        request.method(),
        request.url().path(),
        request
            .url()
            .query()
            .map(|q| format!("?{q}"))
            .unwrap_or_default()
    );
    let response = match client.execute(request).await {
        Ok(r) => r,
        Err(e) => {
            tally.failed(kind, format!("{what}: {e:?}"));
            return None;
        }
    };
    let status = response.status().as_u16();
    let headers = response.headers().clone();
    let body = match response.bytes().await {
        Ok(b) => b.to_vec(),
        Err(e) => {
            tally.failed(kind, format!("{what}: {status}, body cut: {e:?}"));
            return None;
        }
    };
    if ok.contains(&status) {
        tally.done(kind);
    } else if refused.contains(&status) {
        tally.refused(kind);
    } else {
        let text = String::from_utf8_lossy(&body[..body.len().min(300)]).into_owned();
        tally.failed(kind, format!("{what}: answered {status}: {text}"));
        return None;
    }
    Some(Answer {
        status,
        headers,
        body,
    })
}

fn client() -> Res<Client> {
    Ok(Client::builder()
        .timeout(CLIENT_TIMEOUT)
        // Below the server's idle timeout (60 s): a connection is never reused just as the
        // server closes it.
        .pool_idle_timeout(Duration::from_secs(20))
        .redirect(reqwest::redirect::Policy::none())
        .build()?)
}

/// What every client task needs.
#[derive(Clone)]
struct Ctx {
    base: String,
    addr: std::net::SocketAddr,
    tally: Arc<Tally>,
    stop: Arc<AtomicBool>,
    files: Arc<Files>,
    tokens: Arc<BTreeMap<&'static str, String>>,
    /// Makes every upload a new file.
    uploads: Arc<AtomicU64>,
}

impl Ctx {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    fn token(&self, user: &str) -> &str {
        self.tokens.get(user).map_or("", String::as_str)
    }

    /// Sleeps `d`, or less when the run ends first.
    async fn pause(&self, d: Duration) {
        let end = Instant::now() + d;
        while !self.stopped() && Instant::now() < end {
            tokio::time::sleep((end - Instant::now()).min(Duration::from_millis(500))).await;
        }
    }

    /// Follows submission `id` until it is scored: `Some(true)` once done, `Some(false)` when it
    /// failed or took too long (both counted as failures), `None` when the run ended first.
    async fn scored(&self, client: &Client, user: &str, id: i64) -> Option<bool> {
        let started = Instant::now();
        loop {
            if self.stopped() {
                return None;
            }
            if started.elapsed() > EVALUATION_TIMEOUT {
                self.tally.failed(
                    "evaluation",
                    format!("submission {id} not scored within {EVALUATION_TIMEOUT:?}"),
                );
                return Some(false);
            }
            let request = client
                .get(format!("{}/api/v1/submissions/{id}", self.base))
                .bearer_auth(self.token(user));
            let status = exchange(&self.tally, client, "own submission", request, &[200], &[])
                .await
                .and_then(|a| a.json())
                .and_then(|v| v["status"].as_str().map(str::to_string));
            match status.as_deref() {
                Some("done") => {
                    self.tally.done("evaluation");
                    self.tally.evaluated.fetch_add(1, Ordering::Relaxed);
                    return Some(true);
                }
                Some("failed") => {
                    self.tally
                        .failed("evaluation", format!("submission {id} failed to evaluate"));
                    return Some(false);
                }
                _ => tokio::time::sleep(Duration::from_millis(500)).await,
            }
        }
    }

    /// Deletes submission `id` of `user`.
    async fn delete(&self, client: &Client, user: &str, id: i64) {
        let request = client
            .delete(format!("{}/api/v1/submissions/{id}", self.base))
            .bearer_auth(self.token(user));
        exchange(&self.tally, client, "delete", request, &[200], &[]).await;
    }

    fn next_upload(&self) -> u64 {
        self.uploads.fetch_add(1, Ordering::Relaxed)
    }
}

/// The whole run: the curated submissions, then every client until the end, sampling.
async fn drive(
    addr: std::net::SocketAddr,
    files: Arc<Files>,
    tokens: Arc<BTreeMap<&'static str, String>>,
    settings: &Settings,
    watched: &Watched,
) -> Res<Run> {
    let ctx = Ctx {
        base: format!("http://{addr}"),
        addr,
        tally: Arc::new(Tally {
            start: Instant::now(),
            kinds: Mutex::default(),
            failures: Mutex::default(),
            evaluated: AtomicU64::new(0),
        }),
        stop: Arc::new(AtomicBool::new(false)),
        files,
        tokens,
        uploads: Arc::new(AtomicU64::new(0)),
    };
    let routes = Arc::new(curate(&ctx).await?);
    let mut pg = match &watched.postgres {
        Some((admin, _)) => {
            use sqlx::Connection;
            Some(sqlx::PgConnection::connect(admin).await?)
        }
        None => None,
    };
    // The clock starts now: the warm-up above is not part of the run.
    let ctx = Ctx {
        tally: Arc::new(Tally {
            start: Instant::now(),
            kinds: Mutex::default(),
            failures: Mutex::default(),
            evaluated: AtomicU64::new(0),
        }),
        ..ctx
    };
    let mut tasks = Vec::new();
    for i in 0..READERS {
        tasks.push(tokio::spawn(reader(
            ctx.clone(),
            routes.clone(),
            i,
            settings.pause,
        )));
    }
    for (i, user) in UPLOADERS.iter().enumerate() {
        tasks.push(tokio::spawn(uploader(ctx.clone(), user, i)));
    }
    tasks.push(tokio::spawn(greedy(ctx.clone())));
    tasks.push(tokio::spawn(sign_ins(ctx.clone())));
    tasks.push(tokio::spawn(intruder(ctx.clone())));

    print_header(watched.worker.is_some());
    let mut samples = Vec::new();
    let start = ctx.tally.start;
    let mut k = 0u32;
    loop {
        let at = (settings.every * k).min(settings.length);
        tokio::time::sleep_until(tokio::time::Instant::from_std(start + at)).await;
        let sample = sample(&ctx.tally, at, watched, pg.as_mut()).await?;
        print_row(&sample);
        samples.push(sample);
        if at >= settings.length {
            break;
        }
        k += 1;
    }
    ctx.stop.store(true, Ordering::Relaxed);
    for t in tasks {
        if tokio::time::timeout(CLIENT_TIMEOUT + Duration::from_secs(30), t)
            .await
            .is_err()
        {
            ctx.tally
                .failed("bench", "a client did not stop after the run".to_string());
        }
    }
    Ok(Run {
        samples,
        kinds: ctx.tally.kinds(),
        failures: ctx
            .tally
            .failures
            .lock()
            .map(|f| f.clone())
            .unwrap_or_default(),
        postgres: watched.worker.is_some(),
    })
}

/// One route a reader reads, and what it should answer.
struct Route {
    kind: &'static str,
    path: String,
    /// Asks for gzip, as browsers do (pages).
    gzip: bool,
    /// The answer must be a PNG picture.
    png: bool,
}

impl Route {
    fn new(kind: &'static str, path: String) -> Route {
        let gzip = !path.starts_with("/api/") && !path.contains("/export.");
        Route {
            kind,
            path,
            gzip,
            png: false,
        }
    }
}

/// The curator's public submissions, the same all run long: two on each dataset to compare
/// and a 2D one per task, scored before the run starts. Returns what the readers read.
async fn curate(ctx: &Ctx) -> Res<Vec<Route>> {
    let client = client()?;
    let f = &ctx.files;
    let token = ctx.token(CURATOR);
    let mut ids = BTreeMap::new();
    for (method, dataset, name, body, protocol) in [
        (
            "curated-small",
            "synthA",
            "small_synthA-test.csv",
            &f.reference_csv,
            None,
        ),
        (
            "curated-medium",
            "synthA",
            "medium_synthA-test.csv",
            &f.reference_medium_csv,
            None,
        ),
        (
            "curated-noisy",
            SYNTH,
            "noisy_synthsoak-test.csv",
            &f.synth_csv,
            None,
        ),
        (
            "curated-precise",
            SYNTH,
            "precise_synthsoak-test.csv",
            &f.synth_precise_csv,
            None,
        ),
        (
            "curated-masks",
            SYNTH,
            "masks_synthsoak-test.json",
            &f.synth_masks_json,
            None,
        ),
        (
            "curated-boxes",
            SYNTH,
            "boxes_synthsoak-test.json",
            &f.synth_boxes_json,
            Some("bop22-det"),
        ),
    ] {
        let mut form = Form::new()
            .text("method", method)
            .text("dataset", dataset)
            .text("visibility", "public")
            .part(
                "file",
                Part::bytes(body.clone().into_bytes()).file_name(name),
            );
        if let Some(p) = protocol {
            form = form.text("protocol", p);
        }
        let r = client
            .post(format!("{}/api/v1/submissions", ctx.base))
            .bearer_auth(token)
            .multipart(form)
            .send()
            .await?;
        let status = r.status();
        let v: Value = r.json().await?;
        if status.as_u16() != 202 {
            return Err(format!("curated upload {method}: {status} {v}").into());
        }
        ids.insert(method, v["id"].as_i64().ok_or("an id")?);
    }
    for (method, id) in &ids {
        if ctx.scored(&client, CURATOR, *id).await != Some(true) {
            return Err(format!("curated submission {method} was not scored").into());
        }
    }
    let id = |m: &str| ids.get(m).copied().unwrap_or_default();
    let (small, medium, noisy, precise) = (
        id("curated-small"),
        id("curated-medium"),
        id("curated-noisy"),
        id("curated-precise"),
    );
    let mut routes = vec![
        Route::new("page", "/".to_string()),
        Route::new("page", "/datasets".to_string()),
    ];
    for board in ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] {
        routes.push(Route::new("board", format!("/leaderboards/{board}")));
        routes.push(Route::new("board", format!("/api/v1/leaderboards/{board}")));
        routes.push(Route::new(
            "export",
            format!("/leaderboards/{board}/export.csv"),
        ));
        routes.push(Route::new(
            "export",
            format!("/leaderboards/{board}/export.json"),
        ));
    }
    for dataset in ["synthA", SYNTH] {
        routes.push(Route::new(
            "board",
            format!("/leaderboards/bop19?dataset={dataset}"),
        ));
        routes.push(Route::new(
            "board",
            format!("/api/v1/leaderboards/eccv18?dataset={dataset}"),
        ));
    }
    for (a, b) in [(small, medium), (noisy, precise)] {
        routes.push(Route::new("compare", format!("/compare?a={a}&b={b}")));
        routes.push(Route::new(
            "compare",
            format!("/api/v1/compare?a={a}&b={b}"),
        ));
        routes.push(Route::new(
            "compare",
            format!("/compare?a={a}&b={b}&protocol=eccv18"),
        ));
    }
    for s in [small, noisy] {
        routes.push(Route::new("page", format!("/submissions/{s}")));
        routes.push(Route::new("page", format!("/submissions/{s}/targets")));
        routes.push(Route::new(
            "api",
            format!("/api/v1/submissions/{s}/targets"),
        ));
        let gallery = client
            .get(format!("{}/api/v1/submissions/{s}/targets", ctx.base))
            .send()
            .await?
            .json::<Value>()
            .await?;
        let worst = gallery["objects"]
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|o| o["worst"].as_array().into_iter().flatten().take(1));
        for target in worst.take(3) {
            let (Some(page), Some(picture)) =
                (target["url"].as_str(), target["image_url"].as_str())
            else {
                return Err(format!("a target without its addresses: {target}").into());
            };
            routes.push(Route::new("page", page.to_string()));
            for path in [picture.to_string(), format!("{picture}?crop=object")] {
                routes.push(Route {
                    png: true,
                    ..Route::new("picture", path)
                });
            }
        }
    }
    let submission: Value = client
        .get(format!("{}/api/v1/submissions/{small}", ctx.base))
        .send()
        .await?
        .json()
        .await?;
    let method = submission["method_id"].as_i64().ok_or("a method id")?;
    routes.push(Route::new("page", format!("/methods/{method}")));
    for path in [
        format!("/api/v1/submissions/{small}"),
        format!("/api/v1/submissions/{noisy}/report"),
        format!("/api/v1/methods/{method}"),
        "/api/v1/methods".to_string(),
        "/api/v1/datasets".to_string(),
        "/api/v1/submissions".to_string(),
    ] {
        routes.push(Route::new("api", path));
    }
    Ok(routes)
}

/// A reader: every route in turn from its own place in the list, with a pause between two.
async fn reader(ctx: Ctx, routes: Arc<Vec<Route>>, i: usize, pause: Duration) {
    let Ok(client) = client() else {
        ctx.tally.failed("bench", "no HTTP client".to_string());
        return;
    };
    let mut n = i * 7;
    while !ctx.stopped() {
        let route = &routes[n % routes.len()];
        n += 1;
        let mut request = client.get(format!("{}{}", ctx.base, route.path));
        if route.gzip {
            request = request.header(ACCEPT_ENCODING, "gzip, deflate, br");
        }
        if let Some(answer) = exchange(&ctx.tally, &client, route.kind, request, &[200], &[]).await
            && route.png
        {
            let typed = answer
                .headers
                .get(CONTENT_TYPE)
                .is_some_and(|v| v.as_bytes() == b"image/png");
            if !typed || !answer.body.starts_with(b"\x89PNG\r\n\x1a\n") {
                ctx.tally
                    .failed(route.kind, format!("GET {}: not a PNG picture", route.path));
            }
        }
        ctx.pause(pause).await;
    }
}

/// An uploader that keeps to the fair-use limit: it asks its quota first and waits when none
/// is left; it uploads the valid files in turn, follows each to its scores, deletes what is
/// beyond [`KEEP`] per dataset, and sends a malformed file after each.
async fn uploader(ctx: Ctx, user: &'static str, i: usize) {
    let Ok(client) = client() else {
        ctx.tally.failed("bench", "no HTTP client".to_string());
        return;
    };
    let mut kept: BTreeMap<&str, VecDeque<i64>> = BTreeMap::new();
    let mut round = i;
    while !ctx.stopped() {
        let upload = ctx.files.valid(round, ctx.next_upload());
        let dataset = upload.dataset;
        let quota = client
            .get(format!("{}/api/v1/me/quota?dataset={dataset}", ctx.base))
            .bearer_auth(ctx.token(user));
        let Some(quota) = exchange(&ctx.tally, &client, "quota", quota, &[200], &[])
            .await
            .and_then(|a| a.json())
        else {
            ctx.pause(Duration::from_secs(1)).await;
            continue;
        };
        if quota["left"].as_u64() == Some(0) {
            let wait = quota["next_at"].as_i64().unwrap_or_default() - server::clock::now_ms();
            ctx.pause(Duration::from_millis(wait.clamp(100, 600_000) as u64))
                .await;
            continue;
        }
        let method = format!("{user}-{}", upload.method);
        let request = upload.request(&client, &ctx.base, ctx.token(user), &method);
        let accepted = exchange(&ctx.tally, &client, "upload", request, &[202], &[])
            .await
            .and_then(|a| a.json())
            .and_then(|v| v["id"].as_i64());
        if let Some(id) = accepted
            && ctx.scored(&client, user, id).await.is_some()
        {
            let mine = kept.entry(dataset).or_default();
            mine.push_back(id);
            while mine.len() > KEEP {
                if let Some(old) = mine.pop_front() {
                    ctx.delete(&client, user, old).await;
                }
            }
        }
        malformed(&ctx, &client, user, round).await;
        round += 1;
        ctx.pause(Duration::from_secs(1)).await;
    }
}

/// The `kind`-th malformed upload of `user`: refused naming the problem (422), or over the size
/// limit (413).
async fn malformed(ctx: &Ctx, client: &Client, user: &str, kind: usize) {
    match ctx.files.malformed(kind) {
        Some(upload) => {
            let request = upload.request(client, &ctx.base, ctx.token(user), "broken");
            exchange(&ctx.tally, client, "malformed upload", request, &[], &[422]).await;
        }
        None => match oversize(ctx.addr, ctx.token(user)).await {
            Ok(413) => ctx.tally.refused("upload over the size limit"),
            Ok(status) => ctx.tally.failed(
                "upload over the size limit",
                format!("POST /api/v1/submissions: answered {status}"),
            ),
            Err(e) => ctx.tally.failed(
                "upload over the size limit",
                format!("POST /api/v1/submissions: {e}"),
            ),
        },
    }
}

/// An upload that announces a body over the size limit: the answer's status, which must come
/// before any of the body is sent.
async fn oversize(addr: std::net::SocketAddr, token: &str) -> Res<u16> {
    let talk = async {
        let mut stream = tokio::net::TcpStream::connect(addr).await?;
        let head = format!(
            "POST /api/v1/submissions HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {token}\r\n\
             Content-Type: multipart/form-data; boundary=soak\r\nContent-Length: {}\r\n\r\n",
            (MAX_UPLOAD_MB + 1) << 20
        );
        stream.write_all(head.as_bytes()).await?;
        let mut answer = Vec::new();
        let mut buf = [0u8; 1024];
        while !answer.contains(&b'\n') {
            let n = stream.read(&mut buf).await?;
            if n == 0 {
                break;
            }
            answer.extend_from_slice(&buf[..n]);
        }
        Ok::<_, std::io::Error>(answer)
    };
    let answer = tokio::time::timeout(CLIENT_TIMEOUT, talk).await??;
    let line = String::from_utf8_lossy(&answer);
    Ok(line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("no status line: {line:?}"))?)
}

/// A user who uploads every few seconds without looking at the quota: over the limit it gets
/// 429 with `Retry-After`. It deletes its submissions once scored and out of the window, so
/// that it meets the limit again in the next.
async fn greedy(ctx: Ctx) {
    const KIND: &str = "upload past the limit";
    let Ok(client) = client() else {
        ctx.tally.failed("bench", "no HTTP client".to_string());
        return;
    };
    let mut mine: VecDeque<(i64, i64)> = VecDeque::new();
    let mut round = 0;
    while !ctx.stopped() {
        let cutoff = server::clock::now_ms() - (WINDOW_SECS * 1000) as i64;
        while let Some(&(id, created)) = mine.front()
            && created < cutoff
        {
            if ctx.scored(&client, GREEDY, id).await.is_none() {
                return;
            }
            ctx.delete(&client, GREEDY, id).await;
            mine.pop_front();
        }
        // The two kinds of CSV, one per dataset.
        let upload = ctx.files.valid(round % 2, ctx.next_upload());
        round += 1;
        let request = upload.request(&client, &ctx.base, ctx.token(GREEDY), "greedy");
        if let Some(answer) = exchange(&ctx.tally, &client, KIND, request, &[202], &[429]).await {
            let v = answer.json().unwrap_or_default();
            if answer.status == 202 {
                let id = v["id"].as_i64().unwrap_or_default();
                let created = v["submission"]["created_at"].as_i64().unwrap_or_default();
                mine.push_back((id, created));
            } else if !answer.headers.contains_key(RETRY_AFTER) || v["retry_at"].as_i64().is_none()
            {
                ctx.tally
                    .failed(KIND, format!("a 429 without when to retry: {v}"));
            }
        }
        ctx.pause(Duration::from_secs(5)).await;
    }
}

/// Browsers signing in through the form in turn as each uploader (a new browser each time):
/// the account page with its CSRF token, their submissions, now and then a malformed file
/// through the upload form, and signing out with the token.
async fn sign_ins(ctx: Ctx) {
    const KIND: &str = "sign-in";
    let mut round = 0usize;
    while !ctx.stopped() {
        let user = UPLOADERS[round % UPLOADERS.len()];
        if let Err(e) = sign_in(&ctx, user, round.is_multiple_of(3)).await {
            ctx.tally.failed(KIND, e.to_string());
        }
        round += 1;
        ctx.pause(Duration::from_secs(3)).await;
    }
}

/// One browser's visit; an `Err` is a failure not counted yet.
async fn sign_in(ctx: &Ctx, user: &str, form_upload: bool) -> Res<()> {
    const KIND: &str = "sign-in";
    let browser = Client::builder()
        .cookie_store(true)
        .timeout(CLIENT_TIMEOUT)
        .redirect(reqwest::redirect::Policy::none())
        .build()?;
    let (t, base) = (&ctx.tally, &ctx.base);
    let page = |path: &str| browser.get(format!("{base}{path}"));
    if exchange(t, &browser, KIND, page("/login"), &[200], &[])
        .await
        .is_none()
    {
        return Ok(());
    }
    let pw = password(user);
    let login = browser
        .post(format!("{base}/login"))
        .header(ORIGIN, base.as_str())
        .form(&[("name", user), ("password", &pw), ("next", "/account")]);
    let Some(signed) = exchange(t, &browser, KIND, login, &[303], &[]).await else {
        return Ok(());
    };
    if signed.headers.get(LOCATION).map(|v| v.as_bytes()) != Some(b"/account") {
        return Err(format!("signed in {user} but sent elsewhere: {:?}", signed.headers).into());
    }
    let Some(account) = exchange(t, &browser, KIND, page("/account"), &[200], &[]).await else {
        return Ok(());
    };
    let html = String::from_utf8_lossy(&account.body);
    let needle = "name=\"csrf\" value=\"";
    let csrf = html
        .find(needle)
        .and_then(|at| html[at + needle.len()..].split('"').next())
        .ok_or("the account page has no CSRF token")?
        .to_string();
    exchange(t, &browser, KIND, page("/me/submissions"), &[200], &[]).await;
    if form_upload {
        let form = Form::new()
            .text("csrf", csrf.clone())
            .text("method", "form-broken")
            .text("dataset", "synthA")
            .part(
                "file",
                Part::bytes(ctx.files.bad_lines_csv.clone()).file_name("form_synthA-test.csv"),
            );
        let submit = browser
            .post(format!("{base}/submit"))
            .header(ORIGIN, base.as_str())
            .multipart(form);
        exchange(t, &browser, "malformed upload (form)", submit, &[], &[422]).await;
    }
    let logout = browser
        .post(format!("{base}/logout"))
        .header(ORIGIN, base.as_str())
        .form(&[("csrf", csrf.as_str())]);
    exchange(t, &browser, KIND, logout, &[303], &[]).await;
    // Signed out: the account page sends the browser to sign in.
    exchange(t, &browser, KIND, page("/account"), &[303], &[]).await;
    Ok(())
}

/// Someone from another address guessing the victim's password (401, then 429 once over the
/// address's or the account's limit) and sending a made-up API token (401).
async fn intruder(ctx: Ctx) {
    let Ok(client) = Client::builder()
        .timeout(CLIENT_TIMEOUT)
        .local_address(std::net::IpAddr::from([127, 0, 0, 2]))
        .redirect(reqwest::redirect::Policy::none())
        .build()
    else {
        ctx.tally.failed("bench", "no HTTP client".to_string());
        return;
    };
    let mut n = 0u64;
    while !ctx.stopped() {
        let guess = format!("guess-{n}");
        let login = client
            .post(format!("{}/login", ctx.base))
            .header(ORIGIN, ctx.base.as_str())
            .form(&[("name", VICTIM), ("password", &guess), ("next", "/account")]);
        exchange(
            &ctx.tally,
            &client,
            "wrong password",
            login,
            &[],
            &[401, 429],
        )
        .await;
        let forged = client
            .get(format!("{}/api/v1/me/submissions", ctx.base))
            .bearer_auth(format!("made-up-token-{n}"));
        exchange(&ctx.tally, &client, "made-up token", forged, &[], &[401]).await;
        n += 1;
        ctx.pause(Duration::from_secs(10)).await;
    }
}

/// Resident memory and open files of a process.
#[derive(Clone, Copy, Debug, Default)]
struct ProcStat {
    rss_kib: u64,
    fds: u64,
}

fn proc_stat(pid: u32) -> Res<ProcStat> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let rss_kib = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .ok_or("no VmRSS: the process has ended")?;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd"))?.count() as u64;
    Ok(ProcStat { rss_kib, fds })
}

/// The server's descriptors of the SQLite database files (the database, its WAL and its
/// shared memory: three per connection).
fn sqlite_fds(pid: u32) -> Res<u64> {
    let mut n = 0;
    for fd in std::fs::read_dir(format!("/proc/{pid}/fd"))? {
        let Ok(target) = std::fs::read_link(fd?.path()) else {
            continue;
        };
        if target
            .file_name()
            .and_then(|f| f.to_str())
            .is_some_and(|f| f.starts_with("poseboard.db"))
        {
            n += 1;
        }
    }
    Ok(n)
}

struct Sample {
    at: Duration,
    server: ProcStat,
    worker: Option<ProcStat>,
    db: u64,
    kinds: BTreeMap<&'static str, Counts>,
    evaluated: u64,
}

impl Sample {
    fn totals(&self) -> Counts {
        self.kinds.values().fold(Counts::default(), |a, c| Counts {
            done: a.done + c.done,
            refused: a.refused + c.refused,
            failed: a.failed + c.failed,
        })
    }
}

/// Readings per sample: open files and connections are counted this many times, 100 ms apart,
/// and the least count is kept. A leak raises that floor; a descriptor open for an instant (a
/// request's socket, a temporary file, a connection the pool is just replacing) does not, and
/// on SQLite, whose counts are a handful, one such descriptor would be a 10 % change.
const READINGS: usize = 5;

async fn sample(
    tally: &Tally,
    at: Duration,
    watched: &Watched,
    mut pg: Option<&mut sqlx::PgConnection>,
) -> Res<Sample> {
    let mut floor: Option<(u64, u64, Option<u64>)> = None;
    for reading in 0..READINGS {
        if reading > 0 {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let db = match (pg.as_deref_mut(), &watched.postgres) {
            (Some(conn), Some((_, name))) => {
                let n: i64 =
                    sqlx::query_scalar("SELECT count(*) FROM pg_stat_activity WHERE datname = $1")
                        .bind(name)
                        .fetch_one(conn)
                        .await?;
                n as u64
            }
            _ => sqlite_fds(watched.server)?,
        };
        let server = proc_stat(watched.server)?.fds;
        let worker = watched.worker.map(proc_stat).transpose()?.map(|w| w.fds);
        floor = Some(match floor {
            None => (db, server, worker),
            Some((d, s, w)) => (
                d.min(db),
                s.min(server),
                w.zip(worker).map(|(a, b)| a.min(b)),
            ),
        });
    }
    let (db, server_fds, worker_fds) = floor.ok_or("no reading")?;
    let mut server = proc_stat(watched.server)?;
    server.fds = server_fds;
    let mut worker = watched.worker.map(proc_stat).transpose()?;
    if let (Some(w), Some(fds)) = (worker.as_mut(), worker_fds) {
        w.fds = fds;
    }
    Ok(Sample {
        at,
        server,
        worker,
        db,
        kinds: tally.kinds(),
        evaluated: tally.evaluated.load(Ordering::Relaxed),
    })
}

fn mib(kib: u64) -> f64 {
    kib as f64 / 1024.0
}

fn print_header(worker: bool) {
    println!(
        "{:>6} {:>11} {:>9} {:>11} {:>9} {:>8} {:>9} {:>8} {:>7} {:>9}",
        "min",
        "server MiB",
        "srv files",
        if worker { "worker MiB" } else { "" },
        if worker { "wkr files" } else { "" },
        "db conns",
        "requests",
        "refused",
        "failed",
        "evaluated"
    );
}

fn print_row(s: &Sample) {
    let t = s.totals();
    let (wrss, wfds) = match s.worker {
        Some(w) => (format!("{:.1}", mib(w.rss_kib)), w.fds.to_string()),
        None => (String::new(), String::new()),
    };
    println!(
        "{:>6.1} {:>11.1} {:>9} {:>11} {:>9} {:>8} {:>9} {:>8} {:>7} {:>9}",
        s.at.as_secs_f64() / 60.0,
        mib(s.server.rss_kib),
        s.server.fds,
        wrss,
        wfds,
        s.db,
        t.total(),
        t.refused,
        t.failed,
        s.evaluated
    );
}

struct Run {
    samples: Vec<Sample>,
    /// At the end, after every client stopped.
    kinds: BTreeMap<&'static str, Counts>,
    failures: Vec<String>,
    postgres: bool,
}

/// Prints the requests per kind and what failed, writes the files, and returns the reasons to
/// fail (none: PASS).
fn report(run: &Run, settings: &Settings, out: &Path) -> Res<Vec<String>> {
    println!(
        "\n{:<28} {:>9} {:>9} {:>8}",
        "requests", "done", "refused", "failed"
    );
    for (kind, c) in &run.kinds {
        println!("{kind:<28} {:>9} {:>9} {:>8}", c.done, c.refused, c.failed);
    }
    for f in run.failures.iter().take(20) {
        println!("failed: {f}");
    }
    write_files(run, out)?;
    let Some(end) = run.samples.last() else {
        return Ok(vec!["no sample was taken".to_string()]);
    };
    // The tenth minute of an hour; 1/6 of a shorter run.
    let reference_at = (settings.length / 6).min(Duration::from_secs(600));
    let reference = run
        .samples
        .iter()
        .find(|s| s.at >= reference_at)
        .unwrap_or(end);
    let mut reasons = Vec::new();
    let minute = reference.at.as_secs_f64() / 60.0;
    let mut within = |what: &str, unit: &str, start: f64, end: f64| {
        let change = (end - start) / start.max(f64::MIN_POSITIVE);
        let line = format!(
            "{what}: {start:.1}{unit} at minute {minute:.1}, {end:.1}{unit} at the end ({:+.1} %)",
            change * 100.0
        );
        println!("{line}");
        if change.abs() > TOLERANCE {
            reasons.push(format!("{line}: beyond {:.0} %", TOLERANCE * 100.0));
        }
    };
    within(
        "server memory",
        " MiB",
        mib(reference.server.rss_kib),
        mib(end.server.rss_kib),
    );
    within(
        "server open files",
        "",
        reference.server.fds as f64,
        end.server.fds as f64,
    );
    if let (Some(r), Some(e)) = (reference.worker, end.worker) {
        within("worker memory", " MiB", mib(r.rss_kib), mib(e.rss_kib));
        within("worker open files", "", r.fds as f64, e.fds as f64);
    }
    // The pools open connections on demand and close those idle for ten minutes or older than
    // thirty, so their count follows the load between none and the pools' bound: a leaked
    // connection raises it (or, held at the bound, fails requests, which is checked below),
    // while a pool shedding idle ones lowers it and is no fault. Only a rise fails.
    let (db_start, db_end) = (reference.db as f64, end.db as f64);
    let change = (db_end - db_start) / db_start.max(f64::MIN_POSITIVE);
    let line = format!(
        "database connections: {db_start:.1} at minute {minute:.1}, {db_end:.1} at the end ({:+.1} %)",
        change * 100.0
    );
    println!("{line}");
    if change > TOLERANCE {
        reasons.push(format!(
            "{line}: more than {:.0} % above",
            TOLERANCE * 100.0
        ));
    }
    let failed: u64 = run.kinds.values().map(|c| c.failed).sum();
    if failed > 0 {
        reasons.push(format!(
            "{failed} requests failed other than as intended (failures.txt)"
        ));
    }
    for pair in run.samples.windows(2) {
        if pair[1].evaluated == pair[0].evaluated {
            reasons.push(format!(
                "no evaluation finished between minute {:.1} and {:.1}",
                pair[0].at.as_secs_f64() / 60.0,
                pair[1].at.as_secs_f64() / 60.0
            ));
        }
    }
    if reference.at == end.at {
        reasons.push("the run is too short for a reference sample before its end".to_string());
    }
    Ok(reasons)
}

fn write_files(run: &Run, out: &Path) -> Res<()> {
    let mut csv = String::from(
        "elapsed_s,server_rss_kib,server_fds,worker_rss_kib,worker_fds,db_connections,\
         requests,refused,failed,evaluated\n",
    );
    let mut kinds = String::from("elapsed_s,kind,done,refused,failed\n");
    for s in &run.samples {
        let t = s.totals();
        let (wrss, wfds) = s
            .worker
            .map(|w| (w.rss_kib.to_string(), w.fds.to_string()))
            .unwrap_or_default();
        writeln!(
            csv,
            "{},{},{},{wrss},{wfds},{},{},{},{},{}",
            s.at.as_secs(),
            s.server.rss_kib,
            s.server.fds,
            s.db,
            t.total(),
            t.refused,
            t.failed,
            s.evaluated
        )?;
        for (kind, c) in &s.kinds {
            writeln!(
                kinds,
                "{},{kind},{},{},{}",
                s.at.as_secs(),
                c.done,
                c.refused,
                c.failed
            )?;
        }
    }
    std::fs::write(out.join("soak.csv"), csv)?;
    std::fs::write(out.join("kinds.csv"), kinds)?;
    std::fs::write(out.join("failures.txt"), run.failures.join("\n"))?;
    std::fs::write(out.join("soak.svg"), plot(run))?;
    Ok(())
}

/// A step of about a quarter of `max` that reads well: 1, 2 or 5 times a power of ten.
fn nice_step(max: f64) -> f64 {
    let rough = (max / 4.0).max(1e-9);
    let power = 10f64.powf(rough.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|s| *s >= rough)
        .unwrap_or(10.0 * power)
}

/// `v` with as many decimals as `step` needs.
fn tick(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

/// The plot of the run: memory above, open files and database connections below, over minutes.
fn plot(run: &Run) -> String {
    const W: f64 = 720.0;
    const PANEL: f64 = 200.0;
    const LEFT: f64 = 60.0;
    const RIGHT: f64 = 700.0;
    let minutes = run
        .samples
        .last()
        .map_or(1.0, |s| s.at.as_secs_f64() / 60.0)
        .max(1.0 / 60.0);
    let x = |at: Duration| LEFT + (RIGHT - LEFT) * at.as_secs_f64() / 60.0 / minutes;
    let mut memory = vec![(
        "server",
        "#1f77b4",
        run.samples
            .iter()
            .map(|s| (s.at, mib(s.server.rss_kib)))
            .collect::<Vec<_>>(),
    )];
    let mut files = vec![(
        "server",
        "#1f77b4",
        run.samples
            .iter()
            .map(|s| (s.at, s.server.fds as f64))
            .collect::<Vec<_>>(),
    )];
    if run.postgres {
        let worker = |f: fn(ProcStat) -> f64| {
            run.samples
                .iter()
                .filter_map(|s| s.worker.map(|w| (s.at, f(w))))
                .collect::<Vec<_>>()
        };
        memory.push(("worker", "#ff7f0e", worker(|w| mib(w.rss_kib))));
        files.push(("worker", "#ff7f0e", worker(|w| w.fds as f64)));
    }
    files.push((
        "database connections",
        "#2ca02c",
        run.samples.iter().map(|s| (s.at, s.db as f64)).collect(),
    ));
    let mut svg = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {W} {}\" \
         font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" \
         fill=\"white\"/>\n",
        2.0 * PANEL + 70.0
    );
    for (i, (title, lines)) in [("resident memory (MiB)", memory), ("open files", files)]
        .into_iter()
        .enumerate()
    {
        let top = 20.0 + i as f64 * (PANEL + 20.0);
        let bottom = top + PANEL - 40.0;
        let max = lines
            .iter()
            .flat_map(|(_, _, p)| p.iter().map(|(_, v)| *v))
            .fold(1.0, f64::max)
            * 1.1;
        let step = nice_step(max);
        let top_value = (max / step).ceil() * step;
        let y = |v: f64| bottom - (bottom - top) * v / top_value;
        let _ = writeln!(
            svg,
            "<text x=\"{LEFT}\" y=\"{}\" font-weight=\"bold\">{title}</text>",
            top - 6.0
        );
        let mut v = 0.0;
        while v <= top_value + step / 2.0 {
            let _ = writeln!(
                svg,
                "<line x1=\"{LEFT}\" x2=\"{RIGHT}\" y1=\"{0:.1}\" y2=\"{0:.1}\" stroke=\"#ddd\"/>\
                 <text x=\"{1}\" y=\"{2:.1}\" text-anchor=\"end\">{3}</text>",
                y(v),
                LEFT - 6.0,
                y(v) + 4.0,
                tick(v, step)
            );
            v += step;
        }
        let minute_step = nice_step(minutes);
        let mut m = 0.0;
        while m <= minutes + 1e-9 {
            let _ = writeln!(
                svg,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                x(Duration::from_secs_f64(m * 60.0)),
                bottom + 14.0,
                tick(m, minute_step)
            );
            m += minute_step;
        }
        let _ = writeln!(
            svg,
            "<text x=\"{RIGHT}\" y=\"{:.1}\" text-anchor=\"end\">minutes</text>",
            bottom + 28.0
        );
        for (j, (label, colour, points)) in lines.iter().enumerate() {
            let path: Vec<String> = points
                .iter()
                .map(|(at, v)| format!("{:.1},{:.1}", x(*at), y(*v)))
                .collect();
            let _ = writeln!(
                svg,
                "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\" points=\"{}\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\" fill=\"{colour}\">{label}</text>",
                path.join(" "),
                LEFT + 200.0 + 150.0 * j as f64,
                top - 6.0
            );
        }
    }
    svg.push_str("</svg>\n");
    svg
}
