//! Configuration of `poseboard serve` and `poseboard worker`: flags with environment
//! fallbacks and defaults that just work (a SQLite file and a demo dataset in `./poseboard-data`).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

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
    /// Folder of the datasets' prepared forms (decoded depth and ground-truth renders, a
    /// subfolder per dataset), which the workers of this process make in the background and
    /// evaluate from once complete (default: DATA_DIR/prepared).
    #[arg(long, env = "POSEBOARD_PREPARED_DIR")]
    pub prepared_dir: Option<PathBuf>,
    /// Prepare no dataset: every evaluation reads the dataset itself.
    #[arg(long, env = "POSEBOARD_NO_PREPARE")]
    pub no_prepare: bool,
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
    /// The core datasets (comma-separated names): the columns of the main leaderboards and
    /// what their average is over. Given at start, it sets every dataset's flag (the
    /// administrator's toggle on the datasets page can change them later, until the next start
    /// with this option). Default: the flags set before, and for a dataset never set, every
    /// dataset but the demo one once another is served.
    #[arg(long, env = "POSEBOARD_CORE_DATASETS", value_delimiter = ',')]
    pub core_datasets: Vec<String>,
    /// Do not generate the demo dataset and submissions.
    #[arg(long, env = "POSEBOARD_NO_DEMO")]
    pub no_demo: bool,
    /// The address users reach the service at (`https://poseboard.example.org`), for the
    /// examples the pages show; default: the scheme and host of each request.
    #[arg(long, env = "POSEBOARD_PUBLIC_URL")]
    pub public_url: Option<String>,
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
    pub http: HttpConfig,
    /// How often the server looks for challenges whose deadline has passed without their
    /// snapshot, in seconds (it also looks as it starts); the snapshot is dated at the
    /// deadline whenever it is taken.
    #[arg(long, env = "POSEBOARD_CHALLENGE_CHECK_SECS", default_value_t = 30,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub challenge_check_secs: u64,
    #[command(flatten)]
    pub common: Config,
}

/// How long clients may take. Every bound is on what the client does (or fails to do), so a
/// connection that sends nothing, or half a request, cannot hold a descriptor for ever; an
/// upload is bounded by its progress rather than by a wall clock, so a slow but working link
/// can send the largest file allowed.
#[derive(Args, Clone, Debug)]
pub struct HttpConfig {
    /// Seconds a client has to send a request's headers, from its connection or its previous
    /// request; a connection that takes longer is closed.
    #[arg(long, env = "POSEBOARD_HEADER_TIMEOUT_SECS", default_value_t = 15,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub header_timeout_secs: u64,
    /// Seconds a connection may pass without a byte either way before it is closed (a request
    /// under way is answered first).
    #[arg(long, env = "POSEBOARD_IDLE_TIMEOUT_SECS", default_value_t = 60,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub idle_timeout_secs: u64,
    /// Seconds a request other than an upload may take to be answered.
    #[arg(long, env = "POSEBOARD_REQUEST_TIMEOUT_SECS", default_value_t = 120,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub request_timeout_secs: u64,
    /// An upload must keep delivering at least this many KiB every `--upload-window-secs`
    /// (however long the whole upload takes); one that falls behind is refused with 408.
    #[arg(long, env = "POSEBOARD_UPLOAD_MIN_KIB", default_value_t = 64,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub upload_min_kib: u64,
    /// The window of `--upload-min-kib`, in seconds.
    #[arg(long, env = "POSEBOARD_UPLOAD_WINDOW_SECS", default_value_t = 20,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub upload_window_secs: u64,
}

/// The progress an upload's body must keep making.
#[derive(Clone, Copy, Debug)]
pub struct ProgressRule {
    pub min_bytes: u64,
    pub window: Duration,
}

impl HttpConfig {
    pub fn header_timeout(&self) -> Duration {
        Duration::from_secs(self.header_timeout_secs)
    }

    pub fn idle_timeout(&self) -> Duration {
        Duration::from_secs(self.idle_timeout_secs)
    }

    pub fn request_timeout(&self) -> Duration {
        Duration::from_secs(self.request_timeout_secs)
    }

    pub fn upload_progress(&self) -> ProgressRule {
        ProgressRule {
            min_bytes: self.upload_min_kib.saturating_mul(1024),
            window: Duration::from_secs(self.upload_window_secs),
        }
    }
}

impl Config {
    pub fn datasets_dir(&self) -> PathBuf {
        self.datasets
            .clone()
            .unwrap_or_else(|| self.data_dir.join("datasets"))
    }

    /// Where this process's workers keep the datasets' prepared forms; `None` when preparing is
    /// turned off.
    pub fn prepared_dir(&self) -> Option<PathBuf> {
        (!self.no_prepare).then(|| {
            self.prepared_dir
                .clone()
                .unwrap_or_else(|| self.data_dir.join("prepared"))
        })
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
