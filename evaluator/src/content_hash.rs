//! The content hash of a dataset: what lets a worker on another machine prove that its copy of
//! a dataset is the one the server registered, so that two copies never give two answers.
//!
//! It covers exactly the files that decide scores ([`Dataset::score_files`]: targets, models
//! information, meshes, camera files, the target scenes' ground truth and the target images'
//! depth), each by its path relative to the dataset folder, its size and its SHA-256. RGB
//! images, masks and other splits are left out: they are most of a BOP download and change no
//! score. The files are hashed in parallel, so a real test split (hundreds of MB of depth
//! images) takes about a second; it is computed when the server registers a dataset and when a
//! worker first needs it, and it keys a prepared dataset.
//!
//! An evaluation with a prepared form needs the hash on every run, to know the form is current,
//! and reading every depth image for it was 18 % of a one-thread evaluation of a large set.
//! [`content_hash_cached`] keeps each file's digest in the prepared folder ([`CACHE_FILE`])
//! keyed by the file's stat (size, mtime and ctime in ns, inode), as git's index and make do:
//! a file whose stat is unchanged is trusted to have unchanged bytes, so an unchanged dataset
//! is stat'ed instead of read. Writing a file changes its mtime and ctime (setting the mtime
//! back still changes the ctime), and replacing it changes its inode, so an edit is re-hashed;
//! a file written so recently that a second write could keep its timestamp ([`RACY`], git's
//! "racily clean" case) is not cached. What is not caught (a write that forges every field of
//! the stat) is still guarded against for the prepared data: opening a form recomputes one
//! image from the dataset and compares, and each prepared block has its own checksum. The
//! result is the very hash [`content_hash`] computes; the server registers datasets with the
//! full computation.

use std::collections::HashMap;
use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crate::dataset::Dataset;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// The name of the digest cache in a prepared folder.
pub const CACHE_FILE: &str = "hash-cache.json";

/// A file modified less than this before a hash began is not cached: within one timestamp tick
/// (up to 2 s on some file systems) a second write of the same size could leave its stat as it
/// was.
pub const RACY: Duration = Duration::from_secs(3);

/// The hash as lowercase hex, or the first file that cannot be read.
pub fn content_hash(dataset: &Dataset) -> Result<String, String> {
    let files = dataset.score_files().map_err(|e| e.to_string())?;
    let digests = files
        .par_iter()
        .map(|path| file_digest(path).map_err(|e| format!("{}: {e}", path.display())))
        .collect::<Result<Vec<_>, String>>()?;
    Ok(combine(dataset, &files, &digests))
}

/// [`content_hash`], reading only the files whose stat differs from the one recorded in
/// `dir`'s [`CACHE_FILE`] (a prepared folder), and recording the rest there for the next run.
/// A cache that cannot be read is ignored and rewritten; one that cannot be written (a
/// read-only folder, or no folder yet) only leaves the next run as slow as this one.
pub fn content_hash_cached(dataset: &Dataset, dir: &Path) -> Result<String, String> {
    let files = dataset.score_files().map_err(|e| e.to_string())?;
    let cache_path = dir.join(CACHE_FILE);
    let cache = std::fs::read(&cache_path)
        .ok()
        .and_then(|bytes| serde_json::from_slice::<Cache>(&bytes).ok())
        .filter(|c| c.version == CACHE_VERSION)
        .unwrap_or_default();
    let racy_since = SystemTime::now()
        .checked_sub(RACY)
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX));
    let looked = files
        .par_iter()
        .map(|path| {
            let failed = |e: std::io::Error| format!("{}: {e}", path.display());
            let key = relative(dataset, path);
            let stat = Stat::of(&std::fs::metadata(path).map_err(failed)?);
            if let Some(entry) = cache.files.get(&key).filter(|e| e.stat == stat)
                && let Ok(digest) = hex::decode(&entry.sha256)
                && digest.len() == 32
            {
                return Ok((key, (stat.size, digest), Some(entry.clone()), false));
            }
            let (size, digest) = file_digest(path).map_err(failed)?;
            // Read as stat'ed, and old enough that its stat changes with its next write.
            let keep = (size == stat.size && stat.mtime_ns < racy_since).then(|| Entry {
                stat,
                sha256: hex::encode(&digest),
            });
            Ok((key, (size, digest), keep, true))
        })
        .collect::<Result<Vec<_>, String>>()?;
    let rehashed = looked.iter().any(|l| l.3);
    let digests: Vec<(u64, Vec<u8>)> = looked.iter().map(|l| l.1.clone()).collect();
    let hash = combine(dataset, &files, &digests);
    let fresh = Cache {
        version: CACHE_VERSION,
        files: looked
            .into_iter()
            .filter_map(|(key, _, entry, _)| entry.map(|e| (key, e)))
            .collect(),
    };
    if (rehashed || fresh.files.len() != cache.files.len()) && dir.is_dir() {
        write_cache(&cache_path, &fresh);
    }
    Ok(hash)
}

/// The version of [`CACHE_FILE`]'s layout; another is ignored and rewritten.
const CACHE_VERSION: u32 = 1;

#[derive(Debug, Default, Serialize, Deserialize)]
struct Cache {
    version: u32,
    /// Per file, by its path relative to the dataset folder.
    files: HashMap<String, Entry>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Entry {
    #[serde(flatten)]
    stat: Stat,
    sha256: String,
}

/// What of a file's stat must be unchanged for its digest to be trusted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
struct Stat {
    size: u64,
    mtime_ns: i64,
    ctime_ns: i64,
    inode: u64,
}

impl Stat {
    fn of(meta: &std::fs::Metadata) -> Stat {
        let ns = |s: i64, n: i64| s.saturating_mul(1_000_000_000).saturating_add(n);
        Stat {
            size: meta.size(),
            mtime_ns: ns(meta.mtime(), meta.mtime_nsec()),
            ctime_ns: ns(meta.ctime(), meta.ctime_nsec()),
            inode: meta.ino(),
        }
    }
}

/// Written under a temporary name and renamed, so that a reader never sees half a cache; a
/// failure is left unsaid (the cache only saves time).
fn write_cache(path: &Path, cache: &Cache) {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".tmp{}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    let json = serde_json::to_vec(cache).expect("a hash cache serialises");
    if std::fs::write(&tmp, json).is_err() || std::fs::rename(&tmp, path).is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
}

/// A score file's path relative to the dataset folder, `/`-separated.
fn relative(dataset: &Dataset, path: &Path) -> String {
    let rel = path.strip_prefix(&dataset.root).unwrap_or(path);
    let parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    parts.join("/")
}

/// The hash of the files' relative paths, sizes and digests, in order.
fn combine(dataset: &Dataset, files: &[PathBuf], digests: &[(u64, Vec<u8>)]) -> String {
    let mut all = Sha256::new();
    for (path, (size, digest)) in files.iter().zip(digests) {
        all.update(relative(dataset, path).as_bytes());
        all.update([0]);
        all.update(size.to_le_bytes());
        all.update(digest);
    }
    hex::encode(all.finalize())
}

/// The size and SHA-256 of one file, read in blocks.
fn file_digest(path: &Path) -> std::io::Result<(u64, Vec<u8>)> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    let mut size = 0u64;
    loop {
        let n = file.read(&mut buf)?;
        if n == 0 {
            break;
        }
        size += n as u64;
        hasher.update(&buf[..n]);
    }
    Ok((size, hasher.finalize().to_vec()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn copy_dir(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let entry = entry.unwrap();
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy_dir(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), &target).unwrap();
            }
        }
    }

    fn reference() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference/dataset")
    }

    #[test]
    fn copies_agree_and_a_changed_depth_image_or_model_file_does_not() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a/synthA"), dir.path().join("b/synthA"));
        copy_dir(&reference(), &a);
        copy_dir(&reference(), &b);
        let hash = |p: &Path| content_hash(&Dataset::load(p).unwrap()).unwrap();
        let original = hash(&a);
        assert_eq!(original.len(), 64);
        assert_eq!(hash(&b), original, "same content in another folder");

        // An RGB image changes no score.
        let rgb = std::fs::read_dir(b.join("test/000001/rgb"))
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        std::fs::write(&rgb, b"other pixels").unwrap();
        assert_eq!(hash(&b), original);

        let depth = b.join("test/000001/depth/000002.png");
        let mut bytes = std::fs::read(&depth).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&depth, &bytes).unwrap();
        assert_ne!(hash(&b), original, "a changed depth image");

        copy_dir(&reference(), &b);
        assert_eq!(hash(&b), original);
        let info = b.join("models_eval/models_info.json");
        let mut bytes = std::fs::read(&info).unwrap();
        bytes.push(b'\n');
        std::fs::write(&info, &bytes).unwrap();
        assert_ne!(hash(&b), original, "a changed models_info.json");
    }

    /// Every file under `dir` made an hour old, as a downloaded dataset's are (a file written
    /// within [`RACY`] is not cached).
    fn age(dir: &Path) {
        let old = SystemTime::now() - Duration::from_secs(3600);
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                age(&path);
            } else {
                let file = std::fs::File::options().write(true).open(&path).unwrap();
                file.set_modified(old).unwrap();
            }
        }
    }

    /// An aged copy of the reference dataset in `dir`, with an empty folder for its cache.
    fn aged_copy(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf, Dataset) {
        let (root, prepared) = (dir.join("synthA"), dir.join("prepared"));
        copy_dir(&reference(), &root);
        age(&root);
        std::fs::create_dir(&prepared).unwrap();
        let dataset = Dataset::load(&root).unwrap();
        (root, prepared, dataset)
    }

    fn read_cache(dir: &Path) -> Cache {
        serde_json::from_slice(&std::fs::read(dir.join(CACHE_FILE)).unwrap()).unwrap()
    }

    #[test]
    fn the_cached_hash_is_the_full_hash_and_a_matching_stat_is_trusted() {
        let dir = tempfile::tempdir().unwrap();
        let (_, prepared, dataset) = aged_copy(dir.path());
        let full = content_hash(&dataset).unwrap();
        assert_eq!(content_hash_cached(&dataset, &prepared).unwrap(), full);
        let cache = read_cache(&prepared);
        assert_eq!(cache.files.len(), dataset.score_files().unwrap().len());
        assert_eq!(content_hash_cached(&dataset, &prepared).unwrap(), full);

        // A digest whose file's stat matches is used without reading the file: that is the
        // point of the cache (and why only the stat guards it).
        let mut forged = cache;
        let entry = forged
            .files
            .get_mut("test/000001/depth/000002.png")
            .unwrap();
        entry.sha256 = hex::encode([7u8; 32]);
        write_cache(&prepared.join(CACHE_FILE), &forged);
        assert_ne!(content_hash_cached(&dataset, &prepared).unwrap(), full);

        // A cache that cannot be read is ignored and rewritten.
        for junk in ["{ not json", r#"{"version": 99, "files": {}}"#, ""] {
            std::fs::write(prepared.join(CACHE_FILE), junk).unwrap();
            assert_eq!(content_hash_cached(&dataset, &prepared).unwrap(), full);
            assert_eq!(read_cache(&prepared).version, CACHE_VERSION);
        }
        // Without a folder to keep it in, the hash is still computed.
        let nowhere = dir.path().join("none");
        assert_eq!(content_hash_cached(&dataset, &nowhere).unwrap(), full);
        assert!(!nowhere.exists());
    }

    #[test]
    fn a_changed_depth_image_or_model_is_hashed_again_with_a_cache_present() {
        let dir = tempfile::tempdir().unwrap();
        let (root, prepared, dataset) = aged_copy(dir.path());
        let original = content_hash_cached(&dataset, &prepared).unwrap();
        let cached = |what: &str| {
            let hash = content_hash_cached(&dataset, &prepared).unwrap();
            assert_eq!(hash, content_hash(&dataset).unwrap(), "{what}");
            hash
        };

        // Same size, one byte changed, the mtime set back to what it was: the ctime differs.
        let depth = root.join("test/000001/depth/000002.png");
        let mtime = std::fs::metadata(&depth).unwrap().modified().unwrap();
        let mut bytes = std::fs::read(&depth).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&depth, &bytes).unwrap();
        let file = std::fs::File::options().write(true).open(&depth).unwrap();
        file.set_modified(mtime).unwrap();
        assert_ne!(cached("a changed depth image"), original);
        bytes[last] ^= 1;
        std::fs::write(&depth, &bytes).unwrap();
        assert_eq!(cached("the depth image as it was"), original);

        // A model replaced by another file (another inode) of another size.
        let model = root.join("models_eval/obj_000001.ply");
        let mut bytes = std::fs::read(&model).unwrap();
        bytes.extend_from_slice(b"\n");
        let other = root.join("models_eval/replacement");
        std::fs::write(&other, &bytes).unwrap();
        std::fs::rename(&other, &model).unwrap();
        assert_ne!(cached("a changed model"), original);
    }
}
