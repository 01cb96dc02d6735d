//! A dataset file that turns unreadable while a job evaluates (issue 29, point 4): the depth
//! images of the dataset are cut short, as a copy interrupted over them would leave them, once
//! the job is under way. The file uploaded is not at fault, so the job is not failed as the
//! user's: it is tried again as the service's fault, each attempt counted, and once out of
//! attempts fails as the service's fault, which its page says and the uploader's fair-use
//! count does not charge. The queue lives in the database, so this runs on both.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::{
    Db, TestDb, both_databases, get_as, get_json, signed_in, start, synth_with_results, upload,
};
use serde_json::Value;

/// Every depth image under `dir`.
fn depth_images(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir)
        .expect("folder")
        .filter_map(|e| e.ok())
    {
        let path = entry.path();
        if path.is_dir() {
            found.extend(depth_images(&path));
        } else if path.parent().is_some_and(|p| p.ends_with("depth")) {
            found.push(path);
        }
    }
    found
}

/// Polls submission `id` until `until` holds of it, for at most `limit`.
fn poll(base: &str, id: i64, limit: Duration, until: impl Fn(&Value) -> bool) -> Value {
    let start = Instant::now();
    loop {
        let s = get_json(&format!("{base}/api/v1/submissions/{id}"));
        if until(&s) {
            return s;
        }
        assert!(start.elapsed() < limit, "submission {id}: {s}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn a_dataset_file_broken_mid_job_fails_it_as_the_services_fault(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let (datasets, results) = synth_with_results(dir.path(), "synthbig", 20, 10);
    let file = results
        .iter()
        .find(|p| p.to_string_lossy().contains("noisy"))
        .expect("a noisy demo result");
    let db = TestDb::new(kind, "brokends");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &["--no-demo", "--eval-threads", "1"]);
    let r = upload(&server, "broken", "synthbig", file, None);
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("JSON")["id"].as_i64().expect("id");

    // Under way: some estimates evaluated, the job not finished.
    let running = poll(&server.base, id, Duration::from_secs(60), |s| {
        assert_ne!(s["status"], "done", "{kind:?}: done before the files broke");
        s["status"] == "running" && s["work_done"].as_i64().unwrap_or(0) > 0
    });
    let images = depth_images(&datasets.join("synthbig"));
    assert!(images.len() >= 200, "{} depth images", images.len());
    for image in &images {
        let f = std::fs::OpenOptions::new()
            .write(true)
            .open(image)
            .expect("depth image");
        let len = f.metadata().expect("size").len();
        f.set_len(len / 2).expect("cut short");
    }
    assert_eq!(running["attempts"], 1, "{kind:?}");

    let failed = poll(&server.base, id, Duration::from_secs(180), |s| {
        assert_ne!(
            s["status"], "done",
            "{kind:?}: scored from broken files: {s}"
        );
        s["status"] == "failed"
    });
    assert_eq!(failed["fault"], "service", "{kind:?}: {failed}");
    assert_eq!(
        failed["attempts"], 3,
        "{kind:?}: every attempt kept: {failed}"
    );
    let error = failed["error"].as_str().expect("error");
    assert!(error.contains("depth"), "{kind:?}: {error}");

    // The page tells the uploader it was not their file; their quota is not charged.
    let owner = signed_in(&server, "tester");
    let page = owner
        .get(format!("{}/submissions/{id}", server.base))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains("a fault of the service, not of your file"),
        "{kind:?}: {page}"
    );
    let quota: Value = get_as(
        &format!("{}/api/v1/me/quota?dataset=synthbig", server.base),
        &server.token,
    )
    .json()
    .expect("JSON");
    assert_eq!(quota["used"], 0, "{kind:?}: {quota}");
}
both_databases!(a_dataset_file_broken_mid_job_fails_it_as_the_services_fault);
