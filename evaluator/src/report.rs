//! The report of one evaluation: every number poseboard shows, with bop_toolkit's key names
//! where the quantity is the same (`recall`, `obj_recalls`, `bop19_average_recall`, ...), and
//! the parameters that produced it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::bootstrap::{BootstrapSummary, ImageCounts};
use crate::dataset::Dataset;
use crate::matching::{EstimateErrors, NTop};
use crate::protocol::{Column, ErrorKind, Protocol, ProtocolName, normalised_error};
use crate::results::Results;
use crate::score::{Scored, ScoredImage, Scores, Targets, counted_instances};
use crate::selection::Selection;
use crate::stats::{mean, recall};

/// The version of the evaluator, stored with every score so that scores from different
/// evaluator versions are never mixed silently.
pub const EVALUATOR_VERSION: &str = env!("CARGO_PKG_VERSION");

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub evaluator_version: String,
    pub dataset: String,
    pub protocol: ProtocolName,
    pub parameters: Parameters,
    /// Rows of the result file.
    pub estimates_count: usize,
    /// Estimates whose errors were computed (the first n_top of each target).
    pub estimates_evaluated: usize,
    /// Estimates for images or objects that are not test targets (ignored, as bop_toolkit does).
    pub estimates_ignored: usize,
    pub targets_without_estimate: usize,
    pub warnings: Vec<String>,

    /// ECCV'18: recall and its breakdowns at the main tau and theta.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub localization: Option<Scores>,
    /// ECCV'18: the reported time of each image shared among its targets, averaged over targets.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub average_time_per_target: Option<f64>,
    /// ECCV'18 Fig. 5 left: recall against the threshold of correctness theta, one curve per tau.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recall_vs_theta: Vec<ThetaCurve>,
    /// ECCV'18 Fig. 5 right: recall of ground-truth instances by their visible fraction.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recall_vs_visib: Vec<VisibBin>,
    /// BOP'19: per error type, recall against the threshold of correctness, averaged over the
    /// error's other settings (the VSD taus): the curves whose means are AR_VSD, AR_MSSD, AR_MSPD.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recall_vs_threshold: Vec<ThresholdCurve>,

    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop19_average_recall: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop19_average_recall_vsd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop19_average_recall_mssd: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop19_average_recall_mspd: Option<f64>,
    /// BOP'19: mean over images of the time given for the image; -1 when any time is negative
    /// (not measured), as bop_toolkit writes it. Absent for other protocols.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bop19_average_time_per_image: Option<f64>,
    /// BOP'19: per object (and per scene), the average recall over the three errors.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub obj_average_recalls: BTreeMap<u32, f64>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub scene_average_recalls: BTreeMap<u32, f64>,

    /// Mean recall over the thresholds of each error type (its average recall).
    pub average_recalls: BTreeMap<String, f64>,
    /// `[error signature][score signature]` = recall, with bop_toolkit's signatures
    /// (`error=vsd_ntop=-1_delta=15.000_tau=0.050`, `th=0.050_min-visib=-1.000`).
    pub per_error_recall_per_threshold: BTreeMap<String, BTreeMap<String, f64>>,

    /// The bootstrap 95 % interval of the headline score, when the caller drew one (see
    /// [`crate::bootstrap`]); absent otherwise, so reports without it read as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bootstrap: Option<BootstrapSummary>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameters {
    pub n_top: i64,
    pub visib_gt_min: f64,
    pub max_sym_disc_step: f64,
    pub main_tau: f64,
    pub main_theta: f64,
    pub errors: Vec<ErrorParameters>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorParameters {
    #[serde(rename = "type")]
    pub kind: String,
    pub thresholds: Vec<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vsd_delta: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vsd_taus: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vsd_normalized_by_diameter: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub visib_mode: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ThetaCurve {
    pub tau: f64,
    /// (theta, recall) in increasing theta.
    pub points: Vec<(f64, f64)>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ThresholdCurve {
    /// The error type (`vsd`, `mssd`, `mspd`, ...).
    pub error: String,
    /// (threshold, recall) in the protocol's threshold order.
    pub points: Vec<(f64, f64)>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VisibBin {
    pub visib_from: f64,
    pub visib_to: f64,
    /// Target instances in the bin: over all bins, the recall's `targets_count`.
    pub instances: usize,
    pub matched: usize,
    pub recall: f64,
}

pub fn parameters(protocol: &Protocol) -> Parameters {
    Parameters {
        n_top: protocol.n_top.as_i64(),
        visib_gt_min: protocol.visib_gt_min,
        max_sym_disc_step: protocol.max_sym_disc_step,
        main_tau: protocol.main_tau,
        main_theta: protocol.main_theta,
        errors: protocol
            .errors
            .iter()
            .map(|e| {
                let vsd = match &e.kind {
                    ErrorKind::Vsd(p) => Some(p),
                    _ => None,
                };
                ErrorParameters {
                    kind: e.kind.name().to_string(),
                    thresholds: e.thresholds.clone(),
                    vsd_delta: vsd.map(|p| p.delta),
                    vsd_taus: vsd.map(|p| p.taus.clone()),
                    vsd_normalized_by_diameter: vsd.map(|p| p.normalized_by_diameter),
                    visib_mode: vsd.map(|p| p.visib_mode.name().to_string()),
                }
            })
            .collect(),
    }
}

impl Parameters {
    /// The parameters as the protocol defines them, for a record a reader reads: every number
    /// the decimal it is written with (bop_toolkit's `np.arange(0.05, 0.51, 0.05)` makes
    /// 0.15000000000000002 of the 0.15 it lists; see [`as_defined`]), and the thresholds and
    /// taus in increasing order, each once (eccv18's 0.3 is first for the headline, and its
    /// curve's 0.30000000000000004 reads 0.3 too). The evaluation keeps using the exact
    /// values, which are bop_toolkit's.
    pub fn as_defined(&self) -> Parameters {
        let list = |v: &[f64]| {
            let mut out: Vec<f64> = v.iter().copied().map(as_defined).collect();
            out.sort_by(f64::total_cmp);
            out.dedup();
            out
        };
        Parameters {
            n_top: self.n_top,
            visib_gt_min: as_defined(self.visib_gt_min),
            max_sym_disc_step: as_defined(self.max_sym_disc_step),
            main_tau: as_defined(self.main_tau),
            main_theta: as_defined(self.main_theta),
            errors: self
                .errors
                .iter()
                .map(|e| ErrorParameters {
                    kind: e.kind.clone(),
                    thresholds: list(&e.thresholds),
                    vsd_delta: e.vsd_delta.map(as_defined),
                    vsd_taus: e.vsd_taus.as_deref().map(list),
                    vsd_normalized_by_diameter: e.vsd_normalized_by_diameter,
                    visib_mode: e.visib_mode.clone(),
                })
                .collect(),
        }
    }
}

/// The value a protocol parameter is written as: the number of the fewest significant digits
/// within a few units in the last place of `v`, the error a computed list such as
/// `start + i * step` carries (0.30000000000000004 is 0.3); any other value as it is. Its
/// shortest round-trip decimal is then the one the protocol is written with.
pub fn as_defined(v: f64) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    (0..f64::DIGITS as usize)
        .filter_map(|digits| format!("{v:.digits$e}").parse::<f64>().ok())
        .find(|w| (w - v).abs() <= 4.0 * f64::EPSILON * v.abs())
        .unwrap_or(v)
}

/// bop_toolkit's score signature.
pub fn score_signature(threshold: f64, visib_gt_min: f64) -> String {
    format!("th={threshold:.3}_min-visib={visib_gt_min:.3}")
}

pub(crate) fn build(
    dataset: &Dataset,
    results: &Results,
    protocol: &Protocol,
    columns: &[Column],
    images: &[ScoredImage],
    errors: &[EstimateErrors],
    selection: &Selection,
) -> (Report, ImageCounts) {
    let object_ids: Vec<u32> = dataset.objects.keys().copied().collect();
    let scene_ids: Vec<u32> = dataset.scenes.keys().copied().collect();

    // Scores for every (column, threshold), in protocol order.
    let targets = Targets::new(images, &object_ids, &scene_ids, protocol.n_top);
    let mut per_column: Vec<Vec<(f64, Scored)>> = Vec::with_capacity(columns.len());
    for (ci, col) in columns.iter().enumerate() {
        let spec = &protocol.errors[col.error];
        let scored = targets.scores_at(errors, &spec.thresholds, |e, i| {
            normalised_error(dataset, &spec.kind, e, e.errors[ci][i])
        });
        let scored = spec.thresholds.iter().copied().zip(scored).collect();
        per_column.push(scored);
    }

    let mut per_error_recall_per_threshold = BTreeMap::new();
    let mut recalls_by_error: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    for (col, scored) in columns.iter().zip(&per_column) {
        let name = protocol.errors[col.error].kind.name();
        let entry: &mut BTreeMap<String, f64> = per_error_recall_per_threshold
            .entry(col.signature.clone())
            .or_default();
        for (th, s) in scored {
            entry.insert(score_signature(*th, protocol.visib_gt_min), s.scores.recall);
            recalls_by_error
                .entry(name)
                .or_default()
                .push(s.scores.recall);
        }
    }
    let average_recalls: BTreeMap<String, f64> = recalls_by_error
        .iter()
        .map(|(k, v)| (k.to_string(), mean(v)))
        .collect();

    let mut report = Report {
        evaluator_version: EVALUATOR_VERSION.to_string(),
        dataset: dataset.name.clone(),
        protocol: protocol.name,
        parameters: parameters(protocol),
        estimates_count: results.estimates.len(),
        estimates_evaluated: selection.evaluated,
        estimates_ignored: selection.ignored,
        targets_without_estimate: selection.targets_without_estimate,
        warnings: warnings(dataset, results, selection),
        localization: None,
        average_time_per_target: None,
        recall_vs_theta: Vec::new(),
        recall_vs_visib: Vec::new(),
        recall_vs_threshold: Vec::new(),
        bop19_average_recall: None,
        bop19_average_recall_vsd: None,
        bop19_average_recall_mssd: None,
        bop19_average_recall_mspd: None,
        bop19_average_time_per_image: None,
        obj_average_recalls: BTreeMap::new(),
        scene_average_recalls: BTreeMap::new(),
        average_recalls,
        per_error_recall_per_threshold,
        bootstrap: None,
    };
    let mut counts = ImageCounts {
        targets: per_column
            .first()
            .and_then(|scored| scored.first())
            .map(|(_, s)| s.image_targets.clone())
            .unwrap_or_default(),
        groups: Vec::new(),
    };

    match protocol.name {
        ProtocolName::Eccv18 => {
            let vsd_cols: Vec<usize> = (0..columns.len())
                .filter(|&c| columns[c].tau.is_some())
                .collect();
            for &c in &vsd_cols {
                let mut points: Vec<(f64, f64)> = per_column[c]
                    .iter()
                    .map(|(th, s)| (*th, s.scores.recall))
                    .collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                points.dedup_by(|a, b| a.0 == b.0);
                report.recall_vs_theta.push(ThetaCurve {
                    tau: columns[c].tau.unwrap_or_default(),
                    points,
                });
            }
            let main = vsd_cols
                .iter()
                .find(|&&c| columns[c].tau == Some(protocol.main_tau))
                .and_then(|&c| {
                    per_column[c]
                        .iter()
                        .find(|(th, _)| *th == protocol.main_theta)
                });
            if let Some((_, scored)) = main {
                counts.groups = vec![vec![scored.image_tps.clone()]];
                report.localization = Some(scored.scores.clone());
                report.recall_vs_visib = visib_bins(images, &scored.matched, protocol.n_top);
            }
            report.average_time_per_target = time_per_target(results, images);
        }
        ProtocolName::Bop19 => {
            let avg = |name: &str| report.average_recalls.get(name).copied();
            report.bop19_average_recall_vsd = avg("vsd");
            report.bop19_average_recall_mssd = avg("mssd");
            report.bop19_average_recall_mspd = avg("mspd");
            if let (Some(v), Some(s), Some(p)) = (
                report.bop19_average_recall_vsd,
                report.bop19_average_recall_mssd,
                report.bop19_average_recall_mspd,
            ) {
                report.bop19_average_recall = Some(mean(&[v, s, p]));
                // As `average_recalls` gathers them: by column, then threshold.
                counts.groups = ["vsd", "mssd", "mspd"]
                    .iter()
                    .map(|name| {
                        columns
                            .iter()
                            .zip(&per_column)
                            .filter(|(c, _)| protocol.errors[c.error].kind.name() == *name)
                            .flat_map(|(_, scored)| scored.iter().map(|(_, s)| s.image_tps.clone()))
                            .collect()
                    })
                    .collect();
            }
            report.bop19_average_time_per_image =
                Some(results.average_time_per_image().unwrap_or(-1.0));
            report.recall_vs_threshold = threshold_curves(protocol, columns, &per_column);
            report.obj_average_recalls =
                grouped_average_recall(protocol, columns, &per_column, |s| &s.obj_recalls);
            report.scene_average_recalls =
                grouped_average_recall(protocol, columns, &per_column, |s| &s.scene_recalls);
        }
    }
    (report, counts)
}

/// Per error type, the recall at each of its thresholds averaged over its columns (VSD taus).
fn threshold_curves(
    protocol: &Protocol,
    columns: &[Column],
    per_column: &[Vec<(f64, Scored)>],
) -> Vec<ThresholdCurve> {
    protocol
        .errors
        .iter()
        .enumerate()
        .map(|(e, spec)| {
            let points = spec
                .thresholds
                .iter()
                .enumerate()
                .map(|(k, &th)| {
                    let recalls: Vec<f64> = columns
                        .iter()
                        .zip(per_column)
                        .filter(|(c, _)| c.error == e)
                        .map(|(_, scored)| scored[k].1.scores.recall)
                        .collect();
                    (th, mean(&recalls))
                })
                .collect();
            ThresholdCurve {
                error: spec.kind.name().to_string(),
                points,
            }
        })
        .collect()
}

/// Per object (or scene): the mean over error types of the mean recall over that type's
/// thresholds, the per-object breakdown of the BOP'19 average recall.
fn grouped_average_recall(
    protocol: &Protocol,
    columns: &[Column],
    per_column: &[Vec<(f64, Scored)>],
    group: impl Fn(&Scores) -> &BTreeMap<u32, f64>,
) -> BTreeMap<u32, f64> {
    let mut per_error: Vec<BTreeMap<u32, Vec<f64>>> = vec![BTreeMap::new(); protocol.errors.len()];
    for (col, scored) in columns.iter().zip(per_column) {
        for (_, s) in scored {
            for (&id, &r) in group(&s.scores) {
                per_error[col.error].entry(id).or_default().push(r);
            }
        }
    }
    let mut out: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
    for errs in per_error {
        for (id, recalls) in errs {
            out.entry(id).or_default().push(mean(&recalls));
        }
    }
    out.into_iter().map(|(id, v)| (id, mean(&v))).collect()
}

/// The instances the protocol targets, by visible fraction: those that count in the recall
/// (`targets_count`, see `counted_instances`), so the bins add up to its targets and true
/// positives.
fn visib_bins(images: &[ScoredImage], matched: &[Vec<bool>], n_top: NTop) -> Vec<VisibBin> {
    let mut counts = [(0usize, 0usize); 10];
    for (im, m) in images.iter().zip(matched) {
        for gt_id in counted_instances(&im.gts, m, n_top) {
            let bin = ((im.gts[gt_id].1 * 10.0).floor().max(0.0) as usize).min(9);
            counts[bin].0 += 1;
            counts[bin].1 += m[gt_id] as usize;
        }
    }
    counts
        .iter()
        .enumerate()
        .map(|(i, &(n, hit))| VisibBin {
            visib_from: i as f64 / 10.0,
            visib_to: (i + 1) as f64 / 10.0,
            instances: n,
            matched: hit,
            recall: recall(hit, n),
        })
        .collect()
}

fn time_per_target(results: &Results, images: &[ScoredImage]) -> Option<f64> {
    if !results.times_available {
        return None;
    }
    let (mut time, mut targets) = (0.0, 0usize);
    for im in images {
        if let Some(t) = results.image_times.get(&(im.scene_id, im.im_id)) {
            time += t;
            targets += im.estimates.len();
        }
    }
    (targets > 0).then(|| time / targets as f64)
}

fn warnings(dataset: &Dataset, results: &Results, selection: &Selection) -> Vec<String> {
    let mut w = Vec::new();
    if selection.ignored > 0 {
        w.push(format!(
            "{} of {} estimates are for images or objects that are not test targets of {}; they were ignored, as bop_toolkit does",
            selection.ignored,
            results.estimates.len(),
            dataset.name
        ));
    }
    if selection.evaluated == 0 {
        w.push("no estimate is for a test target: every score is 0".to_string());
    } else if selection.targets_without_estimate > 0 {
        w.push(format!(
            "{} of {} targets have no estimate; they count as misses",
            selection.targets_without_estimate,
            dataset.targets.len()
        ));
    }
    if !results.times_available && !results.estimates.is_empty() {
        w.push(
            "some estimates give a negative time (not measured): no average time is reported"
                .to_string(),
        );
    }
    w
}

impl Report {
    /// The headline number of the protocol: recall (eccv18) or average recall (bop19).
    pub fn headline(&self) -> f64 {
        match self.protocol {
            ProtocolName::Eccv18 => self.localization.as_ref().map_or(0.0, |s| s.recall),
            ProtocolName::Bop19 => self.bop19_average_recall.unwrap_or(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Protocol, bop19_fractions};

    #[test]
    fn parameters_read_as_the_protocols_define_them() {
        // The values evaluated with stay numpy's: bop_toolkit compares against these bits.
        assert_eq!(bop19_fractions()[2], 0.15000000000000002);
        assert_eq!(
            Protocol::bop19().errors[0].thresholds[2],
            0.15000000000000002
        );

        let fractions = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5];
        let bop19 = parameters(&Protocol::bop19()).as_defined();
        assert_eq!(bop19.errors[0].thresholds, fractions);
        assert_eq!(bop19.errors[0].vsd_taus.as_deref(), Some(&fractions[..]));
        assert_eq!(bop19.errors[1].thresholds, fractions);
        let px: Vec<f64> = (1..=10).map(|i| f64::from(i) * 5.0).collect();
        assert_eq!(bop19.errors[2].thresholds, px);
        assert_eq!(
            serde_json::to_string(&bop19.errors[0].thresholds).expect("JSON"),
            "[0.05,0.1,0.15,0.2,0.25,0.3,0.35,0.4,0.45,0.5]"
        );

        // eccv18: the headline theta and the curve's, in increasing order, 0.3 once.
        let eccv18 = parameters(&Protocol::eccv18()).as_defined();
        let thetas = [
            0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75,
            0.8, 0.85, 0.9, 0.95, 1.0,
        ];
        assert_eq!(eccv18.errors[0].thresholds, thetas);
        assert_eq!(eccv18.errors[0].vsd_taus, Some(vec![20.0, 80.0]));
        assert_eq!(
            (eccv18.main_tau, eccv18.main_theta, eccv18.visib_gt_min),
            (20.0, 0.3, 0.1)
        );

        // A value no list computed stays as it is.
        for v in [1.0 / 3.0, 0.123_456_789, -1.0, 0.0, 1e-9] {
            assert_eq!(as_defined(v), v);
        }
    }
}
