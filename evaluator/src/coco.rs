//! The 2D tasks the BOP site ranks since 2022: detection (`bop22-det`, boxes) and
//! segmentation (`bop22-seg`, masks), scored as bop_toolkit's `scripts/eval_bop22_coco.py`
//! scores them with the pycocotools fork it names (MartinSmeyer/cocoapi): COCOeval over the
//! target images of all scenes merged, reporting the twelve COCO numbers under the toolkit's
//! keys (`AP`, `AP50`, ..., `AR_large`, `average_time_per_image`).
//!
//! - [`rle`], COCO's run-length encoded masks, with maskApi's semantics.
//! - [`gt`], the `scene_gt_coco.json` / `scene_gt_coco_modal.json` files of a dataset.
//! - [`results`], the `METHOD_DATASET-test.json` result files.
//! - [`eval`], COCOeval.
//!
//! These tasks are not variants of [`crate::ProtocolName`]: their inputs (JSON results, COCO
//! ground truth), parameters and report share nothing with the 6D protocols, and the server
//! matches on `ProtocolName` exhaustively in many places, so a separate [`CocoTask`] keeps
//! the two apart until the service grows boards for these tasks.
//!
//! Where poseboard differs from the toolkit, on purpose:
//! - `average_time_per_image` is the plain mean over the file's images (see
//!   [`results::CocoResults::average_time_per_image`] for the toolkit's bug it avoids);
//! - files the toolkit lets through but cannot score (RLE counts that do not add up to the
//!   mask, boxes with a negative size, a box in some entries only of a segmentation file) are
//!   refused with the entry named, instead of hanging, crashing or scoring -1.
//!
//! Like the toolkit, a file with no entry for a target image scores -1 everywhere.

use serde::{Deserialize, Serialize};

pub mod eval;
pub mod gt;
pub mod problems;
pub mod results;
pub mod rle;

use crate::bootstrap::{self, Bootstrap, BootstrapSummary};
use crate::report::EVALUATOR_VERSION;
pub use eval::{ImageEvals, ImageOutcome, IouType};
pub use gt::{BboxType, CocoGt};
pub use results::{CocoResults, load_coco_results, parse_coco_results};

/// A 2D task: what is compared with the ground truth.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CocoTask {
    /// Boxes, against the amodal (default) or modal ground-truth boxes.
    Detection(BboxType),
    /// Masks of the visible part.
    Segmentation,
}

impl CocoTask {
    /// The protocol name poseboard uses on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            CocoTask::Detection(_) => "bop22-det",
            CocoTask::Segmentation => "bop22-seg",
        }
    }

    pub fn iou_type(self) -> IouType {
        match self {
            CocoTask::Detection(_) => IouType::Bbox,
            CocoTask::Segmentation => IouType::Segm,
        }
    }

    /// The ground-truth file read: segmentation reads the amodal file, as the toolkit does
    /// (the masks are the same in both).
    pub fn bbox_type(self) -> BboxType {
        match self {
            CocoTask::Detection(b) => b,
            CocoTask::Segmentation => BboxType::Amodal,
        }
    }
}

/// What a 2D score is computed with, for its reproducibility record: COCOeval's parameters
/// as this evaluator runs them (fixed for a task; the thresholds as the protocol defines them,
/// 0.50:0.05:0.95, rather than as `linspace` rounds them).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoParameters {
    pub iou_type: IouType,
    pub bbox_type: BboxType,
    pub iou_thresholds: Vec<f64>,
    pub recall_points: usize,
    pub max_detections: Vec<usize>,
    /// All, small, medium and large, in pixels (bounds inclusive).
    pub area_ranges: Vec<[f64; 2]>,
}

impl CocoTask {
    pub fn parameters(self) -> CocoParameters {
        CocoParameters {
            iou_type: self.iou_type(),
            bbox_type: self.bbox_type(),
            iou_thresholds: eval::iou_thresholds()
                .into_iter()
                .map(crate::report::as_defined)
                .collect(),
            recall_points: eval::recall_thresholds().len(),
            max_detections: eval::MAX_DETS.to_vec(),
            area_ranges: eval::AREA_RANGES.to_vec(),
        }
    }
}

/// The report of one evaluation, with the toolkit's key names for its numbers (its file is
/// `scores_bop22_coco_{segm,bbox}[_modal].json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CocoReport {
    pub evaluator_version: String,
    pub dataset: String,
    /// `bop22-det` or `bop22-seg`.
    pub protocol: String,
    pub ann_type: IouType,
    pub bbox_type: BboxType,
    /// Entries of the result file.
    pub entries_count: usize,
    /// Entries for target images and categories of the dataset: the ones scored.
    pub entries_evaluated: usize,
    /// Entries for other images or categories, left out as the toolkit leaves them out.
    pub entries_ignored: usize,
    pub target_images: usize,
    pub target_images_without_entry: usize,
    #[serde(rename = "AP")]
    pub ap: f64,
    #[serde(rename = "AP50")]
    pub ap50: f64,
    #[serde(rename = "AP75")]
    pub ap75: f64,
    #[serde(rename = "AP_small")]
    pub ap_small: f64,
    #[serde(rename = "AP_medium")]
    pub ap_medium: f64,
    #[serde(rename = "AP_large")]
    pub ap_large: f64,
    #[serde(rename = "AR1")]
    pub ar1: f64,
    #[serde(rename = "AR10")]
    pub ar10: f64,
    #[serde(rename = "AR100")]
    pub ar100: f64,
    #[serde(rename = "AR_small")]
    pub ar_small: f64,
    #[serde(rename = "AR_medium")]
    pub ar_medium: f64,
    #[serde(rename = "AR_large")]
    pub ar_large: f64,
    /// Seconds; -1 when some entry gives no time, as the toolkit writes it.
    pub average_time_per_image: f64,
    /// Precision at the recall points 0, 0.01, ..., 1 (area all, 100 detections, mean over
    /// categories; -1 where undefined): at IoU 0.5, at 0.75, and averaged over the thresholds.
    pub precision_recall: PrecisionRecall,
    /// The bootstrap 95 % interval of `AP`, when the caller drew one
    /// ([`CocoEvaluation::bootstrap`]); absent otherwise, so reports without it read as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bootstrap: Option<BootstrapSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrecisionRecall {
    pub iou_50: Vec<f64>,
    pub iou_75: Vec<f64>,
    pub iou_mean: Vec<f64>,
}

/// The toolkit's names of the twelve numbers, in COCOeval's `stats` order.
pub const STAT_NAMES: [&str; 12] = [
    "AP",
    "AP50",
    "AP75",
    "AP_small",
    "AP_medium",
    "AP_large",
    "AR1",
    "AR10",
    "AR100",
    "AR_small",
    "AR_medium",
    "AR_large",
];

impl CocoReport {
    /// The twelve numbers in COCOeval's `stats` order, with the toolkit's names.
    pub fn stats(&self) -> [(&'static str, f64); 12] {
        let values = [
            self.ap,
            self.ap50,
            self.ap75,
            self.ap_small,
            self.ap_medium,
            self.ap_large,
            self.ar1,
            self.ar10,
            self.ar100,
            self.ar_small,
            self.ar_medium,
            self.ar_large,
        ];
        std::array::from_fn(|i| (STAT_NAMES[i], values[i]))
    }
}

/// A report with what its AP was accumulated from, for the AP's bootstrap.
pub struct CocoEvaluation {
    pub report: CocoReport,
    /// `None` when no entry is for a target image (the report is -1 everywhere).
    pub images: Option<ImageEvals>,
}

impl CocoEvaluation {
    /// Bootstrap replicates of the AP over the target images, drawn as the 6D headlines' are
    /// ([`crate::bootstrap::resample`]: the same seed draws the same images), recorded in the
    /// report's `bootstrap`. `None` when there is nothing to resample, or when a resampling
    /// holds no regular instance (its AP is undefined, so no interval is claimed).
    pub fn bootstrap(&mut self, seed: u64, replicates: usize) -> Option<Bootstrap> {
        let images = self.images.as_ref()?;
        let b = bootstrap::resample(images.images(), seed, replicates, |w| {
            Some(images.weighted_ap(w)).filter(|ap| *ap >= 0.0)
        })?;
        self.report.bootstrap = Some(b.summary());
        Some(b)
    }
}

/// Scores `results` on `gt` for `task`. The results must meet the task's needs
/// ([`CocoResults::require`]); `gt` must have been loaded with masks for segmentation.
/// Parallel on the caller's rayon pool.
pub fn evaluate(gt: &CocoGt, results: &CocoResults, task: CocoTask) -> crate::Result<CocoReport> {
    evaluation(gt, results, task).map(|e| e.report)
}

/// [`evaluate`], keeping what a bootstrap of the AP needs.
pub fn evaluation(
    gt: &CocoGt,
    results: &CocoResults,
    task: CocoTask,
) -> crate::Result<CocoEvaluation> {
    results.require(task).map_err(crate::Error::CocoResults)?;
    let iou_type = task.iou_type();
    if iou_type == IouType::Segm && gt.annotations.iter().any(|a| a.segmentation.is_none()) {
        return Err(crate::Error::Parameters(
            "the ground truth was loaded without masks".into(),
        ));
    }
    let (detections, with_target_image) = detections(gt, results);
    let targets_entries = results
        .entries
        .iter()
        .filter(|e| gt.image_index(e.scene_id, e.image_id).is_some())
        .count();

    let (stats, curves, time, images) = if targets_entries == 0 {
        // The toolkit's loadRes fails on an empty list (IndexError), and it writes -1.
        let none = vec![-1.0; 101];
        (
            [-1.0; 12],
            PrecisionRecall {
                iou_50: none.clone(),
                iou_75: none.clone(),
                iou_mean: none,
            },
            -1.0,
            None,
        )
    } else {
        let (acc, images) = eval::evaluate(gt, &detections, iou_type);
        (
            acc.summarize(),
            PrecisionRecall {
                iou_50: acc.precision_curve(Some(0.5)),
                iou_75: acc.precision_curve(Some(0.75)),
                iou_mean: acc.precision_curve(None),
            },
            results.average_time_per_image().unwrap_or(-1.0),
            Some(images),
        )
    };
    let report = CocoReport {
        evaluator_version: EVALUATOR_VERSION.to_string(),
        dataset: gt.name.clone(),
        protocol: task.name().to_string(),
        ann_type: iou_type,
        bbox_type: task.bbox_type(),
        entries_count: results.entries.len(),
        entries_evaluated: detections.len(),
        entries_ignored: results.entries.len() - detections.len(),
        target_images: gt.images.len(),
        target_images_without_entry: gt.images.len() - with_target_image,
        ap: stats[0],
        ap50: stats[1],
        ap75: stats[2],
        ap_small: stats[3],
        ap_medium: stats[4],
        ap_large: stats[5],
        ar1: stats[6],
        ar10: stats[7],
        ar100: stats[8],
        ar_small: stats[9],
        ar_medium: stats[10],
        ar_large: stats[11],
        average_time_per_image: time,
        precision_recall: curves,
        bootstrap: None,
    };
    Ok(CocoEvaluation { report, images })
}

/// The entries of `results` for target images and categories, as COCOeval takes them in, and
/// how many target images have an entry.
fn detections<'a>(gt: &CocoGt, results: &'a CocoResults) -> (Vec<eval::Detection<'a>>, usize) {
    // loadRes takes the areas from the boxes when its first result has one.
    let box_areas = results.entries.first().is_some_and(|e| e.bbox.is_some());
    let mut detections = Vec::new();
    let mut per_image = vec![false; gt.images.len()];
    for e in &results.entries {
        let Some(image) = gt.image_index(e.scene_id, e.image_id) else {
            continue;
        };
        per_image[image] = true;
        if gt.categories.binary_search(&e.category_id).is_err() {
            continue;
        }
        let bbox = e
            .bbox
            .unwrap_or_else(|| e.segmentation.as_ref().map_or([0.0; 4], |m| m.to_bbox()));
        let area = if box_areas {
            bbox[2] * bbox[3]
        } else {
            e.segmentation.as_ref().map_or(0.0, |m| f64::from(m.area()))
        };
        detections.push(eval::Detection {
            image,
            category_id: e.category_id,
            score: e.score,
            area,
            bbox,
            mask: e.segmentation.as_ref(),
        });
    }
    // The toolkit's scene merge: detections of earlier scenes (in targets order) first, file
    // order within a scene; only the order within an image matters to COCOeval, and a stable
    // sort by image keeps it.
    detections.sort_by_key(|d| d.image);
    (detections, per_image.iter().filter(|&&b| b).count())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::DatasetOptions;

    fn fixtures() -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/coco")
    }

    fn case(task: CocoTask, name: &str) -> (CocoGt, CocoResults) {
        let gt = CocoGt::load(
            &fixtures().join("dataset/tudl"),
            &DatasetOptions::default(),
            task.bbox_type(),
            task == CocoTask::Segmentation,
        )
        .expect("ground truth loads");
        let results = load_coco_results(&fixtures().join(format!("results/{name}_tudl-test.json")))
            .expect("results parse");
        (gt, results)
    }

    const TASKS: [CocoTask; 2] = [
        CocoTask::Detection(BboxType::Amodal),
        CocoTask::Segmentation,
    ];

    #[test]
    fn unit_weights_give_the_reports_ap_to_the_bit() {
        for task in TASKS {
            for name in [
                "noisy",
                "visible",
                "duplicated",
                "falsepositive",
                "tied",
                "many",
            ] {
                let (gt, results) = case(task, name);
                let e = evaluation(&gt, &results, task).expect("evaluates");
                let images = e.images.as_ref().expect("entries for target images");
                let ones = vec![1; images.images()];
                assert_eq!(
                    images.weighted_ap(&ones).to_bits(),
                    e.report.ap.to_bits(),
                    "{name}"
                );
            }
        }
    }

    #[test]
    fn weights_score_as_cocoeval_on_the_repeated_images() {
        for task in TASKS {
            for name in ["noisy", "tied", "many", "falsepositive"] {
                let (gt, results) = case(task, name);
                let e = evaluation(&gt, &results, task).expect("evaluates");
                let images = e.images.as_ref().expect("entries for target images");
                let n = images.images();
                assert!(n >= 3, "{name}: {n} images");
                // Every image 0 to 3 times, none left as it was for the first three.
                let weights: Vec<u32> = (0..n).map(|i| [2, 0, 3, 1][i % 4]).collect();
                let (repeated, copies) = gt.repeated(&weights);
                let (detections, _) = detections(&gt, &results);
                let mut on_copies = Vec::new();
                for d in &detections {
                    for &image in &copies[d.image] {
                        on_copies.push(eval::Detection { image, ..d.clone() });
                    }
                }
                let (acc, _) = eval::evaluate(&repeated, &on_copies, task.iou_type());
                assert_eq!(
                    images.weighted_ap(&weights).to_bits(),
                    acc.summarize()[0].to_bits(),
                    "{name} {}",
                    task.name()
                );
            }
        }
    }

    #[test]
    fn outcomes_at_50_add_up_to_the_matching() {
        let task = CocoTask::Detection(BboxType::Amodal);
        // Exact boxes: every regular instance matched, nothing else.
        let (gt, exact) = case(task, "exact");
        let e = evaluation(&gt, &exact, task).expect("evaluates");
        let outcomes = e.images.as_ref().expect("images").outcomes_at_50(&gt);
        assert!(!outcomes.is_empty());
        for o in &outcomes {
            assert_eq!((o.missed(), o.false_positives), (0, 0), "{o:?}");
        }
        let regular = gt.annotations.iter().filter(|a| !a.ignore).count();
        assert_eq!(outcomes.iter().map(|o| o.matched).sum::<usize>(), regular);
        // Extra boxes that hit nothing are false positives, and the instances stay the same.
        let (_, fp) = case(task, "falsepositive");
        let e = evaluation(&gt, &fp, task).expect("evaluates");
        let with_fp = e.images.as_ref().expect("images").outcomes_at_50(&gt);
        assert!(with_fp.iter().map(|o| o.false_positives).sum::<usize>() > 0);
        assert_eq!(
            with_fp.iter().map(|o| o.instances).sum::<usize>(),
            outcomes.iter().map(|o| o.instances).sum::<usize>()
        );
    }

    #[test]
    fn parameters_read_as_defined() {
        let p = CocoTask::Segmentation.parameters();
        assert_eq!(
            p.iou_thresholds,
            [0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95]
        );
        assert_eq!((p.iou_type, p.recall_points), (IouType::Segm, 101));
        assert_eq!(p.max_detections, [1, 10, 100]);
    }

    #[test]
    fn the_bootstrap_is_recorded_and_reproducible() {
        let task = CocoTask::Detection(BboxType::Amodal);
        let (gt, results) = case(task, "noisy");
        let mut a = evaluation(&gt, &results, task).expect("evaluates");
        let ap = a.report.ap;
        let b = a.bootstrap(7, 200).expect("replicates");
        assert_eq!(b.replicates.len(), 200);
        let summary = a.report.bootstrap.clone().expect("recorded");
        assert_eq!(summary.ci95, b.ci95());
        assert!(
            summary.ci95[0] <= ap && ap <= summary.ci95[1],
            "{summary:?} {ap}"
        );
        // The AP itself is untouched, and the same seed draws the same replicates.
        assert_eq!(a.report.ap.to_bits(), ap.to_bits());
        let mut again = evaluation(&gt, &results, task).expect("evaluates");
        assert_eq!(again.bootstrap(7, 200), Some(b));
        // Nothing for a target image: nothing to resample.
        let (_, none) = case(task, "onlynontarget");
        let mut e = evaluation(&gt, &none, task).expect("evaluates");
        assert!(e.bootstrap(7, 10).is_none());
        assert!(e.report.bootstrap.is_none());
    }
}
