//! `poseboard eval` and `poseboard check-results` with the BOP'22 2D protocols, run as a user
//! runs them on the COCO reference fixture (`tests/fixtures/coco`), checked against the scores
//! bop_toolkit's `eval_bop22_coco.py` computed there.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::{eval_report, poseboard};
use serde_json::Value;

const STATS: [&str; 12] = [
    "AP",
    "AP50",
    "AP75",
    "AP_small",
    "AP_medium",
    "AP_large",
    "AR1",
    "AR10",
    "AR100",
    "AR_small",
    "AR_medium",
    "AR_large",
];

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/coco")
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn expected(case: &str) -> Value {
    let p = fixtures().join("expected").join(format!("{case}.json"));
    serde_json::from_str(&std::fs::read_to_string(p).expect("expected file")).expect("json")
}

/// `poseboard eval` of a case's file on the folder of datasets (the file's name says which).
fn eval(case: &str, extra: &[&str]) -> (Output, Value) {
    let results = fixtures()
        .join("results")
        .join(format!("{case}_tudl-test.json"));
    eval_report(&fixtures().join("dataset"), &results, extra)
}

fn assert_scores(report: &Value, want: &Value) {
    for key in STATS {
        let (g, w) = (
            report[key].as_f64().expect(key),
            want[key].as_f64().expect(key),
        );
        assert!((g - w).abs() <= 1e-9, "{key}: {g} != {w}");
    }
}

#[test]
fn bop22_seg_reports_the_toolkit_keys_and_scores() {
    let (output, report) = eval("noisy", &["--protocol", "bop22-seg", "--threads", "2"]);
    assert_scores(&report, &expected("noisy")["segm"]);
    assert_eq!(report["protocol"], "bop22-seg");
    assert_eq!(report["ann_type"], "segm");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let ap = report["AP"].as_f64().unwrap();
    assert!(stdout.contains(&format!("AP  {ap:.4}")), "{stdout}");
}

#[test]
fn bop22_det_amodal_by_default_and_modal_on_request() {
    let want = expected("falsepositive");
    let (_, amodal) = eval("falsepositive", &["--protocol", "bop22-det"]);
    assert_scores(&amodal, &want["bbox"]);
    assert_eq!(amodal["bbox_type"], "amodal");
    let (_, modal) = eval(
        "falsepositive",
        &["--protocol", "bop22-det", "--bbox-type", "modal"],
    );
    assert_scores(&modal, &want["bbox_modal"]);
    assert_eq!(modal["bbox_type"], "modal");
    assert_ne!(amodal["AP"], modal["AP"]);
}

#[test]
fn bbox_type_is_refused_for_segmentation() {
    let results = fixtures().join("results/noisy_tudl-test.json");
    let output = poseboard(&[
        "eval",
        "--dataset",
        path(&fixtures().join("dataset")),
        "--results",
        path(&results),
        "--protocol",
        "bop22-seg",
        "--bbox-type",
        "modal",
    ]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("--bbox-type is for"));
}

#[test]
fn check_results_names_the_malformed_entry_and_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = r#"{"scene_id": 1, "image_id": 1, "category_id": 1, "score": 0.9, "bbox": [1, 2, 3, 4], "segmentation": {"counts": [307200], "size": [480, 640]}, "time": 0.1}"#;
    for (body, message) in [
        (
            format!(
                r#"[{good}, {{"scene_id": 1, "image_id": 1, "category_id": "one", "score": 0.5}}]"#
            ),
            "entry 1, `category_id`: a string is not an integer",
        ),
        (
            format!(
                r#"[{good}, {good}, {{"scene_id": 1, "image_id": 2, "category_id": 1, "score": 0.5, "segmentation": {{"counts": [5, 3], "size": [480, 640]}}}}]"#
            ),
            "entry 2, `segmentation`: the counts add up to 8 pixels, not 480 x 640 = 307200",
        ),
        (
            format!(
                r#"[{good}, {{"scene_id": 1, "image_id": 1, "category_id": 2, "score": 0.5, "time": 0.2}}]"#
            ),
            "entry 1, `time`: 0.2 s, but entry 0 gives 0.1 s",
        ),
        (
            format!(r#"[{good}, {{"scene_id": 1, "image_id": 1, "category_id": 2,]"#),
            "entry 1: not valid JSON (line 1, column",
        ),
    ] {
        let file = dir.path().join("bad_tudl-test.json");
        std::fs::write(&file, body).expect("write");
        let output = poseboard(&["check-results", path(&file)]);
        assert!(!output.status.success(), "accepted: {message}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(message), "{message}: {stderr}");
        // eval refuses it the same way.
        let output = poseboard(&[
            "eval",
            "--dataset",
            path(&fixtures().join("dataset")),
            "--results",
            path(&file),
            "--protocol",
            "bop22-det",
        ]);
        assert!(!output.status.success());
        assert!(String::from_utf8_lossy(&output.stderr).contains(message));
    }
}

#[test]
fn check_results_says_which_tasks_a_file_serves_and_its_coverage() {
    let nobbox = fixtures().join("results/nobbox_tudl-test.json");
    let output = poseboard(&["check-results", path(&nobbox)]);
    assert!(output.status.success());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(stdout.contains("OK for bop22-seg"), "{stdout}");
    assert!(!stdout.contains("bop22-det"), "{stdout}");

    let output = poseboard(&["check-results", path(&nobbox), "--protocol", "bop22-det"]);
    assert!(!output.status.success());
    assert!(
        String::from_utf8_lossy(&output.stderr).contains("entry 0, `bbox`: missing"),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );

    let nontarget = fixtures().join("results/nontarget_tudl-test.json");
    let output = poseboard(&[
        "check-results",
        path(&nontarget),
        "--dataset",
        path(&fixtures().join("dataset")),
    ]);
    assert!(output.status.success());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        stdout.contains("OK for bop22-det and bop22-seg"),
        "{stdout}"
    );
    assert!(
        stdout.contains("tudl: 8 target images, 1 without an entry; 5 entries"),
        "{stdout}"
    );
}
