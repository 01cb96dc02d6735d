//! The pre-flight check of an upload: how the file covers the dataset's targets and what looks
//! wrong, computed before the file is queued, shown at once and kept with the submission. The
//! coverage itself is the evaluator's (`evaluator::selection::Coverage`), so what is announced
//! here is what the evaluation will do.

use std::collections::BTreeMap;

use evaluator::Dataset;
use evaluator::protocol::{Protocol, ProtocolName};
use evaluator::results::Results;
use evaluator::selection::Coverage;
use serde::{Deserialize, Serialize};

use crate::wording::counted;

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
    pub queue_position: i64,
    pub estimated_seconds: f64,
}

impl Preflight {
    /// Coverage of a valid result file against the dataset's targets.
    pub fn of(dataset: &Dataset, results: &Results, protocols: &[ProtocolName]) -> Preflight {
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
                counted(targets, "target")
            ));
        }
        if coverage.estimates_ignored > 0 {
            warnings.push(format!(
                "{}, for images or objects that are not test targets, will be ignored",
                counted(coverage.estimates_ignored, "estimate")
            ));
        }
        if coverage.estimates_for_absent_objects > 0 {
            warnings.push(format!(
                "{} for objects that do not appear in the image",
                counted(coverage.estimates_for_absent_objects, "estimate")
            ));
        }
        for (p, n) in &beyond {
            if *n > 0 {
                warnings.push(format!(
                    "{} beyond what {p} considers per target will not count (the highest-scored are used)",
                    counted(*n, "estimate"),
                    p = p.as_str()
                ));
            }
        }
        if let Some(w) = unit_warning(dataset, results) {
            warnings.push(w);
        }
        Preflight {
            estimates: results.estimates.len(),
            images: coverage.images_with_estimates,
            targets,
            targets_without_estimate: without,
            estimates_not_for_targets: coverage.estimates_ignored,
            estimates_for_absent_objects: coverage.estimates_for_absent_objects,
            estimates_beyond_n_top: beyond,
            warnings,
            queue_position: 0,
            estimated_seconds: 0.0,
        }
    }
}

/// Translations in metres instead of millimetres are a common mistake: the estimated
/// distances are then about a thousand times smaller than the ground truth's.
fn unit_warning(dataset: &Dataset, results: &Results) -> Option<String> {
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
    (est > 0.0 && est * 100.0 < gt).then(|| {
        format!(
            "translations look like metres (median distance {est:.3} against {gt:.0} mm in the ground truth): t must be in millimetres"
        )
    })
}
