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

use crate::report::EVALUATOR_VERSION;
pub use eval::IouType;
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
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PrecisionRecall {
    pub iou_50: Vec<f64>,
    pub iou_75: Vec<f64>,
    pub iou_mean: Vec<f64>,
}

impl CocoReport {
    /// The twelve numbers in COCOeval's `stats` order, with the toolkit's names.
    pub fn stats(&self) -> [(&'static str, f64); 12] {
        [
            ("AP", self.ap),
            ("AP50", self.ap50),
            ("AP75", self.ap75),
            ("AP_small", self.ap_small),
            ("AP_medium", self.ap_medium),
            ("AP_large", self.ap_large),
            ("AR1", self.ar1),
            ("AR10", self.ar10),
            ("AR100", self.ar100),
            ("AR_small", self.ar_small),
            ("AR_medium", self.ar_medium),
            ("AR_large", self.ar_large),
        ]
    }
}

/// Scores `results` on `gt` for `task`. The results must meet the task's needs
/// ([`CocoResults::require`]); `gt` must have been loaded with masks for segmentation.
/// Parallel on the caller's rayon pool.
pub fn evaluate(gt: &CocoGt, results: &CocoResults, task: CocoTask) -> crate::Result<CocoReport> {
    results.require(task).map_err(crate::Error::CocoResults)?;
    let iou_type = task.iou_type();
    if iou_type == IouType::Segm && gt.annotations.iter().any(|a| a.segmentation.is_none()) {
        return Err(crate::Error::Parameters(
            "the ground truth was loaded without masks".into(),
        ));
    }
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
    let with_target_image = per_image.iter().filter(|&&b| b).count();
    let targets_entries = results
        .entries
        .iter()
        .filter(|e| gt.image_index(e.scene_id, e.image_id).is_some())
        .count();

    let (stats, curves, time) = if targets_entries == 0 {
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
        )
    } else {
        let acc = eval::evaluate(gt, &detections, iou_type);
        (
            acc.summarize(),
            PrecisionRecall {
                iou_50: acc.precision_curve(Some(0.5)),
                iou_75: acc.precision_curve(Some(0.75)),
                iou_mean: acc.precision_curve(None),
            },
            results.average_time_per_image().unwrap_or(-1.0),
        )
    };
    Ok(CocoReport {
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
    })
}
