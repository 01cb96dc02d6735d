//! Reproduces the BOP'24 6D detection scores bop_toolkit computed on the reference dataset
//! with the targets and result files of `tests/fixtures/bop24` (made by its `generate.py`; the
//! toolkit's commit is in every expected file): every key of `scores_bop24.json` and every
//! per-object AP at every threshold to 1e-9, and the file with two times for one image refused.
//! The same on the reference scenes laid out as the BOP-Industrial datasets IPD and XYZ-IBD
//! (`datasets/ipd`, `datasets/xyzibd`: the evaluated sensor's files beside another sensor's,
//! MSPD normalised by the sensor's published width, XYZ-IBD's cap of 200 estimates per image),
//! scored by the toolkit with its own parameters for those datasets. The verdicts per estimate
//! (`detection::verdicts`, what the service's bop24 pages list) add up to those scores.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use evaluator::dataset::{DatasetOptions, TargetsForm};
use evaluator::detection::{self, DetectionError, DetectionReport};
use evaluator::{Dataset, NoProgress, bootstrap, results};
use serde_json::Value;

const CASES: [&str; 5] = ["gtexact", "noisy", "extra", "ties", "capped"];
/// The datasets the toolkit scored: synthA in the classic layout, then in two of BOP-Industrial.
const DATASETS: [&str; 3] = ["synthA", "ipd", "xyzibd"];
const TOLERANCE: f64 = 1e-9;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn dataset(name: &str) -> &'static Dataset {
    static DS: [OnceLock<Dataset>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let at = DATASETS
        .iter()
        .position(|d| *d == name)
        .expect("a fixture dataset");
    DS[at].get_or_init(|| {
        let (root, targets) = if name == "synthA" {
            (
                fixtures().join("reference/dataset"),
                fixtures().join("bop24/test_targets_bop24.json"),
            )
        } else {
            let root = fixtures().join("bop24/datasets").join(name);
            let targets = root.join("test_targets_bop24.json");
            (root, targets)
        };
        let options = DatasetOptions {
            targets_file: targets.to_string_lossy().into_owned(),
            ..DatasetOptions::default()
        };
        Dataset::load_with(&root, &options)
            .unwrap_or_else(|e| panic!("{name} loads with the bop24 targets: {e}"))
    })
}

fn expected(name: &str, case: &str) -> Value {
    let path = match name {
        "synthA" => fixtures().join(format!("bop24/expected/{case}.json")),
        _ => fixtures().join(format!("bop24/expected/{name}/{case}.json")),
    };
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn result_file(name: &str, case: &str) -> PathBuf {
    fixtures().join(format!("bop24/results/{case}_{name}-test.csv"))
}

fn score(name: &str, case: &str) -> DetectionReport {
    let results = results::load_results(&result_file(name, case)).expect("the result file parses");
    detection::evaluate(
        dataset(name),
        &results,
        detection::default_max_estimates_per_image(name),
        &NoProgress,
        &AtomicBool::new(false),
    )
    .unwrap()
}

fn close(name: &str, ours: f64, theirs: f64) {
    assert!(
        (ours - theirs).abs() <= TOLERANCE,
        "{name}: poseboard {ours}, bop_toolkit {theirs}"
    );
}

#[test]
fn every_key_equals_the_toolkits() {
    for (name, case) in DATASETS
        .into_iter()
        .flat_map(|d| CASES.map(move |c| (d, c)))
    {
        assert_eq!(dataset(name).targets_form, TargetsForm::Images);
        let label = format!("{name} {case}");
        let report = score(name, case);
        let want = expected(name, case);
        let json = serde_json::to_value(&report).unwrap();
        for key in [
            "bop24_mAP",
            "bop24_mAP_mssd",
            "bop24_mAP_mssd_mm",
            "bop24_mAP_mspd",
            "bop25_mAP",
            "bop25_mAP_mm",
            "bop24_average_time_per_image",
        ] {
            close(
                &format!("{label} {key}"),
                json[key].as_f64().unwrap(),
                want[key].as_f64().unwrap(),
            );
        }
        for scores in &report.errors {
            let error = scores.error.name();
            let table = &want["per_threshold"][error];
            for (t, &threshold) in scores.thresholds.iter().enumerate() {
                let sign = format!("th={threshold:.3}_min-visib=0.100");
                let theirs = table[&sign].as_object().unwrap();
                let with_instances: Vec<&String> = theirs
                    .keys()
                    .filter(|o| want["num_targets_per_object"][o.as_str()].as_u64() > Some(0))
                    .collect();
                assert_eq!(
                    scores.objects.len(),
                    with_instances.len(),
                    "{label} {error}"
                );
                for o in &scores.objects {
                    close(
                        &format!("{label} {error} {sign} object {}", o.obj_id),
                        o.ap_per_threshold[t],
                        theirs[&o.obj_id.to_string()].as_f64().unwrap(),
                    );
                    assert_eq!(
                        o.instances as u64,
                        want["num_targets_per_object"][o.obj_id.to_string()]
                            .as_u64()
                            .unwrap()
                    );
                }
            }
            // The curve's mean is the mAP: both come from the same interpolated precisions.
            let curve = &scores.precision_recall;
            close(
                &format!("{label} {error} curve"),
                curve.iter().sum::<f64>() / curve.len() as f64,
                scores.map,
            );
        }
    }
}

#[test]
fn what_the_cases_exercise_happens() {
    for name in DATASETS {
        let capped = score(name, "capped");
        assert!(capped.estimates_beyond_cap > 0, "{name}: {capped:?}");
        let extra = score(name, "extra");
        let noisy = score(name, "noisy");
        assert!(extra.estimates_ignored > 0, "{name}");
        assert_eq!(
            extra.estimates_evaluated, noisy.estimates_evaluated,
            "{name}"
        );
        assert_eq!(score(name, "ties").bop24_average_time_per_image, -1.0);
        // The instances under 10 % visible are not counted.
        assert!(noisy.instances_counted < noisy.instances, "{name}");
        assert_eq!(score(name, "gtexact").bop24_map, 1.0, "{name}");
    }
    // The layouts read the evaluated sensor's files and its published width.
    assert_eq!(dataset("ipd").image_width(1), 2064);
    assert_eq!(dataset("xyzibd").image_width(2), 1440);
    assert_eq!(detection::default_max_estimates_per_image("xyzibd"), 200);
}

/// Per object, at every error and threshold, the true and false positives the verdicts give,
/// ranked over the images as the toolkit ranks them (images as listed, then the order within
/// each image, a stable sort by decreasing score), make the per-object AP of the report to the
/// bit, against the counted instances the verdicts give; the recall at the end of each ranking
/// is the true positives over those instances. Every kept estimate of a present object is
/// matched or not, and the rest are left out as the report counts them.
#[test]
fn the_verdicts_add_up_to_the_scores() {
    use detection::ap;
    use detection::verdicts::{Criterion, Verdict, inspect};
    for (name, case) in DATASETS
        .into_iter()
        .flat_map(|d| CASES.map(move |c| (d, c)))
    {
        let label = format!("{name} {case}");
        let ds = dataset(name);
        let results = results::load_results(&result_file(name, case)).unwrap();
        let cap = detection::default_max_estimates_per_image(name);
        let report = score(name, case);
        let inspection = inspect(ds, &results, cap, None, &AtomicBool::new(false)).unwrap();
        for scores in &report.errors {
            for (t, &threshold) in scores.thresholds.iter().enumerate() {
                let criterion =
                    Criterion::choose(Some(scores.error.name()), Some(threshold)).unwrap();
                let images = inspection.verdicts(ds, &criterion);
                assert_eq!(images.len(), report.target_images, "{label}");
                let of = |v: Verdict| {
                    images
                        .iter()
                        .flat_map(|i| &i.estimates)
                        .filter(|e| e.verdict == v)
                        .count()
                };
                assert_eq!(
                    of(Verdict::TruePositive) + of(Verdict::FalsePositive) + of(Verdict::Ignored),
                    report.estimates_evaluated,
                    "{label}"
                );
                let instances: usize = images.iter().map(|i| i.instances.len()).sum();
                assert_eq!(instances, report.instances, "{label}");
                assert!(
                    of(Verdict::BeyondCap) <= report.estimates_beyond_cap,
                    "{label}"
                );
                assert!(
                    of(Verdict::ObjectAbsent) <= report.estimates_ignored,
                    "{label}"
                );
                for o in &scores.objects {
                    let counted = images
                        .iter()
                        .flat_map(|i| &i.instances)
                        .filter(|i| i.obj_id == o.obj_id && i.counted)
                        .count();
                    assert_eq!(counted, o.instances, "{label} object {}", o.obj_id);
                    let mut ranked: Vec<(f64, bool)> = images
                        .iter()
                        .flat_map(|i| &i.estimates)
                        .filter(|e| e.obj_id == o.obj_id)
                        .filter(|e| {
                            matches!(e.verdict, Verdict::TruePositive | Verdict::FalsePositive)
                        })
                        .map(|e| (e.score, e.verdict == Verdict::TruePositive))
                        .collect();
                    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
                    let hits: Vec<bool> = ranked.iter().map(|r| r.1).collect();
                    let curve = ap::interpolated_precision(&hits, counted);
                    assert_eq!(
                        ap::average_precision(&curve),
                        o.ap_per_threshold[t],
                        "{label} {} {threshold} object {}",
                        scores.error.name(),
                        o.obj_id
                    );
                    // The curve reaches the recall of the true positives and no further.
                    let found = hits.iter().filter(|&&h| h).count();
                    let last = (0..ap::RECALL_POINTS).rev().find(|&p| curve[p] > 0.0);
                    let recall = found as f64 / counted as f64;
                    match last {
                        Some(p) => assert!(
                            p as f64 / 100.0 <= recall + 1e-12
                                && (p + 1 == ap::RECALL_POINTS
                                    || (p + 1) as f64 / 100.0 > recall - 1e-12),
                            "{label} object {}: point {p}, recall {recall}",
                            o.obj_id
                        ),
                        None => assert_eq!(found, 0, "{label}"),
                    }
                }
                // One image inspected alone gives what it gives among all.
                if t == 5 {
                    let first = &images[0];
                    let alone = inspect(
                        ds,
                        &results,
                        cap,
                        Some((first.scene_id, first.im_id)),
                        &AtomicBool::new(false),
                    )
                    .unwrap()
                    .verdicts(ds, &criterion);
                    assert_eq!(alone, std::slice::from_ref(first), "{label}");
                }
            }
        }
        // Every estimate of a target image is listed once.
        let listed: usize = inspection
            .verdicts(ds, &Criterion::choose(None, None).unwrap())
            .iter()
            .map(|i| i.estimates.len())
            .sum();
        let on_targets = results
            .estimates
            .iter()
            .filter(|e| {
                ds.targets
                    .iter()
                    .any(|t| (t.scene_id, t.im_id) == (e.scene_id, e.im_id))
            })
            .count();
        assert_eq!(listed, on_targets, "{label}");
    }
    // The capped file leaves estimates beyond the cap in a target image, the extra one
    // estimates of absent objects.
    let criterion = Criterion::choose(None, None).unwrap();
    for (case, verdict) in [
        ("capped", Verdict::BeyondCap),
        ("extra", Verdict::ObjectAbsent),
    ] {
        let results = results::load_results(&result_file("synthA", case)).unwrap();
        let images = inspect(
            dataset("synthA"),
            &results,
            100,
            None,
            &AtomicBool::new(false),
        )
        .unwrap()
        .verdicts(dataset("synthA"), &criterion);
        assert!(
            images
                .iter()
                .flat_map(|i| &i.estimates)
                .any(|e| e.verdict == verdict),
            "{case}"
        );
    }
}

#[test]
fn two_times_for_one_image_are_refused() {
    for name in DATASETS {
        let want = expected(name, "twotimes");
        assert!(
            want["refused"]
                .as_str()
                .unwrap()
                .contains("scene 1 and image 0"),
            "{name}"
        );
        let msg = results::load_results(&result_file(name, "twotimes"))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("for scene 1, image 0 differs from"),
            "{name}: {msg}"
        );
    }
}

#[test]
fn the_cap_keeps_the_best_scored_over_all_objects() {
    // With a cap of one estimate per image, only each image's best-scored estimate counts,
    // whatever its object.
    let results = results::load_results(&result_file("synthA", "extra")).unwrap();
    let one = detection::evaluate(
        dataset("synthA"),
        &results,
        1,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let images: std::collections::BTreeSet<(u32, u32)> = results
        .estimates
        .iter()
        .map(|e| (e.scene_id, e.im_id))
        .collect();
    assert_eq!(
        one.estimates_beyond_cap,
        results.estimates.len() - images.len()
    );
    assert!(
        detection::evaluate(
            dataset("synthA"),
            &results,
            0,
            &NoProgress,
            &AtomicBool::new(false)
        )
        .is_err()
    );
    assert_eq!(DetectionError::MssdMm.thresholds()[9], 20.0);
}

#[test]
fn the_bootstrap_of_the_map_is_the_report_at_unit_weights_and_reproducible() {
    for name in DATASETS {
        for case in ["noisy", "ties", "capped"] {
            let results = results::load_results(&result_file(name, case)).unwrap();
            let run = || {
                detection::evaluation(
                    dataset(name),
                    &results,
                    detection::default_max_estimates_per_image(name),
                    &NoProgress,
                    &AtomicBool::new(false),
                )
                .unwrap()
            };
            let mut evaluation = run();
            let ones = vec![1; evaluation.outcomes.images()];
            assert_eq!(
                evaluation.outcomes.weighted_map(&ones).unwrap().to_bits(),
                evaluation.report.bop24_map.to_bits(),
                "{name} {case}"
            );
            // An image counted twice is an image whose instances and estimates are there twice.
            let mut twice = ones.clone();
            twice[0] = 2;
            assert_ne!(evaluation.outcomes.weighted_map(&twice), None);
            let b = evaluation
                .bootstrap(bootstrap::dataset_seed(name), 200)
                .expect("replicates");
            assert_eq!(b.replicates.len(), 200);
            let summary = evaluation.report.bootstrap.clone().expect("recorded");
            assert_eq!(summary.ci95, b.ci95());
            assert!(summary.ci95[0] <= summary.ci95[1], "{name} {case}");
            assert!(b.replicates.iter().all(|r| (0.0..=1.0).contains(r)));
            assert!(
                b.replicates
                    .iter()
                    .any(|r| *r != evaluation.report.bop24_map),
                "{name} {case}: the replicates vary"
            );
            assert_eq!(run().bootstrap(bootstrap::dataset_seed(name), 200), Some(b));
        }
    }
    // A perfect file is perfect in every replicate.
    let results = results::load_results(&result_file("synthA", "gtexact")).unwrap();
    let mut exact = detection::evaluation(
        dataset("synthA"),
        &results,
        100,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let b = exact.bootstrap(1, 50).expect("replicates");
    assert!(b.replicates.iter().all(|r| *r == 1.0));
}
