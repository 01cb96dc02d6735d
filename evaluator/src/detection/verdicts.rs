//! Every estimate of a result file at one error and threshold, image by image: true positive,
//! false positive or ignored, with the error that decided it and the instance it took, and the
//! estimates the scores leave out before any matching (beyond the cap of their image, or of an
//! object the image does not hold). A page that lists them shows what the average precision
//! counted only if they come from the scores' own steps, so nothing here matches or caps
//! anew: the cap is [`super::kept`]'s, the errors [`super::image_errors`]'s and the matching
//! [`super::ranking::matches`], the one [`super::ranking::Ranking::scores`] counts.
//!
//! The errors are computed once ([`inspect`]); each criterion then only matches again, as the
//! scores match once per threshold.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::AtomicBool;

use serde::Serialize;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::pipeline::NoProgress;
use crate::results::Results;

use super::image_errors::ImageErrors;
use super::ranking::{self, Outcome};
use super::{DetectionError, Plan, VISIB_GT_MIN};

/// When an estimate is a true positive: matched below one threshold of one error.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Criterion {
    pub error: DetectionError,
    /// One of the error's thresholds (the only ones the scores count at).
    pub threshold: f64,
}

/// Whether two thresholds are one value written differently (`0.3` for `0.05 + 5 * 0.05`).
fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// A threshold as people write it: at most three decimals, without trailing zeros.
pub fn short(value: f64) -> String {
    let s = format!("{value:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

impl Criterion {
    /// What a reader asked for, each unset part taking its default: MSSD, and the middle of
    /// the error's thresholds (0.3 of the diameter, 12 mm, 30 px), as the localization pages
    /// default to the middle. A threshold must be one of the error's, since the scores count at
    /// those only; the message lists them.
    pub fn choose(
        error: Option<&str>,
        threshold: Option<f64>,
    ) -> std::result::Result<Criterion, String> {
        let error = match error {
            None => DetectionError::Mssd,
            Some(name) => DetectionError::named(name).ok_or_else(|| {
                let names: Vec<&str> = DetectionError::ALL.iter().map(|e| e.name()).collect();
                format!("bop24 has no error `{name}` (it has {})", names.join(", "))
            })?,
        };
        let thresholds = error.thresholds();
        let threshold = match threshold {
            None => thresholds[thresholds.len() / 2],
            Some(t) => thresholds
                .iter()
                .copied()
                .find(|&p| same(p, t))
                .ok_or_else(|| {
                    let listed: Vec<String> = thresholds.iter().map(|&p| short(p)).collect();
                    format!(
                        "{} is not a threshold of {} ({}: {})",
                        short(t),
                        error.name(),
                        listed.join(", "),
                        unit(error)
                    )
                })?,
        };
        Ok(Criterion { error, threshold })
    }

    /// In words, with the unit.
    pub fn description(&self) -> String {
        let th = short(self.threshold);
        match self.error {
            DetectionError::Mssd => format!("MSSD below {th} of the object diameter"),
            DetectionError::MssdMm => format!("MSSD below {th} mm"),
            DetectionError::Mspd => format!("MSPD below {th} px (at 640 px image width)"),
        }
    }
}

/// What an error's thresholds are in.
pub fn unit(error: DetectionError) -> &'static str {
    match error {
        DetectionError::Mssd => "fractions of the object diameter",
        DetectionError::MssdMm => "millimetres",
        DetectionError::Mspd => "pixels at 640 px image width",
    }
}

/// What an estimate is at a criterion.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    TruePositive,
    FalsePositive,
    /// Matched to an instance under 10 % visible: neither true nor false.
    Ignored,
    /// Past the cap of estimates per image (the best-scored are kept, over all objects).
    BeyondCap,
    /// Of an object the image does not hold: neither true nor false.
    ObjectAbsent,
}

impl Verdict {
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::TruePositive => "true positive",
            Verdict::FalsePositive => "false positive",
            Verdict::Ignored => "ignored",
            Verdict::BeyondCap => "beyond the cap",
            Verdict::ObjectAbsent => "object absent",
        }
    }
}

/// One estimate of a target image.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EstimateVerdict {
    /// Its line in the result file (the header, when present, is line 1).
    pub line: u64,
    pub obj_id: u32,
    pub score: f64,
    pub verdict: Verdict,
    /// The instance (index in the image's ground truth) `error` is measured against: the one
    /// it took when matched (a true positive or ignored), else the nearest of its object (the
    /// first on ties); `None` for an estimate left out before matching.
    pub gt_id: Option<u32>,
    /// Against `gt_id`, in the unit of the criterion's thresholds; `None` when left out before
    /// matching, or infinite (MSSD is not computed for poses a diameter apart).
    pub error: Option<f64>,
}

/// One ground-truth instance of a target image.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InstanceVerdict {
    pub gt_id: u32,
    pub obj_id: u32,
    pub visib_fract: f64,
    /// At least 10 % visible: counted by the average precision.
    pub counted: bool,
    /// The line of the estimate that took it, if one did.
    pub matched_by: Option<u64>,
}

/// A target image at one criterion.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImageVerdicts {
    pub scene_id: u32,
    pub im_id: u32,
    /// In ground-truth order.
    pub instances: Vec<InstanceVerdict>,
    /// The kept estimates of its objects in the order the matching takes them (objects by
    /// their first instance, each in decreasing score, ties in file order), then those left
    /// out before matching, in file order.
    pub estimates: Vec<EstimateVerdict>,
}

/// The counts of an image (or of several, added up).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Tally {
    /// Instances the average precision counts (at least 10 % visible).
    pub counted: usize,
    pub true_positives: usize,
    pub false_positives: usize,
    pub ignored: usize,
    /// Counted instances no estimate took.
    pub missed: usize,
    pub beyond_cap: usize,
    pub object_absent: usize,
}

impl Tally {
    pub fn add(&mut self, other: Tally) {
        self.counted += other.counted;
        self.true_positives += other.true_positives;
        self.false_positives += other.false_positives;
        self.ignored += other.ignored;
        self.missed += other.missed;
        self.beyond_cap += other.beyond_cap;
        self.object_absent += other.object_absent;
    }

    /// Counted instances missed plus false positives: what the gallery puts first.
    pub fn mistakes(&self) -> usize {
        self.missed + self.false_positives
    }
}

impl ImageVerdicts {
    pub fn tally(&self) -> Tally {
        self.tally_of(|_| true)
    }

    /// The counts of one object's instances and estimates.
    pub fn object_tally(&self, obj_id: u32) -> Tally {
        self.tally_of(|o| o == obj_id)
    }

    /// The objects of its instances and estimates, each once.
    pub fn objects(&self) -> Vec<u32> {
        let mut ids: Vec<u32> = self.instances.iter().map(|i| i.obj_id).collect();
        ids.extend(self.estimates.iter().map(|e| e.obj_id));
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    fn tally_of(&self, object: impl Fn(u32) -> bool) -> Tally {
        let of = |v: Verdict| {
            self.estimates
                .iter()
                .filter(|e| e.verdict == v && object(e.obj_id))
                .count()
        };
        let counted = self
            .instances
            .iter()
            .filter(|i| i.counted && object(i.obj_id))
            .count();
        let true_positives = of(Verdict::TruePositive);
        Tally {
            counted,
            true_positives,
            false_positives: of(Verdict::FalsePositive),
            ignored: of(Verdict::Ignored),
            // Each true positive took a distinct counted instance.
            missed: counted - true_positives,
            beyond_cap: of(Verdict::BeyondCap),
            object_absent: of(Verdict::ObjectAbsent),
        }
    }
}

/// A kept estimate of a present object, or one left out before matching.
#[derive(Clone, Copy)]
struct Row {
    line: u64,
    obj_id: u32,
    score: f64,
}

/// A result file's errors on a dataset's target images, from which [`Inspection::verdicts`]
/// reads every estimate's outcome at any criterion.
pub struct Inspection {
    /// As the scores compute them (only the images inspected).
    errors: Vec<ImageErrors>,
    /// Per image, per object, its kept estimates in the order of `errors`.
    kept: Vec<Vec<Vec<Row>>>,
    /// Per image, the estimates left out before matching, in file order.
    dropped: Vec<Vec<(Row, Verdict)>>,
}

/// The errors of `results`' estimates in the target images of `dataset` (only `image`, a
/// (scene, image) pair, when given: the matching is per image, so one image's verdicts need
/// its errors only), keeping at most `max_estimates_per_image` per image as [`super::evaluate`]
/// does. Parallel on the caller's rayon pool; stops with `Error::Cancelled` when `cancel` is
/// set. An image that is not a target yields nothing.
pub fn inspect(
    dataset: &Dataset,
    results: &Results,
    max_estimates_per_image: usize,
    image: Option<(u32, u32)>,
    cancel: &AtomicBool,
) -> Result<Inspection> {
    if max_estimates_per_image == 0 {
        return Err(Error::Parameters(
            "max_estimates_per_image must be at least 1".into(),
        ));
    }
    let Plan { kept, mut work, .. } = Plan::new(dataset, results, max_estimates_per_image);
    if let Some(only) = image {
        work.retain(|w| (w.scene_id, w.im_id) == only);
    }
    let errors = super::errors(dataset, results, &work, &NoProgress, cancel)?;
    let row = |i: usize| {
        let e = &results.estimates[i];
        Row {
            line: e.line,
            obj_id: e.obj_id,
            score: e.score,
        }
    };
    let is_kept: HashSet<usize> = kept.order.iter().copied().collect();
    let slot: HashMap<(u32, u32), usize> = work
        .iter()
        .enumerate()
        .map(|(n, w)| ((w.scene_id, w.im_id), n))
        .collect();
    let mut dropped: Vec<Vec<(Row, Verdict)>> = vec![Vec::new(); work.len()];
    for (i, e) in results.estimates.iter().enumerate() {
        let Some(&n) = slot.get(&(e.scene_id, e.im_id)) else {
            continue;
        };
        if !is_kept.contains(&i) {
            dropped[n].push((row(i), Verdict::BeyondCap));
        } else if !work[n].objects.iter().any(|(o, _)| *o == e.obj_id) {
            dropped[n].push((row(i), Verdict::ObjectAbsent));
        }
    }
    let kept = work
        .iter()
        .map(|w| {
            w.objects
                .iter()
                .map(|(_, ests)| ests.iter().map(|&i| row(i)).collect())
                .collect()
        })
        .collect();
    Ok(Inspection {
        errors,
        kept,
        dropped,
    })
}

impl Inspection {
    /// Every inspected target image at `criterion`, in bop_toolkit's order of the images
    /// (scenes and images as the targets file first lists them).
    pub fn verdicts(&self, dataset: &Dataset, criterion: &Criterion) -> Vec<ImageVerdicts> {
        let error = criterion.error;
        let matches = ranking::matches(dataset, &self.errors, error, criterion.threshold);
        self.errors
            .iter()
            .enumerate()
            .map(|(n, im)| {
                let image = &dataset.scenes[&im.scene_id].images[&im.im_id];
                let mut matched_by: Vec<Option<u64>> = vec![None; image.gt.len()];
                let mut estimates = Vec::new();
                for (o, obj) in im.objects.iter().enumerate() {
                    for (e, est) in obj.estimates.iter().enumerate() {
                        let m = matches[n][o][e];
                        let row = self.kept[n][o][e];
                        let error_to = |i: usize| {
                            ranking::normalised(dataset, error, im.scene_id, obj.obj_id, est, i)
                        };
                        // The matched instance, else the nearest (the first on ties).
                        let against = m.instance.or_else(|| {
                            (0..obj.gt_ids.len())
                                .min_by(|&a, &b| error_to(a).total_cmp(&error_to(b)))
                        });
                        if let Some(i) = m.instance {
                            matched_by[obj.gt_ids[i]] = Some(row.line);
                        }
                        estimates.push(EstimateVerdict {
                            line: row.line,
                            obj_id: row.obj_id,
                            score: row.score,
                            verdict: match m.outcome {
                                Outcome::TruePositive => Verdict::TruePositive,
                                Outcome::FalsePositive => Verdict::FalsePositive,
                                Outcome::Ignored => Verdict::Ignored,
                            },
                            gt_id: against.map(|i| obj.gt_ids[i] as u32),
                            error: against.map(error_to).filter(|v| v.is_finite()),
                        });
                    }
                }
                estimates.extend(
                    self.dropped[n]
                        .iter()
                        .map(|&(row, verdict)| EstimateVerdict {
                            line: row.line,
                            obj_id: row.obj_id,
                            score: row.score,
                            verdict,
                            gt_id: None,
                            error: None,
                        }),
                );
                let instances = image
                    .gt
                    .iter()
                    .enumerate()
                    .map(|(g, gt)| InstanceVerdict {
                        gt_id: g as u32,
                        obj_id: gt.obj_id,
                        visib_fract: gt.visib_fract,
                        counted: gt.visib_fract >= VISIB_GT_MIN,
                        matched_by: matched_by[g],
                    })
                    .collect();
                ImageVerdicts {
                    scene_id: im.scene_id,
                    im_id: im.im_id,
                    instances,
                    estimates,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_criterion_defaults_to_the_middle_and_takes_only_the_errors_thresholds() {
        let c = Criterion::choose(None, None).unwrap();
        assert_eq!((c.error, c.threshold), (DetectionError::Mssd, 0.3));
        assert_eq!(c.description(), "MSSD below 0.3 of the object diameter");
        let c = Criterion::choose(Some("mspd"), None).unwrap();
        assert_eq!(c.threshold, 30.0);
        let c = Criterion::choose(Some("mssd_mm"), Some(8.0)).unwrap();
        assert_eq!(c.description(), "MSSD below 8 mm");
        // 0.15 is bop19's `0.05 + 2 * 0.05`, written as people write it.
        let c = Criterion::choose(Some("mssd"), Some(0.15)).unwrap();
        assert_eq!(c.threshold, 0.05 + 2.0 * 0.05);
        assert_eq!(
            Criterion::choose(Some("vsd"), None).unwrap_err(),
            "bop24 has no error `vsd` (it has mssd, mssd_mm, mspd)"
        );
        assert_eq!(
            Criterion::choose(Some("mspd"), Some(12.0)).unwrap_err(),
            "12 is not a threshold of mspd (5, 10, 15, 20, 25, 30, 35, 40, 45, 50: pixels at \
             640 px image width)"
        );
    }
}
