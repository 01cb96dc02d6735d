//! Configuration of `poseboard serve` and `poseboard worker`: flags with environment
//! fallbacks and defaults that just work (a SQLite file and a demo dataset in `./poseboard-data`).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Args;

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
    /// Threads of the evaluation pool (default: every core).
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
    /// Do not generate the demo dataset and submissions.
    #[arg(long, env = "POSEBOARD_NO_DEMO")]
    pub no_demo: bool,
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
