//! The preparer: each process that evaluates prepares its own copy of every served dataset in
//! the background (`crate::datasets::prepared`), so that its later evaluations skip the work
//! every file on a dataset shares. Its prepared folder is on its own disk, which the server
//! serving the datasets page may not see, so its progress goes to the database
//! (`store::preparations`), one row per host and folder.
//!
//! It never slows an evaluation down much: the work runs on one thread of its own at the
//! lowest priority, never on the async runtime nor on the evaluation pool, and a job that comes
//! while a dataset is being prepared is evaluated from the dataset. A form made for other
//! content (`foreign`) or by another evaluator (`stale`) is rebuilt, and one with damaged files
//! repaired, each with a log line saying why; a form reported damaged by an evaluation is
//! repaired at once.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use evaluator::prepared::Outcome;
use tokio::task::JoinHandle;

use super::pool::host_name;
use crate::app::AppState;
use crate::datasets::prepared::{self, Count, PrepareError, Tally};
use crate::domain::DatasetId;
use crate::error::Chain;
use crate::shutdown::Shutdown;
use crate::store::datasets::DatasetRow;
use crate::store::preparations::{PreparationRow, PreparationState};

/// How often the served datasets are looked at for one added or registered again.
const POLL: Duration = Duration::from_secs(10);
/// How long a failed preparation is left before it is tried again (a copy fixed, disk freed).
const RETRY_AFTER: Duration = Duration::from_secs(300);
/// How often the progress of a preparation under way is recorded.
const RECORD_EVERY: Duration = Duration::from_secs(1);
/// The lowest scheduling priority: the preparing thread runs when the evaluations leave a
/// core idle.
const NICE: i32 = 19;

/// Starts the preparer of this process's workers, unless preparing is turned off.
pub(super) fn spawn(app: &AppState, shutdown: &Shutdown) -> Option<JoinHandle<()>> {
    let root = app.config.prepared_dir()?;
    let root = std::path::absolute(&root).unwrap_or(root);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "prepare".to_string())
        .start_handler(|_| lower_priority())
        .panic_handler(|_| tracing::error!("a dataset's preparation panicked"))
        .build();
    let pool = match pool {
        Ok(pool) => pool,
        Err(e) => {
            tracing::error!(error = %e, "no thread to prepare datasets on: evaluating from the datasets");
            return None;
        }
    };
    let preparer = Preparer {
        app: app.clone(),
        root,
        host: host_name(),
        pool,
        shutdown: shutdown.clone(),
    };
    Some(tokio::spawn(preparer.run()))
}

/// Makes the calling thread the last to be scheduled (Linux sets the priority per thread).
fn lower_priority() {
    let thread = rustix::thread::gettid();
    if let Err(e) = rustix::process::setpriority_process(Some(thread), NICE) {
        tracing::warn!(error = %e, "the preparing thread keeps its priority");
    }
}

struct Preparer {
    app: AppState,
    /// The folder holding a folder per dataset.
    root: PathBuf,
    host: String,
    /// One thread, at the lowest priority.
    pool: rayon::ThreadPool,
    shutdown: Shutdown,
}

/// What this process last did for a dataset.
struct Settled {
    /// The registered content it was prepared for (or failed on).
    content_hash: String,
    /// When it failed, if it did.
    failed_at: Option<Instant>,
}

/// How one preparation ended.
enum Ended {
    Ready,
    Failed,
    Stopped,
}

impl Preparer {
    async fn run(self) {
        let mut settled: HashMap<DatasetId, Settled> = HashMap::new();
        while !self.shutdown.is_set() {
            match self.app.store.datasets().await {
                Ok(rows) => {
                    let damaged = self.app.prepared.take_damaged();
                    for row in rows {
                        let Some(hash) = row.content_hash.clone() else {
                            continue;
                        };
                        let due = damaged.contains(&row.id)
                            || settled.get(&row.id).is_none_or(|s| {
                                s.content_hash != hash
                                    || s.failed_at.is_some_and(|at| at.elapsed() >= RETRY_AFTER)
                            });
                        if !due {
                            continue;
                        }
                        let failed_at = match self.prepare(&row, &hash).await {
                            Ended::Ready => None,
                            Ended::Failed => Some(Instant::now()),
                            Ended::Stopped => return,
                        };
                        settled.insert(
                            row.id,
                            Settled {
                                content_hash: hash,
                                failed_at,
                            },
                        );
                    }
                }
                Err(e) => tracing::warn!(error = %e, "cannot list the datasets to prepare"),
            }
            tokio::select! {
                _ = self.app.prepared.damage_reported() => {}
                _ = tokio::time::sleep(POLL) => {}
                _ = self.shutdown.wait() => {}
            }
        }
    }

    /// Prepares (or checks and repairs) this process's form of `row`, registered with content
    /// `hash`, recording its progress, and puts it on the shelf once current.
    async fn prepare(&self, row: &DatasetRow, hash: &str) -> Ended {
        let folder = prepared::folder(&self.root, &row.name);
        let loaded = match self.app.loaded(row).await {
            Ok(loaded) => loaded,
            Err(e) => {
                let why = format!("no usable copy of the dataset here: {}", Chain(&e));
                return self.failed(row, why).await;
            }
        };
        if loaded.content_hash != hash {
            // The copy may be fixed by the time this is tried again: read it again then.
            self.app.forget_dataset(row.id).await;
            let why = format!(
                "the copy here differs from the registered one (content hash {} here, {hash} \
                 registered)",
                loaded.content_hash
            );
            return self.failed(row, why).await;
        }
        self.record(row, PreparationState::Preparing, Count::default(), None)
            .await;
        let tally = Arc::new(Tally::default());
        let cancel = Arc::new(AtomicBool::new(false));
        let (tx, rx) = tokio::sync::oneshot::channel();
        {
            let (dataset, hash, folder) = (loaded.dataset, hash.to_string(), folder.clone());
            let (tally, cancel) = (tally.clone(), cancel.clone());
            self.pool.spawn(move || {
                // Nobody waits for a preparation of a stopping process.
                let _ = tx.send(prepared::prepare(&dataset, &hash, &folder, &tally, &cancel));
            });
        }
        tokio::pin!(rx);
        let mut every = tokio::time::interval(RECORD_EVERY);
        let mut recorded = Count::default();
        let result = loop {
            tokio::select! {
                result = &mut rx => break result,
                _ = every.tick() => {
                    let now = tally.now();
                    if now != recorded {
                        let waiting = now.waiting.then(|| {
                            "waiting for another process preparing the same folder".to_string()
                        });
                        self.record(row, PreparationState::Preparing, now, waiting).await;
                        recorded = now;
                    }
                }
                _ = self.shutdown.wait() => {
                    cancel.store(true, Ordering::Relaxed);
                    return Ended::Stopped;
                }
            }
        };
        let (preparation, form) = match result {
            Ok(Ok(done)) => done,
            Ok(Err(PrepareError::Evaluator(evaluator::Error::Cancelled))) => return Ended::Stopped,
            Ok(Err(e)) => {
                let why = Chain(&e).to_string();
                return self.failed(row, why).await;
            }
            Err(_) => {
                return self
                    .failed(row, "the preparation crashed".to_string())
                    .await;
            }
        };
        let (dataset, folder) = (row.name.as_str(), folder.display());
        let (images, megabytes) = (preparation.images, preparation.bytes as f64 / 1e6);
        match &preparation.outcome {
            Outcome::Created => {
                tracing::info!(dataset, %folder, images, megabytes, "dataset prepared")
            }
            Outcome::Current => {
                tracing::info!(dataset, %folder, images, "prepared form current, every file intact")
            }
            Outcome::Repaired { files } => tracing::warn!(
                dataset,
                %folder,
                files = %files.join("; "),
                "prepared form repaired: rebuilt {} damaged or missing file(s)",
                files.len()
            ),
            Outcome::Rebuilt(why) => tracing::warn!(
                dataset,
                %folder,
                images,
                megabytes,
                "prepared form rebuilt, the previous one was {why}"
            ),
        }
        self.app.prepared.put(row.id, hash.to_string(), form);
        let images = preparation.images as u64;
        let count = Count {
            done: images,
            total: images,
            waiting: false,
        };
        self.record(row, PreparationState::Ready, count, None).await;
        Ended::Ready
    }

    /// Says why `row` could not be prepared, in the log and on the datasets page.
    async fn failed(&self, row: &DatasetRow, why: String) -> Ended {
        tracing::warn!(dataset = %row.name, folder = %self.root.display(), "dataset not prepared, evaluating from the dataset: {why}");
        self.record(row, PreparationState::Failed, Count::default(), Some(why))
            .await;
        Ended::Failed
    }

    /// Records where this host's preparation of `row` stands; a database that cannot be
    /// written only leaves the page behind.
    async fn record(
        &self,
        row: &DatasetRow,
        state: PreparationState,
        count: Count,
        detail: Option<String>,
    ) {
        let saved = self
            .app
            .store
            .save_preparation(&PreparationRow {
                dataset_id: row.id,
                host: self.host.clone(),
                folder: self.root.display().to_string(),
                state,
                images_done: count.done as i64,
                images_total: count.total as i64,
                detail,
                updated_at: 0,
            })
            .await;
        if let Err(e) = saved {
            tracing::warn!(dataset = %row.name, error = %e, "cannot record the preparation's progress");
        }
    }
}
