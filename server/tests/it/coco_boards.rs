//! The 2D boards keep their notes' promises (issue 27 item 8), over real HTTP on both
//! databases: each 2D score has a bootstrap 95 % interval over the target images (the
//! evaluator's own, 1000 replicates seeded by the dataset as the 6D scores', around an AP left
//! bit for bit as `poseboard eval` computes it) and a reproducibility record (evaluator version,
//! COCOeval's parameters, the dataset's content hash as registered, the SHA-256 of the uploaded
//! bytes), shown on the board and the submission page; the CSV and JSON exports of a 2D board
//! carry the task's own columns (AP ... AR_large, time, interval, record) and none of the 6D
//! ones; and a 6D board's JSON leaves out the breakdowns its protocol does not have.

use std::path::Path;

use evaluator::bootstrap::{self, REPLICATES};
use evaluator::coco::{self, BboxType, CocoGt, CocoTask, STAT_NAMES};
use evaluator::dataset::DatasetOptions;
use serde_json::Value;
use sha2::{Digest, Sha256};

use crate::common::{
    Db, Server, SynthDemo, TestDb, both_databases, cli_report, client, column, get_json, start,
    upload_scored,
};
use crate::exports::parse_csv;

/// Uploads `file` publicly and waits until it is scored; its id.
fn scored(server: &Server, method: &str, file: &Path, protocol: Option<&str>) -> i64 {
    upload_scored(server, method, "synthdemo", file, protocol)["id"]
        .as_i64()
        .expect("id")
}

/// The interval the evaluator draws for `file` on `dataset`, as the worker must.
fn expected_interval(dataset: &Path, file: &Path, task: CocoTask) -> [f64; 2] {
    let masks = task == CocoTask::Segmentation;
    let gt = CocoGt::load(dataset, &DatasetOptions::default(), BboxType::Amodal, masks)
        .expect("ground truth");
    let results = coco::load_coco_results(file).expect("results");
    let mut evaluation = coco::evaluation(&gt, &results, task).expect("evaluates");
    let b = evaluation
        .bootstrap(bootstrap::dataset_seed("synthdemo"), REPLICATES)
        .expect("replicates");
    assert_eq!(b.replicates.len(), 1000);
    b.ci95()
}

fn coco_boards(kind: Db) {
    let set = SynthDemo::new();
    let (dataset, results) = (&set.dataset, &set.results);
    let det_file = results.join("demo-detector_synthdemo-test.json");
    let seg_file = results.join("demo-segmenter_synthdemo-test.json");
    let pose_file = results.join("demo-precise_synthdemo-test.csv");

    let db = TestDb::new(kind, "cocoboards");
    let data = set.data();
    let server = start(&data, &set.datasets, &db, &["--no-demo"]);
    let base = &server.base;
    let det = scored(&server, "boxes", &det_file, Some("bop22-det"));
    let seg = scored(&server, "masks", &seg_file, Some("bop22-seg"));
    // Scored under both 6D protocols.
    scored(&server, "poses", &pose_file, None);
    let registered = column(
        &db,
        &data,
        "SELECT content_hash FROM datasets WHERE name = 'synthdemo'",
    );

    for (protocol, id, file, task) in [
        (
            "bop22-det",
            det,
            &det_file,
            CocoTask::Detection(BboxType::Amodal),
        ),
        ("bop22-seg", seg, &seg_file, CocoTask::Segmentation),
    ] {
        let cli = cli_report(dataset, file, protocol);
        let board = get_json(&format!("{base}/api/v1/leaderboards/{protocol}"));
        let row = &board["rows"][0];
        let cell = &row["scores"]["synthdemo"];
        assert_eq!(cell["submission_id"], id);

        // The AP is the evaluator's to the bit, and its interval is the evaluator's bootstrap.
        assert_eq!(cell["score"], cli["AP"], "{protocol}");
        let ci: Vec<f64> = serde_json::from_value(cell["ci95"].clone()).expect("ci95");
        assert_eq!(ci, expected_interval(dataset, file, task), "{protocol}");
        let ap = cli["AP"].as_f64().expect("AP");
        assert!(ci[0] <= ap && ap <= ci[1] && ci[0] < ci[1], "{ci:?} {ap}");
        // One dataset shown: the row's interval is the score's.
        assert_eq!(row["ci95"], cell["ci95"]);

        // The record: what the store holds and the bytes uploaded.
        let record = &cell["record"];
        assert_eq!(
            record["evaluator_version"],
            evaluator::report::EVALUATOR_VERSION
        );
        assert_eq!(record["protocol"], protocol);
        assert_eq!(record["dataset_hash"], registered[0].as_str());
        let bytes = std::fs::read(file).expect("file");
        assert_eq!(record["file_sha256"], hex::encode(Sha256::digest(&bytes)));
        assert_eq!(
            record["parameters"]["iou_thresholds"],
            serde_json::json!([0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95])
        );
        assert_eq!(
            record["parameters"]["max_detections"],
            serde_json::json!([1, 10, 100])
        );
        assert_eq!(
            record["parameters"]["iou_type"],
            if protocol == "bop22-det" {
                "bbox"
            } else {
                "segm"
            }
        );
        // No 6D breakdowns on a 2D cell.
        for key in ["recall", "ar_vsd", "ar_mssd", "ar_mspd"] {
            assert!(cell.get(key).is_none(), "{protocol} {key}: {cell}");
        }
        let submission = get_json(&format!("{base}/api/v1/submissions/{id}"));
        assert_eq!(&submission["records"][protocol], record);
        assert_eq!(submission["coco"]["bootstrap"]["ci95"], cell["ci95"]);
        assert_eq!(submission["coco"]["bootstrap"]["replicates"], 1000);

        // The pages show them: the interval on hover, the record on the submission page.
        let page = client()
            .get(format!("{base}/leaderboards/{protocol}"))
            .send()
            .expect("answered")
            .text()
            .expect("page");
        let hover = format!(
            "title=\"95 % bootstrap interval: {:.1} to {:.1}\"",
            ci[0] * 100.0,
            ci[1] * 100.0
        );
        assert!(page.contains(&hover), "{hover}");
        let page = client()
            .get(format!("{base}/submissions/{id}"))
            .send()
            .expect("answered")
            .text()
            .expect("page");
        let records = &page[page.find("id=\"records\"").expect("a record table")..];
        assert!(
            records.contains(&format!("<th>{protocol}</th>"))
                && records.contains(evaluator::report::EVALUATOR_VERSION)
                && records.contains(registered[0].as_str())
                && records.contains("IoU thresholds 0.5, 0.55, 0.6, 0.65,"),
            "{records}"
        );

        // CSV: the task's own columns, filled, and no 6D column.
        let csv = client()
            .get(format!("{base}/leaderboards/{protocol}/export.csv"))
            .send()
            .expect("answered")
            .text()
            .expect("CSV");
        let csv = parse_csv(&csv);
        let (header, line) = (&csv[0], &csv[1]);
        let at = |name: &str| {
            header
                .iter()
                .position(|h| h == &format!("synthdemo {name}"))
                .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
        };
        for name in STAT_NAMES {
            let value: f64 = line[at(name)].parse().expect(name);
            assert_eq!(value, cli[name].as_f64().expect(name), "{protocol} {name}");
        }
        let time: f64 = line[at("time")].parse().expect("time");
        assert_eq!(time, cli["average_time_per_image"].as_f64().expect("time"));
        assert_eq!(line[at("ci95_low")].parse::<f64>().expect("low"), ci[0]);
        assert_eq!(line[at("ci95_high")].parse::<f64>().expect("high"), ci[1]);
        for key in [
            "evaluator_version",
            "protocol",
            "dataset_hash",
            "file_sha256",
        ] {
            assert_eq!(line[at(key)], record[key].as_str().expect(key), "{key}");
        }
        let parameters: Value = serde_json::from_str(&line[at("parameters")]).expect("JSON");
        assert_eq!(&parameters, &record["parameters"]);
        for gone in ["score", "recall", "ar_vsd", "ar_mssd", "ar_mspd"] {
            let name = format!("synthdemo {gone}");
            assert!(!header.contains(&name), "{protocol}: {name} in {header:?}");
        }

        // JSON: the board's rows, COCOeval's parameters, the names of the numbers.
        let json: Value = client()
            .get(format!("{base}/leaderboards/{protocol}/export.json"))
            .send()
            .expect("answered")
            .json()
            .expect("JSON");
        assert_eq!(json["rows"], board["rows"]);
        assert_eq!(json["parameters"], record["parameters"]);
        assert_eq!(json["stats"], serde_json::json!(STAT_NAMES));
    }

    // A 6D board's JSON has its protocol's breakdowns only.
    for (protocol, has, lacks) in [
        (
            "bop19",
            &["ar_vsd", "ar_mssd", "ar_mspd"][..],
            &["recall"][..],
        ),
        (
            "eccv18",
            &["recall"][..],
            &["ar_vsd", "ar_mssd", "ar_mspd"][..],
        ),
    ] {
        for url in [
            format!("{base}/api/v1/leaderboards/{protocol}"),
            format!("{base}/leaderboards/{protocol}/export.json"),
        ] {
            let board = get_json(&url);
            let cell = &board["rows"][0]["scores"]["synthdemo"];
            for key in has {
                assert!(cell[key].is_number(), "{url} {key}: {cell}");
            }
            for key in lacks {
                assert!(cell.get(key).is_none(), "{url} {key}: {cell}");
            }
            assert!(cell.get("stats").is_none(), "{url}: {cell}");
        }
    }
}
both_databases!(coco_boards);
