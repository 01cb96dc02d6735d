//! `poseboard eval --protocol bop24` and `check-results --protocol bop24`, run as a user runs
//! them on the BOP'24 fixture (`tests/fixtures/bop24`: the reference dataset's detection
//! targets and result files), checked against the scores bop_toolkit's `eval_bop24_pose.py`
//! computed there.

use std::path::{Path, PathBuf};

use crate::common::{eval_report, fixtures, poseboard};
use serde_json::Value;

pub(crate) const KEYS: [&str; 7] = [
    "bop24_mAP",
    "bop24_mAP_mssd",
    "bop24_mAP_mssd_mm",
    "bop24_mAP_mspd",
    "bop25_mAP",
    "bop25_mAP_mm",
    "bop24_average_time_per_image",
];

fn bop24() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/bop24")
}

pub(crate) fn result_file(case: &str) -> PathBuf {
    bop24()
        .join("results")
        .join(format!("{case}_synthA-test.csv"))
}

fn expected(case: &str) -> Value {
    let p = bop24().join("expected").join(format!("{case}.json"));
    serde_json::from_str(&std::fs::read_to_string(p).expect("expected file")).expect("json")
}

/// A folder of datasets whose `synthA` is the reference dataset with its bop24 targets file
/// next to its own files (linked).
pub(crate) fn datasets(dir: &Path) -> PathBuf {
    let root = dir.join("datasets");
    let synth = root.join("synthA");
    std::fs::create_dir_all(&synth).expect("mkdir");
    let reference = fixtures().join("dataset").canonicalize().expect("fixture");
    for entry in std::fs::read_dir(&reference).expect("fixture") {
        let entry = entry.expect("entry");
        std::os::unix::fs::symlink(entry.path(), synth.join(entry.file_name())).expect("link");
    }
    std::fs::copy(
        bop24().join("test_targets_bop24.json"),
        synth.join("test_targets_bop24.json"),
    )
    .expect("copy");
    root
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn bop24_reports_the_toolkit_keys_and_scores() {
    let dir = tempfile::tempdir().unwrap();
    let root = datasets(dir.path());
    for case in ["gtexact", "noisy", "extra", "ties", "capped"] {
        let (output, report) = eval_report(
            &root,
            &result_file(case),
            &["--protocol", "bop24", "--threads", "2"],
        );
        let want = expected(case);
        for key in KEYS {
            let (g, w) = (
                report[key].as_f64().expect(key),
                want[key].as_f64().unwrap(),
            );
            assert!((g - w).abs() <= 1e-9, "{case} {key}: {g} != {w}");
        }
        assert_eq!(report["protocol"], "bop24");
        assert_eq!(report["parameters"]["max_estimates_per_image"], 100);
        let stdout = String::from_utf8_lossy(&output.stdout);
        let map = report["bop24_mAP"].as_f64().unwrap();
        assert!(stdout.contains(&format!("bop24_mAP  {map:.4}")), "{stdout}");
        // Per error, the per-object AP at each threshold and the precision-recall curve.
        let errors = report["errors"].as_array().unwrap();
        assert_eq!(errors.len(), 3);
        for e in errors {
            assert_eq!(e["precision_recall"].as_array().unwrap().len(), 101);
            for o in e["objects"].as_array().unwrap() {
                assert_eq!(o["ap_per_threshold"].as_array().unwrap().len(), 10);
            }
        }
    }
}

#[test]
fn the_cap_can_be_chosen() {
    let dir = tempfile::tempdir().unwrap();
    let root = datasets(dir.path());
    let (_, default) = eval_report(&root, &result_file("capped"), &["--protocol", "bop24"]);
    let (_, large) = eval_report(
        &root,
        &result_file("capped"),
        &["--protocol", "bop24", "--max-estimates-per-image", "1000"],
    );
    assert!(default["estimates_beyond_cap"].as_u64().unwrap() > 0);
    assert_eq!(large["estimates_beyond_cap"], 0);
    assert_ne!(default["bop24_mAP"], large["bop24_mAP"]);
}

#[test]
fn two_times_for_one_image_are_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let root = datasets(dir.path());
    let out = poseboard(&[
        "eval",
        "--dataset",
        s(&root),
        "--results",
        s(&result_file("twotimes")),
        "--protocol",
        "bop24",
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("time 0.25 for scene 1, image 0 differs from 0.5 given on line 2"),
        "{stderr}"
    );
}

#[test]
fn localization_options_and_protocols_are_refused_where_they_do_not_apply() {
    let dir = tempfile::tempdir().unwrap();
    let root = datasets(dir.path());
    let results = result_file("noisy");
    let run = |extra: &[&str]| {
        let mut args = vec!["eval", "--dataset", s(&root), "--results", s(&results)];
        args.extend_from_slice(extra);
        let out = poseboard(&args);
        assert!(!out.status.success(), "{extra:?} was accepted");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let msg = run(&["--protocol", "bop24", "--tau", "0.2"]);
    assert!(
        msg.contains("bop24 has fixed errors and thresholds"),
        "{msg}"
    );
    let msg = run(&["--protocol", "bop19", "--max-estimates-per-image", "5"]);
    assert!(
        msg.contains("--max-estimates-per-image is for --protocol bop24 only"),
        "{msg}"
    );
    // The detection targets list images: a localization protocol cannot use them.
    let msg = run(&["--targets-file", "test_targets_bop24.json"]);
    assert!(
        msg.contains("test_targets_bop24.json: a list of images (BOP'24 detection targets)"),
        "{msg}"
    );
}

#[test]
fn check_results_reports_the_detection_coverage() {
    let dir = tempfile::tempdir().unwrap();
    let root = datasets(dir.path());
    let out = poseboard(&[
        "check-results",
        s(&result_file("capped")),
        "--protocol",
        "bop24",
        "--dataset",
        s(&root),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(stdout.contains("a valid result file for bop24"), "{stdout}");
    assert!(
        stdout.contains("synthA: 7 target images, 0 without"),
        "{stdout}"
    );
    assert!(
        stdout.contains("beyond the cap of 100 per image"),
        "{stdout}"
    );

    let out = poseboard(&[
        "check-results",
        s(&result_file("twotimes")),
        "--protocol",
        "bop24",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("scene 1, image 0"));
}
