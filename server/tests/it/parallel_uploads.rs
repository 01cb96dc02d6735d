//! Twelve simultaneous uploads over HTTP by one user, for a method that does not exist yet,
//! against a limit of 5 per day: exactly 5 are created and the other 7 answered 429 stating the
//! limit, never 500 (the method is created once, and the count is exact). Run on both
//! databases, as each serialises the uploads its own way.

use std::path::{Path, PathBuf};
use std::sync::Barrier;

use crate::common::{Db, TestDb, both_databases, fixtures, reference_datasets, start, upload_with};
use serde_json::Value;

/// A distinct valid result file for the reference dataset: its estimates plus one more, with
/// a score of its own.
fn variant(dir: &Path, k: usize) -> PathBuf {
    let text = std::fs::read_to_string(fixtures().join("results/gtexact_synthA-test.csv"))
        .expect("fixture");
    let first = text.lines().nth(1).expect("an estimate");
    let mut fields: Vec<String> = first.split(',').map(str::to_string).collect();
    fields[3] = format!("0.{:03}", k + 1);
    let path = dir.join(format!("racer{k}_synthA-test.csv"));
    std::fs::write(&path, format!("{text}{}\n", fields.join(","))).expect("write");
    path
}

fn parallel_uploads_keep_the_limit(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "race");
    let args = ["--submissions-per-window", "5"];
    let server = start(&dir.path().join("data"), &datasets, &db, &args);
    let files: Vec<PathBuf> = (0..12).map(|k| variant(dir.path(), k)).collect();
    let barrier = Barrier::new(files.len());
    let answers: Vec<(u16, Value)> = std::thread::scope(|s| {
        let handles: Vec<_> = files
            .iter()
            .map(|file| {
                let (server, barrier) = (&server, &barrier);
                s.spawn(move || {
                    barrier.wait();
                    let fields = [("method", "new-racer"), ("dataset", "synthA")];
                    let r = upload_with(server, &server.token, &fields, file);
                    let status = r.status().as_u16();
                    (status, r.json().unwrap_or(Value::Null))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    let created: Vec<&Value> = answers
        .iter()
        .filter(|(s, _)| *s == 201 || *s == 202)
        .map(|(_, b)| b)
        .collect();
    let limited: Vec<&Value> = answers
        .iter()
        .filter(|(s, _)| *s == 429)
        .map(|(_, b)| b)
        .collect();
    let statuses: Vec<u16> = answers.iter().map(|(s, _)| *s).collect();
    assert_eq!(created.len(), 5, "{kind:?}: {statuses:?}");
    assert_eq!(limited.len(), 7, "{kind:?}: {statuses:?}");
    for body in limited {
        let error = body["error"].as_str().unwrap_or_default();
        assert!(error.contains("at most 5 submissions"), "{kind:?}: {body}");
    }
    // All five under one method.
    let methods: std::collections::BTreeSet<String> = created
        .iter()
        .map(|b| b["submission"]["method_id"].to_string())
        .collect();
    assert_eq!(methods.len(), 1, "{kind:?}: {methods:?}");
}
both_databases!(parallel_uploads_keep_the_limit);
