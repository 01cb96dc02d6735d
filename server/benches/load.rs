//! Load benchmark: a real `poseboard serve` (the release build) with a 200-submission
//! leaderboard, driven by 100 concurrent keep-alive clients per route, idle and while large
//! jobs evaluate, once as the service ran before the board cache (`--board-cache-mb 0`, the
//! evaluation pool on every core) and once as it runs now. Prints requests per second and the
//! 50th and 99th percentile latencies per route.
//!
//! `cargo bench -p server --bench load` (SQLite); with `POSEBOARD_BENCH_POSTGRES=postgres://...`
//! (a database the benchmark may create others from) it runs on PostgreSQL instead.
//! `POSEBOARD_BENCH_SECS` (default 10) is each measurement's length, `POSEBOARD_BENCH_CLIENTS`
//! (100) the connections, `POSEBOARD_BENCH_SCENES` (default 60) the size of the dataset the
//! large jobs evaluate.
//!
//! The clients speak HTTP/1.1 by hand on one thread: a general client (reqwest) would take a
//! larger share of the two cores the server has to share with it, and measure itself.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::{Dataset, NoProgress, Report, evaluate, results::load_results};
use server::demo::{SynthOptions, write_dataset, write_demo_results};
use server::domain::{
    Hardware, MethodName, Modality, SubmissionId, TokenLabel, TrainingData, UserName,
};
use server::preflight::Preflight;
use server::store::Store;
use server::store::methods::MethodMeta;
use server::store::queue::Finished;
use server::store::submissions::{Created, NewSubmission};
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader as AsyncBufReader};
use tokio::net::TcpStream;

use common::{PgDb, Res, Server, env_num};

const BOARD_SUBMISSIONS: usize = 200;
const LARGE: &str = "synthlarge";

fn main() -> Res<()> {
    // `cargo bench` passes `--bench`; a plain `cargo test` of the benches passes nothing and
    // must not run for minutes.
    if !std::env::args().any(|a| a == "--bench") {
        println!("load: run with `cargo bench -p server --bench load`");
        return Ok(());
    }
    let secs = env_num("POSEBOARD_BENCH_SECS", 10);
    let clients = env_num("POSEBOARD_BENCH_CLIENTS", 100) as usize;
    let scenes = env_num("POSEBOARD_BENCH_SCENES", 60) as u32;
    let postgres = std::env::var("POSEBOARD_BENCH_POSTGRES").ok();
    let work = tempfile::tempdir()?;
    let datasets = work.path().join("datasets");
    std::fs::create_dir_all(&datasets)?;
    let reference = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference");
    std::os::unix::fs::symlink(
        reference.join("dataset").canonicalize()?,
        datasets.join("synthA"),
    )?;
    let large = datasets.join(LARGE);
    write_dataset(
        &large,
        &SynthOptions {
            seed: 5,
            scenes,
            images_per_scene: 8,
            ..SynthOptions::default()
        },
    )?;
    let large_results = write_demo_results(&large, &work.path().join("large-results"), 3)?;
    let upload_csv = std::fs::read_to_string(reference.join("results/noisesmall_synthA-test.csv"))?;
    let reports = reference_reports(&reference)?;
    println!(
        "poseboard load benchmark: {} database, {BOARD_SUBMISSIONS} public submissions on one \
         dataset, {clients} keep-alive clients, {secs} s per measurement, {} cores",
        if postgres.is_some() {
            "PostgreSQL"
        } else {
            "SQLite"
        },
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:<7} {:<5} {:<40} {:>8} {:>9} {:>9} {:>7}",
        "server", "state", "route", "req/s", "p50 ms", "p99 ms", "errors"
    );
    let mut all = Vec::new();
    for (label, flags) in [
        (
            "before",
            vec![
                "--board-cache-mb".to_string(),
                "0".to_string(),
                "--eval-threads".to_string(),
                std::thread::available_parallelism()
                    .map_or(1, |n| n.get())
                    .to_string(),
            ],
        ),
        ("after", vec![]),
    ] {
        let run = Run {
            label,
            flags,
            work: work.path().join(label),
            datasets: datasets.clone(),
            postgres: postgres.clone(),
            secs,
            clients,
        };
        all.extend(run.measure(&reports, &large_results, &upload_csv)?);
    }
    println!("\nafter / before:");
    for a in all.iter().filter(|m| m.server == "after") {
        if let Some(b) = all
            .iter()
            .find(|b| b.server == "before" && b.state == a.state && b.route == a.route)
        {
            println!(
                "{:<5} {:<40} {:>7.1}x req/s, p99 {:>8.1} ms -> {:>6.1} ms",
                a.state,
                a.route,
                a.rps / b.rps.max(1e-9),
                b.p99_ms,
                a.p99_ms
            );
        }
    }
    Ok(())
}

/// The reference file's reports, the base of the 200 submissions' scores.
fn reference_reports(reference: &Path) -> Res<Vec<Report>> {
    let dataset = Dataset::load(&reference.join("dataset"))?;
    let results = load_results(&reference.join("results/noisemedium_synthA-test.csv"))?;
    let mut reports = Vec::new();
    for p in [ProtocolName::Bop19, ProtocolName::Eccv18] {
        reports.push(
            evaluate(
                &dataset,
                &results,
                &Protocol::named(p),
                &NoProgress,
                &AtomicBool::new(false),
            )?
            .report,
        );
    }
    Ok(reports)
}

/// The reports scaled by `f`: every submission its own scores, so that the board is ranked.
fn scaled(reports: &[Report], f: f64) -> Vec<Report> {
    reports
        .iter()
        .map(|r| {
            let mut r = r.clone();
            for v in [
                &mut r.bop19_average_recall,
                &mut r.bop19_average_recall_vsd,
                &mut r.bop19_average_recall_mssd,
                &mut r.bop19_average_recall_mspd,
            ]
            .into_iter()
            .flatten()
            {
                *v *= f;
            }
            r.obj_average_recalls.values_mut().for_each(|v| *v *= f);
            if let Some(l) = r.localization.as_mut() {
                l.recall *= f;
                l.obj_recalls.values_mut().for_each(|v| *v *= f);
            }
            r
        })
        .collect()
}

struct Run {
    label: &'static str,
    flags: Vec<String>,
    work: PathBuf,
    datasets: PathBuf,
    postgres: Option<String>,
    secs: u64,
    clients: usize,
}

struct Measured {
    server: &'static str,
    state: &'static str,
    route: String,
    rps: f64,
    p99_ms: f64,
}

impl Run {
    fn measure(
        &self,
        reports: &[Report],
        large_results: &[server::demo::DemoResult],
        upload_csv: &str,
    ) -> Res<Vec<Measured>> {
        std::fs::create_dir_all(&self.work)?;
        let pg = match &self.postgres {
            Some(admin) => Some(PgDb::create(admin, self.label)?),
            None => None,
        };
        let url = pg
            .as_ref()
            .map(|p| p.url.clone())
            .unwrap_or_else(|| server::store::sqlite_url(&self.work));
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        let (token, ids) = rt.block_on(populate(&url, &self.datasets, reports))?;
        let server = self.start(pg.as_ref().map(|p| p.url.as_str()))?;
        let addr = server.addr;
        let mut out = Vec::new();
        let board_id = ids[ids.len() / 2];
        let reads: Vec<Route> = vec![
            Route::get(
                "GET /leaderboards/bop19 (page, gzip)",
                "/leaderboards/bop19",
                true,
            ),
            Route::get(
                "GET /api/v1/leaderboards/bop19 (JSON)",
                "/api/v1/leaderboards/bop19",
                false,
            ),
            Route::get(
                "GET /api/v1/submissions/{id} (API read)",
                &format!("/api/v1/submissions/{board_id}"),
                false,
            ),
        ];
        for route in &reads {
            out.push(self.phase(&rt, addr, "idle", route, None)?);
        }
        // Busy: the large jobs are queued first, so the uploads measured after queue behind them.
        let mut jobs = Vec::new();
        for demo in large_results {
            let body = std::fs::read(&demo.path)?;
            let name = demo
                .path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("r.csv");
            let (status, text) = rt.block_on(one_request(
                addr,
                &upload_request(
                    &token,
                    &format!("large-{}", demo.method),
                    LARGE,
                    name,
                    &body,
                ),
            ))?;
            if !(200..300).contains(&status) {
                return Err(format!("large upload answered {status}: {text}").into());
            }
            let v: serde_json::Value = serde_json::from_str(&text)?;
            jobs.push(v["id"].as_i64().ok_or("an id")?);
        }
        let started = Instant::now();
        while !rt.block_on(any_running(addr, &jobs))? {
            if started.elapsed() > Duration::from_secs(60) {
                return Err("the large job did not start".into());
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let uploads = Route {
            name: "POST /api/v1/submissions (upload)".to_string(),
            request: Arc::new({
                let token = token.clone();
                let csv = upload_csv.to_string();
                move |n| {
                    // A new file each time (a re-upload would answer with the old submission).
                    let first = csv.find('\n').map_or(0, |i| i + 1);
                    let row_end = first + csv[first..].find('\n').unwrap_or(0);
                    let mut cols: Vec<&str> = csv[first..row_end].split(',').collect();
                    let score = format!("0.{:09}", n + 1);
                    if cols.len() > 3 {
                        cols[3] = &score;
                    }
                    let body = format!("{}{}{}", &csv[..first], cols.join(","), &csv[row_end..]);
                    upload_request(
                        &token,
                        "bench-uploads",
                        "synthA",
                        "up_synthA-test.csv",
                        body.as_bytes(),
                    )
                }
            }),
        };
        for route in reads.iter().chain([&uploads]) {
            out.push(self.phase(&rt, addr, "busy", route, Some(&jobs))?);
        }
        drop(server);
        drop(pg);
        Ok(out)
    }

    fn start(&self, database_url: Option<&str>) -> Res<Server> {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_poseboard"));
        cmd.args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--submissions-per-window",
            "0",
        ])
        .arg("--data-dir")
        .arg(&self.work)
        .arg("--datasets")
        .arg(&self.datasets)
        .args(&self.flags)
        .env("RUST_LOG", "warn")
        .env_remove("DATABASE_URL")
        .stderr(Stdio::from(std::fs::File::create(
            self.work.join("server.log"),
        )?));
        if let Some(url) = database_url {
            cmd.env("DATABASE_URL", url);
        }
        Server::spawn(&mut cmd)
    }

    fn phase(
        &self,
        rt: &tokio::runtime::Runtime,
        addr: std::net::SocketAddr,
        state: &'static str,
        route: &Route,
        jobs: Option<&[i64]>,
    ) -> Res<Measured> {
        let stats = rt.block_on(drive(
            addr,
            route.request.clone(),
            self.clients,
            Duration::from_secs(self.secs),
        ));
        let mut note = String::new();
        if let Some(jobs) = jobs
            && !rt.block_on(any_running(addr, jobs))?
        {
            note = "  (no large job running at the end: not all busy)".to_string();
        }
        let rps = stats.ok as f64 / stats.elapsed.as_secs_f64();
        let (p50, p99) = (stats.percentile(0.50), stats.percentile(0.99));
        println!(
            "{:<7} {:<5} {:<40} {:>8.0} {:>9.1} {:>9.1} {:>7}{note}",
            self.label, state, route.name, rps, p50, p99, stats.errors
        );
        Ok(Measured {
            server: self.label,
            state,
            route: route.name.clone(),
            rps,
            p99_ms: p99,
        })
    }
}

/// The account, the datasets and the 200 finished public submissions, written through the
/// store before the server starts (the server's registration of the datasets folder keeps
/// their ids). Returns an API token of the account and the submissions' ids.
async fn populate(
    url: &str,
    datasets: &Path,
    reports: &[Report],
) -> Res<(String, Vec<SubmissionId>)> {
    let store = Store::connect(url).await?;
    store.migrate().await?;
    let reference = Dataset::load(&datasets.join("synthA"))?;
    let ds = store
        .register_dataset(&server::app::describe(&reference, &datasets.join("synthA")))
        .await?;
    let owner = store
        .create_user(
            &UserName::parse("bench")?,
            "$argon2id$not-a-real-hash",
            false,
        )
        .await?;
    let token =
        server::service::accounts::create_token(&store, owner, &TokenLabel::parse("bench")?)
            .await?;
    let protocols = [ProtocolName::Bop19, ProtocolName::Eccv18];
    let hardware = Hardware::parse("a GPU")?;
    let preflight = Preflight::default();
    let mut ids = Vec::new();
    for i in 0..BOARD_SUBMISSIONS {
        let method = MethodName::parse(&format!("Method {i:03}"))?;
        let meta = MethodMeta {
            training_data: Some(
                [
                    TrainingData::Synthetic,
                    TrainingData::Real,
                    TrainingData::Both,
                ][i % 3],
            ),
            modality: Some([Modality::Rgb, Modality::Depth, Modality::RgbD][i % 3]),
            ..MethodMeta::default()
        };
        let sha = format!("{i:064x}");
        let new = NewSubmission {
            owner_id: owner,
            team_id: None,
            method: &method,
            meta: &meta,
            dataset_id: ds.id,
            protocols: &protocols,
            task: None,
            visibility: server::domain::Visibility::Public,
            held: false,
            file_name: "m_synthA-test.csv",
            file_sha256: &sha,
            file_size: 1000,
            // Never read: these jobs are finished with scaled reports, not evaluated.
            file_gzip: &[],
            estimates_count: 100,
            hardware: &hardware,
            preflight: &preflight,
        };
        let Created::New(id) = store.create_submission(&new, None).await? else {
            return Err("a new submission".into());
        };
        let job = store
            .claim("populate", 60_000, 3, &[])
            .await?
            .ok_or("the job just queued")?;
        let f = 0.4 + 0.6 * (i as f64 / BOARD_SUBMISSIONS as f64);
        store
            .finish(
                job.id,
                "populate",
                &Finished {
                    reports: scaled(reports, f),
                    errors: Vec::new(),
                    replicates: Default::default(),
                    eval_ms: 1000,
                    dataset_hash: "load-bench".to_string(),
                },
            )
            .await?;
        ids.push(id);
    }
    Ok((token, ids))
}

/// One route: its name and its request bytes for the n-th request.
struct Route {
    name: String,
    request: Arc<dyn Fn(u64) -> Vec<u8> + Send + Sync>,
}

impl Route {
    fn get(name: &str, path: &str, gzip: bool) -> Route {
        let bytes = format!(
            "GET {path} HTTP/1.1\r\nHost: bench\r\n{}\r\n",
            if gzip {
                "Accept-Encoding: gzip, deflate, br\r\n"
            } else {
                ""
            }
        )
        .into_bytes();
        Route {
            name: name.to_string(),
            request: Arc::new(move |_| bytes.clone()),
        }
    }
}

fn upload_request(token: &str, method: &str, dataset: &str, file: &str, csv: &[u8]) -> Vec<u8> {
    let boundary = "poseboardbenchboundary";
    let mut body = Vec::new();
    for (k, v) in [("method", method), ("dataset", dataset)] {
        body.extend_from_slice(
            format!("--{boundary}\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n")
                .as_bytes(),
        );
    }
    body.extend_from_slice(
        format!(
            "--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{file}\"\r\n\
             Content-Type: text/csv\r\n\r\n"
        )
        .as_bytes(),
    );
    body.extend_from_slice(csv);
    body.extend_from_slice(format!("\r\n--{boundary}--\r\n").as_bytes());
    let mut request = format!(
        "POST /api/v1/submissions HTTP/1.1\r\nHost: bench\r\nAuthorization: Bearer {token}\r\n\
         Content-Type: multipart/form-data; boundary={boundary}\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )
    .into_bytes();
    request.extend_from_slice(&body);
    request
}

/// Whether any of the jobs is being evaluated.
async fn any_running(addr: std::net::SocketAddr, jobs: &[i64]) -> Res<bool> {
    for id in jobs {
        let get = format!("GET /api/v1/submissions/{id} HTTP/1.1\r\nHost: bench\r\n\r\n");
        let (_, text) = one_request(addr, get.as_bytes()).await?;
        let v: serde_json::Value = serde_json::from_str(&text)?;
        if v["status"] == "running" {
            return Ok(true);
        }
    }
    Ok(false)
}

async fn one_request(addr: std::net::SocketAddr, request: &[u8]) -> Res<(u16, String)> {
    let mut conn = AsyncBufReader::new(TcpStream::connect(addr).await?);
    conn.get_mut().write_all(request).await?;
    let mut body = Vec::new();
    let (status, _) = read_response(&mut conn, Some(&mut body)).await?;
    Ok((status, String::from_utf8_lossy(&body).into_owned()))
}

struct Stats {
    latencies_us: Vec<u64>,
    ok: u64,
    errors: u64,
    elapsed: Duration,
}

impl Stats {
    fn percentile(&self, q: f64) -> f64 {
        if self.latencies_us.is_empty() {
            return f64::NAN;
        }
        let i = ((self.latencies_us.len() as f64 * q).ceil() as usize)
            .clamp(1, self.latencies_us.len())
            - 1;
        self.latencies_us[i] as f64 / 1000.0
    }
}

/// `clients` connections, each sending one request after the other for `length`.
async fn drive(
    addr: std::net::SocketAddr,
    request: Arc<dyn Fn(u64) -> Vec<u8> + Send + Sync>,
    clients: usize,
    length: Duration,
) -> Stats {
    let counter = Arc::new(AtomicU64::new(0));
    let start = Instant::now();
    let deadline = start + length;
    let tasks: Vec<_> = (0..clients)
        .map(|_| {
            let (request, counter) = (request.clone(), counter.clone());
            tokio::spawn(async move { client(addr, request, counter, deadline).await })
        })
        .collect();
    let mut stats = Stats {
        latencies_us: Vec::new(),
        ok: 0,
        errors: 0,
        elapsed: Duration::ZERO,
    };
    for t in tasks {
        if let Ok((lat, ok, errors)) = t.await {
            stats.latencies_us.extend(lat);
            stats.ok += ok;
            stats.errors += errors;
        }
    }
    stats.elapsed = start.elapsed();
    stats.latencies_us.sort_unstable();
    stats
}

async fn client(
    addr: std::net::SocketAddr,
    request: Arc<dyn Fn(u64) -> Vec<u8> + Send + Sync>,
    counter: Arc<AtomicU64>,
    deadline: Instant,
) -> (Vec<u64>, u64, u64) {
    let (mut lat, mut ok, mut errors) = (Vec::new(), 0, 0);
    let mut conn: Option<AsyncBufReader<TcpStream>> = None;
    while Instant::now() < deadline {
        let c = match conn.as_mut() {
            Some(c) => c,
            None => match TcpStream::connect(addr).await {
                Ok(s) => {
                    let _ = s.set_nodelay(true);
                    conn.insert(AsyncBufReader::with_capacity(64 * 1024, s))
                }
                Err(_) => {
                    errors += 1;
                    tokio::time::sleep(Duration::from_millis(10)).await;
                    continue;
                }
            },
        };
        let bytes = request(counter.fetch_add(1, Ordering::Relaxed));
        let t0 = Instant::now();
        let answer = tokio::time::timeout(Duration::from_secs(30), async {
            c.get_mut().write_all(&bytes).await?;
            read_response(c, None).await
        })
        .await;
        match answer {
            Ok(Ok((status, keep_alive))) => {
                lat.push(t0.elapsed().as_micros() as u64);
                if (200..300).contains(&status) {
                    ok += 1;
                } else {
                    errors += 1;
                }
                if !keep_alive {
                    conn = None;
                }
            }
            _ => {
                errors += 1;
                conn = None;
            }
        }
    }
    (lat, ok, errors)
}

/// Reads one response: its status and whether the connection stays open; the body goes to
/// `keep` when given, otherwise it is skipped.
async fn read_response(
    c: &mut AsyncBufReader<TcpStream>,
    mut keep: Option<&mut Vec<u8>>,
) -> std::io::Result<(u16, bool)> {
    let bad = |what: &str| std::io::Error::new(std::io::ErrorKind::InvalidData, what.to_string());
    let mut line = Vec::new();
    c.read_until(b'\n', &mut line).await?;
    let status: u16 = std::str::from_utf8(&line)
        .ok()
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| bad("status line"))?;
    let (mut length, mut chunked, mut keep_alive) = (None, false, true);
    loop {
        line.clear();
        if c.read_until(b'\n', &mut line).await? == 0 {
            return Err(bad("headers cut"));
        }
        let text = String::from_utf8_lossy(&line).to_ascii_lowercase();
        let text = text.trim_end();
        if text.is_empty() {
            break;
        }
        if let Some(v) = text.strip_prefix("content-length:") {
            length = v.trim().parse::<usize>().ok();
        } else if text.starts_with("transfer-encoding:") && text.contains("chunked") {
            chunked = true;
        } else if text.starts_with("connection:") && text.contains("close") {
            keep_alive = false;
        }
    }
    if chunked {
        loop {
            line.clear();
            c.read_until(b'\n', &mut line).await?;
            let size = std::str::from_utf8(&line)
                .ok()
                .and_then(|l| l.trim().split(';').next())
                .and_then(|h| usize::from_str_radix(h.trim(), 16).ok())
                .ok_or_else(|| bad("chunk size"))?;
            if size == 0 {
                // Trailers until the empty line.
                loop {
                    line.clear();
                    c.read_until(b'\n', &mut line).await?;
                    if line.trim_ascii().is_empty() {
                        break;
                    }
                }
                break;
            }
            body(c, size, keep.as_deref_mut()).await?;
            line.clear();
            c.read_until(b'\n', &mut line).await?;
        }
    } else if let Some(n) = length {
        body(c, n, keep).await?;
    }
    Ok((status, keep_alive))
}

/// Reads `n` body bytes into `keep`, or skips them.
async fn body(
    c: &mut AsyncBufReader<TcpStream>,
    n: usize,
    keep: Option<&mut Vec<u8>>,
) -> std::io::Result<()> {
    match keep {
        Some(out) => {
            let at = out.len();
            out.resize(at + n, 0);
            c.read_exact(&mut out[at..]).await.map(|_| ())
        }
        None => {
            let copied = tokio::io::copy(&mut c.take(n as u64), &mut tokio::io::sink()).await?;
            if copied as usize == n {
                Ok(())
            } else {
                Err(std::io::ErrorKind::UnexpectedEof.into())
            }
        }
    }
}
