//! The prepared forms of the served datasets (see `evaluator::prepared`), as a process that
//! evaluates keeps them: one folder per dataset under its prepared folder, made in the
//! background, and read by an evaluation only once it is complete and current for the content
//! the server registered. Until then, and whenever it cannot be made, evaluations read the
//! dataset itself: the prepared form only saves time, it never decides a score.
//!
//! Several processes on one machine may share the folder (a server and `poseboard worker`s with
//! one data directory): a lock file beside each dataset's folder makes one of them prepare it
//! while the others wait, then find it current. The evaluator writes every file under a
//! temporary name and renames it, so a process reading a form while another repairs it never
//! sees a half-written file.

use std::collections::{HashMap, HashSet};
use std::ffi::OsString;
use std::fs::{File, TryLockError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use evaluator::prepared::{self, Preparation, Prepared, Unusable};
use evaluator::{Dataset, Progress};
use tokio::sync::Notify;

use crate::domain::DatasetId;

/// How often a preparation waiting for another process's lock looks again (and whether it was
/// cancelled meanwhile).
const LOCK_POLL: Duration = Duration::from_millis(200);

/// The prepared forms this process's evaluations may read, by dataset. A form is put here
/// only after its preparation finished and it opened as current for the registered content, so
/// an evaluation reads either a complete, current form or none.
#[derive(Default)]
pub struct Shelf {
    current: Mutex<HashMap<DatasetId, (String, Arc<Prepared>)>>,
    /// Datasets whose form an evaluation found damaged files in, to be repaired.
    damaged: Mutex<HashSet<DatasetId>>,
    /// Wakes the preparer when a form is to be repaired.
    wake: Notify,
}

impl Shelf {
    /// The current prepared form of dataset `id` if it was made for `content_hash` (the content
    /// of this process's copy, as checked against the registered one).
    pub fn current(&self, id: DatasetId, content_hash: &str) -> Option<Arc<Prepared>> {
        let current = self.current.lock().unwrap_or_else(|e| e.into_inner());
        current
            .get(&id)
            .filter(|(hash, _)| hash == content_hash)
            .map(|(_, form)| form.clone())
    }

    /// Makes `form`, just prepared and opened for `content_hash`, the one evaluations of `id`
    /// read.
    pub fn put(&self, id: DatasetId, content_hash: String, form: Prepared) {
        self.current
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id, (content_hash, Arc::new(form)));
    }

    /// An evaluation refused files of dataset `id`'s form: the preparer is woken to rebuild
    /// them. The form stays in use meanwhile, since a refused file's image is computed from
    /// the dataset.
    pub fn report_damaged(&self, id: DatasetId) {
        self.damaged
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id);
        self.wake.notify_one();
    }

    /// The datasets reported damaged since the last call.
    pub fn take_damaged(&self) -> HashSet<DatasetId> {
        std::mem::take(&mut *self.damaged.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Resolves when a form is reported damaged (at once if one was since the last wait).
    pub async fn damage_reported(&self) {
        self.wake.notified().await
    }
}

/// The folder of dataset `name`'s prepared form under `root`. By name, not by content: a
/// dataset whose content changes finds its old form foreign and rebuilds it in place, so no
/// folder of content no longer served is left behind.
pub fn folder(root: &Path, name: &str) -> PathBuf {
    root.join(name)
}

/// How far one preparation has come, written by the preparing thread and read by whoever
/// records it.
#[derive(Debug, Default)]
pub struct Tally {
    done: AtomicU64,
    total: AtomicU64,
    /// Another process holds the folder's lock: this one waits for it.
    waiting: AtomicBool,
}

/// A moment of a [`Tally`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Count {
    pub done: u64,
    /// 0 until the preparation has counted the images.
    pub total: u64,
    pub waiting: bool,
}

impl Tally {
    pub fn now(&self) -> Count {
        Count {
            done: self.done.load(Ordering::Relaxed),
            total: self.total.load(Ordering::Relaxed),
            waiting: self.waiting.load(Ordering::Relaxed),
        }
    }
}

impl Progress for Tally {
    fn start(&self, total: u64) {
        self.total.store(total, Ordering::Relaxed);
    }

    fn advance(&self, n: u64) {
        self.done.fetch_add(n, Ordering::Relaxed);
    }
}

/// Why a dataset could not be prepared.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    #[error(transparent)]
    Evaluator(#[from] evaluator::Error),
    #[error("the lock file {}: {source}", path.display())]
    Lock {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The form just made does not open as current (another process replaced its manifest
    /// meanwhile): it is not read.
    #[error("the form just prepared cannot be used: {0}")]
    Unusable(Unusable),
}

/// Makes `folder` the current prepared form of `dataset` (whose content hash is
/// `content_hash`) and opens it, keeping what is current and intact and rebuilding the rest.
/// Runs on the caller's rayon pool while holding the folder's lock file; `cancel` stops it at
/// its next image, or while it waits for the lock.
pub fn prepare(
    dataset: &Dataset,
    content_hash: &str,
    folder: &Path,
    tally: &Tally,
    cancel: &AtomicBool,
) -> Result<(Preparation, Prepared), PrepareError> {
    let _lock = lock(&lock_path(folder), tally, cancel)?;
    let preparation = prepared::prepare(dataset, content_hash, folder, tally, cancel)?;
    let form = Prepared::open(folder, content_hash).map_err(PrepareError::Unusable)?;
    Ok((preparation, form))
}

/// `folder` with `.lock` appended: beside the folder, which a preparation may empty.
fn lock_path(folder: &Path) -> PathBuf {
    let mut path = OsString::from(folder.as_os_str());
    path.push(".lock");
    PathBuf::from(path)
}

/// The lock file at `path`, locked; released when the file is closed, so also when its
/// process dies.
fn lock(path: &Path, tally: &Tally, cancel: &AtomicBool) -> Result<File, PrepareError> {
    let failed = |source| PrepareError::Lock {
        path: path.to_path_buf(),
        source,
    };
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(failed)?;
    }
    let file = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(path)
        .map_err(failed)?;
    loop {
        match file.try_lock() {
            Ok(()) => {
                tally.waiting.store(false, Ordering::Relaxed);
                return Ok(file);
            }
            Err(TryLockError::WouldBlock) => {
                tally.waiting.store(true, Ordering::Relaxed);
                if cancel.load(Ordering::Relaxed) {
                    return Err(evaluator::Error::Cancelled.into());
                }
                std::thread::sleep(LOCK_POLL);
            }
            Err(TryLockError::Error(e)) => return Err(failed(e)),
        }
    }
}
