//! Ranking as on the BOP site, through the real HTTP API on both databases: the main table shows
//! the core datasets given by `--core-datasets` and ranks the methods with a score on each by
//! their average (equal scores at the precision shown share a rank), the others follow unranked
//! by coverage and mean, never by name; every row names its owner; a method's entry is its best
//! submission, not its latest, unless its owner pins another; the owner (and nobody else) edits
//! the method's details, and an upload without `hardware` keeps the method's.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::common::{
    Db, Server, TestDb, account, admin_token, board_methods, both_databases, cli_report, client,
    fixtures, get_json, post_as, start, upload_with, wait_done,
};
use serde_json::{Value, json};

/// A datasets folder serving the reference dataset as `synthA`, `synthB` and `synthC`.
fn three_datasets(dir: &Path) -> PathBuf {
    let datasets = dir.join("datasets");
    std::fs::create_dir_all(&datasets).expect("mkdir");
    let reference = fixtures().join("dataset").canonicalize().expect("fixture");
    for name in ["synthA", "synthB", "synthC"] {
        std::os::unix::fs::symlink(&reference, datasets.join(name)).expect("symlink");
    }
    datasets
}

/// The reference result file `stem` named for `dataset` (its content fits all three).
fn result_for(dir: &Path, stem: &str, dataset: &str) -> PathBuf {
    let to = dir.join(format!("{stem}_{dataset}-test.csv"));
    if !to.exists() {
        std::fs::copy(
            fixtures().join(format!("results/{stem}_synthA-test.csv")),
            &to,
        )
        .expect("copy");
    }
    to
}

/// Uploads for publication and waits for the evaluation; returns the submission id.
fn submit(server: &Server, token: &str, dir: &Path, fields: &[(&str, &str)], stem: &str) -> i64 {
    let mut fields = fields.to_vec();
    fields.push(("visibility", "public"));
    let dataset = fields
        .iter()
        .find(|(k, _)| *k == "dataset")
        .map(|(_, v)| *v)
        .expect("dataset");
    let r = upload_with(server, token, &fields, &result_for(dir, stem, dataset));
    assert_eq!(r.status(), 202, "{stem} on {dataset}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
    id
}

/// The rows of a board by method name.
fn rows_by_method(board: &Value) -> BTreeMap<String, Value> {
    board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| (r["method"].as_str().expect("method").to_string(), r.clone()))
        .collect()
}

fn ranking(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let files = dir.path().join("files");
    std::fs::create_dir_all(&files).expect("mkdir");
    let datasets = three_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "ranking");
    let server = start(
        &data,
        &datasets,
        &db,
        &[
            "--core-datasets",
            "synthA,synthB",
            "--submissions-per-window",
            "0",
        ],
    );
    let base = server.base.clone();
    let tester = server.token.clone();
    let alice = account(&data, &db, "alice");
    let f = files.as_path();

    // tester's `best-net`: a good file, then a worse one later on synthA; the good one on B.
    let small_a = submit(
        &server,
        &tester,
        f,
        &[
            ("method", "best-net"),
            ("dataset", "synthA"),
            ("hardware", "rig 1"),
        ],
        "noisesmall",
    );
    let large_a = submit(
        &server,
        &tester,
        f,
        &[("method", "best-net"), ("dataset", "synthA")],
        "noiselarge",
    );
    submit(
        &server,
        &tester,
        f,
        &[("method", "best-net"), ("dataset", "synthB")],
        "noisesmall",
    );
    // alice's `tie-net`: the same scores, so the same rank.
    for ds in ["synthA", "synthB"] {
        submit(
            &server,
            &alice,
            f,
            &[("method", "tie-net"), ("dataset", ds)],
            "noisesmall",
        );
    }
    // A worse method on both core datasets.
    submit(
        &server,
        &tester,
        f,
        &[("method", "third-net"), ("dataset", "synthA")],
        "noiselarge",
    );
    submit(
        &server,
        &tester,
        f,
        &[("method", "third-net"), ("dataset", "synthB")],
        "noisemedium",
    );
    // Two methods on one core dataset each: unranked, the better mean first though its name
    // comes later; one of them also on synthC, which is not core.
    submit(
        &server,
        &tester,
        f,
        &[("method", "z-partial"), ("dataset", "synthA")],
        "gtexact",
    );
    submit(
        &server,
        &tester,
        f,
        &[("method", "z-partial"), ("dataset", "synthC")],
        "noisesmall",
    );
    submit(
        &server,
        &alice,
        f,
        &[("method", "a-partial"), ("dataset", "synthB")],
        "random",
    );

    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    let columns: Vec<&str> = board["columns"]
        .as_array()
        .expect("columns")
        .iter()
        .map(|d| d["name"].as_str().expect("name"))
        .collect();
    assert_eq!(columns, ["synthA", "synthB"], "{kind:?}: the core datasets");
    assert_eq!(
        board_methods(&board),
        ["best-net", "tie-net", "third-net", "z-partial", "a-partial"],
        "{kind:?}: ranked by average, then unranked by mean"
    );
    let rows = rows_by_method(&board);
    let rank = |m: &str| rows[m]["rank"].clone();
    assert_eq!(
        [rank("best-net"), rank("tie-net"), rank("third-net")],
        [json!(1), json!(1), json!(3)],
        "{kind:?}: shared ranks"
    );
    assert_eq!(rank("z-partial"), Value::Null);
    assert_eq!(rank("a-partial"), Value::Null);
    assert_eq!(rows["z-partial"]["average"], Value::Null);
    assert_eq!(rows["z-partial"]["covered"], 1);
    assert!(
        rows["z-partial"]["scores"].get("synthC").is_none(),
        "{kind:?}: not a column"
    );
    for (method, owner) in [
        ("best-net", "tester"),
        ("tie-net", "alice"),
        ("third-net", "tester"),
        ("z-partial", "tester"),
        ("a-partial", "alice"),
    ] {
        assert_eq!(rows[method]["owner"], owner, "{kind:?}: owner of {method}");
    }

    // The best submission is the entry, not the latest; the average and time are the means
    // over the core datasets of what `poseboard eval` gives.
    let small = cli_report(
        &datasets.join("synthA"),
        &result_for(f, "noisesmall", "synthA"),
        "bop19",
    );
    let best = &rows["best-net"];
    assert_eq!(
        best["scores"]["synthA"]["submission_id"], small_a,
        "{kind:?}"
    );
    assert_eq!(
        best["scores"]["synthA"]["score"],
        small["bop19_average_recall"]
    );
    let ar = small["bop19_average_recall"].as_f64().expect("AR");
    let time = small["bop19_average_time_per_image"]
        .as_f64()
        .expect("time");
    assert_eq!(best["average"].as_f64(), Some((ar + ar) / 2.0), "{kind:?}");
    assert_eq!(best["time"].as_f64(), Some((time + time) / 2.0), "{kind:?}");
    assert_eq!(
        best["hardware"], "rig 1",
        "{kind:?}: kept by an upload without it"
    );

    // Another order keeps each row's rank; the page shows the direction and `-` for unranked.
    let by_name = get_json(&format!("{base}/api/v1/leaderboards/bop19?sort=method"));
    assert_eq!(
        board_methods(&by_name),
        ["a-partial", "best-net", "third-net", "tie-net", "z-partial"]
    );
    for (m, row) in rows_by_method(&by_name) {
        assert_eq!(
            row["rank"], rows[&m]["rank"],
            "{kind:?}: rank of {m} by name"
        );
    }
    let page = client()
        .get(format!("{base}/?sort=method"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains(r#"aria-sort="ascending""#), "{kind:?}");
    assert!(page.contains("<td>-</td>"), "{kind:?}: unranked rows");
    assert!(page.contains("alice"), "{kind:?}: owners on the page");

    // A dataset's own board ranks by its score, non-core ones included.
    let a = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"));
    assert_eq!(board_methods(&a)[0], "z-partial", "{kind:?}");
    assert_eq!(a["rows"][0]["rank"], 1);
    let c = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthC"));
    assert_eq!(board_methods(&c), ["z-partial"], "{kind:?}");

    // The owner pins the worse submission: it is the entry, and the submission says so.
    let pin = |token: &str, id: i64, action: &str| {
        post_as(
            &format!("{base}/api/v1/submissions/{id}/{action}"),
            token,
            None,
        )
        .status()
        .as_u16()
    };
    assert_eq!(pin(&alice, large_a, "pin"), 403, "{kind:?}: not alice's");
    assert_eq!(pin(&tester, large_a, "pin"), 200, "{kind:?}");
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    let rows = rows_by_method(&board);
    assert_eq!(
        rows["best-net"]["scores"]["synthA"]["submission_id"],
        large_a
    );
    assert_eq!(rows["best-net"]["scores"]["synthA"]["pinned"], true);
    assert_eq!(rows["tie-net"]["rank"], 1, "{kind:?}");
    assert_eq!(rows["best-net"]["rank"], 2, "{kind:?}");
    let entry = |id: i64| get_json(&format!("{base}/api/v1/submissions/{id}"))["entries"].clone();
    let pinned = entry(large_a);
    assert_eq!(pinned[0]["is_this"], true, "{kind:?}: {pinned}");
    assert_eq!(pinned[0]["reason"], "pinned");
    let unpinned = entry(small_a);
    assert_eq!(unpinned[0]["is_this"], false, "{kind:?}");
    assert_eq!(unpinned[0]["submission_id"], large_a);
    assert_eq!(pin(&tester, large_a, "unpin"), 200);
    let again = entry(small_a);
    assert_eq!(
        (again[0]["is_this"].clone(), again[0]["reason"].clone()),
        (json!(true), json!("best"))
    );

    // The owner edits the method's details; alice may not; a bad value is refused.
    let method_id = rows["best-net"]["method_id"].as_i64().expect("id");
    let url = format!("{base}/api/v1/methods/{method_id}");
    let details = json!({
        "authors": "T. Ester", "year": 2024, "training_data": "synthetic",
        "detection_modality": "rgb", "modality": "rgb-d", "refinement": "ICP",
        "detections": "CNOS", "model_scope": "per-object",
    });
    assert_eq!(
        post_as(&url, &alice, Some(details.clone())).status(),
        403,
        "{kind:?}"
    );
    assert_eq!(
        client()
            .post(&url)
            .json(&details)
            .send()
            .expect("post")
            .status(),
        401
    );
    assert_eq!(
        post_as(&url, &tester, Some(json!({ "year": "soon" }))).status(),
        400
    );
    assert_eq!(
        post_as(&url, &tester, Some(details)).status(),
        200,
        "{kind:?}"
    );
    let method = get_json(&url)["method"].clone();
    for (k, v) in [
        ("owner", json!("tester")),
        ("authors", json!("T. Ester")),
        ("year", json!(2024)),
        ("detection_modality", json!("rgb")),
        ("modality", json!("rgb-d")),
        ("model_scope", json!("per-object")),
        ("hardware", json!("rig 1")),
    ] {
        assert_eq!(method[k], v, "{kind:?}: {k}");
    }
    let listed = get_json(&format!("{base}/api/v1/methods"));
    assert!(
        listed["methods"]
            .as_array()
            .expect("methods")
            .iter()
            .all(|m| m["owner"].as_str().is_some_and(|o| !o.is_empty())),
        "{kind:?}: owner on every method"
    );
    let board = get_json(&format!(
        "{base}/api/v1/leaderboards/bop19?training=synthetic"
    ));
    assert_eq!(
        board_methods(&board),
        ["best-net"],
        "{kind:?}: the boards show the edit"
    );

    // An administrator makes synthC core: a third column, and nobody covers all three.
    let admin = admin_token(&data, &db, "root");
    let r = post_as(
        &format!("{base}/api/v1/admin/datasets/synthC/core"),
        &admin,
        Some(json!({ "core": true })),
    );
    assert_eq!(r.status(), 200, "{kind:?}");
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(
        board["core"],
        json!(["synthA", "synthB", "synthC"]),
        "{kind:?}"
    );
    assert!(
        board["rows"]
            .as_array()
            .expect("rows")
            .iter()
            .all(|r| r["rank"].is_null())
    );
    assert_eq!(
        board_methods(&board)[0],
        "z-partial",
        "{kind:?}: covers two of three"
    );
}
both_databases!(ranking);
