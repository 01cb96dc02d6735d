//! The evaluation protocols poseboard names: `eccv18`, the paper's (VSD only, one estimate per
//! target, targets at least 10 % visible), and `bop19`, the BOP Challenge's average recall over
//! VSD, MSSD and MSPD. Every parameter can be overridden; the report records what was used.

use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::matching::EstimateErrors;
pub use crate::matching::NTop;
use crate::pose_error::vsd::VsdParams;
use crate::visibility::VisibMode;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProtocolName {
    Eccv18,
    Bop19,
}

impl ProtocolName {
    pub fn as_str(self) -> &'static str {
        match self {
            ProtocolName::Eccv18 => "eccv18",
            ProtocolName::Bop19 => "bop19",
        }
    }
}

impl std::str::FromStr for ProtocolName {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "eccv18" => Ok(ProtocolName::Eccv18),
            "bop19" => Ok(ProtocolName::Bop19),
            other => Err(format!("unknown protocol `{other}` (eccv18 or bop19)")),
        }
    }
}

/// A pose error to compute, with the thresholds of correctness its recalls are reported at.
#[derive(Clone, Debug, PartialEq)]
pub struct ErrorSpec {
    pub kind: ErrorKind,
    /// Thresholds on the normalised error: VSD as is, MSSD/ADD/ADI/AD as a fraction of the
    /// diameter, MSPD in pixels at 640 px image width.
    pub thresholds: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ErrorKind {
    Vsd(VsdParams),
    Mssd,
    Mspd,
    Add,
    Adi,
    /// ADI for objects with declared symmetries, ADD for the others (bop_toolkit's `ad`).
    Ad,
}

impl ErrorKind {
    pub fn name(&self) -> &'static str {
        match self {
            ErrorKind::Vsd(_) => "vsd",
            ErrorKind::Mssd => "mssd",
            ErrorKind::Mspd => "mspd",
            ErrorKind::Add => "add",
            ErrorKind::Adi => "adi",
            ErrorKind::Ad => "ad",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Protocol {
    pub name: ProtocolName,
    pub n_top: NTop,
    /// Ground-truth instances less visible than this are not expected to be found; negative:
    /// the `inst_count` most visible instances of each target are (bop_toolkit's `-1`).
    pub visib_gt_min: f64,
    pub max_sym_disc_step: f64,
    pub errors: Vec<ErrorSpec>,
    /// The VSD (tau index, threshold) whose recall is the headline score of `eccv18`.
    pub main_tau: f64,
    pub main_theta: f64,
}

/// The misalignment tolerances of the BOP'19 VSD, and its thresholds of correctness:
/// 0.05, 0.10, ..., 0.50, computed like numpy's `arange(0.05, 0.51, 0.05)` (start + i * step),
/// whose floating-point values bop_toolkit compares against.
pub fn bop19_fractions() -> Vec<f64> {
    (0..10).map(|i| 0.05 + i as f64 * 0.05).collect()
}

/// MSPD thresholds of BOP'19: 5, 10, ..., 50 px.
pub fn bop19_mspd_thresholds() -> Vec<f64> {
    (1..=10).map(|i| 5.0 * i as f64).collect()
}

/// Thresholds of correctness for the recall-vs-theta curves of the paper's Fig. 5.
pub fn theta_curve() -> Vec<f64> {
    (0..=20).map(|i| i as f64 * 0.05).collect()
}

/// The tau of the paper's second curve (Fig. 5 plots tau = 20 and 80 mm).
pub const ECCV18_CURVE_TAU: f64 = 80.0;

impl Protocol {
    /// The ECCV'18 paper: VSD with tau = 20 mm, delta = 15 mm, theta = 0.3, one estimate per
    /// target, targets visible at least 10 %, and the paper's `bop18` visibility.
    pub fn eccv18() -> Self {
        let mut p = Protocol {
            name: ProtocolName::Eccv18,
            n_top: NTop::Top(1),
            visib_gt_min: 0.1,
            max_sym_disc_step: 0.01,
            errors: Vec::new(),
            main_tau: 20.0,
            main_theta: 0.3,
        };
        p.set_vsd(15.0, vec![20.0], false, VisibMode::Bop18, vec![0.3]);
        p
    }

    /// bop_toolkit's `eval_bop19_pose.py` defaults.
    pub fn bop19() -> Self {
        let fractions = bop19_fractions();
        let mut p = Protocol {
            name: ProtocolName::Bop19,
            n_top: NTop::InstCount,
            visib_gt_min: -1.0,
            max_sym_disc_step: 0.01,
            errors: Vec::new(),
            main_tau: fractions[5],
            main_theta: fractions[5],
        };
        p.set_vsd(
            15.0,
            fractions.clone(),
            true,
            VisibMode::Bop19,
            fractions.clone(),
        );
        p.errors.push(ErrorSpec {
            kind: ErrorKind::Mssd,
            thresholds: fractions,
        });
        p.errors.push(ErrorSpec {
            kind: ErrorKind::Mspd,
            thresholds: bop19_mspd_thresholds(),
        });
        p
    }

    pub fn named(name: ProtocolName) -> Self {
        match name {
            ProtocolName::Eccv18 => Self::eccv18(),
            ProtocolName::Bop19 => Self::bop19(),
        }
    }

    /// Replaces the VSD settings. For `eccv18` the curve tau and the theta curve are added to
    /// the given taus and thresholds so that Fig. 5 comes from the same renders.
    pub fn set_vsd(
        &mut self,
        delta: f64,
        taus: Vec<f64>,
        normalized_by_diameter: bool,
        visib_mode: VisibMode,
        thresholds: Vec<f64>,
    ) {
        let (mut taus, mut thresholds) = (taus, thresholds);
        if let Some(&first) = taus.first() {
            self.main_tau = first;
        }
        if let Some(&first) = thresholds.first() {
            self.main_theta = first;
        }
        if self.name == ProtocolName::Eccv18 {
            if !normalized_by_diameter && !taus.contains(&ECCV18_CURVE_TAU) {
                taus.push(ECCV18_CURVE_TAU);
            }
            for th in theta_curve() {
                if !thresholds.contains(&th) {
                    thresholds.push(th);
                }
            }
        }
        let spec = ErrorSpec {
            kind: ErrorKind::Vsd(VsdParams {
                delta,
                taus,
                normalized_by_diameter,
                visib_mode,
            }),
            thresholds,
        };
        match self
            .errors
            .iter_mut()
            .find(|e| matches!(e.kind, ErrorKind::Vsd(_)))
        {
            Some(e) => *e = spec,
            None => self.errors.insert(0, spec),
        }
    }

    pub fn vsd(&self) -> Option<(&VsdParams, &[f64])> {
        self.errors.iter().find_map(|e| match &e.kind {
            ErrorKind::Vsd(p) => Some((p, e.thresholds.as_slice())),
            _ => None,
        })
    }

    /// Checks the parameters once, so the pipeline can trust them.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.max_sym_disc_step > 0.0 && self.max_sym_disc_step <= 1.0) {
            return Err(format!(
                "max_sym_disc_step must be in (0, 1], not {}",
                self.max_sym_disc_step
            ));
        }
        if !self.visib_gt_min.is_finite() || self.visib_gt_min > 1.0 {
            return Err(format!(
                "visib_gt_min must be at most 1, not {}",
                self.visib_gt_min
            ));
        }
        if self.errors.is_empty() {
            return Err("no pose error selected".into());
        }
        for e in &self.errors {
            if e.thresholds.is_empty() || e.thresholds.iter().any(|t| !t.is_finite() || *t < 0.0) {
                return Err(format!(
                    "{}: thresholds must be finite, non-negative and not empty",
                    e.kind.name()
                ));
            }
            if let ErrorKind::Vsd(p) = &e.kind {
                if p.taus.is_empty() || p.taus.iter().any(|t| !t.is_finite() || *t <= 0.0) {
                    return Err("vsd: taus must be positive and not empty".into());
                }
                if !(p.delta.is_finite() && p.delta >= 0.0) {
                    return Err(format!("vsd: delta must be non-negative, not {}", p.delta));
                }
            }
        }
        Ok(())
    }
}

/// One column of per-estimate errors: an error type, and for VSD one of its taus.
#[derive(Clone, Debug, PartialEq)]
pub struct Column {
    /// Index into `Protocol::errors`.
    pub error: usize,
    /// For VSD, the tau of this column.
    pub tau: Option<f64>,
    /// bop_toolkit's error signature, e.g. `error=vsd_ntop=-1_delta=15.000_tau=0.050`.
    pub signature: String,
}

/// The error columns a protocol computes, in a fixed order.
pub fn columns(protocol: &Protocol) -> Vec<Column> {
    let n_top = protocol.n_top.as_i64();
    let mut cols = Vec::new();
    for (i, spec) in protocol.errors.iter().enumerate() {
        match &spec.kind {
            ErrorKind::Vsd(p) => {
                for &tau in &p.taus {
                    cols.push(Column {
                        error: i,
                        tau: Some(tau),
                        signature: format!(
                            "error=vsd_ntop={n_top}_delta={:.3}_tau={tau:.3}",
                            p.delta
                        ),
                    });
                }
            }
            kind => cols.push(Column {
                error: i,
                tau: None,
                signature: format!("error={}_ntop={n_top}", kind.name()),
            }),
        }
    }
    cols
}

/// The error compared with thresholds: VSD as is, MSSD, ADD, ADI and AD as a fraction of the
/// object's diameter, MSPD in pixels at 640 px image width (the width of the scene's sensor
/// where a dataset has several, as bop_toolkit's `eval_calc_scores.py`).
pub fn normalised_error(dataset: &Dataset, kind: &ErrorKind, e: &EstimateErrors, raw: f64) -> f64 {
    match kind {
        ErrorKind::Vsd(_) => raw,
        ErrorKind::Mspd => 640.0 / dataset.image_width(e.scene_id) as f64 * raw,
        ErrorKind::Mssd | ErrorKind::Add | ErrorKind::Adi | ErrorKind::Ad => {
            raw / dataset.objects[&e.obj_id].info.diameter
        }
    }
}

/// Protocol parameters a user may override (the flags of `poseboard eval`, the keywords of the
/// Python package), applied in one place so that every front end gives one report for one set
/// of options; unset ones keep the protocol's values.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    pub visib_mode: Option<VisibMode>,
    pub tau: Option<Vec<f64>>,
    pub tau_normalized: Option<bool>,
    pub theta: Option<Vec<f64>>,
    pub delta: Option<f64>,
    /// bop_toolkit's encoding: N, -1 = as many as instances, 0 = all.
    pub n_top: Option<i64>,
    pub visib_gt_min: Option<f64>,
    pub max_sym_disc_step: Option<f64>,
    /// Errors to compute beyond the protocol's own (ADD, ADI, AD), at `ad_threshold`.
    pub extra_errors: Vec<ErrorKind>,
    /// Threshold of correctness of the extra errors, as a fraction of the object diameter.
    pub ad_threshold: f64,
}

impl Overrides {
    /// Applies the overrides; the message says which value is wrong.
    pub fn apply(&self, protocol: &mut Protocol) -> Result<(), String> {
        if let Some(n) = self.n_top {
            protocol.n_top = NTop::from_i64(n)?;
        }
        if let Some(v) = self.visib_gt_min {
            protocol.visib_gt_min = v;
        }
        if let Some(s) = self.max_sym_disc_step {
            protocol.max_sym_disc_step = s;
        }
        let vsd_changed = self.visib_mode.is_some()
            || self.tau.is_some()
            || self.tau_normalized.is_some()
            || self.theta.is_some()
            || self.delta.is_some();
        if vsd_changed {
            let Some((p, ths)) = protocol.vsd() else {
                return Err("this protocol has no VSD to configure".into());
            };
            let (p, ths) = (p.clone(), ths.to_vec());
            // eccv18 keeps only its main tau and theta by default: set_vsd adds the curves.
            let eccv18 = protocol.name == ProtocolName::Eccv18;
            let taus = self.tau.clone().unwrap_or_else(|| {
                if eccv18 {
                    vec![protocol.main_tau]
                } else {
                    p.taus.clone()
                }
            });
            let thresholds = self.theta.clone().unwrap_or_else(|| {
                if eccv18 {
                    vec![protocol.main_theta]
                } else {
                    ths
                }
            });
            protocol.set_vsd(
                self.delta.unwrap_or(p.delta),
                taus,
                self.tau_normalized.unwrap_or(p.normalized_by_diameter),
                self.visib_mode.unwrap_or(p.visib_mode),
                thresholds,
            );
        }
        for kind in &self.extra_errors {
            if !protocol.errors.iter().any(|e| e.kind == *kind) {
                protocol.errors.push(ErrorSpec {
                    kind: kind.clone(),
                    thresholds: vec![self.ad_threshold],
                });
            }
        }
        protocol.validate()
    }
}
