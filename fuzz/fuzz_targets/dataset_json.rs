//! A dataset's JSON files (`scene_gt.json`, `scene_camera.json`, `scene_gt_info.json`,
//! `models_info.json`, the targets and the camera), which dataset uploads bring, each parsed
//! from its bytes by the parser `Dataset::load` hands it to: the first byte of an input
//! chooses the file, the rest is its content. A scene's three files are parsed together
//! (ground-truth ids are list positions across them), so the two not chosen are the reference
//! dataset's. Nothing is read from disk, so an input costs its own parse only.
#![no_main]

use std::path::Path;

use evaluator::dataset::{
    SceneFiles, parse_camera_size, parse_models_info, parse_scene, parse_targets,
};
use libfuzzer_sys::fuzz_target;

/// The reference dataset's scene files, for the two of a scene an input does not replace.
const SCENE_GT: &[u8] =
    include_bytes!("../../tests/fixtures/reference/dataset/test/000001/scene_gt.json");
const SCENE_CAMERA: &[u8] =
    include_bytes!("../../tests/fixtures/reference/dataset/test/000001/scene_camera.json");
const SCENE_GT_INFO: &[u8] =
    include_bytes!("../../tests/fixtures/reference/dataset/test/000001/scene_gt_info.json");

/// The files an input may be, in the order of its first byte (modulo their number); the seeds
/// of `corpus/dataset_json` follow it.
const FILES: [&str; 6] = [
    "test/000001/scene_gt.json",
    "test/000001/scene_camera.json",
    "test/000001/scene_gt_info.json",
    "models/models_info.json",
    "test_targets_bop19.json",
    "camera.json",
];

fuzz_target!(|data: &[u8]| {
    let Some((&selector, content)) = data.split_first() else {
        return;
    };
    let which = usize::from(selector) % FILES.len();
    let path = Path::new(FILES[which]);
    let scene = |gt, camera, gt_info| {
        let files = SceneFiles {
            camera: (Path::new(FILES[1]), camera),
            gt: (Path::new(FILES[0]), gt),
            gt_info: (Path::new(FILES[2]), gt_info),
        };
        let _ = parse_scene(1, None, files);
    };
    match which {
        0 => scene(content, SCENE_CAMERA, SCENE_GT_INFO),
        1 => scene(SCENE_GT, content, SCENE_GT_INFO),
        2 => scene(SCENE_GT, SCENE_CAMERA, content),
        3 => drop(parse_models_info(content, path)),
        4 => drop(parse_targets(content, path)),
        _ => drop(parse_camera_size(content, path)),
    }
});
