//! Object meshes (PLY, ASCII or binary little endian), which dataset uploads bring.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = evaluator::ply::parse_ply(data, Path::new("obj_000001.ply"));
});
