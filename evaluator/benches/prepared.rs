//! What a prepared dataset buys, measured in one run: one thread over whole result files,
//! loading included, computing from the dataset against reading its prepared form; and the
//! preparation's own time and size. The scores of the two paths are checked equal.
//!
//! `cargo bench -p evaluator --bench prepared [-- DATASET RESULTS_DIR]`
//!
//! By default the reference set (tests/fixtures/reference) and its result files; any BOP
//! dataset folder and folder of result files can be named instead. "Loading included" means
//! everything after the dataset is loaded, as the service holds it: parsing the result file,
//! for the prepared path finding the form current as `poseboard eval` does (the content hash
//! from the digests kept beside it) and opening it, and evaluating.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use evaluator::content_hash::content_hash;
use evaluator::prepared::{self, prepare};
use evaluator::protocol::Protocol;
use evaluator::{Dataset, NoProgress, evaluate_prepared, results};

/// bop_toolkit's VSD estimates per second on one core of this machine class (issue 2).
const TOOLKIT_PER_S: f64 = 47.0;

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference");
    let (dataset_dir, results_dir) = match args.as_slice() {
        [d, r] => (PathBuf::from(d), PathBuf::from(r)),
        _ => (fixtures.join("dataset"), fixtures.join("results")),
    };
    let dataset = Dataset::load(&dataset_dir).expect("dataset");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&results_dir)
        .expect("results folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let cache = tempfile::tempdir().expect("temporary folder");
    let cancel = AtomicBool::new(false);

    let start = Instant::now();
    let prep = one.install(|| {
        let hash = content_hash(&dataset).expect("content hash");
        prepare(&dataset, &hash, cache.path(), &NoProgress, &cancel).expect("preparation")
    });
    println!(
        "{}: prepared {} images on one thread in {:.2} s, {:.1} MB",
        dataset.name,
        prep.images,
        start.elapsed().as_secs_f64(),
        prep.bytes as f64 / 1e6
    );

    println!("one thread over whole files, loading included (estimates/s, ratio):");
    let (mut total_plain, mut total_prepared, mut total_estimates) = (0.0, 0.0, 0usize);
    for protocol in [Protocol::eccv18(), Protocol::bop19()] {
        let (mut plain_s, mut prepared_s, mut estimates) = (0.0, 0.0, 0usize);
        for file in &files {
            let run = |prepared: bool| {
                let start = Instant::now();
                let evaluation = one.install(|| {
                    let res = results::load_results(file).expect("result file");
                    let form = prepared.then(|| {
                        prepared::find(&dataset, Some(cache.path()))
                            .expect("current")
                            .expect("prepared")
                    });
                    let e = evaluate_prepared(
                        &dataset,
                        &res,
                        &protocol,
                        form.as_ref(),
                        &NoProgress,
                        &cancel,
                    )
                    .expect("evaluation");
                    if let Some(form) = form {
                        assert!(form.damaged().is_empty(), "{:?}", form.damaged());
                    }
                    e
                });
                (evaluation, start.elapsed().as_secs_f64())
            };
            // Alternated, so that a neighbour's load falls on both alike.
            let (a, ta) = run(false);
            let (b, tb) = run(true);
            let same = a.errors.len() == b.errors.len()
                && a.errors.iter().zip(&b.errors).all(|(x, y)| {
                    x.errors.iter().flatten().map(|v| v.to_bits()).eq(y
                        .errors
                        .iter()
                        .flatten()
                        .map(|v| v.to_bits()))
                })
                && serde_json::to_string(&a.report).ok() == serde_json::to_string(&b.report).ok();
            assert!(same, "{}: scores differ", file.display());
            plain_s += ta;
            prepared_s += tb;
            estimates += a.errors.len();
        }
        println!(
            "  {:<7} {estimates:>6} estimates: from the dataset {:>7.0}/s ({:>3.0}x bop_toolkit), \
             prepared {:>7.0}/s ({:>3.0}x), ratio {:.2}, scores identical",
            protocol.name.as_str(),
            estimates as f64 / plain_s,
            estimates as f64 / plain_s / TOOLKIT_PER_S,
            estimates as f64 / prepared_s,
            estimates as f64 / prepared_s / TOOLKIT_PER_S,
            plain_s / prepared_s
        );
        total_plain += plain_s;
        total_prepared += prepared_s;
        total_estimates += estimates;
    }
    println!(
        "  both    {total_estimates:>6} estimates: from the dataset {:>7.0}/s ({:>3.0}x), \
         prepared {:>7.0}/s ({:>3.0}x), ratio {:.2}",
        total_estimates as f64 / total_plain,
        total_estimates as f64 / total_plain / TOOLKIT_PER_S,
        total_estimates as f64 / total_prepared,
        total_estimates as f64 / total_prepared / TOOLKIT_PER_S,
        total_plain / total_prepared
    );
}
