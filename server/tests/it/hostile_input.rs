//! Hostile input: SQL and script in a method name and description are stored as given and shown
//! escaped on every page, an uploaded file name with `..` and separators is cut to its last
//! component and nothing escapes the data directory, and giant fields are refused with 400. Run
//! on both databases, as the text goes through both drivers.

use std::time::Duration;

use crate::common::{
    Db, TestDb, both_databases, client, fixtures, get_as, post_without_file, reference_datasets,
    start, upload_with, wait_done,
};
use reqwest::blocking::multipart;
use serde_json::Value;

fn hostile_input(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "hostile");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let script = "<script>alert(1)</script>";
    let method = "x'); DROP TABLE users; --<script>alert(1)</script>";
    // A file name with path separators and `..` is kept as its last component.
    let tricky = dir.path().join("evil.csv");
    std::fs::copy(fixtures().join("results/gtexact_synthA-test.csv"), &tricky).expect("copy");
    let form = multipart::Form::new()
        .text("method", method)
        .text("dataset", "synthA")
        .text(
            "description",
            format!("{script}<img src=x onerror=alert(2)>"),
        )
        .text("hardware", "\"><script>alert(3)</script>")
        // Published: the public pages must show it harmlessly.
        .text("visibility", "public")
        .part(
            "file",
            multipart::Part::file(&tricky)
                .expect("file")
                .file_name("../../etc/passwd"),
        );
    let r = client()
        .post(format!("{base}/api/v1/submissions"))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
        .expect("upload");
    assert_eq!(r.status(), 202, "{kind:?}");
    let sub: Value = r.json().expect("json");
    assert_eq!(sub["submission"]["file_name"], "passwd");
    assert_eq!(sub["submission"]["method"], method, "stored as given");
    let id = sub["id"].as_i64().expect("id");
    wait_done(&base, id, Duration::from_secs(60));
    // Shown harmlessly: escaped on every page.
    let method_id = sub["submission"]["method_id"].as_i64().expect("method id");
    for page in [
        format!("{base}/submissions/{id}"),
        format!("{base}/methods/{method_id}"),
        format!("{base}/leaderboards/bop19"),
    ] {
        let html = get_as(&page, "").text().expect("html");
        assert!(
            !html.contains("<script>alert"),
            "{kind:?}: {page} runs the script"
        );
        assert!(
            html.contains("&lt;script&gt;") || html.contains("&#60;script&#62;"),
            "{kind:?}: {page}"
        );
    }
    // The database is intact: accounts still work.
    assert_eq!(post_without_file(&server, &server.token), 400);
    // Giant fields are refused with a clear 4xx.
    let giant = "a".repeat(20_000);
    let r = upload_with(
        &server,
        &server.token,
        &[
            ("method", "big"),
            ("dataset", "synthA"),
            ("description", giant.as_str()),
        ],
        &tricky,
    );
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("longer than"));
    let r = upload_with(
        &server,
        &server.token,
        &[("method", &"m".repeat(500)), ("dataset", "synthA")],
        &tricky,
    );
    assert_eq!(r.status(), 400);
    // Values that name nothing are refused, not silently read as something else.
    for (fields, what) in [
        (&[("visibility", "Public")][..], "visibility"),
        (&[("modality", "thermal")][..], "modality"),
        (&[("training_data", "imagenet")][..], "training_data"),
        (&[("paper_url", "javascript:alert(1)")][..], "paper_url"),
        (&[("method", "zero\u{200b}width")][..], "method"),
    ] {
        let mut all = vec![("method", "strict"), ("dataset", "synthA")];
        all.retain(|(k, _)| fields.iter().all(|(f, _)| f != k));
        all.extend_from_slice(fields);
        let r = upload_with(&server, &server.token, &all, &tricky);
        assert_eq!(r.status(), 400, "{kind:?} {what}");
        assert!(r.text().expect("body").contains(what), "{kind:?} {what}");
    }
    for query in ["sort=bogus", "modality=thermal", "training=imagenet"] {
        let r = client()
            .get(format!("{}/api/v1/leaderboards/bop19?{query}", server.base))
            .send()
            .expect("board");
        assert_eq!(r.status(), 400, "{kind:?} {query}");
    }
    // Nothing escaped the data directory.
    assert!(!dir.path().join("etc").exists());
}
both_databases!(hostile_input);
