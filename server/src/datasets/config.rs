//! Which split of a dataset folder poseboard reads. A BOP dataset needs no configuration when
//! its folder holds one test split (`test/` or one `test_TYPE/`) and `test_targets_bop19.json`;
//! otherwise an operator puts a `poseboard-dataset.json` next to it, e.g.
//! `{"split_type": "primesense"}` for a T-LESS copy with several sensors, so that the choice
//! lives with the data and holds for `serve`, `worker` and `eval` alike.

use std::path::{Path, PathBuf};

use evaluator::dataset::DatasetOptions;
use serde::Deserialize;

/// The per-folder choice of split, split type and targets file.
pub const CONFIG_FILE: &str = "poseboard-dataset.json";

/// The choice as written in the file or given as flags; unset parts keep the defaults.
#[derive(Clone, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct SplitChoice {
    pub split: Option<String>,
    pub split_type: Option<String>,
    pub targets_file: Option<String>,
}

impl SplitChoice {
    /// Unset parts of `self` taken from `other`.
    pub fn or(self, other: SplitChoice) -> SplitChoice {
        SplitChoice {
            split: self.split.or(other.split),
            split_type: self.split_type.or(other.split_type),
            targets_file: self.targets_file.or(other.targets_file),
        }
    }

    pub fn options(self) -> DatasetOptions {
        let default = DatasetOptions::default();
        DatasetOptions {
            split: self.split.unwrap_or(default.split),
            split_type: self.split_type.or(default.split_type),
            targets_file: self.targets_file.unwrap_or(default.targets_file),
        }
    }
}

/// Why a folder's configuration file cannot be used. The message names the file and says the
/// cause, as the operator or uploader reads it; the cause stays attached for the logs.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error(
        "{}: {source}; expected {{\"split\": .., \"split_type\": .., \"targets_file\": ..}}",
        path.display()
    )]
    Invalid {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}: {source}", path.display())]
    Unreadable {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Why a dataset folder does not load: its configuration, its files (the evaluator says which
/// and why), or a file its content hash reads.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Dataset(#[from] evaluator::Error),
    /// The evaluator's hashing names the file it could not read, in words only.
    #[error("{0}")]
    Hash(String),
}

/// The choice written in `folder`'s configuration file (none when there is no file).
pub fn folder_choice(folder: &Path) -> Result<SplitChoice, ConfigError> {
    let path = folder.join(CONFIG_FILE);
    match std::fs::read(&path) {
        Ok(bytes) => {
            serde_json::from_slice(&bytes).map_err(|source| ConfigError::Invalid { path, source })
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(SplitChoice::default()),
        Err(source) => Err(ConfigError::Unreadable { path, source }),
    }
}

/// The options to load `folder` with: its configuration file over the defaults.
pub fn folder_options(folder: &Path) -> Result<DatasetOptions, ConfigError> {
    Ok(folder_choice(folder)?.options())
}

/// The targets file of BOP'24 6D detection: the images whose every object is a target.
pub const BOP24_TARGETS: &str = "test_targets_bop24.json";

/// The options to load `folder` with for BOP'24 6D detection: the split its configuration file
/// chooses, with [`BOP24_TARGETS`] as targets (the file's `targets_file` is the localization
/// protocols' choice, not this task's).
pub fn bop24_options(folder: &Path) -> Result<DatasetOptions, ConfigError> {
    Ok(DatasetOptions {
        targets_file: BOP24_TARGETS.to_string(),
        ..folder_options(folder)?
    })
}

/// Whether `folder` looks like a dataset to serve: it has its targets file.
pub fn is_dataset_folder(folder: &Path) -> bool {
    folder_options(folder).is_ok_and(|o| folder.join(o.targets_file).is_file())
        || folder.join(CONFIG_FILE).is_file()
}

/// The 2D ground truth (`scene_gt_coco.json` per scene) of the dataset in `folder`, for the
/// split its configuration chooses, with the masks decoded when `with_masks` (segmentation).
/// The service ranks detection against the amodal boxes, as the BOP site does.
pub fn coco_gt(folder: &Path, with_masks: bool) -> Result<evaluator::coco::CocoGt, LoadError> {
    let opts = folder_options(folder)?;
    Ok(evaluator::coco::CocoGt::load(
        folder,
        &opts,
        evaluator::coco::BboxType::Amodal,
        with_masks,
    )?)
}
