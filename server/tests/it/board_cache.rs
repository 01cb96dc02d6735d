//! Leaderboards are served from memory, and a cached board never outlives a change: a job that
//! ends, an administrator's hide, unhide and delete, whether made by the server itself, by
//! another server process on the same database, or by a direct store call. A board is the same
//! bytes for every reader, signed in or not, and never shows a viewer's private rows. Real
//! HTTP against the `poseboard` binary, on both databases.

use crate::common;

use std::time::Duration;

use crate::common::{
    Db, Server, TestDb, admin_token, board_methods, both_databases, client, execute, fixtures,
    get_as, post_as, reference_datasets, start, upload, upload_with, wait_done,
};
use serde_json::Value;

fn html(server: &Server) -> String {
    let r = client()
        .get(format!("{}/leaderboards/bop19", server.base))
        .send()
        .expect("answered");
    assert!(r.status().is_success(), "{}", r.status());
    r.text().expect("page")
}

/// The methods of the BOP'19 board's JSON, in rank order.
fn methods(server: &Server) -> Vec<String> {
    board_methods(&common::get_json(&format!(
        "{}/api/v1/leaderboards/bop19",
        server.base
    )))
}

fn id_of(r: reqwest::blocking::Response) -> i64 {
    assert!(r.status().is_success(), "upload: {}", r.status());
    r.json::<Value>().expect("json")["id"].as_i64().expect("id")
}

fn boards_follow_every_change(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "boards");
    let data = dir.path().join("data");
    let root = admin_token(&data, &db, "root");
    // Server A never looks at the database for other processes' changes during this test (an
    // hour between looks): what it shows after its own changes, it learns from itself.
    let a = start(&data, &datasets, &db, &["--board-recheck-ms", "3600000"]);
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let act = |id: i64, what: &str| {
        let r = post_as(
            &format!("{}/api/v1/admin/submissions/{id}/{what}", a.base),
            &root,
            None,
        );
        assert!(r.status().is_success(), "{what}: {}", r.status());
    };

    // The empty board is rendered and kept while the jobs wait.
    assert!(!html(&a).contains("cached-alpha"));
    assert!(methods(&a).is_empty(), "{kind:?}");
    let private = id_of(upload_with(
        &a,
        &a.token,
        &[
            ("method", "private-gamma"),
            ("dataset", "synthA"),
            ("visibility", "private"),
        ],
        &fixtures().join("results/noisemedium_synthA-test.csv"),
    ));
    // One worker takes jobs in order: once alpha is done, the private one is too.
    let alpha = id_of(upload(&a, "cached-alpha", "synthA", &file, None));
    wait_done(&a.base, alpha, Duration::from_secs(120));
    let mine: Value = get_as(
        &format!("{}/api/v1/submissions/{private}", a.base),
        &a.token,
    )
    .json()
    .expect("json");
    assert_eq!(mine["status"], "done", "{kind:?}");

    // A job that ends changes the board, page and JSON.
    assert!(html(&a).contains("cached-alpha"), "{kind:?}: job ended");
    assert_eq!(methods(&a), ["cached-alpha"]);

    // The board is one shared answer: the owner of the private submission, signed in, gets the
    // very bytes an anonymous reader gets, without the private row.
    let owners = client()
        .get(format!("{}/leaderboards/bop19", a.base))
        .bearer_auth(&a.token)
        .send()
        .expect("answered")
        .text()
        .expect("page");
    assert_eq!(owners, html(&a));
    assert!(!owners.contains("private-gamma"));
    let owners_json: Value = client()
        .get(format!("{}/api/v1/leaderboards/bop19", a.base))
        .bearer_auth(&a.token)
        .send()
        .expect("answered")
        .json()
        .expect("json");
    assert_eq!(board_methods(&owners_json), ["cached-alpha"]);

    // Served from memory: a change made behind the service's back (no board version bump) does
    // not show.
    execute(
        &db,
        &data,
        "UPDATE methods SET name = 'renamed-quietly' WHERE name = 'cached-alpha'",
    );
    assert!(
        html(&a).contains("cached-alpha"),
        "{kind:?}: from the cache"
    );
    assert_eq!(methods(&a), ["cached-alpha"]);

    // An administrator's hide and unhide change it at once (and the unhidden board is rendered
    // afresh from the database).
    act(alpha, "hide");
    let page = html(&a);
    assert!(!page.contains("cached-alpha") && !page.contains("renamed-quietly"));
    assert!(methods(&a).is_empty(), "{kind:?}: hidden");
    act(alpha, "unhide");
    assert!(html(&a).contains("renamed-quietly"));
    assert_eq!(methods(&a), ["renamed-quietly"]);

    // Server B shares the database and looks at the board version on every request; A's
    // changes are another process's to it.
    let b = start(&data, &datasets, &db, &["--board-recheck-ms", "0"]);
    assert!(html(&b).contains("renamed-quietly"));
    assert_eq!(methods(&b), ["renamed-quietly"]);
    act(alpha, "hide");
    assert!(
        !html(&b).contains("renamed-quietly"),
        "{kind:?}: hidden by A"
    );
    assert!(methods(&b).is_empty());
    act(alpha, "unhide");
    assert_eq!(methods(&b), ["renamed-quietly"]);
    assert!(html(&b).contains("renamed-quietly"));

    // A job that ends in whichever process's worker shows on B.
    let beta = id_of(upload(
        &a,
        "cached-beta",
        "synthA",
        &fixtures().join("results/noiselarge_synthA-test.csv"),
        None,
    ));
    wait_done(&a.base, beta, Duration::from_secs(120));
    assert!(html(&b).contains("cached-beta"), "{kind:?}: job ended");
    assert!(methods(&b).contains(&"cached-beta".to_string()));

    // A direct store call from yet another process (this test) on the same database.
    let url = db.url().unwrap_or_else(|| server::store::sqlite_url(&data));
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
        .block_on(async {
            let store = server::store::Store::connect(&url).await.expect("store");
            assert!(
                store
                    .set_hidden(server::domain::SubmissionId::new(beta), true)
                    .await
                    .expect("hidden")
            );
        });
    assert!(
        !html(&b).contains("cached-beta"),
        "{kind:?}: hidden by a store call"
    );
    assert_eq!(methods(&b), ["renamed-quietly"]);

    // A delete by an administrator, on A: gone from both.
    act(alpha, "delete");
    assert!(methods(&b).is_empty(), "{kind:?}: deleted");
    assert!(!html(&b).contains("renamed-quietly"));
    assert!(methods(&a).is_empty());
    assert!(!html(&a).contains("renamed-quietly"));
}
both_databases!(boards_follow_every_change);

/// With the cache turned off every request renders: the same change behind the service's back
/// shows at once (what the cache trades for speed, and what the benchmark compares against).
fn no_cache_renders_every_request(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "boards_off");
    let data = dir.path().join("data");
    let a = start(&data, &datasets, &db, &["--board-cache-mb", "0"]);
    let id = id_of(upload(
        &a,
        "uncached",
        "synthA",
        &fixtures().join("results/noisesmall_synthA-test.csv"),
        None,
    ));
    wait_done(&a.base, id, Duration::from_secs(120));
    assert_eq!(methods(&a), ["uncached"]);
    execute(&db, &data, "UPDATE methods SET name = 'renamed-quietly'");
    assert_eq!(methods(&a), ["renamed-quietly"], "{kind:?}");
    assert!(html(&a).contains("renamed-quietly"));
}
both_databases!(no_cache_renders_every_request);

/// Browsers get the cached board gzipped (with the bytes of the plain answer inside), other
/// clients plain; both say that the answer varies with Accept-Encoding.
fn gzip_for_those_who_ask(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "boards_gzip");
    let data = dir.path().join("data");
    let a = start(&data, &datasets, &db, &[]);
    let get = |path: &str, gzip: bool| {
        let mut r = client().get(format!("{}{path}", a.base));
        if gzip {
            r = r.header("accept-encoding", "gzip, deflate");
        }
        r.send().expect("answered")
    };
    for path in ["/leaderboards/eccv18", "/api/v1/leaderboards/eccv18", "/"] {
        let plain = get(path, false);
        assert_eq!(plain.headers()["vary"], "accept-encoding");
        assert!(plain.headers().get("content-encoding").is_none());
        let plain = plain.bytes().expect("body");
        let zipped = get(path, true);
        assert_eq!(
            zipped.headers()["content-encoding"],
            "gzip",
            "{kind:?} {path}"
        );
        let zipped = zipped.bytes().expect("body");
        let mut unzipped = Vec::new();
        std::io::Read::read_to_end(
            &mut flate2::read::GzDecoder::new(&zipped[..]),
            &mut unzipped,
        )
        .expect("gzip");
        assert_eq!(unzipped, plain.to_vec(), "{path}");
    }
    // A query that fails is an error, never a cached board.
    assert_eq!(
        get("/api/v1/leaderboards/bop19?sort=nonsense", false).status(),
        400
    );
    assert_eq!(
        get("/leaderboards/bop19?sort=nonsense", false).status(),
        400
    );
}
both_databases!(gzip_for_those_who_ask);
