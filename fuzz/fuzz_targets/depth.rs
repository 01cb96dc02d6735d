//! What the two depth targets share: the evaluator opens depth images by path, so each input is
//! written to one file of a temporary folder kept for the whole run, then read in full.

use std::path::PathBuf;
use std::sync::OnceLock;

use evaluator::depth_files::{DepthFile, DepthFormat};

static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();

pub fn read(data: &[u8], format: DepthFormat) {
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("temporary folder"));
    let path: PathBuf = dir.path().join(format!("000000.{}", format.extension()));
    std::fs::write(&path, data).expect("input written");
    if let Ok(file) = DepthFile::open(path, format, 0.1) {
        let (_, height) = file.size();
        let _ = file.read_rows(0..height);
    }
}
