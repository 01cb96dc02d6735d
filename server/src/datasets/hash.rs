//! The content hash of a dataset: what lets a worker on another machine prove that its copy of
//! a dataset is the one the server registered, so that two copies never give two answers.
//!
//! It covers exactly the files that decide scores ([`Dataset::score_files`]: targets, models
//! information, meshes, camera files, the target scenes' ground truth and the target images'
//! depth), each by its path relative to the dataset folder, its size and its SHA-256. RGB
//! images, masks and other splits are left out: they are most of a BOP download and change no
//! score. The files are hashed in parallel, so a real test split (hundreds of MB of depth
//! images) takes about a second; it is computed when the server registers a dataset and when a
//! worker first needs it.

use std::io::Read;
use std::path::Path;

use evaluator::Dataset;
use rayon::prelude::*;
use sha2::{Digest, Sha256};

/// The hash as lowercase hex, or the first file that cannot be read.
pub fn content_hash(dataset: &Dataset) -> Result<String, String> {
    let files = dataset.score_files().map_err(|e| e.to_string())?;
    let digests = files
        .par_iter()
        .map(|path| file_digest(path).map_err(|e| format!("{}: {e}", path.display())))
        .collect::<Result<Vec<_>, String>>()?;
    let mut all = Sha256::new();
    for (path, (size, digest)) in files.iter().zip(digests) {
        let rel = path.strip_prefix(&dataset.root).unwrap_or(path);
        let rel: Vec<String> = rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect();
        all.update(rel.join("/").as_bytes());
        all.update([0]);
        all.update(size.to_le_bytes());
        all.update(digest);
    }
    Ok(hex::encode(all.finalize()))
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
}
