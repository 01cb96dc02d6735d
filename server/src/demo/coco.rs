//! BOP'22 2D result files of two fictitious methods, derived from the demo dataset's
//! `scene_gt_coco.json`, so that the detection and segmentation boards are not empty on a first
//! start: a detector whose boxes are the ground truth's, shifted and resized by a few percent,
//! and a segmenter that gives most instances their exact visible mask and some only the box
//! around it. Both miss a few instances and add a false positive per image with a low score.

use std::path::Path;

use anyhow::{Context, Result};
use evaluator::coco::rle::Rle;
use evaluator::coco::{BboxType, CocoGt};
use evaluator::dataset::DatasetOptions;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};

use super::DemoResult;

/// Probability that an instance gets no detection.
const MISSING: f64 = 0.1;
/// Probability that the segmenter gives an instance the box around its mask instead.
const BOX_MASK: f64 = 0.25;
/// Standard size of the detector's box errors, as a fraction of the box's size.
const BOX_ERROR: f64 = 0.06;

/// Writes `demo-detector_{dataset}-test.json` (boxes) and `demo-segmenter_{dataset}-test.json`
/// (masks) for the dataset in `dataset_dir` into `out_dir`. Deterministic in `seed`.
pub fn write_demo_coco_results(
    dataset_dir: &Path,
    out_dir: &Path,
    seed: u64,
) -> Result<Vec<DemoResult>> {
    let gt = CocoGt::load(
        dataset_dir,
        &DatasetOptions::default(),
        BboxType::Amodal,
        true,
    )
    .with_context(|| {
        format!(
            "cannot load the 2D ground truth in {}",
            dataset_dir.display()
        )
    })?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let methods = [
        (
            "demo-detector",
            "Synthetic demo (2D detection): the ground-truth boxes shifted and resized by a few \
             percent, a few instances missed, a false positive per image.",
            false,
        ),
        (
            "demo-segmenter",
            "Synthetic demo (2D segmentation): the exact visible masks for most instances, the \
             box around the mask for some, a few instances missed, a false positive per image.",
            true,
        ),
    ];
    methods
        .iter()
        .enumerate()
        .map(|(n, &(method, description, masks))| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(100 + n as u64);
            let entries = entries(&gt, masks, &mut rng);
            let path = out_dir.join(format!("{method}_{}-test.json", gt.name));
            std::fs::write(&path, Value::from(entries).to_string())
                .with_context(|| format!("cannot write {}", path.display()))?;
            Ok(DemoResult {
                method: method.to_string(),
                description: description.to_string(),
                path,
            })
        })
        .collect()
}

/// The entries of one method, image by image.
fn entries(gt: &CocoGt, masks: bool, rng: &mut ChaCha8Rng) -> Vec<Value> {
    let mut out = Vec::new();
    for (index, image) in gt.images.iter().enumerate() {
        // One time for all the entries of an image, as the toolkit requires.
        let time = (rng.random_range(0.04..0.12f64) * 1000.0).round() / 1000.0;
        let mut size = (0, 0);
        for a in gt.annotations.iter().filter(|a| a.image == index) {
            let Some(mask) = &a.segmentation else {
                continue;
            };
            size = (mask.height(), mask.width());
            if rng.random_bool(MISSING) {
                continue;
            }
            let score = round3(rng.random_range(0.5..1.0));
            let mut entry = json!({
                "scene_id": image.scene_id, "image_id": image.im_id,
                "category_id": a.category_id, "score": score, "time": time,
            });
            if masks {
                let mask = if rng.random_bool(BOX_MASK) {
                    rectangle(mask.height(), mask.width(), mask.to_bbox())
                } else {
                    mask.clone()
                };
                entry["bbox"] = json!(mask.to_bbox());
                entry["segmentation"] = json!({
                    "counts": mask.counts(), "size": [mask.height(), mask.width()],
                });
            } else {
                let [x, y, w, h] = a.bbox;
                let mut err = || 1.0 + BOX_ERROR * rng.random_range(-1.0..1.0f64);
                let (w2, h2) = (w * err(), h * err());
                let (dx, dy) = (w * (err() - 1.0), h * (err() - 1.0));
                entry["bbox"] = json!([round3(x + dx), round3(y + dy), round3(w2), round3(h2)]);
            }
            out.push(entry);
        }
        if size.0 > 0 {
            // A false positive: a box of a random object somewhere in the image.
            let (h, w) = (f64::from(size.0), f64::from(size.1));
            let b = [
                rng.random_range(0.0..w * 0.8).floor(),
                rng.random_range(0.0..h * 0.8).floor(),
                rng.random_range(10.0..w * 0.2).floor(),
                rng.random_range(10.0..h * 0.2).floor(),
            ];
            let category = gt.categories[rng.random_range(0..gt.categories.len())];
            let mut entry = json!({
                "scene_id": image.scene_id, "image_id": image.im_id, "category_id": category,
                "score": round3(rng.random_range(0.05..0.5)), "time": time, "bbox": b,
            });
            if masks {
                let mask = rectangle(size.0, size.1, b);
                entry["bbox"] = json!(mask.to_bbox());
                entry["segmentation"] = json!({"counts": mask.counts(), "size": [size.0, size.1]});
            }
            out.push(entry);
        }
    }
    out
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// The mask of the pixels of a box `[x, y, w, h]` (clipped to the image), encoded column by
/// column straight into runs.
fn rectangle(height: u32, width: u32, [x, y, w, h]: [f64; 4]) -> Rle {
    let clip = |v: f64, max: u32| (v.max(0.0) as u32).min(max);
    let (x0, x1) = (clip(x, width), clip(x + w, width));
    let (y0, y1) = (clip(y, height), clip(y + h, height));
    let mut counts = Vec::new();
    let mut last_end = 0;
    if y1 > y0 {
        for col in x0..x1 {
            let (start, end) = (col * height + y0, col * height + y1);
            if start == last_end && !counts.is_empty() {
                *counts.last_mut().expect("a run") += end - start;
            } else {
                counts.push(start - last_end);
                counts.push(end - start);
            }
            last_end = end;
        }
    }
    counts.push(width * height - last_end);
    Rle::from_counts(height, width, counts).expect("runs within the image")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::{SynthOptions, write_dataset};
    use evaluator::coco::{self, CocoTask, load_coco_results};

    #[test]
    fn the_demo_detector_and_segmenter_score_well_but_not_perfectly() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("synthdemo");
        write_dataset(&dir, &SynthOptions::default()).unwrap();
        let out = tmp.path().join("results");
        let demos = write_demo_coco_results(&dir, &out, 11).unwrap();
        let gt = CocoGt::load(&dir, &DatasetOptions::default(), BboxType::Amodal, true).unwrap();
        for (demo, task) in demos.iter().zip([
            CocoTask::Detection(BboxType::Amodal),
            CocoTask::Segmentation,
        ]) {
            let results = load_coco_results(&demo.path).unwrap();
            let ap = coco::evaluate(&gt, &results, task).unwrap().ap;
            assert!(ap > 0.3 && ap < 0.99, "{}: AP {ap}", demo.method);
        }
        let again = write_demo_coco_results(&dir, &tmp.path().join("again"), 11).unwrap();
        for (a, b) in demos.iter().zip(&again) {
            assert_eq!(
                std::fs::read(&a.path).unwrap(),
                std::fs::read(&b.path).unwrap()
            );
        }
    }

    #[test]
    fn rectangles_cover_the_box_clipped_to_the_image() {
        let r = rectangle(4, 5, [1.0, 1.0, 2.0, 2.0]);
        assert_eq!(r.area(), 4);
        assert_eq!(r.to_bbox(), [1.0, 1.0, 2.0, 2.0]);
        assert_eq!(rectangle(4, 5, [3.0, -2.0, 9.0, 3.0]).area(), 2);
    }
}
