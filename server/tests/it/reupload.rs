//! Re-sending a file already submitted for a method: the existing submission is answered
//! (200, not evaluated again), and a visibility given with it becomes that submission's, so
//! re-sending is how its owner publishes or withdraws it; without the field it keeps its own
//! (a retry never publishes a private submission). Run on both databases.

use crate::common;

use std::path::Path;

use crate::common::{
    Db, Server, TestDb, both_databases, fixtures, get_as, reference_datasets, start, upload_with,
};
use serde_json::Value;
use std::time::{Duration, Instant};

/// The methods on the BOP'19 board's JSON (served from the board cache).
fn on_board(server: &Server) -> Vec<String> {
    common::board_methods(&common::get_json(&format!(
        "{}/api/v1/leaderboards/bop19",
        server.base
    )))
}

/// Waits until the owner sees the submission evaluated.
fn wait_owner(server: &Server, id: i64) {
    let start = Instant::now();
    loop {
        let s: Value = get_as(
            &format!("{}/api/v1/submissions/{id}", server.base),
            &server.token,
        )
        .json()
        .expect("json");
        if s["status"] == "done" {
            return;
        }
        assert!(start.elapsed() < Duration::from_secs(120), "not done: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn send(server: &Server, file: &Path, visibility: Option<&str>) -> (u16, Value) {
    let mut fields = vec![("method", "shy-net"), ("dataset", "synthA")];
    if let Some(v) = visibility {
        fields.push(("visibility", v));
    }
    let r = upload_with(server, &server.token, &fields, file);
    (r.status().as_u16(), r.json().expect("json"))
}

fn reupload_with_another_visibility(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "reup");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let public_status = |id: i64| {
        get_as(&format!("{}/api/v1/submissions/{id}", server.base), "")
            .status()
            .as_u16()
    };

    let (status, first) = send(&server, &file, Some("private"));
    assert_eq!(status, 202, "{kind:?}: {first}");
    let id = first["id"].as_i64().expect("id");
    assert_eq!(public_status(id), 404, "{kind:?}: private");
    wait_owner(&server, id);
    assert!(
        !on_board(&server).contains(&"shy-net".to_string()),
        "{kind:?}: private"
    );

    // Asked public: the same submission, now public.
    let (status, again) = send(&server, &file, Some("public"));
    assert_eq!(status, 200, "{kind:?}: {again}");
    assert_eq!(again["id"], id, "{kind:?}");
    assert_eq!(again["duplicate"], true, "{kind:?}");
    assert_eq!(again["submission"]["visibility"], "public", "{kind:?}");
    assert_eq!(public_status(id), 200, "{kind:?}: published");
    assert!(
        on_board(&server).contains(&"shy-net".to_string()),
        "{kind:?}: a published submission enters the cached board"
    );

    // Without the field: unchanged.
    let (status, again) = send(&server, &file, None);
    assert_eq!(status, 200, "{kind:?}");
    assert_eq!(again["submission"]["visibility"], "public", "{kind:?}");

    // Asked private: withdrawn.
    let (status, again) = send(&server, &file, Some("private"));
    assert_eq!(status, 200, "{kind:?}");
    assert_eq!(again["id"], id, "{kind:?}");
    assert_eq!(again["submission"]["visibility"], "private", "{kind:?}");
    assert_eq!(public_status(id), 404, "{kind:?}: withdrawn");
    assert!(
        !on_board(&server).contains(&"shy-net".to_string()),
        "{kind:?}: a withdrawn submission leaves the cached board"
    );
    let (status, again) = send(&server, &file, None);
    assert_eq!(status, 200, "{kind:?}");
    assert_eq!(
        again["submission"]["visibility"], "private",
        "{kind:?}: a retry without the field does not publish it"
    );
}
both_databases!(reupload_with_another_visibility);
