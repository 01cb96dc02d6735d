//! 16-bit depth images in PNG, read from disk as the evaluator reads a dataset's: the header,
//! then every row.
#![no_main]

use evaluator::depth_files::DepthFormat;

mod depth;

libfuzzer_sys::fuzz_target!(|data: &[u8]| depth::read(data, DepthFormat::Png));
