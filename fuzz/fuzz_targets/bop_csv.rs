//! The BOP'19 result file (`scene_id,im_id,obj_id,score,R,t,time`): the CSV every 6D submission
//! is. Parsing must end in estimates or in problems naming lines, never in a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(results) = evaluator::results::parse_results(data) {
        // The one computation made from the parsed times alone.
        let _ = results.average_time_per_image();
    }
});
