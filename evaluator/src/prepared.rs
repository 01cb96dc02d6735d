//! Prepared datasets: what scoring needs that no result file changes, computed once per
//! dataset instead of once per evaluation. A leaderboard scores hundreds of files against the
//! same few datasets, and a profile of one thread over a whole file spent most of its time
//! inflating the test images' depth PNGs and rendering the ground-truth poses; both are the
//! same for every submission.
//!
//! A prepared dataset is a folder of plain files, one per target image ([`file`]: its depth and
//! its ground-truth renders, LZ4-compressed), and a `manifest.json` naming the dataset content
//! ([`crate::content_hash`]) and the evaluator it was made for. An evaluation reads one image's
//! file when it reaches that image, so memory stays bounded, and any number of processes can
//! read the folder at once. It is an accelerator and never a source of truth: a folder made for
//! other content or by another evaluator is refused as a whole ([`Unusable`]), a damaged file is
//! refused by its checksum and that image is computed from the dataset instead
//! ([`Prepared::damaged`]), and [`prepare`] rebuilds whatever is refused. "The evaluator" is
//! its source, fingerprinted at build time, not only its version number: a renderer changed
//! between releases makes every older form stale, so opening a form need not compute an image
//! afresh to find out (it did, which cost more than evaluating a small result file).

pub mod file;

use std::collections::{BTreeSet, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::content_hash::content_hash_cached;
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::render::{DepthWindow, Model, Renderer};
use file::{FORMAT, ImageData, PreparedImage, Stamp, evaluator_version};

/// The folder a dataset's prepared form is looked for in when no other is named.
pub const DEFAULT_DIR: &str = "poseboard_prepared";

const MANIFEST: &str = "manifest.json";

/// `DEFAULT_DIR` inside the dataset's folder.
pub fn default_dir(dataset: &Dataset) -> PathBuf {
    dataset.root.join(DEFAULT_DIR)
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Manifest {
    format: u32,
    evaluator: String,
    content_hash: String,
    dataset: String,
    images: usize,
    bytes: u64,
}

/// Why a folder cannot be used as the prepared form of a dataset.
#[derive(Clone, Debug, PartialEq)]
pub enum Unusable {
    /// No manifest: never prepared (or a preparation that did not finish).
    Missing,
    /// The manifest cannot be read or parsed.
    Unreadable(String),
    /// Made by another evaluator or in another format.
    Stale { evaluator: String },
    /// Made for another content of the dataset.
    Foreign { content_hash: String },
}

impl fmt::Display for Unusable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unusable::Missing => write!(f, "not prepared (no {MANIFEST})"),
            Unusable::Unreadable(e) => write!(f, "its {MANIFEST} is unreadable: {e}"),
            Unusable::Stale { evaluator } => write!(
                f,
                "stale: made by evaluator {evaluator}, this is {}",
                evaluator_version()
            ),
            Unusable::Foreign { content_hash } => write!(
                f,
                "foreign: made for dataset content {content_hash}, which is not this dataset's"
            ),
        }
    }
}

/// A prepared form found current for one dataset content, to evaluate with
/// (`evaluate_prepared`).
#[derive(Debug)]
pub struct Prepared {
    dir: PathBuf,
    content_hash: String,
    evaluator: String,
    damaged: Mutex<Vec<String>>,
}

impl Prepared {
    /// The prepared form in `dir`, if it was made for `content_hash` (the dataset's
    /// [`crate::content_hash::content_hash`]) by this evaluator.
    pub fn open(dir: &Path, content_hash: &str) -> std::result::Result<Prepared, Unusable> {
        let manifest = match std::fs::read(dir.join(MANIFEST)) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(Unusable::Missing),
            Err(e) => return Err(Unusable::Unreadable(e.to_string())),
            Ok(bytes) => serde_json::from_slice::<Manifest>(&bytes)
                .map_err(|e| Unusable::Unreadable(e.to_string()))?,
        };
        let evaluator = evaluator_version();
        if manifest.format != FORMAT || manifest.evaluator != evaluator {
            return Err(Unusable::Stale {
                evaluator: manifest.evaluator,
            });
        }
        if manifest.content_hash != content_hash {
            return Err(Unusable::Foreign {
                content_hash: manifest.content_hash,
            });
        }
        Ok(Prepared {
            dir: dir.to_path_buf(),
            content_hash: content_hash.to_string(),
            evaluator,
            damaged: Mutex::new(Vec::new()),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn stamp(&self, scene_id: u32, im_id: u32) -> Stamp<'_> {
        Stamp {
            content_hash: &self.content_hash,
            evaluator: &self.evaluator,
            scene_id,
            im_id,
        }
    }

    /// The file of one image, its header and index verified (its blocks are checked as they
    /// are read); the message names the file and its problem.
    pub(crate) fn image(
        &self,
        scene_id: u32,
        im_id: u32,
    ) -> std::result::Result<PreparedImage, String> {
        let path = image_path(&self.dir, scene_id, im_id);
        PreparedImage::open(&path, &self.stamp(scene_id, im_id))
            .map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Remembers a file an evaluation could not use (its image was computed from the dataset).
    pub(crate) fn note_damaged(&self, problem: String) {
        self.damaged
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(problem);
    }

    /// The files evaluations so far refused, each with its problem: run [`prepare`] to rebuild
    /// them.
    pub fn damaged(&self) -> Vec<String> {
        let mut d = self
            .damaged
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        d.sort();
        d.dedup();
        d
    }
}

/// The prepared form an evaluation of `dataset` uses: the one in `dir`, or else in
/// [`default_dir`] when that exists. `Ok(None)`: none there; `Err`: one there but unusable, with
/// the reason (the caller says it and evaluates without). The dataset's content hash is taken
/// with the digests cached in the folder ([`content_hash_cached`]), so that an unchanged dataset
/// is stat'ed, not read, on every evaluation.
pub fn find(
    dataset: &Dataset,
    dir: Option<&Path>,
) -> std::result::Result<Option<Prepared>, String> {
    let dir = dir
        .map(Path::to_path_buf)
        .unwrap_or_else(|| default_dir(dataset));
    if !dir.exists() {
        return Ok(None);
    }
    let why = match content_hash_cached(dataset, &dir) {
        Ok(hash) => match Prepared::open(&dir, &hash) {
            Ok(prepared) => return Ok(Some(prepared)),
            Err(why) => why.to_string(),
        },
        Err(e) => format!("the dataset's content hash cannot be computed: {e}"),
    };
    Err(format!("{}: prepared form not used, {why}", dir.display()))
}

/// What [`prepare`] found and did.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Nothing was there: every image was prepared.
    Created,
    /// Already current, every file intact.
    Current,
    /// Current, but some files were missing or damaged: those were rebuilt.
    Repaired { files: Vec<String> },
    /// The folder was unusable for this reason: every image was prepared again.
    Rebuilt(Unusable),
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Outcome::Created => write!(f, "prepared"),
            Outcome::Current => write!(f, "already current, every file intact"),
            Outcome::Repaired { files } => {
                write!(f, "rebuilt {} damaged or missing file(s):", files.len())?;
                for file in files {
                    write!(f, "\n  {file}")?;
                }
                Ok(())
            }
            Outcome::Rebuilt(why) => write!(f, "rebuilt, the previous one was {why}"),
        }
    }
}

/// A finished preparation.
#[derive(Clone, Debug, PartialEq)]
pub struct Preparation {
    pub outcome: Outcome,
    pub images: usize,
    /// Size of the prepared folder's files.
    pub bytes: u64,
}

/// Makes `dir` the prepared form of `dataset` (whose content hash is `content_hash`): keeps
/// what is current and intact, rebuilds the rest. Images are prepared in parallel on the
/// caller's rayon pool; `progress` counts images. Files are written under temporary names and
/// renamed, and the manifest last, so that a reader never sees a half-written file and an
/// interrupted preparation leaves no current-looking folder.
pub fn prepare(
    dataset: &Dataset,
    content_hash: &str,
    dir: &Path,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<Preparation> {
    let images = target_images(dataset);
    progress.start(images.len() as u64);
    let found = Prepared::open(dir, content_hash);
    if found.is_err() {
        match std::fs::remove_file(dir.join(MANIFEST)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(Error::io(dir.join(MANIFEST), e));
            }
            _ => {}
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let writer = Prepared {
        dir: dir.to_path_buf(),
        content_hash: content_hash.to_string(),
        evaluator: evaluator_version(),
        damaged: Mutex::new(Vec::new()),
    };
    let models = models(dataset);
    let bytes = AtomicU64::new(0);
    let done = AtomicUsize::new(0);
    let repaired = Mutex::new(Vec::new());
    images.par_iter().try_for_each(|&(scene_id, im_id)| {
        if cancel.load(Ordering::Relaxed) {
            return Err(Error::Cancelled);
        }
        let path = image_path(dir, scene_id, im_id);
        let intact = if found.is_ok() {
            // Every block checked: an evaluation checks only those it reads.
            match writer
                .image(scene_id, im_id)
                .and_then(|p| p.verify().map_err(|e| format!("{}: {e}", path.display())))
            {
                Ok(_) => true,
                Err(problem) => {
                    repaired
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push(problem);
                    false
                }
            }
        } else {
            false
        };
        if !intact {
            let data = compute_image(dataset, &models, scene_id, im_id)?;
            write_atomically(&path, &data.encode(&writer.stamp(scene_id, im_id)))?;
        }
        let size = std::fs::metadata(&path)
            .map_err(|e| Error::io(&path, e))?
            .len();
        bytes.fetch_add(size, Ordering::Relaxed);
        done.fetch_add(1, Ordering::Relaxed);
        progress.advance(1);
        Ok(())
    })?;
    let bytes = bytes.into_inner();
    let manifest = Manifest {
        format: FORMAT,
        evaluator: writer.evaluator.clone(),
        content_hash: content_hash.to_string(),
        dataset: dataset.name.clone(),
        images: done.into_inner(),
        bytes,
    };
    let json = serde_json::to_vec_pretty(&manifest).expect("a manifest serialises");
    write_atomically(&dir.join(MANIFEST), &json)?;
    let mut repaired = repaired.into_inner().unwrap_or_else(|e| e.into_inner());
    repaired.sort();
    let outcome = match found {
        Ok(_) if repaired.is_empty() => Outcome::Current,
        Ok(_) => Outcome::Repaired { files: repaired },
        Err(Unusable::Missing) => Outcome::Created,
        Err(why) => Outcome::Rebuilt(why),
    };
    Ok(Preparation {
        outcome,
        images: images.len(),
        bytes,
    })
}

/// The distinct target images, in order.
fn target_images(dataset: &Dataset) -> Vec<(u32, u32)> {
    let set: BTreeSet<(u32, u32)> = dataset
        .targets
        .iter()
        .map(|t| (t.scene_id, t.im_id))
        .collect();
    set.into_iter().collect()
}

fn image_path(dir: &Path, scene_id: u32, im_id: u32) -> PathBuf {
    dir.join(format!("{scene_id:06}"))
        .join(format!("{im_id:06}.pbprep"))
}

/// Render-ready models of the dataset's objects.
fn models(dataset: &Dataset) -> HashMap<u32, Model> {
    dataset
        .objects
        .iter()
        .map(|(&id, o)| (id, Model::new(&o.mesh)))
        .collect()
}

/// One image's depth, decoded, and its ground-truth instances rendered at the depth image's
/// size, exactly as an evaluation without a prepared form makes them.
fn compute_image(
    dataset: &Dataset,
    models: &HashMap<u32, Model>,
    scene_id: u32,
    im_id: u32,
) -> Result<ImageData> {
    let depth = dataset.load_depth(scene_id, im_id)?;
    let image = &dataset.scenes[&scene_id].images[&im_id];
    let mut renderer = Renderer::new();
    let gts = image
        .gt
        .iter()
        .map(|g| match models.get(&g.obj_id) {
            Some(model) => {
                renderer.render_model(model, &g.pose, &image.camera, depth.width, depth.height)
            }
            None => DepthWindow::empty(),
        })
        .collect();
    Ok(ImageData {
        width: depth.width,
        height: depth.height,
        depth: depth.data,
        depth_scale: image.depth_scale as f32,
        gts,
    })
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let parent = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}
