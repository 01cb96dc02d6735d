//! The outcome of each target instance under the matching behind the scores: which estimate was
//! matched to it, with what error, and so whether it counts as correct. The scores are counts of
//! these outcomes: at any error column and threshold, the correct instances over all of them is
//! the recall the report gives there (`tests/outcomes.rs` checks it), so a page that lists single
//! targets gives the verdicts the scores count.
//!
//! "Correct" is binary at one error column and one threshold, a [`Criterion`]. By default it is
//! the protocol's first error, VSD: for `eccv18` at the paper's tau and theta (20 mm, 0.3); for
//! `bop19`, which has no main setting, at the middle of its taus and of its thresholds (tau 0.3
//! of the object diameter, theta 0.3, the sixth of ten values). Another error is taken at the
//! middle of its thresholds (`bop19`: MSSD 0.3 of the diameter, MSPD 30 px). BOP'19's average recall itself gives no verdict per target (it
//! averages recalls over 120 settings of error, tau and threshold); its central setting does.

use std::collections::{BTreeMap, HashMap, HashSet};

use serde::Serialize;

use crate::dataset::Dataset;
use crate::matching::{EstimateErrors, match_image_object, valid_gts};
use crate::protocol::{ErrorKind, Protocol, ProtocolName, columns, normalised_error};
use crate::score::counted_instances;

/// When a target instance counts as correct: matched, under the protocol's greedy matching, by
/// an estimate whose error in one column is strictly below a threshold.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Criterion {
    /// The error type (`vsd`, `mssd`, `mspd`, `add`, ...).
    pub error: String,
    /// For VSD, the misalignment tolerance of its column (mm, or a fraction of the diameter).
    pub tau: Option<f64>,
    /// On the normalised error (see `protocol::normalised_error`).
    pub threshold: f64,
    /// In words, with units.
    pub description: String,
    /// Index into the protocol's errors.
    #[serde(skip)]
    pub spec: usize,
    /// Index into the protocol's columns (`protocol::columns`), the layout of stored errors.
    #[serde(skip)]
    pub column: usize,
}

/// Whether two parameters are the same value written differently (`0.3` given for bop19's
/// `0.05 + 5 * 0.05`).
fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

impl Criterion {
    /// The criterion of the protocol's defaults (see the module's documentation).
    pub fn default_for(protocol: &Protocol) -> Result<Criterion, String> {
        Criterion::choose(protocol, None, None, None)
    }

    /// A criterion from what a reader asked: the error by name, for VSD its tau (one the
    /// protocol computed), and any threshold; each unset part takes the default. A threshold
    /// that is one of the protocol's, written differently, is taken as the protocol's, so that
    /// the outcomes add up to the recall the report gives there.
    pub fn choose(
        protocol: &Protocol,
        error: Option<&str>,
        tau: Option<f64>,
        threshold: Option<f64>,
    ) -> Result<Criterion, String> {
        let names: Vec<&str> = protocol.errors.iter().map(|e| e.kind.name()).collect();
        let spec = match error {
            None => 0,
            Some(name) => names.iter().position(|n| *n == name).ok_or_else(|| {
                format!(
                    "the protocol has no error `{name}` (it has {})",
                    names.join(", ")
                )
            })?,
        };
        let kind = &protocol
            .errors
            .get(spec)
            .ok_or("the protocol has no error")?
            .kind;
        let thresholds = &protocol.errors[spec].thresholds;
        let cols = columns(protocol);
        let middle = |values: &[f64]| values.get(values.len() / 2).copied();
        let (column, tau, default) = match kind {
            ErrorKind::Vsd(params) => {
                // The paper's tau and theta; the BOP Challenge has no main one: the middle.
                let (main_tau, main_theta) = if protocol.name == ProtocolName::Eccv18 {
                    (protocol.main_tau, protocol.main_theta)
                } else {
                    (
                        middle(&params.taus).ok_or("vsd has no tau")?,
                        middle(thresholds).ok_or("vsd has no threshold")?,
                    )
                };
                let wanted = tau.unwrap_or(main_tau);
                let column = cols
                    .iter()
                    .position(|c| c.error == spec && c.tau.is_some_and(|t| same(t, wanted)))
                    .ok_or_else(|| {
                        let taus: Vec<String> = params.taus.iter().map(|t| t.to_string()).collect();
                        format!("vsd was computed at tau {}, not {wanted}", taus.join(", "))
                    })?;
                (column, cols[column].tau, main_theta)
            }
            _ if tau.is_some() => return Err("tau applies to vsd only".into()),
            _ => {
                let column = cols
                    .iter()
                    .position(|c| c.error == spec)
                    .ok_or("the error has no column")?;
                let threshold = middle(thresholds).ok_or("the error has no threshold")?;
                (column, None, threshold)
            }
        };
        let threshold = match threshold {
            None => default,
            Some(t) if !(t.is_finite() && t >= 0.0) => {
                return Err(format!(
                    "the threshold must be a non-negative number, not {t}"
                ));
            }
            Some(t) => thresholds
                .iter()
                .copied()
                .find(|&p| same(p, t))
                .unwrap_or(t),
        };
        Ok(Criterion {
            error: kind.name().to_string(),
            tau,
            threshold,
            description: describe(kind, tau, threshold),
            spec,
            column,
        })
    }
}

fn describe(kind: &ErrorKind, tau: Option<f64>, threshold: f64) -> String {
    let th = format!("{:.3}", threshold)
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_string();
    match kind {
        ErrorKind::Vsd(p) => {
            let tau = format!("{:.3}", tau.unwrap_or_default())
                .trim_end_matches('0')
                .trim_end_matches('.')
                .to_string();
            let unit = if p.normalized_by_diameter {
                " of the object diameter"
            } else {
                " mm"
            };
            format!("VSD below {th} at tau {tau}{unit}")
        }
        ErrorKind::Mspd => format!("MSPD below {th} px (at 640 px image width)"),
        other => format!(
            "{} below {th} of the object diameter",
            other.name().to_uppercase()
        ),
    }
}

/// What happened to one target instance.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetOutcome {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    /// The instance's index in its image's ground truth.
    pub gt_id: u32,
    pub visib_fract: f64,
    /// How many estimates of its object in its image were evaluated.
    pub estimates: usize,
    /// The estimate matched to it (its `est_id`); `None`: missed.
    pub est_id: Option<u32>,
    /// The normalised error of the matched estimate; for a missed instance, the lowest error
    /// of any evaluated estimate of its object against it (the near miss). `None` without
    /// estimates, or when that error is infinite (the estimate is far off).
    pub error: Option<f64>,
    /// Matched, so counted as a true positive by the recall at this criterion.
    pub correct: bool,
}

/// The outcome of every target instance the recall counts (per image and object its valid
/// instances, at most n_top of them: see `score::counted_instances`), in image order, then by
/// object and gt id. `errors` are the evaluated estimates with their errors in the columns of
/// `protocol` (an `Evaluation`'s, or those stored from one).
pub fn outcomes(
    dataset: &Dataset,
    protocol: &Protocol,
    errors: &[EstimateErrors],
    criterion: &Criterion,
) -> Vec<TargetOutcome> {
    let kind = &protocol.errors[criterion.spec].kind;
    let column = criterion.column;
    let error =
        |e: &EstimateErrors, i: usize| normalised_error(dataset, kind, e, e.errors[column][i]);

    // Each target's estimates in decreasing score order, ties in file order (as selected).
    let mut by_target: HashMap<(u32, u32, u32), Vec<&EstimateErrors>> = HashMap::new();
    for e in errors {
        by_target
            .entry((e.scene_id, e.im_id, e.obj_id))
            .or_default()
            .push(e);
    }
    for ests in by_target.values_mut() {
        ests.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.est_id.cmp(&b.est_id)));
    }
    // The targets of each image, once each, in the targets file's order.
    let mut images: BTreeMap<(u32, u32), Vec<(u32, u32)>> = BTreeMap::new();
    let mut seen = HashSet::new();
    for t in &dataset.targets {
        if seen.insert((t.scene_id, t.im_id, t.obj_id)) {
            images
                .entry((t.scene_id, t.im_id))
                .or_default()
                .push((t.obj_id, t.inst_count));
        }
    }

    let mut out = Vec::new();
    for ((scene_id, im_id), targets) in images {
        let Some(image) = dataset
            .scenes
            .get(&scene_id)
            .and_then(|s| s.images.get(&im_id))
        else {
            continue;
        };
        let valid = valid_gts(image, &targets, protocol.visib_gt_min);
        let mut matched = vec![false; image.gt.len()];
        let mut matched_by: Vec<Option<&EstimateErrors>> = vec![None; image.gt.len()];
        let none = Vec::new();
        let ests_of = |obj: u32| by_target.get(&(scene_id, im_id, obj)).unwrap_or(&none);
        for &(obj, _) in &targets {
            let ests = ests_of(obj);
            let found = match_image_object(
                ests.iter().copied(),
                protocol.n_top,
                criterion.threshold,
                &valid,
                &mut matched,
                error,
            );
            for (position, gt) in found {
                matched_by[gt] = Some(ests[position]);
            }
        }
        let gts: Vec<(u32, f64, bool)> = image
            .gt
            .iter()
            .zip(&valid)
            .map(|(g, &v)| (g.obj_id, g.visib_fract, v))
            .collect();
        let mut counted = counted_instances(&gts, &matched, protocol.n_top);
        counted.sort_unstable();
        for gt in counted {
            let (obj_id, visib_fract, _) = gts[gt];
            let ests = ests_of(obj_id);
            let against = |e: &EstimateErrors| {
                e.gt_ids
                    .iter()
                    .position(|&g| g as usize == gt)
                    .map(|i| error(e, i))
            };
            let err = match matched_by[gt] {
                Some(e) => against(e),
                None => ests
                    .iter()
                    .filter_map(|e| against(e))
                    .min_by(f64::total_cmp),
            };
            out.push(TargetOutcome {
                scene_id,
                im_id,
                obj_id,
                gt_id: gt as u32,
                visib_fract,
                estimates: ests.len(),
                est_id: matched_by[gt].map(|e| e.est_id),
                error: err.filter(|e| e.is_finite()),
                correct: matched[gt],
            });
        }
    }
    out
}
