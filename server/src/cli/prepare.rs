//! `poseboard dataset prepare`, and how `poseboard eval` finds a prepared dataset: the
//! per-dataset work of scoring (decoded depth, ground-truth renders) done once and kept in
//! plain files (see `evaluator::prepared`). Evaluation never needs one: a missing, stale,
//! foreign or damaged prepared form only makes it slower, and says why.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::Args;
use evaluator::content_hash::content_hash_cached;
use evaluator::prepared::{self, Prepared};
use evaluator::{Dataset, Progress};
use indicatif::{ProgressBar, ProgressStyle};

use super::eval::{SplitArgs, dataset_options, worker_pool};

#[derive(Args, Debug)]
pub struct PrepareArgs {
    /// A BOP dataset folder.
    pub dir: PathBuf,
    #[command(flatten)]
    pub split: SplitArgs,
    /// Where to write the prepared form (default: DIR/poseboard_prepared, where `poseboard
    /// eval` looks for it).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (default: every core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Prepares (or checks and repairs) a dataset's prepared form, then prints what it found, the
/// time it took and the size of the folder.
pub fn run(args: PrepareArgs) -> Result<()> {
    let start = Instant::now();
    let options = dataset_options(&args.dir, &args.split)?;
    let dataset = Dataset::load_with(&args.dir, &options)
        .map_err(|e| anyhow::anyhow!("cannot load the dataset in {}: {e}", args.dir.display()))?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| prepared::default_dir(&dataset));
    let pool = worker_pool(args.threads)?;
    let bar = ImagesBar::new();
    // The folder first, so that the first run leaves the dataset's file digests there too:
    // without them the first `eval` after it would read the whole dataset again to hash it.
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let done = pool.install(|| -> Result<_> {
        // The digests cached in the folder by earlier runs spare reading unchanged files.
        let hash = content_hash_cached(&dataset, &out).map_err(anyhow::Error::msg)?;
        prepared::prepare(&dataset, &hash, &out, &bar, &AtomicBool::new(false))
            .context("preparation failed")
    })?;
    bar.0.finish_and_clear();
    println!(
        "{}: {} images, {:.1} MB in {}, {:.1} s: {}",
        dataset.name,
        done.images,
        done.bytes as f64 / 1e6,
        out.display(),
        start.elapsed().as_secs_f64(),
        done.outcome
    );
    Ok(())
}

/// The prepared form `poseboard eval` uses: `--prepared DIR`, else the dataset's default folder
/// when there is one; none with `--unprepared`. One that cannot be used is named on stderr.
pub fn find(dataset: &Dataset, named: Option<&Path>, unprepared: bool) -> Option<Prepared> {
    if unprepared {
        return None;
    }
    if let Some(dir) = named.filter(|d| !d.exists()) {
        eprintln!(
            "{}: no such folder, evaluating without a prepared form",
            dir.display()
        );
        return None;
    }
    prepared::find(dataset, named).unwrap_or_else(|why| {
        eprintln!(
            "{why}; `poseboard dataset prepare {}` rebuilds it",
            dataset.root.display()
        );
        None
    })
}

/// After an evaluation, names the prepared files it had to refuse.
pub fn report_damaged(prepared: &Prepared, dataset: &Dataset) {
    let damaged = prepared.damaged();
    for problem in &damaged {
        eprintln!("prepared file refused, its image computed from the dataset: {problem}");
    }
    if !damaged.is_empty() {
        eprintln!(
            "`poseboard dataset prepare {}` rebuilds the refused files",
            dataset.root.display()
        );
    }
}

/// A progress bar over images on stderr, drawn only when stderr is a terminal.
struct ImagesBar(ProgressBar);

impl ImagesBar {
    fn new() -> Self {
        let bar = ProgressBar::hidden();
        bar.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} images  {elapsed} (eta {eta})")
                .expect("a valid template"),
        );
        ImagesBar(bar)
    }
}

impl Progress for ImagesBar {
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
