//! Fingerprints the evaluator's own source for the stamp of prepared datasets
//! (`prepared::file::evaluator_version`). A prepared form holds renders and depth this code
//! computed; any change to the code may change them, while the crate's version number changes
//! only at a release. Keyed by the source itself, a form made by other code is stale and never
//! read, and opening a form need not recompute an image to find out.
//!
//! FNV-1a over every file under `src/` (sorted by path, each path and its bytes) and
//! `Cargo.toml`: a change detector, not a defence against forgery, and no dependency for the
//! build script.

use std::path::{Path, PathBuf};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            files(&path, out);
        } else {
            out.push(path);
        }
    }
}

fn main() {
    let root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let mut paths = vec![root.join("Cargo.toml")];
    files(&root.join("src"), &mut paths);
    paths.sort();
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            hash ^= u64::from(b);
            hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for path in &paths {
        let relative = path.strip_prefix(&root).expect("under the crate");
        feed(relative.to_string_lossy().as_bytes());
        feed(&[0]);
        feed(&std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())));
        feed(&[0]);
    }
    println!("cargo:rustc-env=EVALUATOR_SOURCE={hash:016x}");
    println!("cargo:rerun-if-changed=src");
    println!("cargo:rerun-if-changed=Cargo.toml");
}
