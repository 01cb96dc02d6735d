//! A method's page is its home: its scores and ranks on every board and dataset it has a
//! public entry on (ranked as that dataset's board ranks it), its submissions over time (to its
//! owner the private and held ones too, with a "held" badge), and an edit form laid out one
//! field a row. Its JSON twin answers the owner before anything of the method is public, and
//! nobody else then. Run on both databases.

use std::time::Duration;

use reqwest::blocking::Client;
use serde_json::{Value, json};

use crate::common::{
    Db, TestDb, both_databases, client, fixtures, get_as, get_json, post_as, reference_datasets,
    start, upload, upload_with, wait_done,
};
use crate::publishing::{in_metres, wait_owner};

/// The ids of the submissions a method's JSON lists, in its order.
fn listed(method: &Value) -> Vec<i64> {
    method["submissions"]
        .as_array()
        .expect("submissions")
        .iter()
        .map(|s| s["id"].as_i64().expect("id"))
        .collect()
}

/// The table row of submission `id` on a method's page, if listed.
fn row_of(page: &str, id: i64) -> Option<&str> {
    let at = page.find(&format!("<tr id=\"submission-{id}\">"))?;
    Some(&page[at..at + page[at..].find("</tr>")?])
}

fn the_method_page_is_its_home(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let metres = in_metres(dir.path());
    let db = TestDb::new(kind, "methodpage");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let (base, owner) = (server.base.clone(), server.token.clone());
    let fixture = |name: &str| fixtures().join("results").join(name);
    let id_of = |r: reqwest::blocking::Response| -> i64 {
        assert_eq!(r.status(), 202, "{kind:?}");
        r.json::<Value>().expect("json")["id"].as_i64().expect("id")
    };

    // A private upload: the method is its owner's alone, page and JSON.
    let first = id_of(upload_with(
        &server,
        &owner,
        &[("method", "home-net"), ("dataset", "synthA")],
        &fixture("noisemedium_synthA-test.csv"),
    ));
    let method = wait_owner(&server, &owner, first)["method_id"]
        .as_i64()
        .expect("method id");
    let api = format!("{base}/api/v1/methods/{method}");
    let page_url = format!("{base}/methods/{method}");
    assert_eq!(get_as(&api, "").status(), 404, "{kind:?}");
    assert_eq!(get_as(&page_url, "").status(), 404, "{kind:?}");
    let r = get_as(&api, &owner);
    assert_eq!(
        r.status(),
        200,
        "{kind:?}: the owner sees it before it is public"
    );
    let mine: Value = r.json().expect("json");
    assert_eq!(mine["method"]["name"], "home-net");
    assert_eq!(listed(&mine), vec![first], "{kind:?}");
    assert_eq!(mine["standings"], json!([]), "{kind:?}");

    // A held upload (translations in metres), the first one published, and a rival.
    let r = upload_with(
        &server,
        &owner,
        &[
            ("method", "home-net"),
            ("dataset", "synthA"),
            ("visibility", "public"),
        ],
        &metres,
    );
    let held = id_of(r);
    assert_eq!(wait_owner(&server, &owner, held)["held"], true, "{kind:?}");
    let r = post_as(
        &format!("{base}/api/v1/submissions/{first}/visibility"),
        &owner,
        Some(json!({ "visibility": "public" })),
    );
    assert_eq!(r.status(), 200, "{kind:?}");
    let rival = id_of(upload(
        &server,
        "rival-net",
        "synthA",
        &fixture("noisesmall_synthA-test.csv"),
        None,
    ));
    wait_done(&base, rival, Duration::from_secs(120));

    // Everyone: the public submission and where it stands, as the dataset's board ranks it.
    let public = get_json(&api);
    assert_eq!(listed(&public), vec![first], "{kind:?}: {public}");
    let standings = public["standings"].as_array().expect("standings");
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"));
    let row = board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == "home-net")
        .expect("on the board")
        .clone();
    let bop19 = standings
        .iter()
        .find(|s| s["protocol"] == "bop19" && s["dataset"] == "synthA")
        .unwrap_or_else(|| panic!("{kind:?}: no bop19 standing: {public}"));
    assert_eq!(bop19["rank"], row["rank"], "{kind:?}: {public}");
    assert_eq!(bop19["ranked"], 2, "{kind:?}: {public}");
    assert_eq!(bop19["submission_id"], first, "{kind:?}");
    assert_eq!(bop19["score"], row["scores"]["synthA"]["score"], "{kind:?}");
    assert!(
        standings
            .iter()
            .all(|s| s["ranked"] == 2 && s["rank"].is_u64()),
        "{kind:?}: {public}"
    );
    assert_eq!(
        public["submissions"][0]["scores"]["bop19"], bop19["score"],
        "{kind:?}: {public}"
    );

    let page = get_as(&page_url, "").text().expect("html");
    let rank = bop19["rank"].as_u64().expect("rank");
    let standing_row = page
        .split("<tr>")
        .find(|r| r.contains("href=\"/leaderboards/bop19?dataset=synthA\""))
        .unwrap_or_else(|| panic!("{kind:?}: no bop19 standing on the page: {page}"));
    assert!(
        standing_row.contains(&format!("{rank} of 2")),
        "{kind:?}: {standing_row}"
    );
    assert!(row_of(&page, first).is_some(), "{kind:?}: {page}");
    assert!(row_of(&page, held).is_none(), "{kind:?}: {page}");
    assert!(!page.contains("class=\"method-edit\""), "{kind:?}");

    // Its owner: the held one too, with its badge, through the API and in the browser, and
    // the edit form.
    let mine: Value = get_as(&api, &owner).json().expect("json");
    assert_eq!(listed(&mine), vec![held, first], "{kind:?}: {mine}");
    assert_eq!(mine["submissions"][0]["held"], true, "{kind:?}");
    let browser = Client::builder()
        .cookie_store(true)
        .build()
        .expect("client");
    let r = browser
        .post(format!("{base}/login"))
        .form(&[
            ("name", "tester"),
            ("password", "tester-secret-password"),
            ("next", &format!("/methods/{method}")),
        ])
        .send()
        .expect("signed in");
    assert!(r.status().is_success(), "{kind:?}: {}", r.status());
    let page = r.text().expect("html");
    let held_row = row_of(&page, held).unwrap_or_else(|| panic!("{kind:?}: {page}"));
    assert!(
        held_row.contains("<span class=\"status held\"") && held_row.contains(">held</span>"),
        "{kind:?}: {held_row}"
    );
    assert!(held_row.contains("private"), "{kind:?}: {held_row}");
    assert!(
        row_of(&page, first).is_some_and(|r| r.contains("public")),
        "{kind:?}"
    );
    let form = &page[page
        .find("<form method=\"post\" action=\"/methods/")
        .unwrap_or_else(|| panic!("{kind:?}: no edit form: {page}"))..];
    let form = &form[..form.find("</form>").expect("form end")];
    assert!(form.contains("class=\"method-edit\""), "{form}");
    assert!(form.matches("<label>").count() >= 10, "{form}");
    // Laid out as a form: one field a row, each label above its field.
    let css = client()
        .get(format!("{base}/static/style.css"))
        .send()
        .expect("css")
        .text()
        .expect("text");
    assert!(
        css.contains("form.method-edit { display: grid;")
            && css.contains("form.method-edit label { display: grid;"),
        "the edit form is not laid out one field a row"
    );
}
both_databases!(the_method_page_is_its_home);
