//! From errors to true and false positives, and to average precision per object: the greedy
//! matching of each image and object at each threshold, then the ranking of every estimate of
//! an object over all images by score, as bop_toolkit's `pose_matching.match_poses` and
//! `score.calc_pose_detection_scores` do.

use std::cmp::Ordering;
use std::collections::BTreeMap;

use crate::dataset::Dataset;
use crate::stats;

use super::ap::{self, RECALL_POINTS};
use super::image_errors::{EstimateErrors, ImageErrors};
use super::{DetectionError, ErrorScores, ObjectAp, VISIB_GT_MIN};

/// Where an estimate is: (image, object within the image, estimate within the object).
type Place = (usize, usize, usize);

/// Per object, per threshold: its ranked estimates as (image, true positive).
pub type RankedByImage = BTreeMap<u32, Vec<Vec<(u32, bool)>>>;

/// The order of every object's estimates, and its counted instances; the same at every
/// threshold, so computed once.
pub struct Ranking {
    /// Per object with a counted instance: its estimates over all target images in decreasing
    /// score, ties in the toolkit's order (images as listed, objects by first instance, then
    /// the order within the image and object).
    order: BTreeMap<u32, Vec<Place>>,
    /// Per object: instances at least [`VISIB_GT_MIN`] visible (only objects with some).
    counted: BTreeMap<u32, usize>,
    /// Per object: the images with such instances, and how many each has.
    counted_per_image: BTreeMap<u32, Vec<(u32, u32)>>,
    instances: usize,
}

/// What an estimate is at one threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    TruePositive,
    FalsePositive,
    /// Matched to an instance too little visible to count: neither.
    Ignored,
}

/// An estimate at one threshold: its outcome and, when matched, the instance it took (an
/// index into its object's `gt_ids`), which pages show beside the verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Match {
    pub outcome: Outcome,
    pub instance: Option<usize>,
}

impl Ranking {
    pub fn new(dataset: &Dataset, images: &[ImageErrors]) -> Self {
        let mut counted: BTreeMap<u32, usize> = BTreeMap::new();
        let mut counted_per_image: BTreeMap<u32, Vec<(u32, u32)>> = BTreeMap::new();
        let mut instances = 0;
        let mut scored: BTreeMap<u32, Vec<(f64, Place)>> = BTreeMap::new();
        for (i, im) in images.iter().enumerate() {
            let image = &dataset.scenes[&im.scene_id].images[&im.im_id];
            for (o, obj) in im.objects.iter().enumerate() {
                instances += obj.gt_ids.len();
                let visible = obj
                    .gt_ids
                    .iter()
                    .filter(|&&g| image.gt[g].visib_fract >= VISIB_GT_MIN)
                    .count();
                if visible > 0 {
                    *counted.entry(obj.obj_id).or_default() += visible;
                    counted_per_image
                        .entry(obj.obj_id)
                        .or_default()
                        .push((i as u32, visible as u32));
                }
                let list = scored.entry(obj.obj_id).or_default();
                list.extend(
                    obj.estimates
                        .iter()
                        .enumerate()
                        .map(|(e, est)| (est.score, (i, o, e))),
                );
            }
        }
        let order = scored
            .into_iter()
            .filter(|(obj_id, _)| counted.contains_key(obj_id))
            .map(|(obj_id, mut list)| {
                // Stable: equal scores keep the order they were gathered in.
                list.sort_by(|a, b| b.0.partial_cmp(&a.0).unwrap_or(Ordering::Equal));
                (obj_id, list.into_iter().map(|(_, place)| place).collect())
            })
            .collect();
        Ranking {
            order,
            counted,
            counted_per_image,
            instances,
        }
    }

    /// Ground-truth instances in the target images.
    pub fn instances(&self) -> usize {
        self.instances
    }

    /// Instances visible enough to be counted.
    pub fn instances_counted(&self) -> usize {
        self.counted.values().sum()
    }

    /// Per object with a counted instance: the images holding such instances and how many.
    pub fn counted_per_image(&self) -> &BTreeMap<u32, Vec<(u32, u32)>> {
        &self.counted_per_image
    }

    /// Per-object AP at each of `error`'s thresholds, their means and the mean curve; and per
    /// object, per threshold, its ranked estimates as (image, true positive), the ignored ones
    /// left out (what a bootstrap replicate re-weights).
    pub fn scores(
        &self,
        dataset: &Dataset,
        images: &[ImageErrors],
        error: DetectionError,
    ) -> (ErrorScores, RankedByImage) {
        let thresholds = error.thresholds();
        let mut curves: BTreeMap<u32, Vec<[f64; RECALL_POINTS]>> = BTreeMap::new();
        let mut ranked_images = RankedByImage::new();
        for &threshold in &thresholds {
            let matches = matches(dataset, images, error, threshold);
            for (obj_id, order) in &self.order {
                let ranked: Vec<(u32, bool)> = order
                    .iter()
                    .map(|&(i, o, e)| (i as u32, matches[i][o][e].outcome))
                    .filter(|&(_, x)| x != Outcome::Ignored)
                    .map(|(i, x)| (i, x == Outcome::TruePositive))
                    .collect();
                let hits: Vec<bool> = ranked.iter().map(|r| r.1).collect();
                curves
                    .entry(*obj_id)
                    .or_default()
                    .push(ap::interpolated_precision(&hits, self.counted[obj_id]));
                ranked_images.entry(*obj_id).or_default().push(ranked);
            }
        }
        let objects: Vec<ObjectAp> = curves
            .iter()
            .map(|(&obj_id, per_threshold)| {
                let ap_per_threshold: Vec<f64> =
                    per_threshold.iter().map(ap::average_precision).collect();
                ObjectAp {
                    obj_id,
                    instances: self.counted[&obj_id],
                    ap: stats::mean(&ap_per_threshold),
                    ap_per_threshold,
                }
            })
            .collect();
        // The toolkit averages over objects in the order of their ids as strings ("10" before
        // "2"), which it reads back from JSON keys.
        let mut by_name: Vec<&ObjectAp> = objects.iter().collect();
        by_name.sort_by_key(|o| o.obj_id.to_string());
        let map = stats::mean(&by_name.iter().map(|o| o.ap).collect::<Vec<_>>());
        let precision_recall = if curves.is_empty() {
            Vec::new()
        } else {
            (0..RECALL_POINTS)
                .map(|p| {
                    let per_object: Vec<f64> = curves
                        .values()
                        .map(|c| stats::mean(&c.iter().map(|curve| curve[p]).collect::<Vec<_>>()))
                        .collect();
                    stats::mean(&per_object)
                })
                .collect()
        };
        let scores = ErrorScores {
            error,
            thresholds,
            map,
            objects,
            precision_recall,
        };
        (scores, ranked_images)
    }
}

/// The error `error` thresholds: estimate `e`'s against instance `i` of its object, in the
/// unit of the error's thresholds. MSPD is normalised by the width of the scene's evaluated
/// sensor, as the toolkit does (HOT3D's two headsets differ).
pub fn normalised(
    dataset: &Dataset,
    error: DetectionError,
    scene_id: u32,
    obj_id: u32,
    e: &EstimateErrors,
    i: usize,
) -> f64 {
    match error {
        DetectionError::Mssd => e.mssd[i] / dataset.objects[&obj_id].info.diameter,
        DetectionError::MssdMm => e.mssd[i],
        DetectionError::Mspd => 640.0 / f64::from(dataset.image_width(scene_id)) * e.mspd[i],
    }
}

/// Every estimate's match at one threshold of `error`, indexed like the errors: the greedy
/// matching of each image and object (estimates in decreasing score take the unmatched instance
/// with the lowest error strictly below the threshold, the first such instance on ties). The
/// scores and the pages that list single estimates both read it, so they cannot disagree.
pub fn matches(
    dataset: &Dataset,
    images: &[ImageErrors],
    error: DetectionError,
    threshold: f64,
) -> Vec<Vec<Vec<Match>>> {
    images
        .iter()
        .map(|im| {
            let image = &dataset.scenes[&im.scene_id].images[&im.im_id];
            im.objects
                .iter()
                .map(|obj| {
                    let mut matched = vec![false; obj.gt_ids.len()];
                    obj.estimates
                        .iter()
                        .map(|est| {
                            let mut best: Option<usize> = None;
                            let mut best_error = threshold;
                            for (i, &taken) in matched.iter().enumerate() {
                                if taken {
                                    continue;
                                }
                                let e = normalised(dataset, error, im.scene_id, obj.obj_id, est, i);
                                if e < best_error {
                                    best = Some(i);
                                    best_error = e;
                                }
                            }
                            let outcome = match best {
                                None => Outcome::FalsePositive,
                                Some(i) => {
                                    matched[i] = true;
                                    if image.gt[obj.gt_ids[i]].visib_fract >= VISIB_GT_MIN {
                                        Outcome::TruePositive
                                    } else {
                                        Outcome::Ignored
                                    }
                                }
                            };
                            Match {
                                outcome,
                                instance: best,
                            }
                        })
                        .collect()
                })
                .collect()
        })
        .collect()
}
