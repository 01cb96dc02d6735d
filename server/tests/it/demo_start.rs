//! The first start, as the README's first command makes it: no datasets directory and every
//! setting at its default. The demo dataset is made, every demo file is submitted (more files
//! than the fair-use limit lets a user submit in a day: the demo is the service's own, not a
//! user's) and evaluated, and every board has its demo rows.

use std::time::Duration;

use crate::common::{
    Db, TestDb, board_methods, both_databases, get_json, start_first_time, wait_done,
};

const WAIT: Duration = Duration::from_secs(300);

fn first_start(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "demo_start");
    let server = start_first_time(&dir.path().join("data"), &db);
    let base = &server.base;

    let methods = get_json(&format!("{base}/api/v1/methods"));
    let methods = methods["methods"].as_array().expect("methods");
    let mut submissions = 0;
    for m in methods {
        let id = m["id"].as_i64().expect("id");
        let of_method = get_json(&format!("{base}/api/v1/methods/{id}"));
        for s in of_method["submissions"].as_array().expect("submissions") {
            wait_done(base, s["id"].as_i64().expect("id"), WAIT);
            submissions += 1;
        }
    }
    let limit = 5;
    assert!(
        submissions > limit,
        "{submissions} demo submissions: the test should submit more than the default limit"
    );

    let sorted = |mut v: Vec<String>| {
        v.sort();
        v
    };
    let pose = sorted(board_methods(&get_json(&format!(
        "{base}/api/v1/leaderboards/bop19"
    ))));
    assert!(pose.len() >= 3, "{pose:?}");
    assert!(pose.iter().all(|n| n.starts_with("demo-")), "{pose:?}");
    assert_eq!(
        pose,
        sorted(board_methods(&get_json(&format!(
            "{base}/api/v1/leaderboards/eccv18"
        )))),
        "the same methods under both 6D protocols"
    );
    for task in ["bop22-det", "bop22-seg"] {
        let rows = board_methods(&get_json(&format!("{base}/api/v1/leaderboards/{task}")));
        assert_eq!(rows.len(), 1, "{task}: {rows:?}");
    }
    // The demo 6D detector, scored at start, is on the bop24 board.
    let detection = board_methods(&get_json(&format!("{base}/api/v1/leaderboards/bop24")));
    assert_eq!(detection, ["demo-6d-detector"], "the bop24 board");
    assert_eq!(
        pose.len() + 3,
        methods.len(),
        "every demo method is on a board"
    );
}

both_databases!(first_start);
