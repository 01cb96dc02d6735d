//! The content hash of a dataset lives in the evaluator ([`evaluator::content_hash`]), which
//! keys prepared datasets with it; the service extends it with the targets file of BOP'24 6D
//! detection, which the evaluator's localization form of the dataset does not read.

use sha2::{Digest, Sha256};

use evaluator::Dataset;

use super::config::BOP24_TARGETS;

/// The evaluator's content hash of `dataset`, extended, when its folder has
/// `test_targets_bop24.json`, with that file's name, size and SHA-256: bop24 scores depend on
/// the images it lists, so a worker whose copy lists others is refused as one with other
/// ground truth is. A folder without the file keeps the evaluator's hash (datasets registered
/// before keep theirs). The error names the file that cannot be read.
pub fn content_hash(dataset: &Dataset) -> Result<String, String> {
    let hash = evaluator::content_hash::content_hash(dataset)?;
    let path = dataset.root.join(BOP24_TARGETS);
    match std::fs::read(&path) {
        Ok(bytes) => {
            let mut all = Sha256::new();
            all.update(hash.as_bytes());
            all.update([0]);
            all.update(BOP24_TARGETS.as_bytes());
            all.update([0]);
            all.update((bytes.len() as u64).to_le_bytes());
            all.update(Sha256::digest(&bytes));
            Ok(hex::encode(all.finalize()))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(hash),
        Err(e) => Err(format!("{}: {e}", path.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The reference dataset's files linked into `dir`, with `bop24` as its BOP'24 targets.
    fn linked(dir: &Path, bop24: Option<&str>) -> Dataset {
        let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures");
        let reference = fixtures.join("reference/dataset");
        for entry in std::fs::read_dir(&reference).unwrap() {
            let entry = entry.unwrap();
            std::os::unix::fs::symlink(entry.path(), dir.join(entry.file_name())).unwrap();
        }
        if let Some(text) = bop24 {
            std::fs::write(dir.join(BOP24_TARGETS), text).unwrap();
        }
        Dataset::load(dir).unwrap()
    }

    #[test]
    fn the_bop24_targets_file_is_covered_when_present() {
        let tmp = tempfile::tempdir().unwrap();
        let [plain, one, other] = ["plain", "one", "other"].map(|n| tmp.path().join(n));
        for d in [&plain, &one, &other] {
            std::fs::create_dir(d).unwrap();
        }
        let plain = linked(&plain, None);
        let one = linked(&one, Some(r#"[{"im_id": 0, "scene_id": 1}]"#));
        let other = linked(&other, Some(r#"[{"im_id": 1, "scene_id": 1}]"#));
        let evaluator_hash = evaluator::content_hash::content_hash(&plain).unwrap();
        assert_eq!(content_hash(&plain).unwrap(), evaluator_hash);
        assert_eq!(
            evaluator::content_hash::content_hash(&one).unwrap(),
            evaluator_hash
        );
        let (a, b) = (content_hash(&one).unwrap(), content_hash(&other).unwrap());
        assert!(a != evaluator_hash && b != evaluator_hash && a != b);
    }
}
