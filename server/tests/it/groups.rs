//! Issue 28, points 1 and 2, through the real HTTP API on both databases. Categories: a method
//! declares its onboarding (`model-based`, `model-free`) and objects (`seen`, `unseen`), and
//! `?objects=...&onboarding=...` boards show only the methods of those categories, ranked among
//! themselves, alike in the page, the JSON and the exports; an unset field matches no filter
//! value. Groups: `?group=NAME` ranks by the mean over the group's served datasets with the core
//! average's rule for missing ones; `--core-datasets` still sets the default group; only
//! administrators create, replace and delete groups (audited); an unknown group is a 404 naming
//! it.

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::common::{
    Db, Server, TestDb, admin_token, board_methods, both_databases, client, csrf_of, fixtures,
    get_as, get_json, post_as, signed_in, start, upload_with, wait_done,
};
use serde_json::{Value, json};

/// A datasets folder serving the reference dataset under each of `names`.
fn datasets_named(dir: &Path, names: &[&str]) -> PathBuf {
    let datasets = dir.join("datasets");
    std::fs::create_dir_all(&datasets).expect("mkdir");
    let reference = fixtures().join("dataset").canonicalize().expect("fixture");
    for name in names {
        std::os::unix::fs::symlink(&reference, datasets.join(name)).expect("symlink");
    }
    datasets
}

/// Uploads the reference file `stem` to `dataset` for publication as `method` with `extra`
/// fields, and waits for its scores.
fn submit(
    server: &Server,
    dir: &Path,
    method: &str,
    dataset: &str,
    stem: &str,
    extra: &[(&str, &str)],
) {
    let file = dir.join(format!("{stem}_{dataset}-test.csv"));
    if !file.exists() {
        std::fs::copy(
            fixtures().join(format!("results/{stem}_synthA-test.csv")),
            &file,
        )
        .expect("copy");
    }
    let mut fields = vec![
        ("method", method),
        ("dataset", dataset),
        ("visibility", "public"),
    ];
    fields.extend_from_slice(extra);
    let r = upload_with(server, &server.token, &fields, &file);
    assert_eq!(r.status(), 202, "{method} on {dataset}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
}

/// Each row of a board as (method, rank).
fn ranks(board: &Value) -> Vec<(String, Option<u64>)> {
    board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .map(|r| {
            (
                r["method"].as_str().expect("method").to_string(),
                r["rank"].as_u64(),
            )
        })
        .collect()
}

fn named(rows: &[(&str, Option<u64>)]) -> Vec<(String, Option<u64>)> {
    rows.iter().map(|(m, r)| (m.to_string(), *r)).collect()
}

/// The (method, rank) rows of a CSV export.
fn csv_ranks(body: &str) -> Vec<(String, Option<u64>)> {
    let mut lines = body.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let at = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (rank, method) = (at("rank"), at("method"));
    lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            (cells[method].to_string(), cells[rank].parse().ok())
        })
        .collect()
}

fn categories(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = datasets_named(dir.path(), &["synthA"]);
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "categories");
    let server = start(&data, &datasets, &db, &["--submissions-per-window", "0"]);
    let base = server.base.clone();
    let files = dir.path().join("files");
    std::fs::create_dir_all(&files).expect("mkdir");
    // Best to worst: alpha, bravo, charlie, delta (whose categories are not given).
    for (method, stem, extra) in [
        (
            "alpha",
            "gtexact",
            &[("objects", "seen"), ("onboarding", "model-based")][..],
        ),
        (
            "bravo",
            "noisesmall",
            &[("objects", "unseen"), ("onboarding", "model-free")],
        ),
        (
            "charlie",
            "noisemedium",
            &[("objects", "unseen"), ("onboarding", "model-based")],
        ),
        ("delta", "noiselarge", &[]),
    ] {
        submit(&server, &files, method, "synthA", stem, extra);
    }
    let board = |query: &str| get_json(&format!("{base}/api/v1/leaderboards/bop19{query}"));

    let all = board("");
    assert_eq!(
        ranks(&all),
        named(&[
            ("alpha", Some(1)),
            ("bravo", Some(2)),
            ("charlie", Some(3)),
            ("delta", Some(4))
        ]),
        "{kind:?}"
    );
    let alpha = &all["rows"][0];
    assert_eq!(
        (alpha["test_objects"].as_str(), alpha["onboarding"].as_str()),
        (Some("seen"), Some("model-based"))
    );
    assert!(
        all["rows"][3]["test_objects"].is_null(),
        "{}",
        all["rows"][3]
    );

    // Only the unseen ones, ranked among themselves; likewise for each filter and both.
    for (query, expected) in [
        (
            "?objects=unseen",
            named(&[("bravo", Some(1)), ("charlie", Some(2))]),
        ),
        ("?objects=seen", named(&[("alpha", Some(1))])),
        (
            "?onboarding=model-based",
            named(&[("alpha", Some(1)), ("charlie", Some(2))]),
        ),
        (
            "?objects=unseen&onboarding=model-based",
            named(&[("charlie", Some(1))]),
        ),
        ("?objects=seen&onboarding=model-free", Vec::new()),
    ] {
        let filtered = board(query);
        assert_eq!(ranks(&filtered), expected, "{query} {kind:?}");
        // The exports follow the same filter with the same ranks.
        let csv = client()
            .get(format!("{base}/leaderboards/bop19/export.csv{query}"))
            .send()
            .expect("csv")
            .text()
            .expect("text");
        assert_eq!(csv_ranks(&csv), expected, "CSV {query}");
        let export = get_json(&format!("{base}/leaderboards/bop19/export.json{query}"));
        assert_eq!(ranks(&export), expected, "JSON export {query}");
    }
    // The page: the filter's methods only, and the controls to choose the categories.
    let page = client()
        .get(format!("{base}/leaderboards/bop19?objects=unseen"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains(">bravo<") && page.contains(">charlie<"),
        "{page}"
    );
    assert!(!page.contains(">alpha<") && !page.contains(">delta<"));
    assert!(page.contains("objects=seen") && page.contains("onboarding=model-free"));

    // Bad values: 400 naming the parameter and the words it takes, on the page and the JSON.
    for (url, words) in [
        (
            format!("{base}/api/v1/leaderboards/bop19?objects=blind"),
            "seen, unseen",
        ),
        (
            format!("{base}/leaderboards/bop19?onboarding=cad"),
            "model-based, model-free",
        ),
        (
            format!("{base}/leaderboards/bop19/export.csv?objects=all"),
            "seen, unseen",
        ),
    ] {
        let r = client().get(&url).send().expect("answered");
        assert_eq!(r.status(), 400, "{url}");
        let body = r.text().expect("body");
        let parameter = if url.contains("onboarding") {
            "onboarding"
        } else {
            "objects"
        };
        assert!(
            body.contains(&format!("`{parameter}`")) && body.contains(words),
            "{url}: {body}"
        );
    }

    // The owner sets delta's categories through the API: it joins the unseen board, re-ranked.
    let delta = all["rows"][3]["method_id"].as_i64().expect("id");
    let r = post_as(
        &format!("{base}/api/v1/methods/{delta}"),
        &server.token,
        Some(json!({ "objects": "unseen", "onboarding": "model-free" })),
    );
    assert!(r.status().is_success(), "{}", r.status());
    assert_eq!(
        ranks(&board("?objects=unseen")),
        named(&[("bravo", Some(1)), ("charlie", Some(2)), ("delta", Some(3))])
    );
    assert_eq!(
        ranks(&board("?onboarding=model-free")),
        named(&[("bravo", Some(1)), ("delta", Some(2))])
    );
    let r = post_as(
        &format!("{base}/api/v1/methods/{delta}"),
        &server.token,
        Some(json!({ "objects": "some" })),
    );
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("objects"));
    // The method page shows them.
    let page = client()
        .get(format!("{base}/methods/{delta}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains("model-free") && page.contains("unseen"),
        "{page}"
    );
}
both_databases!(categories);

/// The names of a JSON list of strings.
fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap_or_else(|| panic!("a list: {v}"))
        .iter()
        .map(|s| s.as_str().expect("a string").to_string())
        .collect()
}

/// The group `name` of `GET /api/v1/groups`.
fn group(base: &str, name: &str) -> Option<Value> {
    get_json(&format!("{base}/api/v1/groups"))["groups"]
        .as_array()
        .expect("groups")
        .iter()
        .find(|g| g["name"] == name)
        .cloned()
}

fn groups(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = datasets_named(dir.path(), &["synthA", "synthB"]);
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "groups");
    let root = admin_token(&data, &db, "root");
    let server = start(
        &data,
        &datasets,
        &db,
        &["--core-datasets", "synthA", "--submissions-per-window", "0"],
    );
    let base = server.base.clone();
    let files = dir.path().join("files");
    std::fs::create_dir_all(&files).expect("mkdir");
    // alpha: exact on synthA, far off on synthB; bravo: close on synthA, exact on synthB;
    // charlie: synthA only.
    for (method, dataset, stem) in [
        ("alpha", "synthA", "gtexact"),
        ("alpha", "synthB", "noiselarge"),
        ("bravo", "synthA", "noisesmall"),
        ("bravo", "synthB", "gtexact"),
        ("charlie", "synthA", "noisemedium"),
    ] {
        submit(&server, &files, method, dataset, stem, &[]);
    }
    let board = |query: &str| get_json(&format!("{base}/api/v1/leaderboards/bop19{query}"));
    let score = |method: &str, dataset: &str| {
        let b = board(&format!("?dataset={dataset}"));
        b["rows"]
            .as_array()
            .expect("rows")
            .iter()
            .find(|r| r["method"] == method)
            .expect("row")["scores"][dataset]["score"]
            .as_f64()
            .expect("score")
    };

    // The groups: the default one (the core datasets of --core-datasets) and BOP's, of which
    // this server serves none.
    let core = group(&base, "core").expect("the default group");
    assert_eq!(core["default"], true, "{kind:?}");
    assert_eq!(strings(&core["datasets"]), ["synthA"]);
    let classic = group(&base, "BOP-Classic-Core").expect("BOP-Classic-Core");
    assert_eq!(
        strings(&classic["datasets"]),
        ["hb", "icbin", "itodd", "lmo", "tless", "tudl", "ycbv"]
    );
    assert!(strings(&classic["served"]).is_empty());
    for (name, members) in [
        ("BOP-Industrial", vec!["ipd", "itoddmv", "xyzibd"]),
        ("BOP-H3", vec!["handal", "hopev2", "hot3d"]),
    ] {
        assert_eq!(
            strings(&group(&base, name).expect(name)["datasets"]),
            members
        );
    }

    // The default board ranks over the core datasets, with or without naming the group.
    let default = board("");
    assert_eq!(
        ranks(&default),
        named(&[("alpha", Some(1)), ("bravo", Some(2)), ("charlie", Some(3))]),
        "{kind:?}"
    );
    assert_eq!(
        (default["group"].as_str(), strings(&default["core"])),
        (Some("core"), vec!["synthA".to_string()])
    );
    assert_eq!(ranks(&board("?group=core")), ranks(&default));
    assert!(strings(&default["groups"]).contains(&"BOP-H3".to_string()));

    // Only an administrator creates a group: to another account the route does not exist (as
    // every admin route), and a request without a valid token is refused.
    let only_b = json!({ "name": "only-B", "datasets": ["synthB", "lmo"] });
    for (token, status) in [(server.token.as_str(), 404), ("", 401)] {
        let r = post_as(
            &format!("{base}/api/v1/admin/groups"),
            token,
            Some(only_b.clone()),
        );
        assert_eq!(r.status(), status, "token {token:?}");
    }
    assert!(group(&base, "only-B").is_none());
    let r = post_as(&format!("{base}/api/v1/admin/groups"), &root, Some(only_b));
    assert_eq!(r.status(), 201);
    let created: Value = r.json().expect("json");
    assert_eq!(strings(&created["group"]["datasets"]), ["lmo", "synthB"]);
    assert_eq!(strings(&created["group"]["served"]), ["synthB"]);
    let r = post_as(
        &format!("{base}/api/v1/admin/groups"),
        &root,
        Some(json!({ "name": "A-and-B", "datasets": ["synthA", "synthB"] })),
    );
    assert_eq!(r.status(), 201);

    // A group's board: its served datasets are the columns, ranked by the mean over them.
    let b_board = board("?group=only-B");
    assert_eq!(strings(&b_board["core"]), ["synthB"]);
    assert_eq!(
        ranks(&b_board),
        named(&[("bravo", Some(1)), ("alpha", Some(2))]),
        "{kind:?}"
    );
    let ab = board("?group=A-and-B");
    // charlie covers one of the two: unranked, after the ranked ones, as on the core board.
    assert_eq!(
        ranks(&ab),
        named(&[("bravo", Some(1)), ("alpha", Some(2)), ("charlie", None)]),
        "{kind:?}"
    );
    for row in ab["rows"].as_array().expect("rows").iter().take(2) {
        let m = row["method"].as_str().expect("method");
        let mean = (score(m, "synthA") + score(m, "synthB")) / 2.0;
        assert!(
            (row["average"].as_f64().expect("average") - mean).abs() < 1e-12,
            "{row}"
        );
    }
    assert_ne!(ranks(&ab), ranks(&default));
    // The filters and the exports take the group too.
    let csv = client()
        .get(format!(
            "{base}/leaderboards/bop19/export.csv?group=A-and-B"
        ))
        .send()
        .expect("csv")
        .text()
        .expect("text");
    assert_eq!(csv_ranks(&csv), ranks(&ab));
    // The page offers every group and marks the one shown.
    let page = client()
        .get(format!("{base}/leaderboards/bop19?group=only-B"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains("group=BOP-Classic-Core") && page.contains("group=A-and-B"),
        "{page}"
    );

    // Replaced: the board follows at once.
    let r = post_as(
        &format!("{base}/api/v1/admin/groups"),
        &root,
        Some(json!({ "name": "only-B", "datasets": ["synthA"] })),
    );
    assert_eq!(r.status(), 200);
    assert_eq!(board_methods(&board("?group=only-B"))[0], "alpha");

    // An unknown group is a 404 naming it, on the page, the JSON and the exports.
    for url in [
        format!("{base}/api/v1/leaderboards/bop19?group=no-such-group"),
        format!("{base}/leaderboards/bop19?group=no-such-group"),
        format!("{base}/leaderboards/bop19/export.csv?group=no-such-group"),
    ] {
        let r = client().get(&url).send().expect("answered");
        assert_eq!(r.status(), 404, "{url}");
        assert!(r.text().expect("body").contains("no-such-group"), "{url}");
    }
    // Bad requests name the problem.
    for body in [
        json!({ "name": "bad name", "datasets": ["synthA"] }),
        json!({ "name": "empty", "datasets": [] }),
        json!({ "name": "up", "datasets": ["../etc"] }),
        json!({ "name": "core", "datasets": ["lmo"] }),
    ] {
        let r = post_as(
            &format!("{base}/api/v1/admin/groups"),
            &root,
            Some(body.clone()),
        );
        assert_eq!(r.status(), 400, "{body}");
    }

    // The page's forms: an administrator adds a group, then deletes it; both are audited.
    let browser = signed_in(&server, "root");
    let page = browser
        .get(format!("{base}/groups"))
        .send()
        .expect("groups page")
        .text()
        .expect("html");
    let csrf = csrf_of(&page);
    let r = browser
        .post(format!("{base}/admin/groups"))
        .form(&[
            ("csrf", csrf.as_str()),
            ("name", "by-form"),
            ("datasets", "synthB, synthA"),
        ])
        .send()
        .expect("add");
    assert!(r.status().is_success(), "{}", r.status());
    assert_eq!(
        strings(&group(&base, "by-form").expect("by-form")["served"]),
        ["synthA", "synthB"]
    );
    let forged = browser
        .post(format!("{base}/admin/groups/by-form/delete"))
        .form(&[("csrf", "forged")])
        .send()
        .expect("delete");
    assert_eq!(forged.status(), 403);
    let r = browser
        .post(format!("{base}/admin/groups/by-form/delete"))
        .form(&[("csrf", csrf.as_str())])
        .send()
        .expect("delete");
    assert!(r.status().is_success());
    assert!(group(&base, "by-form").is_none());
    assert_eq!(
        client()
            .get(format!("{base}/leaderboards/bop19?group=by-form"))
            .send()
            .expect("answered")
            .status(),
        404
    );
    // A reader sees the groups page without the forms.
    let public = client()
        .get(format!("{base}/groups"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(public.contains("BOP-Industrial") && !public.contains("name=\"csrf\""));
    let audit = get_as(&format!("{base}/api/v1/admin/audit"), &root)
        .json::<Value>()
        .expect("audit")
        .to_string();
    assert!(
        audit.contains("save group") && audit.contains("by-form") && audit.contains("delete group"),
        "{audit}"
    );
}
both_databases!(groups);
