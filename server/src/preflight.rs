//! The pre-flight check of an upload: how the file covers the dataset's targets and what looks
//! wrong, computed before the file is queued, shown at once and kept with the submission. The
//! coverage itself is the evaluator's (`evaluator::selection::Coverage`), so what is announced
//! here is what the evaluation will do.

use std::collections::BTreeMap;

use evaluator::Dataset;
use evaluator::coco::{CocoGt, CocoResults};
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::results::Results;
use evaluator::selection::Coverage;
use serde::{Deserialize, Serialize};

use crate::wording::count;

/// What the pre-flight check found.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Preflight {
    pub estimates: usize,
    pub images: usize,
    pub targets: usize,
    pub targets_without_estimate: usize,
    /// Estimates for images or objects that are not test targets (ignored by the evaluation).
    pub estimates_not_for_targets: usize,
    /// Estimates for an object that does not appear in the image at all.
    pub estimates_for_absent_objects: usize,
    /// Per protocol, estimates beyond those it considers per target (n_top).
    pub estimates_beyond_n_top: BTreeMap<ProtocolName, usize>,
    pub warnings: Vec<String>,
    /// What holds publication back until the owner confirms (a file stored before these
    /// were computed has none).
    #[serde(default)]
    pub red_flags: Vec<RedFlag>,
    /// Per protocol, the estimates it will evaluate (the others are ignored or beyond n_top).
    #[serde(default)]
    pub estimates_evaluated: BTreeMap<ProtocolName, usize>,
    pub queue_position: i64,
    /// Seconds until this file's scores are expected, from the speed measured on this server.
    pub estimated_seconds: f64,
}

/// A sign that a file is not what its owner meant to publish: its scores would be
/// meaningless (close to zero), so publication waits for the owner's confirmation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RedFlag {
    /// The translations look like metres, not millimetres.
    Metres {
        median_mm: f64,
        ground_truth_mm: f64,
    },
    /// More than half of the dataset's targets have no estimate.
    MostTargetsMissing { without: usize, targets: usize },
    /// Estimates for objects the dataset does not have (a file for another dataset?).
    UnknownObjects { estimates: usize, objects: Vec<u32> },
}

impl std::fmt::Display for RedFlag {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RedFlag::Metres {
                median_mm,
                ground_truth_mm,
            } => write!(
                f,
                "translations look like metres (median distance {median_mm:.3} against \
                 {ground_truth_mm:.0} mm in the ground truth): t must be in millimetres"
            ),
            RedFlag::MostTargetsMissing { without, targets } => write!(
                f,
                "{without} of {targets} targets have no estimate (more than half)"
            ),
            RedFlag::UnknownObjects { estimates, objects } => {
                let ids: Vec<String> = objects.iter().map(u32::to_string).collect();
                write!(
                    f,
                    "{} for objects the dataset does not have (obj_id {}): is the file for \
                     this dataset?",
                    crate::wording::count(*estimates, "estimate", "estimates"),
                    ids.join(", ")
                )
            }
        }
    }
}

impl Preflight {
    /// Coverage of a valid result file against the dataset's targets, for evaluation under
    /// `protocols`; estimates beyond what a protocol considers per target are warned about
    /// only for the protocols in `warned` (the ones the uploader chose).
    pub fn of(
        dataset: &Dataset,
        results: &Results,
        protocols: &[ProtocolName],
        warned: &[ProtocolName],
    ) -> Preflight {
        let coverage = Coverage::of(dataset, results);
        let beyond: BTreeMap<ProtocolName, usize> = protocols
            .iter()
            .map(|&p| (p, coverage.beyond_n_top(Protocol::named(p).n_top)))
            .collect();
        let mut warnings = Vec::new();
        let targets = coverage.targets();
        let without = coverage.targets_without_estimate;
        if without > 0 {
            warnings.push(format!(
                "{without} of {} without an estimate will count as misses",
                count(targets, "target", "targets")
            ));
        }
        if coverage.estimates_ignored > 0 {
            warnings.push(format!(
                "{}, for images or objects that are not test targets, will be ignored",
                count(coverage.estimates_ignored, "estimate", "estimates")
            ));
        }
        if coverage.estimates_for_absent_objects > 0 {
            warnings.push(format!(
                "{} for objects that do not appear in the image",
                count(
                    coverage.estimates_for_absent_objects,
                    "estimate",
                    "estimates"
                )
            ));
        }
        for (p, n) in &beyond {
            if *n > 0 && warned.contains(p) {
                warnings.push(format!(
                    "{} beyond what {p} considers per target will not count (the highest-scored are used)",
                    count(*n, "estimate", "estimates"),
                    p = p.as_str()
                ));
            }
        }
        let mut red_flags: Vec<RedFlag> = unit_flag(dataset, results).into_iter().collect();
        if without * 2 > targets {
            red_flags.push(RedFlag::MostTargetsMissing { without, targets });
        }
        let unknown: Vec<u32> = results
            .estimates
            .iter()
            .map(|e| e.obj_id)
            .filter(|o| !dataset.objects.contains_key(o))
            .collect();
        if !unknown.is_empty() {
            let mut objects = unknown.clone();
            objects.sort_unstable();
            objects.dedup();
            red_flags.push(RedFlag::UnknownObjects {
                estimates: unknown.len(),
                objects,
            });
        }
        // What the evaluator will select (see `evaluator::selection`): the estimates for
        // targets, at most n_top per target.
        let for_targets = results.estimates.len() - coverage.estimates_ignored;
        let estimates_evaluated = beyond
            .iter()
            .map(|(&p, &n)| (p, for_targets.saturating_sub(n)))
            .collect();
        Preflight {
            estimates: results.estimates.len(),
            images: coverage.images_with_estimates,
            targets,
            targets_without_estimate: without,
            estimates_not_for_targets: coverage.estimates_ignored,
            estimates_for_absent_objects: coverage.estimates_for_absent_objects,
            estimates_beyond_n_top: beyond,
            warnings,
            red_flags,
            estimates_evaluated,
            queue_position: 0,
            estimated_seconds: 0.0,
        }
    }

    /// Coverage of a valid BOP'22 2D result file against the dataset's target images: the
    /// same warnings and red flags as a 6D file's where they apply (targets are images here,
    /// objects are categories).
    pub fn of_coco(gt: &CocoGt, results: &CocoResults) -> Preflight {
        let mut with_entry = vec![false; gt.images.len()];
        let (mut not_for_targets, mut unknown) = (0, Vec::new());
        for e in &results.entries {
            match gt.image_index(e.scene_id, e.image_id) {
                Some(i) => with_entry[i] = true,
                None => not_for_targets += 1,
            }
            if gt.categories.binary_search(&e.category_id).is_err() {
                unknown.push(e.category_id);
            }
        }
        let targets = gt.images.len();
        let without = with_entry.iter().filter(|&&b| !b).count();
        let mut warnings = Vec::new();
        if without > 0 {
            warnings.push(format!(
                "{without} of {} without a detection will count as misses",
                count(targets, "target image", "target images")
            ));
        }
        if not_for_targets > 0 {
            warnings.push(format!(
                "{}, for images that are not test targets, will be ignored",
                count(not_for_targets, "detection", "detections")
            ));
        }
        let mut red_flags = Vec::new();
        if without * 2 > targets {
            red_flags.push(RedFlag::MostTargetsMissing { without, targets });
        }
        if !unknown.is_empty() {
            let estimates = unknown.len();
            unknown.sort_unstable();
            unknown.dedup();
            red_flags.push(RedFlag::UnknownObjects {
                estimates,
                objects: unknown
                    .into_iter()
                    .map(|c| u32::try_from(c).unwrap_or(u32::MAX))
                    .collect(),
            });
        }
        Preflight {
            estimates: results.entries.len(),
            images: results.image_count(),
            targets,
            targets_without_estimate: without,
            estimates_not_for_targets: not_for_targets,
            warnings,
            red_flags,
            ..Preflight::default()
        }
    }

    /// Coverage of a valid result file against the dataset's BOP'24 target images (every
    /// object of each a target), keeping at most `max_estimates_per_image` per image, as the
    /// evaluation will. Estimates of objects absent from an image are what detection expects
    /// (neither true nor false positives), so they are no warning; metres instead of
    /// millimetres, most images without an estimate and unknown objects are red flags as for
    /// the localization protocols.
    pub fn of_bop24(
        dataset: &Dataset,
        results: &Results,
        max_estimates_per_image: usize,
    ) -> Preflight {
        let c = evaluator::detection::coverage(dataset, results, max_estimates_per_image);
        let images: std::collections::BTreeSet<(u32, u32)> = results
            .estimates
            .iter()
            .map(|e| (e.scene_id, e.im_id))
            .collect();
        let mut warnings = Vec::new();
        let (targets, without) = (c.target_images, c.images_without_estimate);
        if without > 0 {
            warnings.push(format!(
                "{without} of {} without an estimate of an object they hold",
                count(targets, "target image", "target images")
            ));
        }
        if c.estimates_beyond_cap > 0 {
            warnings.push(format!(
                "{} beyond the {max_estimates_per_image} best-scored per image will not count",
                count(c.estimates_beyond_cap, "estimate", "estimates")
            ));
        }
        let mut red_flags: Vec<RedFlag> = unit_flag(dataset, results).into_iter().collect();
        if without * 2 > targets {
            red_flags.push(RedFlag::MostTargetsMissing { without, targets });
        }
        let mut unknown: Vec<u32> = results
            .estimates
            .iter()
            .map(|e| e.obj_id)
            .filter(|o| !dataset.objects.contains_key(o))
            .collect();
        if !unknown.is_empty() {
            let estimates = unknown.len();
            unknown.sort_unstable();
            unknown.dedup();
            red_flags.push(RedFlag::UnknownObjects {
                estimates,
                objects: unknown,
            });
        }
        Preflight {
            estimates: results.estimates.len(),
            images: images.len(),
            targets,
            targets_without_estimate: without,
            estimates_not_for_targets: c.estimates_ignored,
            warnings,
            red_flags,
            ..Preflight::default()
        }
    }

    /// Estimate evaluations the job will take: the evaluated estimates summed over protocols.
    pub fn work(&self) -> i64 {
        self.estimates_evaluated.values().sum::<usize>() as i64
    }
}

/// Translations in metres instead of millimetres are a common mistake: the estimated
/// distances are then about a thousand times smaller than the ground truth's.
fn unit_flag(dataset: &Dataset, results: &Results) -> Option<RedFlag> {
    let median = |mut v: Vec<f64>| -> Option<f64> {
        if v.is_empty() {
            return None;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        Some(v[v.len() / 2])
    };
    let est = median(results.estimates.iter().map(|e| e.pose.t.norm()).collect())?;
    let gt = median(
        dataset
            .scenes
            .values()
            .flat_map(|s| s.images.values())
            .flat_map(|im| im.gt.iter().map(|g| g.pose.t.norm()))
            .collect(),
    )?;
    (est > 0.0 && est * 100.0 < gt).then_some(RedFlag::Metres {
        median_mm: est,
        ground_truth_mm: gt,
    })
}
