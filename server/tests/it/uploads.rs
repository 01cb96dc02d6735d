//! Uploading results, the service's main path: a good file is evaluated to exactly the scores
//! `poseboard eval` gives and ranked on the leaderboards (API and pages), and sending it again
//! is recognised as a duplicate; malformed files and unknown datasets are refused naming the
//! problem, leaving no row and no file behind; a body over the size bound gets 413 without being
//! read. The first two run on both databases; the size bound is the HTTP layer's and runs on
//! SQLite only.

use std::time::Duration;

use crate::common::{
    Db, TestDb, both_databases, browser, cli_report, client, column, fixtures, get_json,
    reference_datasets, start, upload, upload_with, wait_done,
};
use reqwest::blocking::multipart;
use serde_json::Value;

fn upload_evaluate_and_rank(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "rank");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisemedium_synthA-test.csv");

    let meta = [
        ("method", "noisy-net"),
        ("dataset", "synthA"),
        ("training_data", "synthetic"),
        ("modality", "rgb-d"),
        ("hardware", "test rig, 2 cores"),
        ("visibility", "public"),
    ];
    let r = upload_with(&server, &server.token, &meta, &file);
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    let id = body["id"].as_i64().expect("id");
    assert_eq!(body["preflight"]["targets"], 28);
    let done = wait_done(&base, id, Duration::from_secs(60));

    let bop19 = cli_report(&datasets.join("synthA"), &file, "bop19");
    let eccv18 = cli_report(&datasets.join("synthA"), &file, "eccv18");
    for key in [
        "bop19_average_recall",
        "bop19_average_recall_vsd",
        "bop19_average_recall_mssd",
        "bop19_average_recall_mspd",
    ] {
        assert_eq!(done["scores"]["bop19"][key], bop19[key], "{kind:?} {key}");
    }
    for key in [
        "recall",
        "obj_recalls",
        "scene_recalls",
        "mean_obj_recall",
        "targets_count",
        "tp_count",
    ] {
        assert_eq!(done["scores"]["eccv18"][key], eccv18[key], "{kind:?} {key}");
    }

    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"));
    let row = &board["rows"][0];
    assert_eq!(row["method"], "noisy-net");
    assert_eq!(
        row["scores"]["synthA"]["score"],
        bop19["bop19_average_recall"]
    );
    for (obj, ar) in bop19["obj_average_recalls"].as_object().expect("objects") {
        assert_eq!(&row["objects"][obj], ar, "object {obj}");
    }
    let board = get_json(&format!("{base}/api/v1/leaderboards/eccv18"));
    assert_eq!(
        board["rows"][0]["scores"]["synthA"]["score"],
        eccv18["recall"]
    );

    let html = client()
        .get(format!("{base}/leaderboards/bop19?dataset=synthA"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    let shown = format!(
        "{:.1}",
        bop19["bop19_average_recall"].as_f64().expect("ar") * 100.0
    );
    assert!(
        html.contains("noisy-net") && html.contains(&shown),
        "{kind:?}: {shown} not on the page"
    );
    let page = client()
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains("<svg"), "curves are drawn");

    // The same file again for the same method is recognised.
    let again = upload(&server, "noisy-net", "synthA", &file, None);
    assert_eq!(again.status(), 200);
    let again: Value = again.json().expect("json");
    assert_eq!(again["duplicate"], true);
    assert_eq!(again["id"], id);
}
both_databases!(upload_evaluate_and_rank);

fn malformed_upload_leaves_nothing(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "bad");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    for (file, needle) in [
        (
            "wrong-columns_synthA-test.csv",
            "line 6 has 6 fields, expected 7",
        ),
        (
            "not-rotation_synthA-test.csv",
            "R on line 5 is not a rotation matrix",
        ),
        ("nan_synthA-test.csv", "non-finite number on line 4"),
    ] {
        let r = upload(
            &server,
            "broken",
            "synthA",
            &fixtures().join("results/malformed").join(file),
            None,
        );
        assert_eq!(r.status(), 422, "{kind:?} {file}");
        let body: Value = r.json().expect("json");
        let problems = body["problems"].as_array().expect("problems");
        assert!(
            problems
                .iter()
                .any(|p| p["message"].as_str().is_some_and(|m| m.contains(needle))),
            "{kind:?} {file}: {body}"
        );
        assert!(problems.iter().all(|p| p["line"].as_u64().is_some()));
    }
    // The browser form shows the problems too.
    let (b, csrf) = browser(&server, "formuser");
    let form = multipart::Form::new()
        .text("csrf", csrf)
        .text("method", "broken")
        .text("dataset", "synthA")
        .file(
            "file",
            fixtures().join("results/malformed/wrong-columns_synthA-test.csv"),
        )
        .expect("file");
    let r = b
        .post(format!("{}/submit", server.base))
        .multipart(form)
        .send()
        .expect("form");
    assert_eq!(r.status(), 422);
    assert!(
        r.text()
            .expect("html")
            .contains("line 6 has 6 fields, expected 7")
    );

    assert_eq!(
        column(&db, &data, "SELECT CAST(COUNT(*) AS TEXT) FROM submissions"),
        vec!["0".to_string()],
        "{kind:?}: no submission row"
    );
    let stored: Vec<_> = std::fs::read_dir(data.join("submissions"))
        .expect("dir")
        .collect();
    assert!(stored.is_empty(), "{kind:?}: no stored file: {stored:?}");

    // Unknown datasets and missing fields are refused with a clear 4xx (the file is named so
    // that its name says no dataset: a BOP name would contradict the field, a 422).
    let unnamed = dir.path().join("results.csv");
    std::fs::copy(fixtures().join("results/gtexact_synthA-test.csv"), &unnamed).expect("copy");
    let r = upload(&server, "x", "nope", &unnamed, None);
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("unknown dataset"));
}
both_databases!(malformed_upload_leaves_nothing);

#[test]
fn an_upload_over_the_size_bound_is_refused_with_413() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "big");
    let server = start(
        &dir.path().join("data"),
        &datasets,
        &db,
        &["--max-upload-mb", "1"],
    );
    // Announce a 50 MiB body and send none of it: the answer must come without the body.
    let addr = server.base.trim_start_matches("http://");
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    write!(
        stream,
        "POST /api/v1/submissions HTTP/1.1\r\nHost: {addr}\r\nContent-Type: multipart/form-data; boundary=x\r\nContent-Length: {}\r\n\r\n",
        50u64 << 20
    )
    .expect("headers sent");
    let mut answer = [0u8; 64];
    let n = stream.read(&mut answer).expect("an answer before the body");
    let head = String::from_utf8_lossy(&answer[..n]);
    assert!(head.starts_with("HTTP/1.1 413"), "{head}");

    // A streamed (chunked) upload that grows past the bound is cut off with 413 as well.
    let big = dir.path().join("big.csv");
    let csv =
        std::fs::read_to_string(fixtures().join("results/gtexact_synthA-test.csv")).expect("csv");
    let mut text = String::new();
    while text.len() < 3 << 20 {
        text.push_str(&csv);
    }
    std::fs::write(&big, text).expect("write");
    let file = std::fs::File::open(&big).expect("open");
    let part = multipart::Part::reader(file).file_name("big.csv");
    let form = multipart::Form::new()
        .text("method", "huge")
        .text("dataset", "synthA")
        .part("file", part);
    match client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
    {
        Ok(r) => assert_eq!(r.status(), 413),
        // The server may close the connection before the client finishes sending.
        Err(e) => assert!(e.is_body() || e.is_request(), "{e}"),
    }
    let stored: Vec<_> = std::fs::read_dir(dir.path().join("data/submissions"))
        .expect("dir")
        .collect();
    assert!(stored.is_empty(), "nothing kept: {stored:?}");
}
