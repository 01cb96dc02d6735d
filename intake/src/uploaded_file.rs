//! A file received from a client, as every later step takes it: already on disk (never whole
//! in memory: uploads reach hundreds of megabytes) and already hashed (duplicates are found by
//! content).

use std::io::Write;
use std::path::Path;

use sha2::{Digest, Sha256};

/// A result file received into a temporary file of the submissions folder (removed unless it
/// is kept), with its content hash.
#[derive(Debug)]
pub struct UploadedFile {
    /// The client's name for it, for display.
    pub name: String,
    pub tmp: tempfile::TempPath,
    pub sha256: String,
    pub size: u64,
}

impl UploadedFile {
    /// A file from bytes already in memory (the demo set-up).
    pub fn from_bytes(dir: &Path, name: &str, bytes: &[u8]) -> std::io::Result<UploadedFile> {
        let mut tmp = tempfile::Builder::new()
            .prefix("upload-")
            .tempfile_in(dir)?;
        tmp.write_all(bytes)?;
        tmp.flush()?;
        Ok(UploadedFile {
            name: name.to_string(),
            tmp: tmp.into_temp_path(),
            sha256: hex::encode(Sha256::digest(bytes)),
            size: bytes.len() as u64,
        })
    }
}
