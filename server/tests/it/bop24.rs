//! BOP'24 6D detection through the service: a `bop24` upload (the API, and `poseboard submit
//! --protocol bop24`) is queued and scored exactly as `poseboard eval --protocol bop24` scores
//! it, every key equal, and ranked on the bop24 board by bop24_mAP, with its parts, time and
//! per-object AP; the submission page shows the scores and the precision-recall curves. A
//! dataset without `test_targets_bop24.json` takes no bop24 upload, and says so.
//!
//! The dataset is the reference one with the BOP'24 fixture's targets (`bop24_cli::datasets`),
//! whose scores against bop_toolkit `bop24_cli.rs` checks; here the service must give the same.

use std::path::Path;
use std::process::{Command, Stdio};

use crate::bop24_cli::{KEYS, datasets, result_file};
use crate::common::{
    self, BIN, Db, TestDb, both_databases, eval_report, fixtures, get_as, get_json, start, upload,
    upload_scored,
};
use serde_json::Value;

/// Uploads `file` for bop24 and waits for its scores: the report the service gives for it.
fn scored(server: &common::Server, method: &str, file: &Path) -> Value {
    let body = upload_scored(server, method, "synthA", file, Some("bop24"));
    assert_eq!(body["submission"]["task"], "bop24", "{body}");
    let id = body["id"].as_i64().expect("id");
    let report = get_json(&format!("{}/api/v1/submissions/{id}/report", server.base));
    let mut report = report["bop24"].clone();
    report["submission_id"] = id.into();
    report
}

/// The interval the evaluator draws for `file` on the bop24 dataset at `root`, as the worker
/// must.
fn expected_interval(root: &Path, file: &Path) -> [f64; 2] {
    let options = evaluator::dataset::DatasetOptions {
        targets_file: "test_targets_bop24.json".into(),
        ..Default::default()
    };
    let dataset = evaluator::Dataset::load_with(root, &options).expect("loads");
    let results = evaluator::results::load_results(file).expect("parses");
    let mut evaluation = evaluator::detection::evaluation(
        &dataset,
        &results,
        100,
        &evaluator::NoProgress,
        &std::sync::atomic::AtomicBool::new(false),
    )
    .expect("evaluates");
    let seed = evaluator::bootstrap::dataset_seed("synthA");
    let b = evaluation
        .bootstrap(seed, evaluator::bootstrap::REPLICATES)
        .expect("replicates");
    b.ci95()
}

fn bop24_service(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let root = datasets(dir.path());
    // A second dataset, the same files without the BOP'24 targets.
    let plain = root.join("plainB");
    std::os::unix::fs::symlink(
        fixtures().join("dataset").canonicalize().expect("fixture"),
        &plain,
    )
    .expect("symlink");
    let db = TestDb::new(kind, "bop24");
    let server = start(&dir.path().join("data"), &root, &db, &["--no-demo"]);
    let base = &server.base;

    // Every key as `poseboard eval --protocol bop24` computes it, for files whose scores
    // differ (exact poses, noise, more estimates per image than the cap, equal scores).
    let (mut maps, mut reports) = (Vec::new(), Vec::new());
    for case in ["gtexact", "noisy", "capped", "ties"] {
        let file = result_file(case);
        let report = scored(&server, case, &file);
        let (_, cli) = eval_report(&root, &file, &["--protocol", "bop24", "--threads", "1"]);
        for key in KEYS {
            assert_eq!(report[key], cli[key], "{case} {key}");
        }
        assert_eq!(
            report["errors"], cli["errors"],
            "{case}: per-object AP and curves"
        );
        assert_eq!(report["parameters"]["max_estimates_per_image"], 100);
        maps.push((case, report["bop24_mAP"].as_f64().expect("bop24_mAP")));
        reports.push((case, report));
    }

    // The board: ranked by bop24_mAP over the core datasets that take bop24 (not plainB).
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop24"));
    assert_eq!(board["protocol"], "bop24");
    assert_eq!(board["core"], serde_json::json!(["synthA"]), "{board}");
    let rows = board["rows"].as_array().expect("rows");
    assert_eq!(rows.len(), maps.len(), "{board}");
    let averages: Vec<f64> = rows
        .iter()
        .map(|r| {
            let (case, map) = maps
                .iter()
                .find(|(case, _)| r["method"] == *case)
                .expect("a method per file");
            assert_eq!(r["average"].as_f64(), Some(*map), "{case}");
            *map
        })
        .collect();
    assert!(averages.windows(2).all(|w| w[0] >= w[1]), "{averages:?}");
    assert!(averages[0] > averages[averages.len() - 1], "{averages:?}");
    assert_eq!(rows[0]["rank"], 1);
    // The 6D localization boards do not show the bop24 submissions.
    let pose = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(pose["rows"].as_array().expect("rows").len(), 0);

    // A dataset's board: the parts, the time and the per-object AP of each entry.
    let noisy = &reports.iter().find(|r| r.0 == "noisy").expect("noisy").1;
    let json = get_json(&format!("{base}/api/v1/leaderboards/bop24?dataset=synthA"));
    let row = json["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == "noisy")
        .expect("the noisy row")
        .clone();
    let cell = &row["scores"]["synthA"];
    assert_eq!(cell["score"], noisy["bop24_mAP"]);
    for key in [
        "bop24_mAP_mssd",
        "bop24_mAP_mspd",
        "bop24_mAP_mssd_mm",
        "bop25_mAP",
        "bop25_mAP_mm",
    ] {
        assert_eq!(cell["stats"][key], noisy[key], "{key}");
    }
    assert_eq!(cell["time"], noisy["bop24_average_time_per_image"]);
    // Its interval is the evaluator's bootstrap of bop24_mAP, drawn as every board's is.
    let ci: Vec<f64> = serde_json::from_value(cell["ci95"].clone()).expect("ci95");
    assert_eq!(
        ci,
        expected_interval(&root.join("synthA"), &result_file("noisy"))
    );
    assert_eq!(noisy["bootstrap"]["ci95"], cell["ci95"]);
    assert_eq!(noisy["bootstrap"]["replicates"], 1000);
    let objects = row["objects"].as_object().expect("per-object AP");
    let counted = noisy["errors"][0]["objects"].as_array().expect("objects");
    assert_eq!(objects.len(), counted.len(), "{row}");
    let per_object: Vec<f64> = objects.values().filter_map(Value::as_f64).collect();
    let mean = per_object.iter().sum::<f64>() / per_object.len() as f64;
    let map = noisy["bop24_mAP"].as_f64().expect("mAP");
    assert!((mean - map).abs() < 1e-12, "{mean} != {map}");
    let client = common::client();
    let page = client
        .get(format!("{base}/leaderboards/bop24?dataset=synthA"))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    assert!(
        page.contains("<th class=\"num\">bop24_mAP_mspd</th>"),
        "{page}"
    );
    assert!(page.contains("Precision vs recall, mean of MSSD and MSPD"));
    assert!(page.contains("eval_bop24_pose.py"));

    // The submission page: the scores, the per-object table and the curves.
    let id = noisy["submission_id"].as_i64().expect("id");
    let page = client
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    assert!(page.contains("bop24 scores") && page.contains("bop25_mAP_mm"));
    assert!(page.contains("id=\"bop24-objects\""));
    assert!(page.contains("Precision vs recall (bop24)") && page.contains("MSPD (5..50 px)"));
    assert!(page.contains("this is the method's entry on"), "{page}");

    // `poseboard submit --protocol bop24` prints the keys the service computed.
    let out = Command::new(BIN)
        .arg("submit")
        .arg(result_file("extra"))
        .args(["--method", "from-cli", "--protocol", "bop24"])
        .env("POSEBOARD_SERVER", base)
        .env("POSEBOARD_TOKEN", &server.token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (_, cli) = eval_report(
        &root,
        &result_file("extra"),
        &["--protocol", "bop24", "--threads", "1"],
    );
    let map = cli["bop24_mAP"].as_f64().expect("mAP");
    assert!(stdout.contains(&format!("bop24_mAP  {map:.4}")), "{stdout}");

    // A dataset without test_targets_bop24.json takes no bop24 upload, saying which file it
    // lacks; a JSON file and a file with two times for one image are refused too; none leaves
    // a submission.
    let submissions = || {
        get_as(&format!("{base}/api/v1/me/submissions"), &server.token)
            .json::<Value>()
            .expect("JSON")["submissions"]
            .as_array()
            .expect("submissions")
            .len()
    };
    let before = submissions();
    let renamed = dir.path().join("noisy_plainB-test.csv");
    std::fs::copy(result_file("noisy"), &renamed).expect("copy");
    let r = upload(&server, "plain", "plainB", &renamed, Some("bop24"));
    assert_eq!(r.status().as_u16(), 400);
    let error = r.json::<Value>().expect("JSON")["error"].to_string();
    assert!(
        error.contains("dataset `plainB` has no test_targets_bop24.json"),
        "{error}"
    );
    let json_file = dir.path().join("boxes_synthA-test.json");
    std::fs::write(&json_file, "[]").expect("write");
    let r = upload(&server, "boxes", "synthA", &json_file, Some("bop24"));
    assert_eq!(r.status().as_u16(), 400);
    let error = r.json::<Value>().expect("JSON")["error"].to_string();
    assert!(
        error.contains("bop24 (6D detection) reads BOP'19 CSV"),
        "{error}"
    );
    let r = upload(
        &server,
        "twice",
        "synthA",
        &result_file("twotimes"),
        Some("bop24"),
    );
    assert_eq!(r.status().as_u16(), 422);
    let answer: Value = r.json().expect("JSON");
    assert!(answer.to_string().contains("scene 1, image 0"), "{answer}");
    assert_eq!(submissions(), before);
}

both_databases!(bop24_service);
