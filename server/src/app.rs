//! The application state shared by the HTTP handlers, the services and the workers: the
//! store, the configuration, the evaluation pool and the loaded datasets.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use evaluator::Dataset;
use tokio::sync::{Mutex, Notify};

use crate::board_cache::BoardCache;
use crate::config::Config;
use crate::dataset_config::{folder_options, is_dataset_folder};
use crate::error::{AppError, AppResult};
use crate::store::Store;
use crate::store::datasets::DatasetRow;

pub struct App {
    pub store: Store,
    pub config: Config,
    /// Wakes idle workers when a submission is queued (the database stays the truth).
    pub wake: Notify,
    /// The evaluation threads; handlers never evaluate on the async runtime.
    pub pool: rayon::ThreadPool,
    /// Rendered leaderboards, shared by every reader.
    pub boards: BoardCache,
    datasets: Mutex<HashMap<i64, Arc<Dataset>>>,
}

pub type AppState = Arc<App>;

impl App {
    /// Connects and migrates the database, registers the datasets of the datasets directory,
    /// and returns the state.
    pub async fn start(config: Config) -> anyhow::Result<AppState> {
        crate::metrics::install()?;
        std::fs::create_dir_all(&config.data_dir)?;
        std::fs::create_dir_all(config.submissions_dir())?;
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
            config,
            wake: Notify::new(),
            pool: pool.build()?,
            datasets: Mutex::new(HashMap::new()),
        });
        app.register_datasets().await?;
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
                    tracing::error!(folder = %folder.display(), error = %e, "dataset skipped")
                }
            }
        }
        Ok(())
    }

    /// Loads the BOP dataset in `folder` and registers it (a retired one stays retired).
    pub async fn register_dataset(&self, folder: &Path) -> AppResult<DatasetRow> {
        let path = folder.to_path_buf();
        let ds = tokio::task::spawn_blocking(move || load(&path))
            .await
            .map_err(|e| AppError::Internal(e.to_string()))?
            .map_err(|e| AppError::BadRequest(format!("not a usable BOP dataset: {e}")))?;
        let row = self.store.register_dataset(&describe(&ds, folder)).await?;
        self.datasets.lock().await.insert(row.id, Arc::new(ds));
        Ok(row)
    }

    /// The loaded dataset of a registered id (loaded from disk on first use by this process).
    pub async fn dataset(&self, row: &DatasetRow) -> AppResult<Arc<Dataset>> {
        if let Some(ds) = self.datasets.lock().await.get(&row.id) {
            return Ok(ds.clone());
        }
        let path = PathBuf::from(&row.path);
        let ds = tokio::task::spawn_blocking(move || load(&path))
            .await
            .map_err(|e| AppError::Internal(e.to_string()))?
            .map_err(|e| AppError::Internal(format!("dataset {}: {e}", row.name)))?;
        let ds = Arc::new(ds);
        self.datasets.lock().await.insert(row.id, ds.clone());
        Ok(ds)
    }

    /// Where an uploaded file with this content hash is kept.
    pub fn stored_file(&self, sha256: &str) -> PathBuf {
        self.config.submissions_dir().join(format!("{sha256}.csv"))
    }
}

/// Loads the dataset in `folder` with the split its configuration file chooses.
fn load(folder: &Path) -> Result<Dataset, String> {
    let opts = folder_options(folder)?;
    Dataset::load_with(folder, &opts).map_err(|e| e.to_string())
}

fn describe(ds: &Dataset, folder: &Path) -> DatasetRow {
    DatasetRow {
        id: 0,
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
    }
}
