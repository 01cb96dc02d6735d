//! The service prepares the datasets it serves (issue 26 point 2), as an operator runs it: the
//! worker prepares its copy in the background while the datasets page and its JSON follow the
//! progress, a job that comes meanwhile is evaluated from the dataset, and one evaluated from
//! the prepared form is given the very same stored scores. A form made by another evaluator
//! (stale) or for other content (foreign) is rebuilt, and a truncated file is refused by its
//! checksum, its image computed from the dataset and the file rebuilt, each said in the log.

use std::fs::File;
use std::path::Path;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::common::{
    Db, Server, TestDb, both_databases, client, fixtures, get_json, poseboard, reference_datasets,
    start, upload_scored,
};

/// This server's one recorded preparation of `synthA`, once there is one.
fn preparation(base: &str) -> Option<Value> {
    let listed = get_json(&format!("{base}/api/v1/datasets"));
    let synth = listed["datasets"]
        .as_array()
        .expect("datasets")
        .iter()
        .find(|d| d["name"] == "synthA")
        .expect("synthA served")
        .clone();
    let prepared = synth["prepared"].as_array().expect("prepared").clone();
    assert!(prepared.len() <= 1, "one host, one folder: {prepared:?}");
    prepared.into_iter().next()
}

/// Polls until `check` holds, for at most two minutes.
fn wait_until(what: &str, mut check: impl FnMut() -> bool) {
    let start = Instant::now();
    while !check() {
        assert!(start.elapsed() < Duration::from_secs(120), "never {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits for the preparation of `synthA` to be in `state`, and returns it.
fn wait_state(base: &str, state: &str) -> Value {
    let mut seen = None;
    wait_until(&format!("{state}: {seen:?}"), || {
        seen = preparation(base);
        seen.as_ref().is_some_and(|p| p["state"] == state)
    });
    seen.expect("a preparation")
}

/// The server's log, without the terminal colours it writes even to a file.
fn log(data: &Path) -> String {
    let text = std::fs::read_to_string(data.join("server.log")).expect("server log");
    let mut plain = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            chars.by_ref().find(|c| c.is_ascii_alphabetic());
        } else {
            plain.push(c);
        }
    }
    plain
}

/// The lines the evaluation of submission `id` logged.
fn job_lines(data: &Path, id: i64) -> Vec<String> {
    let span = format!("submission={id} ");
    log(data)
        .lines()
        .filter(|l| l.contains(&span))
        .map(str::to_string)
        .collect()
}

/// The stored reports of a submission, per protocol.
fn stored_report(server: &Server, id: i64) -> Value {
    let url = format!("{}/api/v1/submissions/{id}/report", server.base);
    let r = client().get(url).send().expect("answered");
    assert!(r.status().is_success(), "report {id}: {}", r.status());
    r.json().expect("JSON")
}

fn datasets_page(base: &str) -> String {
    client()
        .get(format!("{base}/datasets"))
        .send()
        .expect("answered")
        .text()
        .expect("page")
}

fn prepared_in_the_background(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "prep_background");
    // Another process on this host is preparing the same folder (it holds the lock): the
    // server's preparation waits for it, so the first job surely comes while it prepares.
    std::fs::create_dir_all(data.join("prepared")).expect("mkdir");
    let lock = File::create(data.join("prepared/synthA.lock")).expect("lock file");
    lock.lock().expect("locked");
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let base = server.base.clone();

    let mut waiting = None;
    wait_until("shown waiting for the other process", || {
        waiting = preparation(&base);
        waiting.as_ref().is_some_and(|p| !p["detail"].is_null())
    });
    let waiting = waiting.expect("a preparation");
    assert_eq!(waiting["state"], "preparing", "{waiting}");
    assert!(
        waiting["detail"]
            .as_str()
            .is_some_and(|d| d.contains("another process")),
        "{waiting}"
    );
    assert!(
        waiting["folder"]
            .as_str()
            .is_some_and(|f| f.ends_with("prepared")),
        "{waiting}"
    );
    let page = datasets_page(&base);
    assert!(page.contains("preparing"), "{page}");

    let results = fixtures().join("results/noisemedium_synthA-test.csv");
    let plain = upload_scored(&server, "plain", "synthA", &results, None)["id"]
        .as_i64()
        .expect("id");
    let lines = job_lines(&data, plain).join("\n");
    assert!(
        lines.contains("evaluating from the dataset: no prepared form is ready"),
        "{lines}"
    );
    assert_eq!(wait_state(&base, "preparing")["images_done"], 0);

    // The other process is done: this one prepares the folder, the page follows it.
    drop(lock);
    let ready = wait_state(&base, "ready");
    assert_eq!(ready["images_total"], 8, "{ready}");
    assert_eq!(ready["images_done"], 8, "{ready}");
    assert!(ready["detail"].is_null(), "{ready}");
    let page = datasets_page(&base);
    assert!(page.contains("ready, 8 images"), "{page}");
    let form = data.join("prepared/synthA");
    assert!(form.join("manifest.json").is_file());
    assert!(log(&data).contains("dataset prepared"));

    // The same file evaluated from the prepared form: the same stored scores, to the bit.
    let prepared = upload_scored(&server, "prepared", "synthA", &results, None)["id"]
        .as_i64()
        .expect("id");
    let lines = job_lines(&data, prepared).join("\n");
    assert!(
        lines.contains("evaluating from the prepared form"),
        "{lines}"
    );
    let want = stored_report(&server, plain);
    assert!(want["bop19"]["bop19_average_recall"].is_f64(), "{want}");
    assert_eq!(stored_report(&server, prepared), want);

    // A truncated file: refused by its check, its image computed from the dataset (the
    // scores still exact), and rebuilt.
    let file = form.join("000001/000001.pbprep");
    let bytes = std::fs::read(&file).expect("prepared file");
    std::fs::write(&file, &bytes[..bytes.len() / 2]).expect("truncate");
    let damaged = upload_scored(&server, "damaged", "synthA", &results, None)["id"]
        .as_i64()
        .expect("id");
    assert_eq!(stored_report(&server, damaged), want);
    let lines = job_lines(&data, damaged).join("\n");
    assert!(
        lines.contains("prepared file refused, its image computed from the dataset")
            && lines.contains("000001.pbprep: truncated"),
        "{lines}"
    );
    wait_until("the truncated file rebuilt", || {
        std::fs::read(&file).is_ok_and(|now| now == bytes)
    });
    wait_until("the repair logged", || {
        log(&data).contains("prepared form repaired: rebuilt 1 damaged or missing file(s)")
    });
    let ready = wait_state(&base, "ready");
    assert_eq!(ready["images_done"], 8, "{ready}");
    assert!(!log(&data).contains("ERROR"), "{}", log(&data));
}
both_databases!(prepared_in_the_background);

/// Rewrites one key of a prepared form's manifest.
fn edit_manifest(form: &Path, key: &str, value: &str) {
    let path = form.join("manifest.json");
    let mut manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("manifest")).expect("JSON");
    manifest[key] = value.into();
    std::fs::write(&path, manifest.to_string()).expect("manifest written");
}

fn manifest_key(form: &Path, key: &str) -> Value {
    let text = std::fs::read_to_string(form.join("manifest.json")).unwrap_or_default();
    serde_json::from_str::<Value>(&text).map_or(Value::Null, |m| m[key].clone())
}

fn stale_and_foreign_forms_are_rebuilt(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let form = data.join("prepared/synthA");
    let db = TestDb::new(kind, "prep_rebuilt");
    // A form where the server keeps it, made by `poseboard dataset prepare` and then marked
    // as another evaluator's.
    let made = poseboard(&[
        "dataset",
        "prepare",
        datasets.join("synthA").to_str().expect("path"),
        "--out",
        form.to_str().expect("path"),
    ]);
    assert!(made.status.success(), "{made:?}");
    let evaluator = manifest_key(&form, "evaluator");
    let content = manifest_key(&form, "content_hash");
    edit_manifest(&form, "evaluator", "0.0.1 format 0");

    let server = start(&data, &datasets, &db, &["--no-demo"]);
    wait_until("the stale form rebuilt", || {
        log(&data).contains(
            "prepared form rebuilt, the previous one was stale: made by evaluator 0.0.1 format 0",
        )
    });
    wait_state(&server.base, "ready");
    assert_eq!(manifest_key(&form, "evaluator"), evaluator);
    drop(server);

    // Made for other content: foreign.
    edit_manifest(&form, "content_hash", &"0".repeat(64));
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    wait_until("the foreign form rebuilt", || {
        log(&data).contains(&format!(
            "prepared form rebuilt, the previous one was foreign: made for dataset content {}",
            "0".repeat(64)
        ))
    });
    wait_until("the form current again", || {
        manifest_key(&form, "content_hash") == content
    });
    let ready = wait_state(&server.base, "ready");
    assert_eq!(ready["images_done"], 8, "{ready}");
    assert!(!log(&data).contains("ERROR"), "{}", log(&data));
}
both_databases!(stale_and_foreign_forms_are_rebuilt);
