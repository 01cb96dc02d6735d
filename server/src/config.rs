//! Configuration of `poseboard serve` and `poseboard worker`: flags with environment
//! fallbacks and defaults that just work (a SQLite file and a demo dataset in `./poseboard-data`).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::{Args, ValueEnum};

#[derive(Args, Clone, Debug)]
pub struct Config {
    /// Directory for the database file, uploaded result files and the demo dataset.
    #[arg(long, env = "POSEBOARD_DATA_DIR", default_value = "poseboard-data")]
    pub data_dir: PathBuf,
    /// Directory whose subfolders are BOP datasets to serve (default: DATA_DIR/datasets, where
    /// a demo dataset is generated on first start). A worker reads its copies from here, by
    /// dataset name, and never writes to it.
    #[arg(long, env = "POSEBOARD_DATASETS")]
    pub datasets: Option<PathBuf>,
    /// `postgres://...` to use PostgreSQL; default: SQLite in the data directory.
    #[arg(long, env = "DATABASE_URL", hide_env_values = true)]
    pub database_url: Option<String>,
    /// Evaluation workers in this process (`serve --workers 0`: none, the server only takes
    /// uploads and `poseboard worker` processes evaluate).
    #[arg(long, env = "POSEBOARD_WORKERS", default_value_t = 1)]
    pub workers: usize,
    /// Threads of the evaluation pool. Default: every core for `poseboard worker`; one core
    /// fewer (at least one) for `poseboard serve`, whose workers share the machine with the web
    /// threads, so that pages stay quick while a job evaluates.
    #[arg(long, env = "POSEBOARD_EVAL_THREADS")]
    pub eval_threads: Option<usize>,
    /// A worker that has not renewed its lease for this long is taken to be dead.
    #[arg(long, env = "POSEBOARD_LEASE_SECS", default_value_t = 30)]
    pub lease_secs: u64,
    /// Largest accepted result file, in MiB.
    #[arg(long, env = "POSEBOARD_MAX_UPLOAD_MB", default_value_t = 64)]
    pub max_upload_mb: u64,
    /// Submissions a user may make per dataset within the fair-use window (0 = no limit).
    /// Submissions that failed through the service's fault do not count.
    #[arg(long, env = "POSEBOARD_SUBMISSIONS_PER_WINDOW", default_value_t = 5)]
    pub submissions_per_window: u64,
    /// The fair-use window, in seconds (a day by default).
    #[arg(long, env = "POSEBOARD_LIMIT_WINDOW_SECS", default_value_t = 86_400)]
    pub limit_window_secs: u64,
    /// Memory for rendered leaderboards (HTML and JSON), in MiB; 0 renders every request.
    #[arg(long, env = "POSEBOARD_BOARD_CACHE_MB", default_value_t = 32)]
    pub board_cache_mb: u64,
    /// How often, at most, a server looks at the database for board changes made by other
    /// processes (its own are seen at once), in milliseconds.
    #[arg(long, env = "POSEBOARD_BOARD_RECHECK_MS", default_value_t = 250)]
    pub board_recheck_ms: u64,
    /// Do not generate the demo dataset and submissions.
    #[arg(long, env = "POSEBOARD_NO_DEMO")]
    pub no_demo: bool,
    /// `json`: one JSON object per log line, for log collectors.
    #[arg(long, env = "POSEBOARD_LOG_FORMAT", value_enum, default_value_t = LogFormat::Text)]
    pub log_format: LogFormat,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

#[derive(Args, Clone, Debug)]
pub struct ServeConfig {
    /// Address to listen on.
    #[arg(long, env = "POSEBOARD_BIND", default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    #[command(flatten)]
    pub common: Config,
}

impl Config {
    pub fn datasets_dir(&self) -> PathBuf {
        self.datasets
            .clone()
            .unwrap_or_else(|| self.data_dir.join("datasets"))
    }

    pub fn submissions_dir(&self) -> PathBuf {
        self.data_dir.join("submissions")
    }

    pub fn database_url(&self) -> String {
        self.database_url
            .clone()
            .unwrap_or_else(|| crate::store::sqlite_url(&self.data_dir))
    }

    /// The configuration for a server whose workers evaluate beside its web threads: unless
    /// told otherwise, the evaluation pool leaves one core to the web.
    pub fn beside_the_web(mut self) -> Config {
        if self.eval_threads.is_none() {
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            self.eval_threads = Some(cores.saturating_sub(1).max(1));
        }
        self
    }

    pub fn max_upload_bytes(&self) -> u64 {
        self.max_upload_mb.saturating_mul(1 << 20)
    }

    pub fn limit_window_ms(&self) -> i64 {
        self.limit_window_secs.saturating_mul(1000) as i64
    }

    pub fn lease_ms(&self) -> i64 {
        (self.lease_secs.max(1) * 1000) as i64
    }
}
