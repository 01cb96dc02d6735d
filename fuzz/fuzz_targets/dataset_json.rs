//! A dataset's JSON files (`scene_gt.json`, `scene_camera.json`, `scene_gt_info.json`,
//! `models_info.json`, the targets and the camera), which dataset uploads bring: the first byte
//! of an input chooses the file, the rest replaces it in a copy of the reference dataset, which
//! is then loaded as the service loads a dataset. The copy's meshes are a few faces each, so
//! that a load costs the JSON, not the PLY.
#![no_main]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// The files an input may replace, in the order of its first byte (modulo their number); the
/// seeds of `corpus/dataset_json` follow it.
const FILES: [&str; 6] = [
    "test/000001/scene_gt.json",
    "test/000001/scene_camera.json",
    "test/000001/scene_gt_info.json",
    "models/models_info.json",
    "test_targets_bop19.json",
    "camera.json",
];

const MESH: &[u8] = include_bytes!("../corpus/ply/obj_000001-binary.ply");

struct Base {
    dir: tempfile::TempDir,
    /// The reference dataset's bytes of each of `FILES`, put back after each input.
    originals: Vec<Vec<u8>>,
}

fn base() -> &'static Base {
    static BASE: OnceLock<Base> = OnceLock::new();
    BASE.get_or_init(|| {
        let reference =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference/dataset");
        let dir = tempfile::tempdir().expect("temporary folder");
        let root = dir.path().join("synthA");
        let copy = |name: &str| {
            let to = root.join(name);
            std::fs::create_dir_all(to.parent().expect("parent")).expect("folder");
            std::fs::copy(reference.join(name), to).expect("fixture copied");
        };
        for name in FILES {
            copy(name);
        }
        for name in ["scene_gt.json", "scene_camera.json", "scene_gt_info.json"] {
            copy(&format!("test/000002/{name}"));
        }
        for id in 1..=4 {
            std::fs::write(root.join(format!("models/obj_{id:06}.ply")), MESH).expect("mesh");
        }
        let originals = FILES
            .iter()
            .map(|name| std::fs::read(root.join(name)).expect("copied file"))
            .collect();
        Base { dir, originals }
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&selector, content)) = data.split_first() else {
        return;
    };
    let base = base();
    let root: PathBuf = base.dir.path().join("synthA");
    let which = usize::from(selector) % FILES.len();
    let path = root.join(FILES[which]);
    std::fs::write(&path, content).expect("input written");
    let _ = evaluator::Dataset::load(&root);
    std::fs::write(&path, &base.originals[which]).expect("original restored");
});
