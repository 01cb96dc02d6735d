//! The BOP'22 2D tasks through the service: uploads of detection and segmentation JSON files
//! (the task from the field or from the file's content) are validated with the evaluator's
//! parser, queued, scored exactly as `poseboard eval` scores them, and ranked on a board per
//! task, whose per-dataset page shows every AP/AR column and the precision-recall curves.
//!
//! The dataset is the synthetic one `poseboard dataset synth` writes, which has both the 6D
//! ground truth the service needs to register a dataset and the COCO ground truth
//! (`scene_gt_coco.json`); the 2D reference fixture (`tests/fixtures/coco`) has only the latter,
//! and its scores against bop_toolkit are checked by `coco_cli.rs`.

use crate::common;

use std::path::Path;
use std::process::{Command, Stdio};

use crate::common::{
    BIN, Db, TestDb, both_databases, cli_report, get_json, start, upload, upload_scored,
};
use serde_json::Value;

const STATS: [&str; 13] = [
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
    "average_time_per_image",
];

fn poseboard(args: &[&str], paths: &[&Path]) {
    let status = Command::new(BIN)
        .args(args)
        .args(paths)
        .stdout(Stdio::null())
        .status()
        .expect("poseboard runs");
    assert!(status.success(), "{args:?}");
}

/// Uploads `file` and waits for its scores: the report the service gives for it.
fn scored(server: &common::Server, method: &str, file: &Path, protocol: Option<&str>) -> Value {
    let body = upload_scored(server, method, "synthdemo", file, protocol);
    let id = body["id"].as_i64().expect("id");
    let report = get_json(&format!("{}/api/v1/submissions/{id}/report", server.base));
    let task = body["submission"]["task"].as_str().expect("a 2D task");
    let mut report = report[task].clone();
    report["submission_id"] = id.into();
    report
}

fn coco_service(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = dir.path().join("datasets");
    let dataset = datasets.join("synthdemo");
    poseboard(&["dataset", "synth"], &[&dataset]);
    let results = dir.path().join("results");
    poseboard(
        &["dataset", "demo-results", "--coco"],
        &[&dataset, &results],
    );
    let seg_file = results.join("demo-segmenter_synthdemo-test.json");
    let det_file = results.join("demo-detector_synthdemo-test.json");

    let db = TestDb::new(kind, "coco");
    let server = start(&dir.path().join("data"), &datasets, &db, &["--no-demo"]);
    let base = &server.base;

    // The task from the file's content (masks: segmentation), from the field, and the same
    // masks file scored on its boxes when the field asks for detection.
    let seg = scored(&server, "masks", &seg_file, None);
    let det = scored(&server, "boxes", &det_file, Some("bop22-det"));
    let seg_as_det = scored(&server, "masks", &seg_file, Some("bop22-det"));
    for (report, file, protocol) in [
        (&seg, &seg_file, "bop22-seg"),
        (&det, &det_file, "bop22-det"),
        (&seg_as_det, &seg_file, "bop22-det"),
    ] {
        assert_eq!(report["protocol"], protocol);
        let cli = cli_report(&dataset, file, protocol);
        for key in STATS {
            assert_eq!(report[key], cli[key], "{protocol} {key}");
        }
        let ap = report["AP"].as_f64().expect("AP");
        assert!(ap > 0.3 && ap < 1.0, "{protocol}: AP {ap}");
    }

    // A malformed file is refused with its entry and key named, as check-results names them;
    // one without what the task asked for is refused too; neither leaves a submission.
    let bad = dir.path().join("bad_synthdemo-test.json");
    let good = r#"{"scene_id": 1, "image_id": 0, "category_id": 1, "score": 0.9, "bbox": [1, 2, 3, 4], "time": 0.1}"#;
    for (body, protocol, message) in [
        (
            format!(
                r#"[{good}, {{"scene_id": 1, "image_id": 0, "category_id": "one", "score": 0.5, "bbox": [1, 2, 3, 4], "time": 0.1}}]"#
            ),
            None,
            "entry 1, `category_id`: a string is not an integer",
        ),
        (
            format!("[{good}]"),
            Some("bop22-seg"),
            "entry 0, `segmentation`",
        ),
    ] {
        std::fs::write(&bad, body).expect("write");
        let r = upload(&server, "broken", "synthdemo", &bad, protocol);
        assert_eq!(r.status().as_u16(), 422);
        let answer: Value = r.json().expect("JSON");
        assert!(
            answer["problems"]
                .as_array()
                .expect("problems")
                .iter()
                .any(|p| p["message"].as_str().unwrap_or_default().contains(message)),
            "{message}: {answer}"
        );
    }

    // The boards: one per task, ranked by AP averaged over the core datasets (AP_C).
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop22-seg"));
    let rows = board["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), 1, "{board}");
    assert_eq!(rows[0]["method"], "masks");
    assert_eq!(rows[0]["rank"], 1);
    assert_eq!(rows[0]["average"], seg["AP"]);
    assert_eq!(
        rows[0]["scores"]["synthdemo"]["submission_id"],
        seg["submission_id"]
    );
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop22-det"));
    let methods: Vec<&str> = board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| r["method"].as_str().expect("method"))
        .collect();
    let (first, second) = if det["AP"].as_f64() > seg_as_det["AP"].as_f64() {
        ("boxes", "masks")
    } else {
        ("masks", "boxes")
    };
    assert_eq!(methods, [first, second], "{board}");
    // The 6D boards do not show the 2D submissions.
    let pose = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(pose["rows"].as_array().expect("rows").len(), 0);

    // A dataset's page: every AP/AR column and the precision-recall curves.
    let client = common::client();
    let page = client
        .get(format!("{base}/leaderboards/bop22-seg?dataset=synthdemo"))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    for key in &STATS[1..12] {
        assert!(
            page.contains(&format!("<th class=\"num\">{key}</th>")),
            "{key}"
        );
    }
    assert!(page.contains("<svg") && page.contains("Precision vs recall"));
    assert!(page.contains("<polyline") && page.contains(" masks</span>"));
    let json = get_json(&format!(
        "{base}/api/v1/leaderboards/bop22-seg?dataset=synthdemo"
    ));
    let cell = &json["rows"][0]["scores"]["synthdemo"];
    for key in &STATS[..12] {
        assert_eq!(cell["stats"][key], seg[key], "{key}");
    }

    // The submission page shows the scores and the curves.
    let id = seg["submission_id"].as_i64().expect("id");
    let page = client
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    assert!(page.contains("bop22-seg scores") && page.contains("AR_medium"));
    assert!(page.contains("IoU 0.50:0.95 (mean)"));
    assert!(page.contains("this is the method's entry on"), "{page}");
    // A 2D file's entries are counted as detections, not as estimates.
    assert!(page.contains("<tr><th>Detections</th><td>"), "{page}");
    assert!(
        page.contains(" detections to evaluate; at upload"),
        "{page}"
    );
}
both_databases!(coco_service);
