//! A small synthetic BOP dataset made in code, and demo result files for it.
//!
//! A newcomer who starts poseboard without data should see a working leaderboard at once,
//! and real BOP datasets are too large (and not ours) to ship. So the service renders a
//! dataset of its own: six objects chosen to exercise every kind of symmetry handling, a few
//! cluttered table scenes with occlusion, truncation and sensor noise, and the annotations
//! computed with the evaluator's own renderer and visibility rules, so that they agree with
//! what the evaluation sees. Demo submissions of known quality then fill the leaderboard.
//! Each scene also gets the COCO ground truth of the BOP'22 2D tasks, made from the visible
//! masks as bop_toolkit's `calc_gt_coco.py` makes it, and a demo detector and segmenter fill
//! those boards.
//!
//! Everything is drawn from ChaCha8 streams seeded by the options (the same numbers on every
//! platform), so the same options give byte-identical files on every start.

mod coco;
mod files;
mod layouts;
mod scenes;
pub mod setup;
mod shapes;
mod submissions;

use std::path::Path;

use anyhow::{Context, Result, bail};

pub use coco::write_demo_coco_results;
pub use layouts::{
    CHALLENGE_LAYOUTS, CORE_LAYOUTS, ChallengeLayout, CoreLayout, write_challenge_miniature,
    write_core_miniature,
};
pub use submissions::{DETECTOR, DemoResult, write_demo_detection_results, write_demo_results};

pub use crate::domain::DEMO_DATASET;

/// What to generate; the default is what the service writes on first start.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SynthOptions {
    pub seed: u64,
    /// Scenes 1 to `scenes`.
    pub scenes: u32,
    /// Images 0 to `images_per_scene - 1` in each scene.
    pub images_per_scene: u32,
    /// (width, height) of the images; the intrinsics scale with it, so every size shows the
    /// same scenes with the same ground truth.
    pub image_size: (u32, u32),
    /// Object ids 1 to `objects` (at least the six shapes): beyond six, copies of the shapes
    /// under further ids, so that a dataset as wide as T-LESS (30 objects) can be made small.
    /// Object `s + 6k` is a copy of shape `s`; the instances of a shape in a scene take its
    /// ids in turn.
    pub objects: u32,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            seed: 7,
            scenes: 3,
            images_per_scene: 4,
            image_size: (scenes::WIDTH, scenes::HEIGHT),
            objects: shapes::SHAPES,
        }
    }
}

#[derive(serde::Serialize)]
struct CameraInfo {
    cx: f64,
    cy: f64,
    depth_scale: f64,
    fx: f64,
    fy: f64,
    height: u32,
    width: u32,
}

/// Writes the dataset into `dir` (created; must be empty or absent): `camera.json`,
/// `models/`, `models_eval/` (the same files), `test/`, `test_targets_bop19.json` and the
/// BOP'24 image list `test_targets_bop24.json` (every image with a target, so the dataset serves 6D
/// detection too, and the demo detection submission has a board). Images
/// are 640 x 480 with LINEMOD's intrinsics unless `opts.image_size` asks for another size
/// (the intrinsics then scale with it); depth PNGs are in tenths of a millimetre
/// (`depth_scale` 0.1). Same options -> byte-identical files.
pub fn write_dataset(dir: &Path, opts: &SynthOptions) -> Result<()> {
    if opts.scenes == 0 || opts.images_per_scene == 0 {
        bail!("the synthetic dataset needs at least one scene and one image per scene");
    }
    let (width, height) = opts.image_size;
    if width < 64 || height < 48 {
        bail!("images of {width} x {height} are too small: at least 64 x 48");
    }
    if dir.exists() {
        let mut entries =
            std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))?;
        if entries.next().is_some() {
            bail!("{} is not empty", dir.display());
        }
    }
    if opts.objects < shapes::SHAPES {
        bail!(
            "the synthetic dataset has at least its {} shapes as objects",
            shapes::SHAPES
        );
    }
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;

    let shapes = shapes::shapes();
    shapes::write_models(dir, &shapes, opts.objects)?;
    let k = scenes::cam_k(opts.image_size);
    let camera = serde_json::to_value(CameraInfo {
        cx: k[2],
        cy: k[5],
        depth_scale: scenes::DEPTH_SCALE,
        fx: k[0],
        fy: k[4],
        height,
        width,
    })?;
    if let serde_json::Value::Object(fields) = camera {
        files::write_json_object(&dir.join("camera.json"), fields)?;
    }
    let mut targets = Vec::new();
    for scene_id in 1..=opts.scenes {
        targets.extend(scenes::write_scene(
            &dir.join("test"),
            scene_id,
            opts,
            &shapes,
        )?);
    }
    files::write_json_list(&dir.join("test_targets_bop19.json"), &targets)?;
    // Every image with a target, once, in order (the targets are sorted by image).
    let mut images: Vec<serde_json::Value> = targets
        .iter()
        .map(|t| serde_json::json!({"im_id": t.im_id, "scene_id": t.scene_id}))
        .collect();
    images.dedup();
    files::write_json_list(&dir.join("test_targets_bop24.json"), &images)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use std::path::PathBuf;

    /// Every file under `dir`, by relative path.
    fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut stack = vec![dir.to_path_buf()];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    let bytes = std::fs::read(&path).unwrap();
                    out.insert(path.strip_prefix(dir).unwrap().to_path_buf(), bytes);
                }
            }
        }
        out
    }

    #[test]
    fn the_dataset_loads_with_the_evaluator() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join(DEMO_DATASET);
        let opts = SynthOptions::default();
        let start = std::time::Instant::now();
        write_dataset(&dir, &opts).unwrap();
        eprintln!("generated in {:?}", start.elapsed());

        let d = evaluator::Dataset::load(&dir).unwrap();
        assert_eq!(d.name, DEMO_DATASET);
        assert_eq!(
            d.objects.keys().copied().collect::<Vec<_>>(),
            [1, 2, 3, 4, 5, 6]
        );
        assert_eq!(d.scenes.keys().copied().collect::<Vec<_>>(), [1, 2, 3]);
        for scene in d.scenes.values() {
            assert_eq!(
                scene.images.keys().copied().collect::<Vec<_>>(),
                [0, 1, 2, 3]
            );
            for image in scene.images.values() {
                assert!((3..=5).contains(&image.gt.len()), "{}", image.gt.len());
                assert_eq!(image.depth_scale, scenes::DEPTH_SCALE);
                for gt in &image.gt {
                    assert!(
                        (550.0..1050.0).contains(&gt.pose.t.norm()),
                        "{:?}",
                        gt.pose.t
                    );
                }
            }
        }
        assert!(d.targets.len() >= 25, "{}", d.targets.len());
        assert_eq!(d.image_size, (640, 480));
        // Some image shows two instances of one object.
        assert!(d.targets.iter().any(|t| t.inst_count > 1));
        for t in &d.targets {
            let depth = d.load_depth(t.scene_id, t.im_id).unwrap();
            assert_eq!((depth.width, depth.height), (640, 480));
            let valid: Vec<f32> = depth.data.iter().copied().filter(|&v| v > 0.0).collect();
            assert!(valid.len() > 640 * 480 / 2);
            assert!(valid.iter().all(|&v| (300.0..3000.0).contains(&v)));
            assert!(valid.len() < 640 * 480 * 99 / 100, "no holes");
        }
        assert!(d.objects[&2].info.symmetries_discrete.len() == 3);
        assert!(!d.objects[&1].info.is_symmetric());
        assert_eq!(d.objects[&3].info.symmetries_continuous.len(), 1);
    }

    #[test]
    fn thirty_objects_are_copies_of_the_shapes_and_all_are_targets() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("synth30");
        let opts = SynthOptions {
            scenes: 1,
            images_per_scene: 16,
            image_size: (320, 240),
            objects: 30,
            ..SynthOptions::default()
        };
        write_dataset(&dir, &opts).unwrap();
        let d = evaluator::Dataset::load(&dir).unwrap();
        assert_eq!(
            d.objects.keys().copied().collect::<Vec<_>>(),
            (1..=30).collect::<Vec<_>>()
        );
        // Object 8 is a copy of shape 2 (three-fold symmetric), 9 of shape 3 (round).
        assert_eq!(d.objects[&8].info.symmetries_discrete.len(), 3);
        assert_eq!(d.objects[&9].info.symmetries_continuous.len(), 1);
        let targeted: std::collections::BTreeSet<u32> =
            d.targets.iter().map(|t| t.obj_id).collect();
        assert_eq!(targeted.len(), 30, "{targeted:?}");
        // Fewer objects than shapes is refused.
        let five = SynthOptions { objects: 5, ..opts };
        assert!(write_dataset(&tmp.path().join("five"), &five).is_err());
    }

    #[test]
    fn the_same_options_give_the_same_bytes() {
        let tmp = tempfile::tempdir().unwrap();
        let opts = SynthOptions {
            seed: 3,
            scenes: 2,
            images_per_scene: 3,
            ..SynthOptions::default()
        };
        write_dataset(&tmp.path().join("a"), &opts).unwrap();
        write_dataset(&tmp.path().join("b"), &opts).unwrap();
        let (a, b) = (files(&tmp.path().join("a")), files(&tmp.path().join("b")));
        assert!(a.len() > 20);
        assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
        for (path, bytes) in &a {
            assert!(bytes == &b[path], "{} differs", path.display());
        }
        assert_eq!(a.len(), files(&tmp.path().join("a")).len());
        assert_eq!(
            a[Path::new("models/obj_000001.ply")],
            a[Path::new("models_eval/obj_000001.ply")]
        );

        write_dataset(&tmp.path().join("c"), &SynthOptions { seed: 4, ..opts }).unwrap();
        let c = files(&tmp.path().join("c"));
        let depth = Path::new("test/000001/depth/000000.png");
        assert_ne!(a[depth], c[depth]);
    }

    #[test]
    fn refuses_a_folder_that_is_not_empty() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(tmp.path().join("x"), "").unwrap();
        let err = write_dataset(tmp.path(), &SynthOptions::default()).unwrap_err();
        assert!(err.to_string().contains("not empty"), "{err}");
        // An empty folder is fine.
        let empty = tmp.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        write_dataset(
            &empty,
            &SynthOptions {
                scenes: 1,
                images_per_scene: 1,
                ..SynthOptions::default()
            },
        )
        .unwrap();
        assert!(empty.join("test_targets_bop19.json").is_file());
    }

    #[test]
    fn visible_fractions_span_the_range() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join(DEMO_DATASET);
        write_dataset(&dir, &SynthOptions::default()).unwrap();
        let mut fractions = Vec::new();
        let mut truncated = 0;
        for scene in 1..=3 {
            let path = dir.join(format!("test/{scene:06}/scene_gt_info.json"));
            let info: BTreeMap<String, Vec<serde_json::Value>> =
                serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
            for inst in info.values().flatten() {
                let f = inst["visib_fract"].as_f64().unwrap();
                let bbox: Vec<i64> = serde_json::from_value(inst["bbox_obj"].clone()).unwrap();
                let all = inst["px_count_all"].as_u64().unwrap();
                let visib = inst["px_count_visib"].as_u64().unwrap();
                let valid = inst["px_count_valid"].as_u64().unwrap();
                assert!(visib <= all && valid <= all);
                if f >= 0.1 && (bbox[0] < 0 || bbox[0] + bbox[2] >= 640) {
                    truncated += 1;
                }
                fractions.push(f);
            }
        }
        eprintln!("visible fractions: {fractions:?}");
        assert!(fractions.iter().all(|f| (0.0..=1.0).contains(f)));
        assert!(fractions.iter().any(|&f| f < 0.1));
        assert!(fractions.iter().any(|&f| f > 0.1 && f < 0.9));
        assert!(truncated > 0, "no instance is cut by the image border");
    }
}
