//! BOP'24 6D object detection (`bop24`), the BOP challenge's main task since 2024: the method
//! is not told which objects, or how many instances, an image holds, and it is scored by
//! average precision from MSSD and MSPD, as bop_toolkit's `scripts/eval_bop24_pose.py` scores
//! it (with `eval_calc_errors.py` and `eval_calc_scores.py` in `--eval_mode=detection`).
//!
//! - [`kept`]: at most N estimates per image over all objects, and the time per image.
//! - [`image_errors`]: MSSD and MSPD of every kept estimate against each instance of its object.
//! - [`ranking`]: greedy matching per threshold and the per-object true/false positives.
//! - [`ap`]: COCO's 101-point average precision.
//! - [`resampling`]: bootstrap replicates of `bop24_mAP` over the target images.
//! - [`verdicts`]: every estimate's outcome at one error and threshold, image by image.
//!
//! Like the BOP'22 2D tasks ([`crate::coco`]), this is not a [`crate::ProtocolName`]: its
//! targets (images, not objects), its selection of estimates (a cap per image, not n_top per
//! target) and its report (average precision, not recall) share little with the localization
//! protocols, and the server matches on `ProtocolName` exhaustively.
//!
//! What bop_toolkit does and this module reproduces, each point read in the toolkit's source:
//! - targets are images (`test_targets_bop24.json`); every object of an image's ground truth is a
//!   target whatever its visibility; estimates of other objects are neither true nor false
//!   positives;
//! - matching per image and object: estimates in decreasing score take the unmatched instance
//!   with the lowest error strictly below the threshold; an estimate matched to an instance
//!   less than 10 % visible is ignored, and such instances are not counted;
//! - per object and threshold, precision and recall over the score-sorted estimates of all
//!   images, in the toolkit's order for equal scores: scenes and images as the targets file
//!   first lists them, objects by their first instance in the image, then file order;
//! - the mean over thresholds per object, then over the objects with a counted instance.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;
use serde::{Deserialize, Deserializer, Serialize};

use crate::bootstrap::{self, Bootstrap, BootstrapSummary};
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::pipeline::Progress;
use crate::protocol::{bop19_fractions, bop19_mspd_thresholds};
use crate::report::EVALUATOR_VERSION;
use crate::results::Results;
use crate::stats;

pub mod ap;
pub mod image_errors;
pub mod kept;
pub mod ranking;
pub mod resampling;
pub mod verdicts;

/// The protocol's name on the command line and in reports.
pub const PROTOCOL: &str = "bop24";

/// Ground-truth instances less visible than this are not counted, and estimates matched to
/// them are ignored (bop_toolkit's `visib_gt_min` with
/// `ignore_object_visible_less_than_visib_gt_min`).
pub const VISIB_GT_MIN: f64 = 0.1;

/// Discretisation of continuous symmetries, as for BOP'19.
pub const MAX_SYM_DISC_STEP: f64 = 0.01;

/// The toolkit's cap on estimates per image: 200 on XYZ-IBD, 100 elsewhere.
pub fn default_max_estimates_per_image(dataset: &str) -> usize {
    if dataset == "xyzibd" { 200 } else { 100 }
}

/// The three scored errors. MSSD is thresholded twice: as a fraction of the object diameter
/// and, since 2025, in millimetres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DetectionError {
    Mssd,
    MssdMm,
    Mspd,
}

impl DetectionError {
    pub const ALL: [DetectionError; 3] = [
        DetectionError::Mssd,
        DetectionError::MssdMm,
        DetectionError::Mspd,
    ];

    pub fn name(self) -> &'static str {
        match self {
            DetectionError::Mssd => "mssd",
            DetectionError::MssdMm => "mssd_mm",
            DetectionError::Mspd => "mspd",
        }
    }

    /// The error of that name ([`DetectionError::name`]).
    pub fn named(name: &str) -> Option<DetectionError> {
        DetectionError::ALL.into_iter().find(|e| e.name() == name)
    }

    /// 0.05..0.5 x diameter, 2..20 mm, 5..50 px at 640 px image width.
    pub fn thresholds(self) -> Vec<f64> {
        match self {
            DetectionError::Mssd => bop19_fractions(),
            DetectionError::MssdMm => (1..=10).map(|i| 2.0 * i as f64).collect(),
            DetectionError::Mspd => bop19_mspd_thresholds(),
        }
    }
}

/// The report of one `bop24` evaluation, with bop_toolkit's key names (`scores_bop24.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectionReport {
    pub evaluator_version: String,
    pub dataset: String,
    /// `bop24`.
    pub protocol: String,
    pub parameters: DetectionParameters,
    /// Rows of the result file.
    pub estimates_count: usize,
    /// Estimates left out because their image had more than `max_estimates_per_image`.
    pub estimates_beyond_cap: usize,
    /// Kept estimates of objects present in a target image: the ones scored.
    pub estimates_evaluated: usize,
    /// Kept estimates of images that are not targets or of objects absent from the image.
    pub estimates_ignored: usize,
    pub target_images: usize,
    /// Ground-truth instances in the target images, and those visible enough to be counted.
    pub instances: usize,
    pub instances_counted: usize,
    /// Mean of the MSSD and MSPD mAPs. NaN (`null` in JSON) when no instance is counted.
    #[serde(rename = "bop24_mAP", deserialize_with = "nan_as_null")]
    pub bop24_map: f64,
    #[serde(rename = "bop24_mAP_mssd", deserialize_with = "nan_as_null")]
    pub bop24_map_mssd: f64,
    #[serde(rename = "bop24_mAP_mssd_mm", deserialize_with = "nan_as_null")]
    pub bop24_map_mssd_mm: f64,
    #[serde(rename = "bop24_mAP_mspd", deserialize_with = "nan_as_null")]
    pub bop24_map_mspd: f64,
    /// The MSSD mAP alone (BOP'25).
    #[serde(rename = "bop25_mAP", deserialize_with = "nan_as_null")]
    pub bop25_map: f64,
    #[serde(rename = "bop25_mAP_mm", deserialize_with = "nan_as_null")]
    pub bop25_map_mm: f64,
    /// Seconds; -1 when some kept estimate gives no time, as the toolkit writes it.
    pub bop24_average_time_per_image: f64,
    /// Per error: per-object AP at each threshold, and the precision-recall curve.
    pub errors: Vec<ErrorScores>,
    /// The bootstrap 95 % interval of `bop24_mAP`, when the caller drew one
    /// ([`DetectionEvaluation::bootstrap`]); absent otherwise, so reports without it read as
    /// before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bootstrap: Option<BootstrapSummary>,
}

/// A report with what its `bop24_mAP` was accumulated from, for the mAP's bootstrap.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectionEvaluation {
    pub report: DetectionReport,
    pub outcomes: resampling::ImageOutcomes,
}

impl DetectionEvaluation {
    /// Bootstrap replicates of `bop24_mAP` over the target images ([`resampling`]), recorded
    /// in the report's `bootstrap`. `None` when there is nothing to resample, or when a
    /// resampling holds no counted instance (its mAP is undefined, so no interval is claimed).
    pub fn bootstrap(&mut self, seed: u64, replicates: usize) -> Option<Bootstrap> {
        let outcomes = &self.outcomes;
        if outcomes.objects.is_empty() {
            return None;
        }
        let b = bootstrap::resample(outcomes.images(), seed, replicates, |w| {
            outcomes.weighted_map(w)
        })?;
        self.report.bootstrap = Some(b.summary());
        Some(b)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectionParameters {
    pub max_estimates_per_image: usize,
    pub visib_gt_min: f64,
    pub max_sym_disc_step: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorScores {
    pub error: DetectionError,
    pub thresholds: Vec<f64>,
    #[serde(rename = "mAP", deserialize_with = "nan_as_null")]
    pub map: f64,
    /// The objects with at least one counted instance, by id.
    pub objects: Vec<ObjectAp>,
    /// Interpolated precision at the recall points 0, 0.01, ..., 1, averaged over the objects
    /// and thresholds (its mean is `mAP`); empty when no instance is counted.
    pub precision_recall: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectAp {
    pub obj_id: u32,
    /// Counted instances (at least 10 % visible) in the target images.
    pub instances: usize,
    /// Mean over the thresholds.
    #[serde(rename = "AP")]
    pub ap: f64,
    /// At each of the error's thresholds.
    pub ap_per_threshold: Vec<f64>,
}

/// A mean written as `null` (serde_json writes NaN so), read back as NaN: a report the service
/// stored as JSON reads back even when no instance was counted.
fn nan_as_null<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Scores `results` on `dataset` for 6D detection, keeping at most `max_estimates_per_image`
/// estimates per image. Every object of each target image's ground truth is a target, whatever
/// form the targets file has. Parallel on the caller's rayon pool; stops with
/// `Error::Cancelled` when `cancel` is set.
pub fn evaluate(
    dataset: &Dataset,
    results: &Results,
    max_estimates_per_image: usize,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<DetectionReport> {
    evaluation(dataset, results, max_estimates_per_image, progress, cancel).map(|e| e.report)
}

/// [`evaluate`], keeping what a bootstrap of `bop24_mAP` needs.
pub fn evaluation(
    dataset: &Dataset,
    results: &Results,
    max_estimates_per_image: usize,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<DetectionEvaluation> {
    if max_estimates_per_image == 0 {
        return Err(Error::Parameters(
            "max_estimates_per_image must be at least 1".into(),
        ));
    }
    let Plan {
        kept,
        images,
        work,
        evaluated,
    } = Plan::new(dataset, results, max_estimates_per_image);
    let average_time = kept::average_time_per_image(results, &kept);
    progress.start(evaluated as u64);
    let computed = errors(dataset, results, &work, progress, cancel)?;

    let ranking = ranking::Ranking::new(dataset, &computed);
    let (errors, mut ranked): (Vec<ErrorScores>, Vec<_>) = DetectionError::ALL
        .iter()
        .map(|&error| ranking.scores(dataset, &computed, error))
        .unzip();
    let mut by_name: Vec<u32> = ranking.counted_per_image().keys().copied().collect();
    by_name.sort_by_key(|o| o.to_string());
    let mspd = ranked.remove(2);
    let mssd = ranked.remove(0);
    let outcomes = resampling::ImageOutcomes {
        images: images.len(),
        objects: by_name
            .iter()
            .map(|obj_id| resampling::ObjectOutcomes {
                counted: ranking.counted_per_image()[obj_id].clone(),
                ranked: [mssd[obj_id].clone(), mspd[obj_id].clone()],
            })
            .collect(),
    };
    let map = |e: DetectionError| {
        errors
            .iter()
            .find(|s| s.error == e)
            .map_or(f64::NAN, |s| s.map)
    };
    let (mssd, mssd_mm, mspd) = (
        map(DetectionError::Mssd),
        map(DetectionError::MssdMm),
        map(DetectionError::Mspd),
    );
    let report = DetectionReport {
        evaluator_version: EVALUATOR_VERSION.to_string(),
        dataset: dataset.name.clone(),
        protocol: PROTOCOL.to_string(),
        parameters: DetectionParameters {
            max_estimates_per_image,
            visib_gt_min: VISIB_GT_MIN,
            max_sym_disc_step: MAX_SYM_DISC_STEP,
        },
        estimates_count: results.estimates.len(),
        estimates_beyond_cap: kept.beyond_cap,
        estimates_evaluated: evaluated,
        estimates_ignored: kept.order.len() - evaluated,
        target_images: images.len(),
        instances: ranking.instances(),
        instances_counted: ranking.instances_counted(),
        bop24_map: stats::mean(&[mssd, mspd]),
        bop24_map_mssd: mssd,
        bop24_map_mssd_mm: mssd_mm,
        bop24_map_mspd: mspd,
        bop25_map: mssd,
        bop25_map_mm: mssd_mm,
        bop24_average_time_per_image: average_time.unwrap_or(-1.0),
        errors,
        bootstrap: None,
    };
    Ok(DetectionEvaluation { report, outcomes })
}

/// The errors of the estimates of `work`'s images, in parallel on the caller's rayon pool.
fn errors(
    dataset: &Dataset,
    results: &Results,
    work: &[image_errors::ImageWork],
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<Vec<image_errors::ImageErrors>> {
    let symmetries = image_errors::symmetries(dataset, work);
    work.par_iter()
        .map(|w| {
            if cancel.load(Ordering::Relaxed) {
                return Err(Error::Cancelled);
            }
            let errors = w.errors(dataset, results, &symmetries);
            progress.advance(w.estimate_count() as u64);
            Ok(errors)
        })
        .collect()
}

/// What a result file covers of a dataset's detection targets, known before any error is
/// computed (for `check-results`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Coverage {
    pub target_images: usize,
    /// Target images without a kept estimate of an object they hold.
    pub images_without_estimate: usize,
    pub estimates_beyond_cap: usize,
    pub estimates_evaluated: usize,
    /// Kept estimates of images that are not targets or of objects absent from the image.
    pub estimates_ignored: usize,
}

pub fn coverage(dataset: &Dataset, results: &Results, max_estimates_per_image: usize) -> Coverage {
    let plan = Plan::new(dataset, results, max_estimates_per_image);
    Coverage {
        target_images: plan.images.len(),
        images_without_estimate: plan.work.iter().filter(|w| w.estimate_count() == 0).count(),
        estimates_beyond_cap: plan.kept.beyond_cap,
        estimates_evaluated: plan.evaluated,
        estimates_ignored: plan.kept.order.len() - plan.evaluated,
    }
}

/// The kept estimates sorted into the target images and their objects.
struct Plan {
    kept: kept::Kept,
    images: Vec<(u32, u32)>,
    work: Vec<image_errors::ImageWork>,
    evaluated: usize,
}

impl Plan {
    fn new(dataset: &Dataset, results: &Results, max_estimates_per_image: usize) -> Self {
        let kept = kept::keep(results, max_estimates_per_image);
        let images = target_images(dataset);
        let mut by_image_object: HashMap<(u32, u32, u32), Vec<usize>> = HashMap::new();
        for &i in &kept.order {
            let e = &results.estimates[i];
            by_image_object
                .entry((e.scene_id, e.im_id, e.obj_id))
                .or_default()
                .push(i);
        }
        let work: Vec<image_errors::ImageWork> = images
            .iter()
            .map(|&(scene_id, im_id)| {
                image_errors::ImageWork::new(dataset, scene_id, im_id, &by_image_object)
            })
            .collect();
        let evaluated = work.iter().map(|w| w.estimate_count()).sum();
        Plan {
            kept,
            images,
            work,
            evaluated,
        }
    }
}

/// The target images in bop_toolkit's order: scenes as the targets file first names them,
/// and within a scene its images as the file first names them.
fn target_images(dataset: &Dataset) -> Vec<(u32, u32)> {
    let mut scenes: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut seen = HashSet::new();
    for t in &dataset.targets {
        if !seen.insert((t.scene_id, t.im_id)) {
            continue;
        }
        let slot = match scenes.iter().position(|(s, _)| *s == t.scene_id) {
            Some(i) => i,
            None => {
                scenes.push((t.scene_id, Vec::new()));
                scenes.len() - 1
            }
        };
        scenes[slot].1.push(t.im_id);
    }
    scenes
        .into_iter()
        .flat_map(|(s, images)| images.into_iter().map(move |i| (s, i)))
        .collect()
}
