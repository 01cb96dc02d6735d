//! The BOP'22 result file of the 2D detection and segmentation tasks (a JSON list of COCO
//! entries with run-length-encoded masks).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = evaluator::coco::results::parse_coco_results(data);
});
