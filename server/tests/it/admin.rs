//! Administration: the admin routes do not exist for other accounts; an administrator can hide,
//! unhide, re-run (to the same scores) and delete a submission (with its file), retire and add
//! back datasets from the API and from the datasets page (with CSRF), and every action lands in
//! the audit log, newest first. Run on both databases.

use crate::common;

use std::time::Duration;

use crate::common::{
    Db, TestDb, admin, both_databases, csrf_of, fixtures, get_as, get_json, post_as,
    reference_datasets, start, upload, wait_done,
};
use reqwest::blocking::Client;
use serde_json::Value;

fn administration(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "admin");
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).expect("mkdir");
    std::fs::write(data.join("root.pw"), "root-secret-password\n").expect("pw");
    admin(
        &data,
        &db,
        &[
            "create-user",
            "root",
            "--password-file",
            data.join("root.pw").to_str().expect("path"),
            "--admin",
        ],
    );
    let root = admin(&data, &db, &["create-token", "root"]);
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "moderated", "synthA", &file, None);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let done = wait_done(&base, id, Duration::from_secs(60));
    let action = |token: &str, what: &str| {
        post_as(
            &format!("{base}/api/v1/admin/submissions/{id}/{what}"),
            token,
            None,
        )
    };

    // Not an administrator: the routes do not exist.
    assert_eq!(action(&server.token, "hide").status(), 404, "{kind:?}");
    assert_eq!(
        get_as(&format!("{base}/api/v1/admin/audit"), &server.token).status(),
        404
    );

    assert!(action(&root, "hide").status().is_success());
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), "").status(),
        404,
        "{kind:?}: hidden"
    );
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), &server.token).status(),
        200,
        "owner still sees it"
    );
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board["rows"].as_array().map(Vec::len), Some(0));
    assert!(action(&root, "unhide").status().is_success());
    assert_eq!(
        get_json(&format!("{base}/api/v1/leaderboards/bop19"))["rows"]
            .as_array()
            .map(Vec::len),
        Some(1)
    );

    // A re-run evaluates again, to the same scores.
    assert!(action(&root, "rerun").status().is_success());
    let again = wait_done(&base, id, Duration::from_secs(60));
    assert_eq!(again["scores"], done["scores"], "{kind:?}");

    // Datasets can be retired and added back (by folder name only).
    let retire = post_as(
        &format!("{base}/api/v1/admin/datasets/synthA/retire"),
        &root,
        None,
    );
    assert!(retire.status().is_success());
    assert!(
        !get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );
    let bad = post_as(
        &format!("{base}/api/v1/admin/datasets"),
        &root,
        Some(serde_json::json!({ "name": "../etc" })),
    );
    assert_eq!(bad.status(), 400);
    let add = post_as(
        &format!("{base}/api/v1/admin/datasets"),
        &root,
        Some(serde_json::json!({ "name": "synthA" })),
    );
    assert!(
        add.status().is_success(),
        "{}",
        add.text().unwrap_or_default()
    );
    assert!(
        get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );

    // The same from the datasets page, in an administrator's browser.
    let b = Client::builder()
        .cookie_store(true)
        .build()
        .expect("client");
    let page = b
        .post(format!("{base}/login"))
        .form(&[
            ("name", "root"),
            ("password", "root-secret-password"),
            ("next", "/datasets"),
        ])
        .send()
        .expect("login")
        .text()
        .expect("html");
    let csrf = csrf_of(&page);
    let r = b
        .post(format!("{base}/admin/datasets/synthA/retire"))
        .form(&[("csrf", csrf.as_str())])
        .send()
        .expect("retire");
    assert!(r.status().is_success());
    assert!(
        !get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );
    let forged = b
        .post(format!("{base}/admin/datasets"))
        .form(&[("csrf", "forged"), ("name", "synthA")])
        .send()
        .expect("add");
    assert_eq!(forged.status(), 403);
    let r = b
        .post(format!("{base}/admin/datasets"))
        .form(&[("csrf", csrf.as_str()), ("name", "synthA")])
        .send()
        .expect("add");
    assert!(r.status().is_success());
    assert!(
        get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );

    // Deleted: gone for everyone, with its file.
    assert!(action(&root, "delete").status().is_success());
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), &root).status(),
        404
    );
    assert_eq!(
        std::fs::read_dir(data.join("submissions"))
            .expect("dir")
            .count(),
        0
    );
    assert!(
        common::column(&db, &data, "SELECT sha256 FROM submission_files").is_empty(),
        "the database copy of the file went with it"
    );

    let audit = get_as(&format!("{base}/api/v1/admin/audit"), &root)
        .json::<Value>()
        .expect("json");
    let actions: Vec<&str> = audit["audit"]
        .as_array()
        .expect("entries")
        .iter()
        .filter_map(|e| {
            assert_eq!(e["actor"], "root");
            e["action"].as_str()
        })
        .collect();
    assert_eq!(
        actions,
        [
            "delete",
            "add dataset",
            "retire dataset",
            "add dataset",
            "retire dataset",
            "rerun",
            "unhide",
            "hide"
        ],
        "{kind:?}"
    );

    // A retired dataset stays retired across a restart, until it is added again.
    let retire = post_as(
        &format!("{base}/api/v1/admin/datasets/synthA/retire"),
        &root,
        None,
    );
    assert!(retire.status().is_success());
    drop(server);
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let served = get_json(&format!("{base}/api/v1/datasets"));
    assert!(!served.to_string().contains("synthA"), "{kind:?}: {served}");
    let add = post_as(
        &format!("{base}/api/v1/admin/datasets"),
        &root,
        Some(serde_json::json!({ "name": "synthA" })),
    );
    assert!(add.status().is_success());
    assert!(
        get_json(&format!("{base}/api/v1/datasets"))
            .to_string()
            .contains("synthA")
    );
}
both_databases!(administration);
