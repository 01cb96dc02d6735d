//! `poseboard eval` and `poseboard check-results`: the evaluator on the command line, for a
//! researcher with a dataset and a result file on disk.
//!
//! The 2D tasks of BOP'22 (`bop22-det`, `bop22-seg`) go to `evaluator::coco`, and BOP'24's 6D
//! detection (`bop24`) to `evaluator::detection`, through their own branches ([`EvalProtocol`])
//! rather than as `ProtocolName` variants: their files, parameters and report differ from the
//! 6D localization protocols', and the server's boards, queue and pages match on
//! `ProtocolName` throughout.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Args;
use evaluator::coco::{self, BboxType, CocoGt, CocoReport, CocoTask};
use evaluator::dataset::DatasetOptions;
use evaluator::detection::{self, DetectionReport};
use evaluator::protocol::{ErrorKind, Overrides, ProtocolName};
use evaluator::visibility::VisibMode;
use evaluator::{Dataset, Progress, Protocol, Report, evaluate_prepared, results};
use indicatif::{ProgressBar, ProgressStyle};

use crate::datasets::config::{BOP24_TARGETS, SplitChoice, folder_choice};
use crate::preflight::Preflight;
use crate::service::submissions::Protocols;
use crate::wording::count;

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// A BOP dataset folder (models/ or models_eval/, test/ or test_TYPE/,
    /// test_targets_bop19.json), or a folder of datasets: then the one the result file is
    /// named for (`METHOD_DATASET-test.csv`).
    #[arg(long)]
    pub dataset: PathBuf,
    #[command(flatten)]
    pub split: SplitArgs,
    /// A result file: BOP'19 CSV for the 6D protocols, BOP'22 JSON (`METHOD_DATASET-test.json`)
    /// for bop22-det and bop22-seg.
    #[arg(long)]
    pub results: PathBuf,
    /// eccv18, bop19 (6D localization), bop24 (6D detection), bop22-det (2D detection, boxes)
    /// or bop22-seg (2D segmentation, masks).
    #[arg(long, default_value = "bop19")]
    pub protocol: EvalProtocol,
    /// bop24: estimates kept per image, the best-scored over all objects (default: the
    /// toolkit's, 200 for xyzibd and 100 for the other datasets).
    #[arg(long)]
    pub max_estimates_per_image: Option<usize>,
    /// bop22-det: compare with the boxes around the full silhouette (amodal, the default) or
    /// around the visible part (modal, `scene_gt_coco_modal.json`).
    #[arg(long)]
    pub bbox_type: Option<BboxType>,
    /// Write the full report (every score, the parameters used) as JSON to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write every evaluated estimate's errors against each ground-truth instance as JSON.
    #[arg(long)]
    pub errors_out: Option<PathBuf>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// The dataset's prepared form (`poseboard dataset prepare`); default: the dataset's
    /// `poseboard_prepared` folder when there is one. Scores are the same without it.
    #[arg(long, conflicts_with = "unprepared")]
    pub prepared: Option<PathBuf>,
    /// Compute everything from the dataset, even when a prepared form is there.
    #[arg(long)]
    pub unprepared: bool,
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
    /// Whether any 6D localization option is set (the extra errors included).
    fn any(&self) -> bool {
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

/// A protocol name on the command line: a 6D protocol or a BOP'22 2D task.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EvalProtocol {
    Pose(ProtocolName),
    /// BOP'24 6D detection.
    Bop24,
    Detection,
    Segmentation,
}

impl std::str::FromStr for EvalProtocol {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "bop22-det" => Ok(EvalProtocol::Detection),
            "bop22-seg" => Ok(EvalProtocol::Segmentation),
            detection::PROTOCOL => Ok(EvalProtocol::Bop24),
            other => other.parse().map(EvalProtocol::Pose).map_err(|_| {
                format!("unknown protocol `{other}` (eccv18, bop19, bop24, bop22-det or bop22-seg)")
            }),
        }
    }
}

/// A protocol resolved with its options.
enum Resolved {
    Pose(ProtocolName),
    Bop24,
    Coco(CocoTask),
}

impl EvalProtocol {
    fn resolve(self, bbox_type: Option<BboxType>) -> Result<Resolved> {
        match (self, bbox_type) {
            (EvalProtocol::Detection, b) => Ok(Resolved::Coco(CocoTask::Detection(
                b.unwrap_or(BboxType::Amodal),
            ))),
            (_, Some(_)) => bail!("--bbox-type is for --protocol bop22-det only"),
            (EvalProtocol::Segmentation, None) => Ok(Resolved::Coco(CocoTask::Segmentation)),
            (EvalProtocol::Bop24, None) => Ok(Resolved::Bop24),
            (EvalProtocol::Pose(name), None) => Ok(Resolved::Pose(name)),
        }
    }
}

pub fn run_eval(args: EvalArgs) -> Result<()> {
    let name = match args.protocol.resolve(args.bbox_type)? {
        Resolved::Pose(name) => name,
        Resolved::Bop24 => return run_bop24_eval(&args),
        Resolved::Coco(task) => return run_coco_eval(&args, task),
    };
    if args.max_estimates_per_image.is_some() {
        bail!("--max-estimates-per-image is for --protocol bop24 only");
    }
    if args
        .results
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        bail!(
            "{} is a BOP'22 JSON file: score it with --protocol bop22-det or bop22-seg ({} reads \
             BOP'19 CSV files)",
            args.results.display(),
            name.as_str()
        );
    }
    let mut protocol = Protocol::named(name);
    args.overrides.apply(&mut protocol)?;
    let dataset = load_dataset(&args.dataset, &args.results, &args.split)?;
    let results = load_results(&args.results)?;

    let pool = worker_pool(args.threads)?;
    let prepared =
        pool.install(|| super::prepare::find(&dataset, args.prepared.as_deref(), args.unprepared));
    let bar = Bar::new();
    let evaluation = pool
        .install(|| {
            evaluate_prepared(
                &dataset,
                &results,
                &protocol,
                prepared.as_ref(),
                &bar,
                &AtomicBool::new(false),
            )
        })
        .context("evaluation failed")?;
    bar.finish();
    if let Some(prepared) = &prepared {
        super::prepare::report_damaged(prepared, &dataset);
    }

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

/// `eval` for BOP'24 6D detection: average precision over the target images of
/// `test_targets_bop24.json` (or `--targets-file`).
fn run_bop24_eval(args: &EvalArgs) -> Result<()> {
    if args.overrides.any() || args.errors_out.is_some() {
        bail!(
            "bop24 has fixed errors and thresholds: the options of the localization protocols \
             (--tau, --n-top, --errors-out, ...) do not apply"
        );
    }
    if args
        .results
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        bail!(
            "{} is a BOP'22 JSON file: bop24 reads BOP'19 CSV result files",
            args.results.display()
        );
    }
    let dataset = load_bop24_dataset(&args.dataset, &args.results, &args.split)?;
    let results = load_results(&args.results)?;
    let cap = args
        .max_estimates_per_image
        .unwrap_or_else(|| detection::default_max_estimates_per_image(&dataset.name));
    let pool = worker_pool(args.threads)?;
    let bar = Bar::new();
    let report = pool
        .install(|| detection::evaluate(&dataset, &results, cap, &bar, &AtomicBool::new(false)))
        .context("evaluation failed")?;
    bar.finish();
    print!("{}", bop24_table(&report));
    if let Some(out) = &args.out {
        write_json(out, &report)?;
    }
    Ok(())
}

/// The dataset for bop24: its targets file is `test_targets_bop24.json` unless
/// `--targets-file` names another (a folder's `poseboard-dataset.json` chooses the
/// localization targets, not these).
fn load_bop24_dataset(dir: &Path, results: &Path, split: &SplitArgs) -> Result<Dataset> {
    let dir = dataset_dir(dir, results)?;
    let mut options = dataset_options(&dir, split)?;
    options.targets_file = split
        .targets_file
        .clone()
        .unwrap_or_else(|| BOP24_TARGETS.to_string());
    Dataset::load_with(&dir, &options)
        .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", dir.display()))
}

/// The bop24 scores with the toolkit's names, and the per-object AP, for the terminal.
pub fn bop24_table(r: &DetectionReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "dataset {}  protocol {}  estimates {} (evaluated {}, ignored {}, beyond the cap of {} \
         per image {})",
        r.dataset,
        r.protocol,
        r.estimates_count,
        r.estimates_evaluated,
        r.estimates_ignored,
        r.parameters.max_estimates_per_image,
        r.estimates_beyond_cap
    );
    let _ = writeln!(
        s,
        "target images {}  instances {} ({} at least {} % visible)",
        r.target_images,
        r.instances,
        r.instances_counted,
        r.parameters.visib_gt_min * 100.0
    );
    for (name, v) in [
        ("bop24_mAP", r.bop24_map),
        ("bop24_mAP_mssd", r.bop24_map_mssd),
        ("bop24_mAP_mspd", r.bop24_map_mspd),
        ("bop24_mAP_mssd_mm", r.bop24_map_mssd_mm),
        ("bop25_mAP", r.bop25_map),
        ("bop25_mAP_mm", r.bop25_map_mm),
    ] {
        let _ = writeln!(s, "{name:>18}  {v:.4}");
    }
    let _ = writeln!(
        s,
        "{:>8}  {:>8}  {:>8}  {:>8}",
        "object", "mssd", "mssd_mm", "mspd"
    );
    if let Some(first) = r.errors.first() {
        for (i, o) in first.objects.iter().enumerate() {
            let ap = |e: usize| {
                r.errors
                    .get(e)
                    .and_then(|x| x.objects.get(i))
                    .map_or(f64::NAN, |x| x.ap)
            };
            let _ = writeln!(
                s,
                "{:>8}  {:>8.4}  {:>8.4}  {:>8.4}",
                o.obj_id,
                ap(0),
                ap(1),
                ap(2)
            );
        }
    }
    if r.bop24_average_time_per_image >= 0.0 {
        let _ = writeln!(
            s,
            "average time per image: {:.3} s",
            r.bop24_average_time_per_image
        );
    }
    s
}

/// `eval` for the BOP'22 2D tasks: COCOeval on the dataset's `scene_gt_coco*.json`.
fn run_coco_eval(args: &EvalArgs, task: CocoTask) -> Result<()> {
    let o = &args.overrides;
    if args.max_estimates_per_image.is_some() {
        bail!("--max-estimates-per-image is for --protocol bop24 only");
    }
    if o.any() || args.errors_out.is_some() {
        bail!(
            "{} has no pose errors: the 6D options (--tau, --n-top, --errors-out, ...) do not apply",
            task.name()
        );
    }
    let dir = dataset_dir(&args.dataset, &args.results)?;
    let gt = load_coco_gt(&dir, &args.split, task)?;
    let results = load_coco_results(&args.results)?;
    let pool = worker_pool(args.threads)?;
    let report = pool
        .install(|| coco::evaluate(&gt, &results, task))
        .map_err(|e| match e {
            evaluator::Error::CocoResults(problems) => anyhow::anyhow!(
                "{} cannot be scored for {}:\n{problems}",
                args.results.display(),
                task.name()
            ),
            other => anyhow::Error::new(other).context("evaluation failed"),
        })?;
    print!("{}", coco_table(&report));
    if let Some(out) = &args.out {
        write_json(out, &report)?;
    }
    Ok(())
}

pub(crate) fn worker_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        pool = pool.num_threads(n);
    }
    pool.build().context("cannot start the worker threads")
}

/// The COCO numbers as the toolkit names them, for the terminal.
pub fn coco_table(r: &CocoReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "dataset {}  protocol {} ({}, {} boxes)  entries {} (evaluated {}, ignored {})",
        r.dataset,
        r.protocol,
        r.ann_type.as_str(),
        r.bbox_type.as_str(),
        r.entries_count,
        r.entries_evaluated,
        r.entries_ignored
    );
    let _ = writeln!(
        s,
        "target images {} ({} without an entry)",
        r.target_images, r.target_images_without_entry
    );
    for (name, v) in r.stats() {
        let _ = writeln!(s, "{name:>10}  {v:.4}");
    }
    if r.average_time_per_image >= 0.0 {
        let _ = writeln!(
            s,
            "average time per image: {:.3} s",
            r.average_time_per_image
        );
    }
    s
}

#[derive(Args, Debug)]
pub struct CheckArgs {
    /// The result file to validate: BOP'19 CSV, or BOP'22 JSON (detection, segmentation).
    pub results: PathBuf,
    /// Check that the file can be scored for this protocol (a JSON file: bop22-det needs a
    /// box in every entry, bop22-seg a mask); a `.json` file is read as BOP'22 results.
    #[arg(long)]
    pub protocol: Option<EvalProtocol>,
    /// With --dataset and bop22-det: the ground-truth boxes to report coverage against.
    #[arg(long)]
    pub bbox_type: Option<BboxType>,
    /// With --dataset and bop24: estimates kept per image (default: the toolkit's).
    #[arg(long)]
    pub max_estimates_per_image: Option<usize>,
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

/// Validates a result file and, with `--dataset`, pre-flights it as an upload would be. Exits
/// 0 only for a valid file without red flags: a red flag (metres, most targets without an
/// estimate, objects the dataset lacks) would hold publication back on the service, so a
/// script checking files before upload stops there too.
pub fn run_check(args: CheckArgs) -> Result<()> {
    let resolved = args
        .protocol
        .map(|p| p.resolve(args.bbox_type))
        .transpose()?;
    let is_json = args
        .results
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if args.max_estimates_per_image.is_some() && !matches!(resolved, Some(Resolved::Bop24)) {
        bail!("--max-estimates-per-image is for --protocol bop24 only");
    }
    match resolved {
        Some(Resolved::Coco(task)) => return run_coco_check(&args, Some(task)),
        Some(Resolved::Bop24) if is_json => bail!(
            "{} is a JSON file: bop24 reads BOP'19 CSV result files",
            args.results.display()
        ),
        None if is_json => return run_coco_check(&args, None),
        Some(Resolved::Pose(_)) if is_json => bail!(
            "{} is a JSON file: the 6D protocols read BOP'19 CSV result files",
            args.results.display()
        ),
        _ if args.bbox_type.is_some() => {
            bail!("--bbox-type is for --protocol bop22-det only")
        }
        _ => {}
    }
    let results = load_results(&args.results)?;
    if matches!(resolved, Some(Resolved::Bop24)) {
        return run_bop24_check(&args, &results);
    }
    let images = results.image_times.len().max(
        results
            .estimates
            .iter()
            .map(|e| (e.scene_id, e.im_id))
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
    );
    println!(
        "{}: {} for {}: a valid result file",
        args.results.display(),
        count(results.estimates.len(), "estimate", "estimates"),
        count(images, "image", "images"),
    );
    let Some(dir) = &args.dataset else {
        println!("no --dataset given: coverage and red flags not checked");
        return Ok(());
    };
    let dataset = load_dataset(dir, &args.results, &args.split)?;
    // Localization counts targets per object; an image list would make every object of the
    // ground truth a target and report misses the detection task does not have.
    if dataset.targets_form == evaluator::dataset::TargetsForm::Images {
        bail!(
            "{} lists images (BOP'24 detection targets): check with --protocol bop24, or give \
             targets as in test_targets_bop19.json",
            dataset.targets_path.display()
        );
    }
    // The upload pre-flight check, so the command line and the service say the same.
    let asked: Vec<ProtocolName> = match resolved {
        Some(Resolved::Pose(name)) => vec![name],
        _ => Vec::new(),
    };
    let protocols = Protocols::asked(&asked);
    let p = Preflight::of(&dataset, &results, &protocols.scored, &protocols.warned);
    println!(
        "{}: {}, {} without an estimate; {} not for a target and would be ignored",
        dataset.name,
        count(p.targets, "target", "targets"),
        p.targets_without_estimate,
        count(p.estimates_not_for_targets, "estimate is", "estimates are"),
    );
    for w in &p.warnings {
        println!("warning: {w}");
    }
    for f in &p.red_flags {
        println!("red flag: {f}");
    }
    match p.red_flags.len() {
        0 => {
            println!("OK: no red flag");
            Ok(())
        }
        n => bail!(
            "{}: uploaded, its publication would be held until you confirm it",
            count(n, "red flag", "red flags")
        ),
    }
}

/// `check-results --protocol bop24`: the file is valid (times included: one image, one time);
/// with a dataset, what of its target images the file covers and which estimates would not
/// count. Estimates of absent objects are expected in detection, so nothing is a red flag.
fn run_bop24_check(args: &CheckArgs, results: &evaluator::Results) -> Result<()> {
    let images: std::collections::BTreeSet<(u32, u32)> = results
        .estimates
        .iter()
        .map(|e| (e.scene_id, e.im_id))
        .collect();
    println!(
        "{}: {} for {}: a valid result file for bop24",
        args.results.display(),
        count(results.estimates.len(), "estimate", "estimates"),
        count(images.len(), "image", "images"),
    );
    let Some(dir) = &args.dataset else {
        println!("no --dataset given: coverage not checked");
        return Ok(());
    };
    let dataset = load_bop24_dataset(dir, &args.results, &args.split)?;
    let cap = args
        .max_estimates_per_image
        .unwrap_or_else(|| detection::default_max_estimates_per_image(&dataset.name));
    let c = detection::coverage(&dataset, results, cap);
    println!(
        "{}: {}, {} without an estimate of an object it holds",
        dataset.name,
        count(c.target_images, "target image", "target images"),
        c.images_without_estimate,
    );
    println!(
        "{} beyond the cap of {cap} per image; {} of objects absent from their image or of \
         images that are not targets (neither true nor false positives); {} scored",
        count(c.estimates_beyond_cap, "estimate", "estimates"),
        c.estimates_ignored,
        c.estimates_evaluated,
    );
    Ok(())
}

/// `check-results` for a BOP'22 JSON file: every problem named by entry and key, the tasks the
/// file can be scored for, and with a dataset, its coverage of the target images.
fn run_coco_check(args: &CheckArgs, task: Option<CocoTask>) -> Result<()> {
    let results = load_coco_results(&args.results)?;
    let tasks: Vec<CocoTask> = match task {
        Some(t) => vec![t],
        None => vec![
            CocoTask::Detection(BboxType::Amodal),
            CocoTask::Segmentation,
        ],
    };
    let mut usable = Vec::new();
    for t in &tasks {
        match results.require(*t) {
            Ok(()) => usable.push(t.name()),
            Err(problems) if task.is_some() => bail!(
                "{} cannot be scored for {}:\n{problems}",
                args.results.display(),
                t.name()
            ),
            Err(_) => {}
        }
    }
    if usable.is_empty() {
        bail!(
            "{}: no task can score this file: bop22-det needs a `bbox` in every entry, \
             bop22-seg a `segmentation` in every entry",
            args.results.display()
        );
    }
    println!(
        "{}: {} entries for {} images, OK for {}",
        args.results.display(),
        results.entries.len(),
        results.image_count(),
        usable.join(" and ")
    );
    if let Some(dir) = &args.dataset {
        let dir = dataset_dir(dir, &args.results)?;
        let task = task.unwrap_or(CocoTask::Detection(BboxType::Amodal));
        let gt = CocoGt::load(
            &dir,
            &dataset_options(&dir, &args.split)?,
            task.bbox_type(),
            false,
        )
        .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", dir.display()))?;
        let mut covered = std::collections::BTreeSet::new();
        let mut not_target = 0;
        for e in &results.entries {
            match gt.image_index(e.scene_id, e.image_id) {
                Some(i) => {
                    covered.insert(i);
                }
                None => not_target += 1,
            }
        }
        println!(
            "{}: {} target images, {} without an entry; {} entries are not for a target image \
             and would be ignored",
            gt.name,
            gt.images.len(),
            gt.images.len() - covered.len(),
            not_target
        );
    }
    Ok(())
}

/// The dataset in `dir`, or, when `dir` is a folder of datasets, the one the result file's
/// name (`METHOD_DATASET-SPLIT.csv` or `.json`) names.
fn dataset_dir(dir: &Path, results: &Path) -> Result<PathBuf> {
    let is_dataset = ["models", "models_eval"]
        .iter()
        .any(|m| dir.join(m).is_dir());
    if is_dataset {
        return Ok(dir.to_path_buf());
    }
    let file_name = results.file_name().unwrap_or_default().to_string_lossy();
    match results::parse_result_filename(&file_name) {
        Some(name) if dir.join(&name.dataset).is_dir() => Ok(dir.join(&name.dataset)),
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
}

/// The split and targets file: the flags over the folder's `poseboard-dataset.json` and the
/// defaults.
pub(crate) fn dataset_options(dir: &Path, split: &SplitArgs) -> Result<DatasetOptions> {
    Ok(SplitChoice {
        split: split.split.clone(),
        split_type: split.split_type.clone(),
        targets_file: split.targets_file.clone(),
    }
    .or(folder_choice(dir).map_err(anyhow::Error::msg)?)
    .options())
}

fn load_dataset(dir: &Path, results: &Path, split: &SplitArgs) -> Result<Dataset> {
    let dir = dataset_dir(dir, results)?;
    let options = dataset_options(&dir, split)?;
    // The evaluator's error names the file and what was expected; said once.
    Dataset::load_with(&dir, &options)
        .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", dir.display()))
}

fn load_coco_gt(dir: &Path, split: &SplitArgs, task: CocoTask) -> Result<CocoGt> {
    let options = dataset_options(dir, split)?;
    CocoGt::load(
        dir,
        &options,
        task.bbox_type(),
        task == CocoTask::Segmentation,
    )
    .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", dir.display()))
}

fn load_coco_results(path: &Path) -> Result<coco::CocoResults> {
    coco::load_coco_results(path).map_err(|e| match e {
        evaluator::Error::CocoResults(problems) => {
            anyhow::anyhow!("{} is not a valid result file:\n{problems}", path.display())
        }
        other => anyhow::Error::new(other),
    })
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
    print_scores_as(report, Scale::Fraction);
}

/// [`print_scores`] with the scores on `scale`.
pub(crate) fn print_scores_as(report: &Report, scale: Scale) {
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    print!("{}", table_as(report, scale));
}

/// How a score is written: as bop_toolkit writes it (a fraction), or as the site shows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// 0.4531: what `poseboard eval` prints, to compare with bop_toolkit's output.
    Fraction,
    /// 45.3: the site's scores in %, one decimal (`poseboard submit`).
    Percent,
}

impl Scale {
    fn write(self, v: f64) -> String {
        match self {
            Scale::Fraction => format!("{v:.4}"),
            Scale::Percent => format!("{:.1}", v * 100.0),
        }
    }
}

/// The scores as a table for the terminal.
pub fn table(r: &Report) -> String {
    table_as(r, Scale::Fraction)
}

/// [`table`] with the scores on `scale`.
pub fn table_as(r: &Report, scale: Scale) -> String {
    use std::fmt::Write;
    let f = |v: f64| scale.write(v);
    let unit = match scale {
        Scale::Fraction => "",
        Scale::Percent => "  (scores in %)",
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "dataset {}  protocol {}  estimates {} (evaluated {}, ignored {}){unit}",
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
                    "VSD recall (tau {} mm, theta {}): {}   [{} of {} targets]",
                    r.parameters.main_tau,
                    r.parameters.main_theta,
                    f(l.recall),
                    l.tp_count,
                    l.targets_count
                );
                let _ = writeln!(s, "mean object recall {}", f(l.mean_obj_recall));
                let _ = writeln!(s, "{:>8}  {:>8}", "object", "recall");
                for (o, v) in &l.obj_recalls {
                    let _ = writeln!(s, "{o:>8}  {:>8}", f(*v));
                }
                let _ = writeln!(s, "{:>8}  {:>8}", "scene", "recall");
                for (o, v) in &l.scene_recalls {
                    let _ = writeln!(s, "{o:>8}  {:>8}", f(*v));
                }
            }
            if let Some(t) = r.average_time_per_target {
                let _ = writeln!(s, "average time per target: {t:.3} s");
            }
        }
        ProtocolName::Bop19 => {
            let opt = |v: Option<f64>| v.map_or("-".to_string(), f);
            let _ = writeln!(
                s,
                "AR {}   AR_VSD {}   AR_MSSD {}   AR_MSPD {}",
                opt(r.bop19_average_recall),
                opt(r.bop19_average_recall_vsd),
                opt(r.bop19_average_recall_mssd),
                opt(r.bop19_average_recall_mspd)
            );
            let _ = writeln!(s, "{:>8}  {:>8}", "object", "AR");
            for (o, v) in &r.obj_average_recalls {
                let _ = writeln!(s, "{o:>8}  {:>8}", f(*v));
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
            let _ = writeln!(s, "average recall {name}: {}", f(*ar));
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
