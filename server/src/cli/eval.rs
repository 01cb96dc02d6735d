//! `poseboard eval` and `poseboard check-results`: the evaluator on the command line, for a
//! researcher with a dataset and a result file on disk.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use evaluator::protocol::{ErrorKind, Overrides, ProtocolName};
use evaluator::visibility::VisibMode;
use evaluator::{Dataset, Progress, Protocol, Report, evaluate, results};
use indicatif::{ProgressBar, ProgressStyle};

use crate::dataset_config::{SplitChoice, folder_choice};
use crate::preflight::Preflight;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// A BOP dataset folder (models/ or models_eval/, test/ or test_TYPE/,
    /// test_targets_bop19.json), or a folder of datasets: then the one the result file is
    /// named for (`METHOD_DATASET-test.csv`).
    #[arg(long)]
    pub dataset: PathBuf,
    #[command(flatten)]
    pub split: SplitArgs,
    /// A result file in the BOP'19 CSV format.
    #[arg(long)]
    pub results: PathBuf,
    #[arg(long, default_value = "bop19")]
    pub protocol: ProtocolName,
    /// Write the full report (every score, the parameters used) as JSON to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every evaluated estimate's errors against each ground-truth instance as JSON.
    #[arg(long)]
    pub errors_out: Option<PathBuf>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub overrides: OverrideArgs,
}

/// Protocol parameters a user may override; unset ones keep the protocol's values.
#[derive(Args, Debug, Default)]
pub struct OverrideArgs {
    /// VSD visibility: bop18 (the paper: missing depth hides) or bop19 (missing depth shows).
    #[arg(long)]
    pub visib_mode: Option<VisibMode>,
    /// VSD misalignment tolerance(s): mm, or fractions of the diameter when normalised.
    #[arg(long, value_delimiter = ',')]
    pub tau: Option<Vec<f64>>,
    /// Whether --tau is a fraction of the object diameter (bop19's default) or mm (eccv18's).
    #[arg(long)]
    pub tau_normalized: Option<bool>,
    /// VSD threshold(s) of correctness theta.
    #[arg(long, value_delimiter = ',')]
    pub theta: Option<Vec<f64>>,
    /// VSD visibility tolerance delta in mm.
    #[arg(long)]
    pub delta: Option<f64>,
    /// Estimates considered per target: N, -1 = as many as instances, 0 = all.
    #[arg(long, allow_hyphen_values = true)]
    pub n_top: Option<i64>,
    /// Minimum visible fraction of a ground-truth instance to be a target (-1: the
    /// inst_count most visible instances).
    #[arg(long, allow_hyphen_values = true)]
    pub visib_gt_min: Option<f64>,
    /// Discretisation of continuous symmetries (fraction of the diameter).
    #[arg(long)]
    pub max_sym_disc_step: Option<f64>,
    /// Also compute these errors: add, adi, ad (ADI for objects with declared symmetries,
    /// ADD for the others), reported at --ad-threshold.
    #[arg(long, value_delimiter = ',')]
    pub extra_errors: Vec<ExtraError>,
    /// Threshold of correctness of the extra errors, as a fraction of the object diameter.
    #[arg(long, default_value_t = 0.1)]
    pub ad_threshold: f64,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ExtraError {
    Add,
    Adi,
    Ad,
}

impl OverrideArgs {
    pub fn apply(&self, protocol: &mut Protocol) -> Result<()> {
        Overrides {
            visib_mode: self.visib_mode,
            tau: self.tau.clone(),
            tau_normalized: self.tau_normalized,
            theta: self.theta.clone(),
            delta: self.delta,
            n_top: self.n_top,
            visib_gt_min: self.visib_gt_min,
            max_sym_disc_step: self.max_sym_disc_step,
            extra_errors: self
                .extra_errors
                .iter()
                .map(|e| match e {
                    ExtraError::Add => ErrorKind::Add,
                    ExtraError::Adi => ErrorKind::Adi,
                    ExtraError::Ad => ErrorKind::Ad,
                })
                .collect(),
            ad_threshold: self.ad_threshold,
        }
        .apply(protocol)
        .map_err(anyhow::Error::msg)
    }
}

pub fn run_eval(args: EvalArgs) -> Result<()> {
    let mut protocol = Protocol::named(args.protocol);
    args.overrides.apply(&mut protocol)?;
    let dataset = load_dataset(&args.dataset, &args.results, &args.split)?;
    let results = load_results(&args.results)?;

    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = args.threads {
        pool = pool.num_threads(n);
    }
    let pool = pool.build().context("cannot start the worker threads")?;
    let bar = Bar::new();
    let evaluation = pool
        .install(|| evaluate(&dataset, &results, &protocol, &bar, &AtomicBool::new(false)))
        .context("evaluation failed")?;
    bar.finish();

    print_scores(&evaluation.report);
    if let Some(out) = &args.out {
        write_json(out, &evaluation.report)?;
    }
    if let Some(out) = &args.errors_out {
        let rows = evaluation.error_rows();
        write_json(out, &rows)?;
    }
    Ok(())
}

#[derive(Args, Debug)]
pub struct CheckArgs {
    /// The result file to validate.
    pub results: PathBuf,
    /// A dataset to report coverage against (targets without estimates, ignored estimates):
    /// a dataset folder or a folder of datasets, as for `eval`.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    #[command(flatten)]
    pub split: SplitArgs,
}

/// Which split of the dataset to read, over the folder's `poseboard-dataset.json` and the
/// defaults (`test`, the one split type there is, `test_targets_bop19.json`).
#[derive(Args, Debug, Default)]
pub struct SplitArgs {
    /// The split (default: test).
    #[arg(long)]
    pub split: Option<String>,
    /// The split type: reads `{split}_{type}/` and `camera_{type}.json` (T-LESS and HB:
    /// primesense); needed only when several are present.
    #[arg(long)]
    pub split_type: Option<String>,
    /// The targets file in the dataset folder (default: test_targets_bop19.json).
    #[arg(long)]
    pub targets_file: Option<String>,
}

pub fn run_check(args: CheckArgs) -> Result<()> {
    let results = load_results(&args.results)?;
    println!(
        "{}: {} estimates for {} images, OK",
        args.results.display(),
        results.estimates.len(),
        results.image_times.len().max(
            results
                .estimates
                .iter()
                .map(|e| (e.scene_id, e.im_id))
                .collect::<std::collections::BTreeSet<_>>()
                .len()
        )
    );
    if let Some(dir) = &args.dataset {
        let dataset = load_dataset(dir, &args.results, &args.split)?;
        // The upload pre-flight check, so the command line and the service say the same.
        let p = Preflight::of(
            &dataset,
            &results,
            &[ProtocolName::Bop19, ProtocolName::Eccv18],
        );
        println!(
            "{}: {} targets, {} without an estimate; {} estimates are not for a target and would be ignored",
            dataset.name, p.targets, p.targets_without_estimate, p.estimates_not_for_targets
        );
        for w in &p.warnings {
            println!("warning: {w}");
        }
    }
    Ok(())
}

/// The dataset in `dir`, or, when `dir` is a folder of datasets, the one the result file's
/// name (`METHOD_DATASET-SPLIT.csv`) names.
fn load_dataset(dir: &Path, results: &Path, split: &SplitArgs) -> Result<Dataset> {
    let is_dataset = ["models", "models_eval"]
        .iter()
        .any(|m| dir.join(m).is_dir());
    let dir = if is_dataset {
        dir.to_path_buf()
    } else {
        let file_name = results.file_name().unwrap_or_default().to_string_lossy();
        match results::parse_result_filename(&file_name) {
            Some(name) if dir.join(&name.dataset).is_dir() => dir.join(&name.dataset),
            Some(name) => bail!(
                "{} is not a dataset folder (no models/), and has no folder `{}`, the dataset \
                 {file_name} is named for",
                dir.display(),
                name.dataset
            ),
            None => bail!(
                "{} is not a dataset folder (no models/), and {file_name} is not named \
                 METHOD_DATASET-SPLIT.csv to find the dataset in it",
                dir.display()
            ),
        }
    };
    let choice = SplitChoice {
        split: split.split.clone(),
        split_type: split.split_type.clone(),
        targets_file: split.targets_file.clone(),
    }
    .or(folder_choice(&dir).map_err(anyhow::Error::msg)?);
    // The evaluator's error names the file and what was expected; said once.
    Dataset::load_with(&dir, &choice.options())
        .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", dir.display()))
}

/// Reads and checks a result file; its problems come back naming their lines.
pub(crate) fn load_results(path: &Path) -> Result<evaluator::Results> {
    results::load_results(path).map_err(|e| match e {
        evaluator::Error::Results(problems) => {
            anyhow::anyhow!("{} is not a valid result file:\n{problems}", path.display())
        }
        other => anyhow::Error::new(other),
    })
}

fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

/// A report's warnings on stderr and its scores on stdout, as `eval` and `submit` show them.
pub(crate) fn print_scores(report: &Report) {
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    print!("{}", table(report));
}

/// The scores as a table for the terminal.
pub fn table(r: &Report) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "dataset {}  protocol {}  estimates {} (evaluated {}, ignored {})",
        r.dataset,
        r.protocol.as_str(),
        r.estimates_count,
        r.estimates_evaluated,
        r.estimates_ignored
    );
    match r.protocol {
        ProtocolName::Eccv18 => {
            if let Some(l) = &r.localization {
                let _ = writeln!(
                    s,
                    "VSD recall (tau {} mm, theta {}): {:.4}   [{} of {} targets]",
                    r.parameters.main_tau,
                    r.parameters.main_theta,
                    l.recall,
                    l.tp_count,
                    l.targets_count
                );
                let _ = writeln!(s, "mean object recall {:.4}", l.mean_obj_recall);
                let _ = writeln!(s, "{:>8}  {:>8}", "object", "recall");
                for (o, v) in &l.obj_recalls {
                    let _ = writeln!(s, "{o:>8}  {v:>8.4}");
                }
                let _ = writeln!(s, "{:>8}  {:>8}", "scene", "recall");
                for (o, v) in &l.scene_recalls {
                    let _ = writeln!(s, "{o:>8}  {v:>8.4}");
                }
            }
            if let Some(t) = r.average_time_per_target {
                let _ = writeln!(s, "average time per target: {t:.3} s");
            }
        }
        ProtocolName::Bop19 => {
            let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
            let _ = writeln!(
                s,
                "AR {}   AR_VSD {}   AR_MSSD {}   AR_MSPD {}",
                f(r.bop19_average_recall),
                f(r.bop19_average_recall_vsd),
                f(r.bop19_average_recall_mssd),
                f(r.bop19_average_recall_mspd)
            );
            let _ = writeln!(s, "{:>8}  {:>8}", "object", "AR");
            for (o, v) in &r.obj_average_recalls {
                let _ = writeln!(s, "{o:>8}  {v:>8.4}");
            }
            // bop_toolkit writes -1 when the file gives no times.
            if let Some(t) = r.bop19_average_time_per_image.filter(|t| *t >= 0.0) {
                let _ = writeln!(s, "average time per image: {t:.3} s");
            }
        }
    }
    for (name, ar) in &r.average_recalls {
        // Errors beyond the protocol's own (e.g. ADD) get their average recall listed.
        if !matches!(name.as_str(), "vsd" | "mssd" | "mspd") {
            let _ = writeln!(s, "average recall {name}: {ar:.4}");
        }
    }
    s
}

/// A progress bar on stderr, drawn only when stderr is a terminal.
struct Bar(ProgressBar);

impl Bar {
    fn new() -> Self {
        let bar = ProgressBar::hidden();
        bar.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} estimates  {elapsed} (eta {eta})")
                .expect("a valid template"),
        );
        Bar(bar)
    }

    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

impl Progress for Bar {
    fn start(&self, total: u64) {
        self.0.set_length(total);
        self.0
            .set_draw_target(indicatif::ProgressDrawTarget::stderr());
        self.0.enable_steady_tick(Duration::from_millis(200));
    }

    fn advance(&self, n: u64) {
        self.0.inc(n);
    }
}
