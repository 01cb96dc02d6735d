//! An uploaded result file on its way to the workers: compressed into the database at upload,
//! read back (and checked against its content hash) by whichever worker evaluates it. Uploads
//! taken by older versions were kept only in the server's `submissions/` folder: the server
//! imports them into the database at start, and a worker sharing that folder still reads them
//! there until then.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use flate2::Compression;
use flate2::read::GzDecoder;
use flate2::write::GzEncoder;
use sha2::{Digest, Sha256};

use crate::store::{Store, StoreError};

#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{0}")]
    Store(#[from] StoreError),
    #[error("the uploaded file {0} is neither in the database nor on this machine")]
    Missing(String),
    #[error("the stored copy of {sha256} is damaged: {reason}")]
    Damaged { sha256: String, reason: String },
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// gzip at a fast level: result files are text and shrink about threefold even so.
pub fn compress(bytes: &[u8]) -> std::io::Result<Vec<u8>> {
    let mut encoder = GzEncoder::new(Vec::with_capacity(bytes.len() / 3), Compression::fast());
    encoder.write_all(bytes)?;
    encoder.finish()
}

/// Where an older version kept the file of this content hash.
pub fn legacy_path(submissions_dir: &Path, sha256: &str) -> PathBuf {
    submissions_dir.join(format!("{sha256}.csv"))
}

/// The file of content hash `sha256`: the database copy, else the disk copy of an older
/// version; either is checked against the hash, so a damaged copy is never evaluated.
pub async fn fetch(
    store: &Store,
    submissions_dir: &Path,
    sha256: &str,
) -> Result<Vec<u8>, FileError> {
    let bytes = match store.submission_file(sha256).await? {
        Some(stored) => {
            let sha = sha256.to_string();
            tokio::task::spawn_blocking(move || {
                let mut out = Vec::with_capacity(stored.size.max(0) as usize);
                GzDecoder::new(&stored.gzip[..])
                    .read_to_end(&mut out)
                    .map_err(|e| FileError::Damaged {
                        sha256: sha,
                        reason: e.to_string(),
                    })?;
                Ok::<_, FileError>(out)
            })
            .await
            .map_err(|e| std::io::Error::other(e.to_string()))??
        }
        None => match tokio::fs::read(legacy_path(submissions_dir, sha256)).await {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(FileError::Missing(sha256.to_string()));
            }
            Err(e) => return Err(e.into()),
        },
    };
    let actual = hex::encode(Sha256::digest(&bytes));
    if actual != sha256 {
        return Err(FileError::Damaged {
            sha256: sha256.to_string(),
            reason: format!("its content hashes to {actual}"),
        });
    }
    Ok(bytes)
}

/// Stores in the database every submitted file that an older version kept only on disk;
/// returns how many. The disk copies stay (the operator removes the folder once satisfied).
pub async fn import_legacy(store: &Store, submissions_dir: &Path) -> Result<usize, FileError> {
    let mut imported = 0;
    for sha256 in store.files_missing().await? {
        let path = legacy_path(submissions_dir, &sha256);
        let bytes = match tokio::fs::read(&path).await {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                tracing::warn!(file = %path.display(), "a submitted file is missing: its submission cannot be evaluated again");
                continue;
            }
            Err(e) => return Err(e.into()),
        };
        let size = bytes.len() as i64;
        let gzip = tokio::task::spawn_blocking(move || compress(&bytes))
            .await
            .map_err(|e| std::io::Error::other(e.to_string()))??;
        store.import_file(&sha256, size, &gzip).await?;
        imported += 1;
    }
    Ok(imported)
}
