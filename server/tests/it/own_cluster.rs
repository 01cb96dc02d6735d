//! A PostgreSQL server stopped and started again while the service evaluates (issue 29,
//! point 1): the test makes a PostgreSQL cluster of its own (`initdb` in a temporary folder,
//! `pg_ctl` on a free port), runs `poseboard serve` against it, and stops and starts that
//! cluster twice, each time while a job is being evaluated, as readers browse and `poseboard
//! submit` uploads. No answer is a 500; each upload ends done once, with the scores `poseboard
//! eval` gives. `it::db_faults` kills connections of a database that stays up; here the
//! database itself goes away, refusing every connection, and comes back.
//!
//! The cluster belongs to the operating system's `postgres` account when the tests run as root
//! (`initdb` refuses root); without PostgreSQL's server binaries the test says it is skipped.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::common::{
    Answer, TestDb, assert_200_or_503, cli_report, column, pg_exec, read_until, start,
    submit_and_wait, synth_with_results,
};
use serde_json::Value;

/// A PostgreSQL cluster in a temporary folder, stopped at once when this goes away.
struct Cluster {
    bin: PathBuf,
    /// Holds the cluster's files, its socket and its log; owned by the cluster's account.
    dir: tempfile::TempDir,
    port: u16,
    /// Run the server's binaries as `postgres` (this process is root).
    as_postgres: bool,
}

impl Cluster {
    /// The server binaries of the newest PostgreSQL installed the Debian way.
    fn binaries() -> Option<PathBuf> {
        let mut found: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
            .ok()?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let version = e.file_name().to_string_lossy().parse::<u32>().ok()?;
                let bin = e.path().join("bin");
                (bin.join("initdb").is_file() && bin.join("pg_ctl").is_file())
                    .then_some((version, bin))
            })
            .collect();
        found.sort();
        found.pop().map(|(_, bin)| bin)
    }

    /// Makes a cluster (trust authentication, superuser `postgres`) to be served on a free
    /// port; `None`, having said so, without PostgreSQL's binaries.
    fn create() -> Option<Cluster> {
        let Some(bin) = Cluster::binaries() else {
            eprintln!(
                "SKIPPED: no PostgreSQL server binaries (initdb, pg_ctl) in \
                 /usr/lib/postgresql/*/bin to make a cluster of this test's own"
            );
            return None;
        };
        let dir = tempfile::tempdir().expect("tmp");
        let as_postgres = std::fs::metadata("/proc/self")
            .map(|m| std::os::unix::fs::MetadataExt::uid(&m) == 0)
            .expect("this process's owner");
        if as_postgres {
            let id = |flag: &str| -> u32 {
                let out = Command::new("id")
                    .args([flag, "postgres"])
                    .output()
                    .expect("id runs");
                assert!(
                    out.status.success(),
                    "no account `postgres` to run PostgreSQL"
                );
                String::from_utf8_lossy(&out.stdout)
                    .trim()
                    .parse()
                    .expect("an id")
            };
            std::os::unix::fs::chown(dir.path(), Some(id("-u")), Some(id("-g"))).expect("chown");
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .expect("a free port")
            .local_addr()
            .expect("address")
            .port();
        let cluster = Cluster {
            bin,
            dir,
            port,
            as_postgres,
        };
        let out = cluster.run(
            "initdb",
            &[
                "--pgdata",
                &cluster.path("pgdata"),
                "--auth=trust",
                "--username=postgres",
                "--encoding=UTF8",
                "--locale=C",
                "--no-sync",
            ],
        );
        assert!(out.status.success(), "initdb: {}", text(&out));
        Some(cluster)
    }

    fn path(&self, name: &str) -> String {
        self.dir.path().join(name).display().to_string()
    }

    /// Runs one of PostgreSQL's binaries as the cluster's account.
    fn run(&self, program: &str, args: &[&str]) -> Output {
        let program = self.bin.join(program);
        let mut cmd = if self.as_postgres {
            let mut cmd = Command::new("runuser");
            cmd.args(["-u", "postgres", "--"]).arg(program);
            cmd
        } else {
            Command::new(program)
        };
        cmd.args(args)
            .current_dir(self.dir.path())
            .stdin(Stdio::null())
            .output()
            .expect("a PostgreSQL binary runs")
    }

    /// Starts the server and waits until it takes connections.
    fn start(&self) {
        let options = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=off",
            self.port,
            self.dir.path().display()
        );
        let (pgdata, log) = (self.path("pgdata"), self.path("server.log"));
        let out = self.run(
            "pg_ctl",
            &["start", "--wait", "-D", &pgdata, "-l", &log, "-o", &options],
        );
        assert!(
            out.status.success(),
            "pg_ctl start: {}\n{}",
            text(&out),
            std::fs::read_to_string(&log).unwrap_or_default()
        );
    }

    /// Stops the server with `mode` (`fast`: connections are ended; `immediate`: no clean
    /// shutdown) and waits until it is gone.
    fn stop(&self, mode: &str) -> Output {
        let pgdata = self.path("pgdata");
        self.run("pg_ctl", &["stop", "--wait", "-D", &pgdata, "-m", mode])
    }

    fn url(&self, database: &str) -> String {
        format!("postgres://postgres@127.0.0.1:{}/{database}", self.port)
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        self.stop("immediate");
    }
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Waits until a job of the database at `db` is being evaluated.
fn until_running(db: &TestDb, data: &Path) {
    let start = Instant::now();
    while column(
        db,
        data,
        "SELECT CAST(id AS TEXT) FROM submissions WHERE status = 'running'",
    )
    .is_empty()
    {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no job ran within two minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_restarted_postgresql_answers_503_never_500() {
    let Some(cluster) = Cluster::create() else {
        return;
    };
    cluster.start();
    pg_exec(&cluster.url("postgres"), "CREATE DATABASE poseboard");
    let db = TestDb::at(cluster.url("poseboard"));
    let dir = tempfile::tempdir().expect("tmp");
    // Evaluations of a few seconds each, so that the database can go away during one.
    let (datasets, results) = synth_with_results(dir.path(), "synthbig", 20, 10);
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &["--no-demo", "--eval-threads", "1"]);
    let base = server.base.clone();
    let files: Vec<&PathBuf> = results
        .iter()
        .filter(|p| {
            let name = p.to_string_lossy();
            name.contains("noisy") || name.contains("precise") || name.contains("rough")
        })
        .collect();
    assert_eq!(files.len(), 3, "{results:?}");

    let paths = [
        "/api/v1/submissions".to_string(),
        "/api/v1/leaderboards/bop19?dataset=synthbig".to_string(),
        "/leaderboards/bop19?dataset=synthbig".to_string(),
        "/api/v1/methods".to_string(),
        "/".to_string(),
    ];
    let stop = AtomicBool::new(false);
    let answers: Mutex<Vec<Answer>> = Mutex::new(Vec::new());
    let submitted: Vec<(PathBuf, Value)> = std::thread::scope(|s| {
        for reader in 0..3 {
            let (paths, stop, answers, base) = (&paths, &stop, &answers, &base);
            let pause = Duration::from_millis(20);
            s.spawn(move || read_until(base, paths, reader, pause, stop, answers));
        }
        let uploads = s.spawn(|| {
            files
                .iter()
                .map(|file| {
                    let name = file.file_name().expect("name").to_string_lossy();
                    let method = name.split('_').next().expect("method");
                    let printed = submit_and_wait(&server, file, method, "synthbig");
                    ((*file).clone(), printed)
                })
                .collect::<Vec<_>>()
        });
        // Twice: the database goes away while a job is evaluated, and comes back.
        for _ in 0..2 {
            until_running(&db, &data);
            std::thread::sleep(Duration::from_millis(300));
            let out = cluster.stop("fast");
            assert!(out.status.success(), "pg_ctl stop: {}", text(&out));
            std::thread::sleep(Duration::from_secs(2));
            cluster.start();
        }
        let submitted = uploads.join().expect("uploads");
        stop.store(true, Ordering::Relaxed);
        submitted
    });

    let answers = answers.into_inner().expect("answers");
    assert!(answers.len() > 20, "only {} reads", answers.len());
    assert_200_or_503(&answers);

    // Each upload done once, with the scores of `poseboard eval`.
    let dataset = datasets.join("synthbig");
    for (file, printed) in &submitted {
        assert_eq!(printed["status"], "done", "{file:?}: {printed}");
        let id = printed["id"].as_i64().expect("id");
        let report = cli_report(&dataset, file, "bop19");
        for key in ["bop19_average_recall", "obj_average_recalls"] {
            assert_eq!(
                printed["scores"]["bop19"][key], report[key],
                "{file:?} {key}"
            );
        }
        let count = |sql: String| column(&db, &data, &sql).concat();
        let submissions = count(format!(
            "SELECT CAST(COUNT(*) AS TEXT) FROM submissions WHERE method_id = \
             (SELECT method_id FROM submissions WHERE id = {id})"
        ));
        let scores = count(format!(
            "SELECT CAST(COUNT(*) AS TEXT) FROM scores WHERE submission_id = {id}"
        ));
        assert_eq!(
            (submissions.as_str(), scores.as_str()),
            ("1", "2"),
            "{file:?}: one submission, scored once under each of its two protocols"
        );
    }
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    assert_eq!(log.matches("request failed").count(), 0, "{log}");
    drop(server);
}
