//! From `evaluate()`'s keyword arguments to a [`Protocol`], with the meaning and defaults of the
//! flags of `poseboard eval` (server/src/cli/eval.rs), so that the package, its `poseboard-eval`
//! script and the command line give one report for one set of options. The Python tests compare
//! the two programs' reports under overrides to keep them in step.

use evaluator::Protocol;
use evaluator::protocol::{ErrorKind, ProtocolName};
use evaluator::visibility::VisibMode;

/// Protocol parameters a user may override, as `evaluate()` takes them (strings where the
/// command line takes words); unset ones keep the protocol's values.
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

impl Overrides {
    /// Whether any option is set (the extra errors included).
    pub fn any(&self) -> bool {
        self.visib_mode.is_some()
            || self.tau.is_some()
            || self.tau_normalized.is_some()
            || self.theta.is_some()
            || self.delta.is_some()
            || self.n_top.is_some()
            || self.visib_gt_min.is_some()
            || self.max_sym_disc_step.is_some()
            || !self.extra_errors.is_empty()
    }
}

/// The named protocol with `overrides` applied (by the evaluator's own rule, as the command
/// line applies them); the message says which value is wrong.
pub fn build(name: &str, o: &Overrides) -> Result<Protocol, String> {
    let mut protocol = Protocol::named(name.parse::<ProtocolName>()?);
    let extra_errors = o
        .extra_errors
        .iter()
        .map(|e| match e.as_str() {
            "add" => Ok(ErrorKind::Add),
            "adi" => Ok(ErrorKind::Adi),
            "ad" => Ok(ErrorKind::Ad),
            other => Err(format!("unknown extra error `{other}` (add, adi or ad)")),
        })
        .collect::<Result<_, _>>()?;
    evaluator::protocol::Overrides {
        visib_mode: o
            .visib_mode
            .as_deref()
            .map(str::parse::<VisibMode>)
            .transpose()?,
        tau: o.tau.clone(),
        tau_normalized: o.tau_normalized,
        theta: o.theta.clone(),
        delta: o.delta,
        n_top: o.n_top,
        visib_gt_min: o.visib_gt_min,
        max_sym_disc_step: o.max_sym_disc_step,
        extra_errors,
        ad_threshold: o.ad_threshold,
    }
    .apply(&mut protocol)?;
    Ok(protocol)
}
