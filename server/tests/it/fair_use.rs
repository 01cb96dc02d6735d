//! Fair use: an account over its submissions-per-window limit gets 429 with when to retry,
//! re-sending an identical file is not limited, and once the window has passed the next upload
//! is accepted. The window is counted in the database, so this runs on both.

use std::time::Duration;

use crate::common::{Db, TestDb, both_databases, fixtures, reference_datasets, start, upload};
use serde_json::Value;

fn fair_use_limit(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "limit");
    let args = ["--submissions-per-window", "1", "--limit-window-secs", "3"];
    let server = start(&dir.path().join("data"), &datasets, &db, &args);
    let first = fixtures().join("results/noisesmall_synthA-test.csv");
    let second = fixtures().join("results/noisemedium_synthA-test.csv");
    assert_eq!(
        upload(&server, "limited", "synthA", &first, None).status(),
        202
    );
    let refused = upload(&server, "limited", "synthA", &second, None);
    assert_eq!(refused.status(), 429, "{kind:?}");
    assert!(refused.headers().contains_key("retry-after"));
    let body: Value = refused.json().expect("json");
    let retry_at = body["retry_at"].as_i64().expect("retry_at");
    // Re-sending an identical file is not a new submission and is not limited.
    assert_eq!(
        upload(&server, "limited", "synthA", &first, None).status(),
        200
    );
    // Once the window has passed, the next one is accepted.
    let now = || {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .expect("clock")
            .as_millis() as i64
    };
    while now() < retry_at {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(
        upload(&server, "limited", "synthA", &second, None).status(),
        202,
        "{kind:?}"
    );
}
both_databases!(fair_use_limit);
