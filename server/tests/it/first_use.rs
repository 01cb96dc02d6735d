//! What a BOP researcher meets in the first hour (issue 27), over real HTTP: warnings only
//! about the protocols the uploader chose, parameters printed as the protocols define them,
//! and errors that name the next step.

use std::process::Command;
use std::time::Duration;

use crate::common::{
    BIN, Db, TestDb, fixtures, get_as, get_json, reference_datasets, start, upload, upload_with,
    wait_done,
};
use serde_json::Value;

/// The pre-flight warnings of an answer to an upload, one per line.
fn warnings(body: &Value) -> String {
    body["preflight"]["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .map(|w| w.as_str().expect("text"))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn warnings_follow_the_protocols_asked_for() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "first_use");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    // Several estimates per target: more than eccv18's one.
    let file = fixtures().join("results/multi_synthA-test.csv");
    let eccv18 = "beyond what eccv18 considers per target will not count";

    // No protocol chosen: scored under both, warned about as a BOP'19 file.
    let r = upload(&server, "plain", "synthA", &file, None);
    assert_eq!(r.status(), 202);
    let body: Value = r.json().expect("json");
    assert_eq!(
        body["submission"]["protocols"],
        serde_json::json!(["bop19", "eccv18"])
    );
    assert!(!warnings(&body).contains("eccv18"), "{}", warnings(&body));
    let id = body["id"].as_i64().expect("id");
    let done = wait_done(&server.base, id, Duration::from_secs(120));
    assert!(
        done["scores"]["eccv18"].is_object(),
        "still scored under eccv18"
    );

    // Asked for eccv18, or for both: its selection is warned about.
    for (method, asked, scored) in [
        ("ecc", "eccv18", serde_json::json!(["eccv18"])),
        (
            "both",
            "bop19,eccv18",
            serde_json::json!(["bop19", "eccv18"]),
        ),
    ] {
        let r = upload(&server, method, "synthA", &file, Some(asked));
        assert_eq!(r.status(), 202, "{asked}");
        let body: Value = r.json().expect("json");
        assert_eq!(body["submission"]["protocols"], scored, "{asked}");
        assert!(
            warnings(&body).contains(eccv18),
            "{asked}: {}",
            warnings(&body)
        );
    }

    // `check-results` says what the upload would: eccv18's selection only when asked for.
    let check = |extra: &[&str]| {
        let out = Command::new(BIN)
            .arg("check-results")
            .arg(&file)
            .arg("--dataset")
            .arg(datasets.join("synthA"))
            .args(extra)
            .output()
            .expect("runs");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let default = check(&[]);
    assert!(!default.contains("eccv18"), "{default}");
    let asked = check(&["--protocol", "eccv18"]);
    assert!(asked.contains(eccv18), "{asked}");
}

#[test]
fn parameters_read_as_the_protocols_define_them() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "first_use");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = &server.base;
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "plain", "synthA", &file, None);
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(base, id, Duration::from_secs(120));

    // numpy's arange(0.05, 0.51, 0.05) computes 0.15000000000000002 and 0.30000000000000004
    // for the 0.15 and 0.3 bop_toolkit lists; eccv18's curve 0.35000000000000003.
    let computed = [
        "0.15000000000000002",
        "0.30000000000000004",
        "0.35000000000000003",
    ];
    let fractions = "0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5";
    let page = get_as(&format!("{base}/submissions/{id}"), "")
        .text()
        .expect("page");
    assert!(
        page.contains(&format!(
            "vsd thresholds {fractions} (delta 15, tau {fractions}"
        )),
        "{page}"
    );
    assert!(
        page.contains("vsd thresholds 0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35,"),
        "{page}"
    );
    let records = get_json(&format!("{base}/api/v1/submissions/{id}"))["records"].clone();
    assert_eq!(
        records["bop19"]["parameters"]["errors"][0]["thresholds"][2],
        0.15
    );
    let mut texts = vec![page, records.to_string()];
    for protocol in ["bop19", "eccv18"] {
        for ext in ["csv", "json", "tex"] {
            let url = format!("{base}/leaderboards/{protocol}/export.{ext}?dataset=synthA");
            let text = get_as(&url, "").text().expect("export");
            // The JSON export is pretty-printed: its numbers compared on one line.
            let text = match ext {
                "json" => serde_json::from_str::<Value>(&text)
                    .expect("JSON")
                    .to_string(),
                _ => text,
            };
            assert!(text.contains("0.05,0.1,0.15,0.2"), "{url}: {text}");
            texts.push(text);
        }
    }
    for text in &texts {
        for c in computed {
            assert!(!text.contains(c), "{c} in {text}");
        }
    }
}

#[test]
fn errors_give_the_next_step() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "first_use");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = &server.base;
    let file = fixtures().join("results/noisesmall_synthA-test.csv");

    // A dataset the server does not serve: the served ones, and where the name was read.
    let unnamed = dir.path().join("results.csv");
    std::fs::copy(&file, &unnamed).expect("copy");
    let r = upload(&server, "m", "tless", &unnamed, None);
    assert_eq!(r.status(), 400);
    let said = r.json::<Value>().expect("json")["error"].to_string();
    assert!(
        said.contains(
            "unknown dataset `tless` (from the field `dataset`): this server serves synthA"
        ),
        "{said}"
    );
    let named = dir.path().join("m_tless-test.csv");
    std::fs::copy(&file, &named).expect("copy");
    let r = upload_with(&server, &server.token, &[("method", "m")], &named);
    assert_eq!(r.status(), 400);
    let said = r.json::<Value>().expect("json")["error"].to_string();
    assert!(
        said.contains(
            "unknown dataset `tless` (from the file name m_tless-test.csv): this server serves \
             synthA"
        ),
        "{said}"
    );
    // A board for it: a 404 page that lists them too, and its JSON twin.
    for path in ["/leaderboards/bop19", "/api/v1/leaderboards/bop19"] {
        let r = get_as(&format!("{base}{path}?dataset=tless"), "");
        assert_eq!(r.status(), 404, "{path}");
        let text = r.text().expect("text");
        assert!(
            text.contains(
                "unknown dataset `tless` (from the parameter `dataset`): this server serves synthA"
            ),
            "{path}: {text}"
        );
    }

    // A spreadsheet's CSV, separated by semicolons: one problem for the file.
    let text = std::fs::read_to_string(&file).expect("fixture");
    let semicolons = dir.path().join("semi_synthA-test.csv");
    std::fs::write(&semicolons, text.replace(',', ";")).expect("write");
    let r = upload(&server, "semi", "synthA", &semicolons, None);
    assert_eq!(r.status(), 422);
    let body: Value = r.json().expect("json");
    let problems = body["problems"].as_array().expect("problems");
    assert_eq!(problems.len(), 1, "{body}");
    assert_eq!(
        problems[0]["message"],
        "the file is separated by `;`; BOP result files use commas"
    );

    // A filter's parameter named as the query names it.
    let r = get_as(
        &format!("{base}/api/v1/leaderboards/bop19?training=realx"),
        "",
    );
    assert_eq!(r.status(), 400);
    let said = r.json::<Value>().expect("json")["error"].to_string();
    assert!(
        said.contains("parameter `training` must be one of"),
        "{said}"
    );
    assert!(!said.contains("training_data"), "{said}");

    // A filter that leaves out every method says so, with the way back.
    let r = upload(&server, "public", "synthA", &file, None);
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(base, id, Duration::from_secs(120));
    let page = |query: &str| {
        get_as(&format!("{base}/leaderboards/bop19{query}"), "")
            .text()
            .expect("page")
    };
    let all = page("?dataset=synthA");
    assert!(all.contains(">public<"), "{all}");
    let none = page("?dataset=synthA&training=real");
    assert!(
        none.contains("No finished public submission matches this filter."),
        "{none}"
    );
    assert!(
        !none.contains("No finished public submission yet"),
        "{none}"
    );
    assert!(
        none.contains("href=\"/leaderboards/bop19?dataset=synthA\""),
        "{none}"
    );
}
