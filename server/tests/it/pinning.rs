//! Pinning means one thing (issue 27), over real HTTP on both databases: only a public finished
//! submission can be pinned as its method's entry; pinning one queued, private or held back
//! answers 409 naming why, its owner's page offers no pin button for it, and the page of
//! another submission names the pinned entry.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{
    BIN, Db, TestDb, both_databases, database_url, fixtures, get_as, post_as, reference_datasets,
    signed_in, start, upload_with,
};
use crate::publishing::in_metres;
use serde_json::Value;

/// A `poseboard worker` on the server's database, stopped when this goes away.
struct Worker(Child);

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn only_public_finished_submissions_are_pinned(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "pinning");
    // No worker in the server: the uploads wait in the queue until the test starts one.
    let server = start(
        &data,
        &datasets,
        &db,
        &[
            "--no-demo",
            "--workers",
            "0",
            "--submissions-per-window",
            "0",
        ],
    );
    let (base, token) = (server.base.clone(), server.token.clone());
    let results = fixtures().join("results");
    let submit = |file: &Path, visibility: &str| -> i64 {
        let fields = [
            ("method", "pin-net"),
            ("dataset", "synthA"),
            ("visibility", visibility),
        ];
        let r = upload_with(&server, &token, &fields, file);
        assert_eq!(r.status(), 202, "{kind:?}");
        r.json::<Value>().expect("json")["id"].as_i64().expect("id")
    };
    let public = submit(&results.join("noisesmall_synthA-test.csv"), "public");
    let private = submit(&results.join("noisemedium_synthA-test.csv"), "private");
    let held = submit(&in_metres(dir.path()), "public");

    // The owner's browser sees the pages with their buttons.
    let b = signed_in(&server, "tester");
    let page = |id: i64| {
        b.get(format!("{base}/submissions/{id}"))
            .send()
            .expect("page")
            .text()
            .expect("html")
    };
    let pin_button = |id: i64| format!(r#"action="/submissions/{id}/pin""#);
    let pin = |id: i64, action: &str| -> (u16, String) {
        let r = post_as(
            &format!("{base}/api/v1/submissions/{id}/{action}"),
            &token,
            None,
        );
        let status = r.status().as_u16();
        let body: Value = r.json().expect("json");
        (
            status,
            body["error"].as_str().unwrap_or_default().to_string(),
        )
    };

    let (status, error) = pin(public, "pin");
    assert_eq!(status, 409, "{kind:?}: queued: {error}");
    assert!(error.contains("queued"), "{kind:?}: {error}");
    assert!(!page(public).contains(&pin_button(public)), "{kind:?}");

    let _worker = Worker(
        Command::new(BIN)
            .arg("worker")
            .arg("--data-dir")
            .arg(data.join("worker"))
            .arg("--datasets")
            .arg(&datasets)
            .env("DATABASE_URL", database_url(&db, &data))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("worker starts"),
    );
    let started = Instant::now();
    for id in [public, private, held] {
        loop {
            let s: Value = get_as(&format!("{base}/api/v1/submissions/{id}"), &token)
                .json()
                .expect("json");
            if s["status"] == "done" {
                break;
            }
            assert_ne!(s["status"], "failed", "{kind:?}: {s}");
            assert!(started.elapsed() < Duration::from_secs(120), "{s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    for (id, why) in [(private, "private"), (held, "held")] {
        let (status, error) = pin(id, "pin");
        assert_eq!(status, 409, "{kind:?}: {why}: {error}");
        assert!(error.contains(why), "{kind:?}: {error}");
        assert!(!page(id).contains(&pin_button(id)), "{kind:?}: {why}");
    }
    assert!(page(public).contains(&pin_button(public)), "{kind:?}");
    assert_eq!(pin(public, "pin").0, 200, "{kind:?}");
    let other = page(private);
    assert!(
        other.contains(&format!(
            r#"<a href="/submissions/{public}">submission {public}</a> (pinned)"#
        )),
        "{kind:?}: the page names the pinned entry"
    );
    let pinned = page(public);
    assert!(pinned.contains("pinned by its owner"), "{kind:?}");
    assert!(
        pinned.contains(&format!(r#"action="/submissions/{public}/unpin""#)),
        "{kind:?}"
    );
    assert_eq!(
        pin(public, "unpin").0,
        200,
        "{kind:?}: unpinning stays allowed"
    );
    assert_eq!(pin(private, "unpin").0, 200, "{kind:?}");
}
both_databases!(only_public_finished_submissions_are_pinned);
