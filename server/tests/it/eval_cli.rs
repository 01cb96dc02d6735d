//! `poseboard eval` and `poseboard check-results` run as a user runs them, on the bundled
//! reference fixture, checked against the scores bop_toolkit computed.

use std::process::Output;

use crate::common::{eval_report, fixtures, poseboard};
use serde_json::Value;

fn expected(name: &str, file: &str) -> Value {
    let path = fixtures().join("expected").join(name).join(file);
    serde_json::from_str(&std::fs::read_to_string(path).expect("expected file")).expect("json")
}

fn eval(result: &str, extra: &[&str]) -> (Output, Value) {
    let results = fixtures().join("results").join(format!("{result}.csv"));
    eval_report(&fixtures().join("dataset"), &results, extra)
}

#[test]
fn bop19_report_has_bop_toolkit_keys_and_scores() {
    let (output, report) = eval(
        "noisemedium_synthA-test",
        &["--protocol", "bop19", "--threads", "2"],
    );
    let want = expected("noisemedium_synthA-test", "bop19.json");
    for key in [
        "bop19_average_recall",
        "bop19_average_recall_vsd",
        "bop19_average_recall_mssd",
        "bop19_average_recall_mspd",
        "bop19_average_time_per_image",
    ] {
        let (g, w) = (
            report[key].as_f64().expect(key),
            want[key].as_f64().expect(key),
        );
        assert!((g - w).abs() <= 1e-6, "{key}: {g} != {w}");
    }
    assert_eq!(report["protocol"], "bop19");
    assert_eq!(report["parameters"]["n_top"], -1);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains(&format!(
            "AR {:.4}",
            want["bop19_average_recall"].as_f64().unwrap()
        )),
        "{stdout}"
    );
}

#[test]
fn eccv18_uses_the_papers_visibility_and_can_switch() {
    let (_, paper) = eval("noisemedium_synthA-test", &["--protocol", "eccv18"]);
    let want = expected("noisemedium_synthA-test", "ecc18_bop18vis.json");
    for key in [
        "recall",
        "targets_count",
        "tp_count",
        "gt_count",
        "mean_obj_recall",
        "obj_recalls",
        "scene_recalls",
    ] {
        assert_eq!(paper[key], want[key], "{key}");
    }
    assert_eq!(paper["parameters"]["errors"][0]["visib_mode"], "bop18");
    assert!(paper["recall_vs_theta"].as_array().expect("curves").len() == 2);
    assert_eq!(paper["recall_vs_visib"].as_array().expect("bins").len(), 10);

    let (_, toolkit) = eval(
        "noisemedium_synthA-test",
        &["--protocol", "eccv18", "--visib-mode", "bop19"],
    );
    let want = expected("noisemedium_synthA-test", "ecc18_bop19vis.json");
    assert_eq!(toolkit["recall"], want["recall"]);
    assert_eq!(toolkit["parameters"]["errors"][0]["visib_mode"], "bop19");
}

#[test]
fn overrides_are_applied_and_recorded() {
    let (_, report) = eval(
        "multi_synthA-test",
        &[
            "--protocol",
            "eccv18",
            "--n-top",
            "0",
            "--tau",
            "30",
            "--theta",
            "0.4",
            "--visib-gt-min",
            "0.2",
        ],
    );
    let p = &report["parameters"];
    assert_eq!(p["n_top"], 0);
    assert_eq!(p["visib_gt_min"], 0.2);
    assert_eq!(p["main_tau"], 30.0);
    assert_eq!(p["main_theta"], 0.4);
    // All three estimates per instance are evaluated with n_top = 0.
    assert!(report["estimates_evaluated"].as_u64().expect("count") > 28 * 2);
}

#[test]
fn extra_errors_report_add_and_adi_recalls() {
    let (output, report) = eval(
        "symflip_synthA-test",
        &[
            "--protocol",
            "bop19",
            "--extra-errors",
            "add,adi",
            "--ad-threshold",
            "0.1",
        ],
    );
    let recall = |dir: &str| {
        let exp = expected(
            "symflip_synthA-test",
            &format!("errors/{dir}/scores_th=0.100_min-visib=-1.000.json"),
        );
        exp["recall"].as_f64().expect("recall")
    };
    assert_eq!(
        report["average_recalls"]["add"].as_f64(),
        Some(recall("add"))
    );
    assert_eq!(
        report["average_recalls"]["adi"].as_f64(),
        Some(recall("adi"))
    );
    // A symmetric flip is wrong under ADD and right under ADI for the symmetric objects.
    assert!(recall("adi") > recall("add"));
    assert!(String::from_utf8_lossy(&output.stdout).contains("average recall add"));
}

#[test]
fn a_malformed_file_exits_non_zero_naming_the_lines() {
    let dataset = fixtures().join("dataset");
    for (file, message) in [
        (
            "wrong-columns_synthA-test.csv",
            "line 6 has 6 fields, expected 7",
        ),
        ("nan_synthA-test.csv", "non-finite number on line 4"),
        (
            "not-rotation_synthA-test.csv",
            "R on line 5 is not a rotation matrix",
        ),
        ("bad-header_synthA-test.csv", "bad header on line 1"),
    ] {
        let path = fixtures().join("results/malformed").join(file);
        let output = poseboard(&[
            "eval",
            "--dataset",
            dataset.to_str().unwrap(),
            "--results",
            path.to_str().unwrap(),
        ]);
        assert!(!output.status.success(), "{file} was accepted");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(message), "{file}: {stderr}");

        let check = poseboard(&["check-results", path.to_str().unwrap()]);
        assert!(!check.status.success());
        assert!(String::from_utf8_lossy(&check.stderr).contains(message));
    }
}

#[test]
fn check_results_reports_coverage() {
    let path = fixtures().join("results/missing_synthA-test.csv");
    let dataset = fixtures().join("dataset");
    let output = poseboard(&[
        "check-results",
        path.to_str().unwrap(),
        "--dataset",
        dataset.to_str().unwrap(),
    ]);
    assert!(output.status.success());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("26 estimates"), "{stdout}");
    assert!(stdout.contains("28 targets"), "{stdout}");
}

#[test]
fn a_missing_dataset_names_the_path() {
    let path = fixtures().join("results/gtexact_synthA-test.csv");
    let output = poseboard(&[
        "eval",
        "--dataset",
        "/nonexistent/ds",
        "--results",
        path.to_str().unwrap(),
    ]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("/nonexistent/ds"));
}
