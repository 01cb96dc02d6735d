//! Trust over time (issue 14 item 5): bootstrap 95 % intervals on every leaderboard average,
//! background re-scoring when the recorded evaluator version is older than the running one
//! (with the before/after differences listed, private ones to their owners only), and the
//! overlaid curves of a dataset's best entries. One server start per database, then one restart
//! to re-score.

use std::path::Path;
use std::time::{Duration, Instant};

use crate::common::*;
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(120);

fn id_of(r: reqwest::blocking::Response) -> i64 {
    assert!(r.status().is_success(), "upload: {}", r.status());
    r.json::<Value>().expect("json")["id"]
        .as_i64()
        .expect("an id")
}

/// The interval of a JSON object that has one.
fn ci(v: &Value) -> Option<(f64, f64)> {
    let c = v.get("ci95")?.as_array()?;
    Some((c[0].as_f64()?, c[1].as_f64()?))
}

/// The text of a page.
fn fetch_page(url: &str) -> String {
    client()
        .get(url)
        .send()
        .and_then(|r| r.text())
        .expect("page")
}

/// The overlaid charts of a board page, each up to its closing tag.
fn overlay_figures(page: &str) -> Vec<&str> {
    page.split("<figure class=\"overlay\">")
        .skip(1)
        .map(|f| &f[..f.find("</figure>").expect("closed")])
        .collect()
}

fn row<'a>(board: &'a Value, method: &str) -> &'a Value {
    board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == method)
        .unwrap_or_else(|| panic!("no row of {method}: {board}"))
}

/// Every interval of the board contains its score, and every average and every score has one.
fn check_intervals(board: &Value) {
    for row in board["rows"].as_array().expect("rows") {
        for (dataset, cell) in row["scores"].as_object().expect("scores") {
            let (lo, hi) = ci(cell).unwrap_or_else(|| panic!("{dataset}: no ci95 in {cell}"));
            let score = cell["score"].as_f64().expect("score");
            assert!(lo <= score && score <= hi, "{dataset}: {lo} {score} {hi}");
        }
        match row["average"].as_f64() {
            Some(avg) => {
                let (lo, hi) = ci(row).unwrap_or_else(|| panic!("no ci95 on {row}"));
                assert!(lo <= avg && avg <= hi, "average: {lo} {avg} {hi}");
            }
            None => assert!(row.get("ci95").is_none(), "{row}"),
        }
    }
}

fn count(db: &TestDb, dir: &Path, sql: &str) -> String {
    column(db, dir, sql).pop().expect("one row")
}

fn trust_over_time(kind: Db) {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "trust");
    let datasets = reference_datasets(dir.path());
    std::os::unix::fs::symlink(
        fixtures().join("dataset").canonicalize().expect("fixture"),
        datasets.join("synthB"),
    )
    .expect("symlink");
    let results = fixtures().join("results");
    let b_file = dir.path().join("noisesmall_synthB-test.csv");
    std::fs::copy(results.join("noisesmall_synthA-test.csv"), &b_file).expect("copy");

    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let alpha_a = id_of(upload(
        &server,
        "alpha",
        "synthA",
        &results.join("noisemedium_synthA-test.csv"),
        None,
    ));
    let alpha_b = id_of(upload(&server, "alpha", "synthB", &b_file, None));
    let gamma_a = id_of(upload(
        &server,
        "gamma",
        "synthA",
        &results.join("noiselarge_synthA-test.csv"),
        None,
    ));
    let beta_private = id_of(upload_with(
        &server,
        &server.token,
        &[
            ("method", "beta"),
            ("dataset", "synthA"),
            ("visibility", "private"),
        ],
        &results.join("noisesmall_synthA-test.csv"),
    ));
    for id in [alpha_a, alpha_b, gamma_a] {
        wait_done(&base, id, WAIT);
    }
    // The private one, as its owner follows it.
    let started = Instant::now();
    loop {
        let s: Value = get_as(
            &format!("{base}/api/v1/submissions/{beta_private}"),
            &server.token,
        )
        .json()
        .expect("json");
        if s["status"] == "done" {
            break;
        }
        assert!(s["status"] != "failed" && started.elapsed() < WAIT, "{s}");
        std::thread::sleep(Duration::from_millis(100));
    }

    // Intervals on every score and average, the same on every read.
    let mut boards = Vec::new();
    for protocol in ["bop19", "eccv18"] {
        let url = format!("{base}/api/v1/leaderboards/{protocol}");
        let board = get_json(&url);
        check_intervals(&board);
        assert!(ci(row(&board, "alpha")).is_some(), "{board}");
        assert_eq!(board, get_json(&url), "a second read");
        let one = get_json(&format!("{url}?dataset=synthA"));
        check_intervals(&one);
        boards.push(board["rows"].clone());
    }
    let alpha = row(
        &get_json(&format!("{base}/api/v1/leaderboards/bop19")),
        "alpha",
    )
    .clone();
    let alpha_score = alpha["scores"]["synthA"]["score"].as_f64().expect("score");
    let page = fetch_page(&format!("{base}/leaderboards/bop19"));
    assert!(page.contains("title=\"95 % bootstrap interval: "), "hover");

    // A dataset's board overlays its ranked entries' curves: one line per method per chart.
    for (protocol, charts) in [("bop19", 3), ("eccv18", 1)] {
        let page = fetch_page(&format!("{base}/leaderboards/{protocol}?dataset=synthA"));
        let figures = overlay_figures(&page);
        assert_eq!(figures.len(), charts, "{protocol}: charts");
        for f in figures {
            assert_eq!(f.matches("<polyline").count(), 2, "{protocol}: {f}");
            assert!(f.contains("alpha") && f.contains("gamma") && !f.contains("beta"));
        }
        assert!(
            page.contains("☑ alpha") && page.contains("☑ gamma"),
            "{protocol}"
        );

        // A reader chooses the methods drawn: gamma alone, then alpha added back by its link.
        let board = get_json(&format!(
            "{base}/api/v1/leaderboards/{protocol}?dataset=synthA"
        ));
        let (alpha_id, gamma_id) = (
            row(&board, "alpha")["method_id"].as_i64().expect("id"),
            row(&board, "gamma")["method_id"].as_i64().expect("id"),
        );
        let page = fetch_page(&format!(
            "{base}/leaderboards/{protocol}?dataset=synthA&curves={gamma_id}"
        ));
        let figures = overlay_figures(&page);
        assert_eq!(figures.len(), charts, "{protocol}: charts of the chosen");
        for f in figures {
            assert_eq!(f.matches("<polyline").count(), 1, "{protocol}: {f}");
            assert!(f.contains("gamma") && !f.contains("alpha"));
        }
        assert!(
            page.contains("☑ gamma") && page.contains("☐ alpha"),
            "{protocol}"
        );
        assert!(
            page.contains("<details class=\"curve-choice\" open>"),
            "the choice stays open"
        );
        assert!(
            page.contains(&format!("curves={gamma_id}%2C{alpha_id}#curves")),
            "{protocol}: the link that adds alpha"
        );
        for bad in ["abc", "1,2,3,4,5,6"] {
            let r = client()
                .get(format!(
                    "{base}/api/v1/leaderboards/{protocol}?dataset=synthA&curves={bad}"
                ))
                .send()
                .expect("answer");
            assert_eq!(r.status().as_u16(), 400, "curves={bad}");
            assert!(r.text().expect("body").contains("curves"), "curves={bad}");
        }
    }
    drop(server);

    // An older evaluator's scores, one of them not what it computes; and a score stored before
    // intervals were.
    execute(
        &db,
        &data,
        &format!(
            "UPDATE submissions SET evaluator_version = '0.0.0' WHERE id IN ({alpha_a}, {beta_private})"
        ),
    );
    for (id, wrong) in [(alpha_a, "0.01"), (beta_private, "0.02")] {
        execute(
            &db,
            &data,
            &format!(
                "UPDATE scores SET score = {wrong} WHERE submission_id = {id} AND protocol = 'bop19'"
            ),
        );
    }
    execute(
        &db,
        &data,
        &format!(
            "UPDATE scores SET ci_low = NULL, ci_high = NULL, replicates = NULL WHERE submission_id = {gamma_a}"
        ),
    );

    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let started = Instant::now();
    while count(
        &db,
        &data,
        "SELECT CAST(COUNT(*) AS TEXT) FROM submissions WHERE rescore = 1",
    ) != "0"
    {
        assert!(started.elapsed() < WAIT, "re-scoring not done");
        std::thread::sleep(Duration::from_millis(200));
    }
    // Restored, with the same intervals another process drew.
    for (protocol, before) in ["bop19", "eccv18"].iter().zip(&boards) {
        let board = get_json(&format!("{base}/api/v1/leaderboards/{protocol}"));
        assert_eq!(&board["rows"], before, "{protocol} after re-scoring");
    }
    let versions = column(
        &db,
        &data,
        "SELECT DISTINCT evaluator_version FROM submissions",
    );
    assert_eq!(versions.len(), 1, "{versions:?}");

    // The differences: the public one to everyone, the private one to its owner only.
    let public = get_json(&format!("{base}/api/v1/rescoring"));
    let changes = public["changes"].as_array().expect("changes");
    let alpha_change = changes
        .iter()
        .find(|c| c["submission_id"] == alpha_a && c["protocol"] == "bop19" && c["key"] == "score")
        .unwrap_or_else(|| panic!("alpha's change listed: {public}"));
    assert_eq!(alpha_change["before"].as_f64(), Some(0.01));
    assert_eq!(alpha_change["after"].as_f64(), Some(alpha_score));
    assert_eq!(alpha_change["old_version"], "0.0.0");
    assert_eq!(alpha_change["new_version"], versions[0].as_str());
    assert_eq!(changes.len(), 1, "only what changed: {public}");
    let own: Value = get_as(&format!("{base}/api/v1/rescoring"), &server.token)
        .json()
        .expect("json");
    let beta = own["changes"]
        .as_array()
        .expect("changes")
        .iter()
        .find(|c| c["submission_id"] == beta_private)
        .unwrap_or_else(|| panic!("the owner sees the private change: {own}"));
    assert_eq!(beta["before"].as_f64(), Some(0.02));
    let other = account(&data, &db, "stranger");
    let theirs: Value = get_as(&format!("{base}/api/v1/rescoring"), &other)
        .json()
        .expect("json");
    assert_eq!(theirs["changes"], public["changes"], "hidden from others");
    let page = fetch_page(&format!("{base}/rescoring"));
    assert!(page.contains("0.010000") && page.contains("0.0.0") && !page.contains("0.020000"));
}
both_databases!(trust_over_time);
