//! The application state shared by the HTTP handlers, the services and the workers: the
//! store, the configuration, the evaluation pool and the loaded datasets with their prepared
//! forms.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use evaluator::Dataset;
use tokio::sync::{Mutex, Notify, OnceCell};

use crate::board_cache::BoardCache;
use crate::config::Config;
use crate::datasets;
use crate::datasets::config::{
    BOP24_TARGETS, LoadError, bop24_options, folder_options, is_dataset_folder,
};
use crate::datasets::parsed_files::ParsedFiles;
use crate::datasets::prepared::Shelf;
use crate::datasets::uploaded_file;
use crate::domain::DatasetId;
use crate::error::{AppError, AppResult, Chain};
use crate::store::Store;
use crate::store::datasets::DatasetRow;

pub struct App {
    pub store: Store,
    pub config: Config,
    pub role: Role,
    /// Wakes idle workers when a submission is queued (the database stays the truth).
    pub wake: Notify,
    /// The evaluation threads; handlers never evaluate on the async runtime.
    pub pool: rayon::ThreadPool,
    /// Rendered leaderboards, shared by every reader.
    pub boards: BoardCache,
    /// Result files parsed for the pictures of their targets.
    pub parsed_files: ParsedFiles,
    /// The datasets' prepared forms this process's evaluations may read (filled by the
    /// workers' preparer).
    pub prepared: Shelf,
    /// The datasets this process has loaded, by id. Each slot is filled once: requests that
    /// arrive while a dataset loads wait for that load instead of reading and hashing the
    /// folder again (a large dataset takes seconds and much memory per load).
    datasets: Mutex<HashMap<DatasetId, Arc<OnceCell<Loaded>>>>,
    /// The datasets this process has loaded for BOP'24 6D detection (with
    /// `test_targets_bop24.json` as targets), by id, each loaded once as above.
    detection: Mutex<HashMap<DatasetId, Arc<OnceCell<Arc<Dataset>>>>>,
}

/// What a process is: the server owns the datasets table and the uploads; a worker process
/// (`poseboard worker`, possibly on another machine) only evaluates, from its own copies of the
/// datasets, and never writes a dataset's row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Server,
    Worker,
}

/// A dataset loaded by this process, with the content hash of its files here.
#[derive(Clone)]
pub struct Loaded {
    pub dataset: Arc<Dataset>,
    pub content_hash: String,
}

pub type AppState = Arc<App>;

impl App {
    /// Connects and migrates the database and returns the state; the server also registers
    /// the datasets of its datasets directory and moves uploads older versions kept on disk
    /// into the database.
    pub async fn start(config: Config, role: Role) -> anyhow::Result<AppState> {
        crate::ops::metrics::install()?;
        if role == Role::Server || config.database_url.is_none() {
            // The SQLite file lives there; a remote worker needs no directory at all.
            std::fs::create_dir_all(&config.data_dir)?;
        }
        if role == Role::Server {
            std::fs::create_dir_all(config.submissions_dir())?;
        }
        let store = Store::connect(&config.database_url()).await?;
        store.migrate().await?;
        let mut pool = rayon::ThreadPoolBuilder::new().thread_name(|i| format!("eval-{i}"));
        if let Some(n) = config.eval_threads {
            pool = pool.num_threads(n);
        }
        let boards = BoardCache::new(
            usize::try_from(config.board_cache_mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX),
            std::time::Duration::from_millis(config.board_recheck_ms),
        );
        let app = Arc::new(App {
            store,
            boards,
            parsed_files: ParsedFiles::new(crate::datasets::parsed_files::DEFAULT_BUDGET),
            prepared: Shelf::default(),
            config,
            role,
            wake: Notify::new(),
            pool: pool.build()?,
            datasets: Mutex::new(HashMap::new()),
            detection: Mutex::new(HashMap::new()),
        });
        if role == Role::Server {
            app.register_datasets().await?;
            if !app.config.core_datasets.is_empty() {
                let unknown = app
                    .store
                    .set_core_datasets(&app.config.core_datasets)
                    .await?;
                if !unknown.is_empty() {
                    anyhow::bail!(
                        "--core-datasets names {}, not served here",
                        unknown.join(", ")
                    );
                }
            }
            let imported =
                uploaded_file::import_legacy(&app.store, &app.config.submissions_dir()).await?;
            if imported > 0 {
                tracing::info!(
                    files = imported,
                    "uploads kept on disk moved into the database"
                );
            }
        }
        Ok(app)
    }

    /// Every subfolder of the datasets directory that loads as a BOP dataset is registered
    /// (one with its targets file, or with a `poseboard-dataset.json` choosing its split);
    /// one an administrator retired stays retired.
    async fn register_datasets(&self) -> anyhow::Result<()> {
        let dir = self.config.datasets_dir();
        let Ok(entries) = std::fs::read_dir(&dir) else {
            tracing::warn!(dir = %dir.display(), "no datasets directory");
            return Ok(());
        };
        let mut folders: Vec<PathBuf> = entries
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .filter(|p| is_dataset_folder(p))
            .collect();
        folders.sort();
        for folder in folders {
            match self.register_dataset(&folder).await {
                Ok(row) if row.retired => {
                    tracing::info!(dataset = %row.name, "dataset retired: not served")
                }
                Ok(row) => {
                    tracing::info!(dataset = %row.name, targets = row.targets_count, "dataset registered")
                }
                Err(e) => {
                    tracing::error!(folder = %folder.display(), error = %Chain(&e), "dataset skipped")
                }
            }
        }
        Ok(())
    }

    /// Loads the BOP dataset in `folder` and registers it with its content hash (a retired one
    /// stays retired).
    pub async fn register_dataset(&self, folder: &Path) -> AppResult<DatasetRow> {
        let loaded = self
            .load(folder.to_path_buf())
            .await?
            .map_err(|e| AppError::BadRequest(format!("not a usable BOP dataset: {e}")))?;
        let mut row = describe(&loaded.dataset, folder);
        row.content_hash = Some(loaded.content_hash.clone());
        let row = self.store.register_dataset(&row).await?;
        self.datasets
            .lock()
            .await
            .insert(row.id, Arc::new(OnceCell::new_with(Some(loaded))));
        Ok(row)
    }

    /// The loaded dataset of a registered id (loaded from disk on first use by this process).
    pub async fn dataset(&self, row: &DatasetRow) -> AppResult<Arc<Dataset>> {
        Ok(self.loaded(row).await?.dataset)
    }

    /// The dataset of a registered row as this process has it, with the content hash of its
    /// files here: the server reads the folder it registered, a worker the folder of that name
    /// in its own datasets directory.
    pub async fn loaded(&self, row: &DatasetRow) -> AppResult<Loaded> {
        let slot = self
            .datasets
            .lock()
            .await
            .entry(row.id)
            .or_default()
            .clone();
        // A failed load leaves the slot empty, so the next request reads the folder again.
        slot.get_or_try_init(|| async {
            let folder = self.folder(row);
            self.load(folder.clone()).await?.map_err(|e| {
                AppError::failed(format!("dataset {} ({})", row.name, folder.display()), e)
            })
        })
        .await
        .cloned()
    }

    /// The folder of a registered dataset for this process: the server reads the folder it
    /// registered, a worker the folder of that name in its own datasets directory.
    fn folder(&self, row: &DatasetRow) -> PathBuf {
        match self.role {
            Role::Server => PathBuf::from(&row.path),
            Role::Worker => self.config.datasets_dir().join(&row.name),
        }
    }

    /// The dataset of a registered row loaded for BOP'24 6D detection: its split as
    /// configured, every object of the images of `test_targets_bop24.json` a target. `None`
    /// when this process's copy has no such file (the dataset takes no bop24 uploads).
    pub async fn bop24_dataset(&self, row: &DatasetRow) -> AppResult<Option<Arc<Dataset>>> {
        let folder = self.folder(row);
        if !folder.join(BOP24_TARGETS).is_file() {
            return Ok(None);
        }
        let slot = self
            .detection
            .lock()
            .await
            .entry(row.id)
            .or_default()
            .clone();
        slot.get_or_try_init(|| async {
            let (name, folder) = (row.name.clone(), folder.clone());
            self.on_pool("loading a dataset for bop24", move || {
                bop24_options(&folder)
                    .map_err(LoadError::from)
                    .and_then(|opts| Ok(Dataset::load_with(&folder, &opts)?))
                    .map(Arc::new)
                    .map_err(|e| {
                        AppError::failed(format!("dataset {name} ({})", folder.display()), e)
                    })
            })
            .await
        })
        .await
        .cloned()
        .map(Some)
    }

    /// Forgets a loaded dataset, so that the next use reads the folder again (a worker whose
    /// copy was refused looks again later, once an operator may have fixed it).
    pub async fn forget_dataset(&self, id: DatasetId) {
        self.datasets.lock().await.remove(&id);
        self.detection.lock().await.remove(&id);
    }

    /// Loads and hashes the dataset in `folder` on the evaluation threads.
    async fn load(&self, folder: PathBuf) -> AppResult<Result<Loaded, LoadError>> {
        self.on_pool("loading a dataset", move || {
            Ok(load(&folder).and_then(|ds| {
                let content_hash = datasets::hash::content_hash(&ds).map_err(LoadError::Hash)?;
                Ok(Loaded {
                    dataset: Arc::new(ds),
                    content_hash,
                })
            }))
        })
        .await
    }

    /// Runs CPU work on the evaluation threads, never on the async ones; `what` names the
    /// work in the error should it panic.
    pub async fn on_pool<T: Send + 'static>(
        &self,
        what: &str,
        work: impl FnOnce() -> AppResult<T> + Send + 'static,
    ) -> AppResult<T> {
        let (tx, rx) = tokio::sync::oneshot::channel();
        self.pool.spawn(move || {
            // The requester may have gone away; then nobody needs the answer.
            let _ = tx.send(work());
        });
        rx.await
            .map_err(|_| AppError::Internal(format!("{what} crashed")))?
    }
}

/// Loads the dataset in `folder` with the split its configuration file chooses.
fn load(folder: &Path) -> Result<Dataset, LoadError> {
    let opts = folder_options(folder)?;
    Ok(Dataset::load_with(folder, &opts)?)
}

/// The row registering `ds`, found in `folder` (without its content hash, which takes a pass
/// over the files).
pub fn describe(ds: &Dataset, folder: &Path) -> DatasetRow {
    DatasetRow {
        id: DatasetId::new(0),
        name: ds.name.clone(),
        path: folder.display().to_string(),
        objects_count: ds.objects.len() as i64,
        scenes_count: ds.scenes.len() as i64,
        images_count: ds.scenes.values().map(|s| s.images.len() as i64).sum(),
        targets_count: ds.targets.len() as i64,
        instances_count: ds.targets.iter().map(|t| t.inst_count as i64).sum(),
        image_width: ds.image_size.0 as i64,
        image_height: ds.image_size.1 as i64,
        added_at: 0,
        retired: false,
        content_hash: None,
        core: None,
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::demo::{SynthOptions, write_dataset};

    #[derive(Parser)]
    struct Args {
        #[command(flatten)]
        config: Config,
    }

    /// Concurrent first requests for a dataset share one load: each gets the very dataset the
    /// others got, not a copy read and hashed again.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_dataset_is_loaded_once_under_concurrent_first_requests() {
        let dir = tempfile::tempdir().expect("temp dir");
        let datasets = dir.path().join("datasets");
        write_dataset(&datasets.join("synth"), &SynthOptions::default()).expect("dataset");
        let db = format!(
            "sqlite://{}?mode=rwc",
            dir.path().join("db.sqlite").display()
        );
        let args = Args::parse_from([
            "test",
            "--data-dir",
            &dir.path().display().to_string(),
            "--datasets",
            &datasets.display().to_string(),
            "--database-url",
            &db,
            "--eval-threads",
            "4",
        ]);
        let app = App::start(args.config, Role::Server).await.expect("start");
        let row = app.store.datasets().await.expect("datasets").remove(0);
        app.forget_dataset(row.id).await;

        let loads = (0..8).map(|_| app.loaded(&row));
        let loaded = futures_util::future::try_join_all(loads)
            .await
            .expect("loaded");
        for other in &loaded[1..] {
            assert!(Arc::ptr_eq(&loaded[0].dataset, &other.dataset));
        }
        // Later requests find it in memory.
        let again = app.loaded(&row).await.expect("loaded again");
        assert!(Arc::ptr_eq(&loaded[0].dataset, &again.dataset));
    }
}
