//! From `evaluate()`'s keyword arguments to a [`Protocol`], with the meaning and defaults of the
//! flags of `poseboard eval` (server/src/cli/eval.rs), so that the package, its `poseboard-eval`
//! script and the command line give one report for one set of options. The Python tests compare
//! the two programs' reports under overrides to keep them in step.

use evaluator::Protocol;
use evaluator::protocol::{ErrorKind, ErrorSpec, NTop, ProtocolName};
use evaluator::visibility::VisibMode;

/// Protocol parameters a user may override; unset ones keep the protocol's values.
#[derive(Debug, Default)]
pub struct Overrides {
    pub visib_mode: Option<String>,
    pub tau: Option<Vec<f64>>,
    pub tau_normalized: Option<bool>,
    pub theta: Option<Vec<f64>>,
    pub delta: Option<f64>,
    pub n_top: Option<i64>,
    pub visib_gt_min: Option<f64>,
    pub max_sym_disc_step: Option<f64>,
    pub extra_errors: Vec<String>,
    pub ad_threshold: f64,
}

/// The named protocol with `overrides` applied; the message says which value is wrong.
pub fn build(name: &str, o: &Overrides) -> Result<Protocol, String> {
    let mut protocol = Protocol::named(name.parse::<ProtocolName>()?);
    if let Some(n) = o.n_top {
        protocol.n_top = NTop::from_i64(n)?;
    }
    if let Some(v) = o.visib_gt_min {
        protocol.visib_gt_min = v;
    }
    if let Some(s) = o.max_sym_disc_step {
        protocol.max_sym_disc_step = s;
    }
    let visib_mode = o
        .visib_mode
        .as_deref()
        .map(str::parse::<VisibMode>)
        .transpose()?;
    let vsd_changed = visib_mode.is_some()
        || o.tau.is_some()
        || o.tau_normalized.is_some()
        || o.theta.is_some()
        || o.delta.is_some();
    if vsd_changed {
        let Some((p, ths)) = protocol.vsd() else {
            return Err("this protocol has no VSD to configure".into());
        };
        let (p, ths) = (p.clone(), ths.to_vec());
        // eccv18 keeps only its main tau and theta by default: set_vsd adds the paper's curves.
        let eccv18 = protocol.name == ProtocolName::Eccv18;
        let taus = o.tau.clone().unwrap_or_else(|| {
            if eccv18 {
                vec![protocol.main_tau]
            } else {
                p.taus.clone()
            }
        });
        let thresholds = o.theta.clone().unwrap_or_else(|| {
            if eccv18 {
                vec![protocol.main_theta]
            } else {
                ths
            }
        });
        protocol.set_vsd(
            o.delta.unwrap_or(p.delta),
            taus,
            o.tau_normalized.unwrap_or(p.normalized_by_diameter),
            visib_mode.unwrap_or(p.visib_mode),
            thresholds,
        );
    }
    for extra in &o.extra_errors {
        let kind = match extra.as_str() {
            "add" => ErrorKind::Add,
            "adi" => ErrorKind::Adi,
            "ad" => ErrorKind::Ad,
            other => return Err(format!("unknown extra error `{other}` (add, adi or ad)")),
        };
        if !protocol.errors.iter().any(|e| e.kind == kind) {
            protocol.errors.push(ErrorSpec {
                kind,
                thresholds: vec![o.ad_threshold],
            });
        }
    }
    protocol.validate()?;
    Ok(protocol)
}
