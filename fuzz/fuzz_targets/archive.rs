//! Zip archives of result files, unpacked as the service unpacks an uploaded `.zip`
//! (`intake::archive`): the entry count, names, compression methods, sizes and CRCs all come
//! from the input. Entries go to a temporary folder kept for the whole run, under a 1 MiB
//! limit of unpacked bytes (the service's is its upload limit), and are removed with the
//! answer.
#![no_main]

use std::io::Cursor;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// Unpacked bytes allowed per archive: enough for every seed, small enough that a zip bomb
/// stops early (as the service's limit stops one).
const LIMIT: u64 = 1 << 20;

static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("temporary folder"));
    let _ = intake::archive::unpack(dir.path(), "results.zip", Cursor::new(data), LIMIT);
});
