//! Reproduces the BOP'24 6D detection scores bop_toolkit computed on the reference dataset
//! with the targets and result files of `tests/fixtures/bop24` (made by its `generate.py`; the
//! toolkit's commit is in every expected file): every key of `scores_bop24.json` and every
//! per-object AP at every threshold to 1e-9, and the file with two times for one image refused.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use evaluator::dataset::{DatasetOptions, TargetsForm};
use evaluator::detection::{self, DetectionError, DetectionReport};
use evaluator::{Dataset, NoProgress, results};
use serde_json::Value;

const CASES: [&str; 5] = ["gtexact", "noisy", "extra", "ties", "capped"];
const TOLERANCE: f64 = 1e-9;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn dataset() -> &'static Dataset {
    static DS: OnceLock<Dataset> = OnceLock::new();
    DS.get_or_init(|| {
        let targets = fixtures().join("bop24/test_targets_bop24.json");
        let options = DatasetOptions {
            targets_file: targets.to_string_lossy().into_owned(),
            ..DatasetOptions::default()
        };
        Dataset::load_with(&fixtures().join("reference/dataset"), &options)
            .expect("the reference dataset loads with the bop24 targets")
    })
}

fn expected(case: &str) -> Value {
    let path = fixtures().join(format!("bop24/expected/{case}.json"));
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn score(case: &str) -> DetectionReport {
    let path = fixtures().join(format!("bop24/results/{case}_synthA-test.csv"));
    let results = results::load_results(&path).expect("the result file parses");
    detection::evaluate(
        dataset(),
        &results,
        detection::default_max_estimates_per_image("synthA"),
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
    assert_eq!(dataset().targets_form, TargetsForm::Images);
    for case in CASES {
        let report = score(case);
        let want = expected(case);
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
                &format!("{case} {key}"),
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
                assert_eq!(scores.objects.len(), with_instances.len(), "{case} {error}");
                for o in &scores.objects {
                    close(
                        &format!("{case} {error} {sign} object {}", o.obj_id),
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
                &format!("{case} {error} curve"),
                curve.iter().sum::<f64>() / curve.len() as f64,
                scores.map,
            );
        }
    }
}

#[test]
fn what_the_cases_exercise_happens() {
    let capped = score("capped");
    assert!(capped.estimates_beyond_cap > 0, "{capped:?}");
    let extra = score("extra");
    let noisy = score("noisy");
    assert!(extra.estimates_ignored > 0);
    assert_eq!(extra.estimates_evaluated, noisy.estimates_evaluated);
    assert_eq!(score("ties").bop24_average_time_per_image, -1.0);
    // The instances under 10 % visible are not counted.
    assert!(noisy.instances_counted < noisy.instances);
}

#[test]
fn two_times_for_one_image_are_refused() {
    let want = expected("twotimes");
    assert!(
        want["refused"]
            .as_str()
            .unwrap()
            .contains("scene 1 and image 0")
    );
    let path = fixtures().join("bop24/results/twotimes_synthA-test.csv");
    let msg = results::load_results(&path).unwrap_err().to_string();
    assert!(
        msg.contains("time 0.25 for scene 1, image 0 differs from 0.5"),
        "{msg}"
    );
}

#[test]
fn the_cap_keeps_the_best_scored_over_all_objects() {
    // With a cap of one estimate per image, only each image's best-scored estimate counts,
    // whatever its object.
    let path = fixtures().join("bop24/results/extra_synthA-test.csv");
    let results = results::load_results(&path).unwrap();
    let one =
        detection::evaluate(dataset(), &results, 1, &NoProgress, &AtomicBool::new(false)).unwrap();
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
        detection::evaluate(dataset(), &results, 0, &NoProgress, &AtomicBool::new(false)).is_err()
    );
    assert_eq!(DetectionError::MssdMm.thresholds()[9], 20.0);
}
