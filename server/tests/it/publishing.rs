//! Publishing, the owner's list and live progress (issue 12), over real HTTP on both
//! databases: an API upload is private unless it asks; a file in metres is held back until its
//! owner confirms; publishing and withdrawing change the board JSON; the owner lists and
//! downloads their submissions (the uploaded bytes, the report and the per-estimate errors
//! `poseboard eval` gives) while another account sees none of it; and a running job's
//! progress moves, with the queue worded plainly and waits estimated from the speed measured
//! on this server.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use crate::common::{
    BIN, Db, Server, TestDb, account, both_databases, browser, client, csrf_of, fixtures, get_as,
    get_json, reference_datasets, start, upload, upload_with,
};
use reqwest::blocking::multipart;
use serde_json::{Value, json};

/// What `poseboard eval` writes for a file: the report and the per-estimate errors.
fn cli_eval(dataset: &Path, results: &Path, protocol: &str) -> (Value, Value) {
    let dir = tempfile::tempdir().expect("tmp");
    let (out, errors) = (
        dir.path().join("report.json"),
        dir.path().join("errors.json"),
    );
    let status = Command::new(BIN)
        .args(["eval", "--protocol", protocol, "--threads", "1"])
        .arg("--dataset")
        .arg(dataset)
        .arg("--results")
        .arg(results)
        .arg("--out")
        .arg(&out)
        .arg("--errors-out")
        .arg(&errors)
        .stdout(Stdio::null())
        .status()
        .expect("poseboard eval runs");
    assert!(status.success());
    let read = |p: &Path| -> Value {
        serde_json::from_str(&std::fs::read_to_string(p).expect("written")).expect("json")
    };
    (read(&out), read(&errors))
}

/// Waits until the owner (`token`) sees submission `id` done; returns its JSON.
pub(crate) fn wait_owner(server: &Server, token: &str, id: i64) -> Value {
    let start = Instant::now();
    loop {
        let s: Value = get_as(&format!("{}/api/v1/submissions/{id}", server.base), token)
            .json()
            .expect("json");
        match s["status"].as_str() {
            Some("done") => return s,
            Some("failed") => panic!("submission {id} failed: {s}"),
            _ => {}
        }
        assert!(start.elapsed() < Duration::from_secs(120), "not done: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The board row of `method` on the BOP'19 JSON board, if any.
fn board_row(server: &Server, method: &str) -> Option<Value> {
    get_json(&format!("{}/api/v1/leaderboards/bop19", server.base))["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == method)
        .cloned()
}

/// POSTs a visibility change as a form, the way `curl -d visibility=public` sends it.
fn set_visibility(server: &Server, token: &str, id: i64, form: &[(&str, &str)]) -> (u16, Value) {
    let r = client()
        .post(format!(
            "{}/api/v1/submissions/{id}/visibility",
            server.base
        ))
        .bearer_auth(token)
        .form(form)
        .send()
        .expect("answered");
    (r.status().as_u16(), r.json().unwrap_or(Value::Null))
}

fn api_default_private_publish_withdraw_and_the_owners_list(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "publish");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let bob = account(&data, &db, "bob");
    let (base, owner) = (server.base.clone(), server.token.clone());
    let file = fixtures().join("results/noisemedium_synthA-test.csv");

    // Anything but public or private is refused.
    let fields = [("method", "quiet-net"), ("dataset", "synthA")];
    let r = upload_with(
        &server,
        &owner,
        &[fields[0], fields[1], ("visibility", "yes")],
        &file,
    );
    assert_eq!(r.status(), 400, "{kind:?}");

    // Without the field: private.
    let r = upload_with(&server, &owner, &fields, &file);
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    let id = body["id"].as_i64().expect("id");
    assert_eq!(body["submission"]["visibility"], "private", "{kind:?}");
    let done = wait_owner(&server, &owner, id);
    assert!(
        done["publication"]
            .as_str()
            .expect("publication")
            .starts_with("private"),
        "{kind:?}: {done}"
    );
    assert_eq!(board_row(&server, "quiet-net"), None, "{kind:?}: private");

    // The owner's list has it, with its score; another account sees none of it.
    let (report, errors) = cli_eval(&datasets.join("synthA"), &file, "bop19");
    let mine: Value = get_as(&format!("{base}/api/v1/me/submissions"), &owner)
        .json()
        .expect("json");
    let listed = &mine["submissions"][0];
    assert_eq!(listed["id"], id, "{kind:?}: {mine}");
    assert_eq!(listed["visibility"], "private");
    assert_eq!(listed["scores"]["bop19"], report["bop19_average_recall"]);
    let theirs: Value = get_as(&format!("{base}/api/v1/me/submissions"), &bob)
        .json()
        .expect("json");
    assert_eq!(theirs["submissions"], json!([]), "{kind:?}");

    // The method of a private submission: its owner sees it on the page and through the API
    // alike (the API used to answer 404 to the owner); anyone else is told nothing is there.
    let method_id = done["method_id"].as_i64().expect("method id");
    for path in [
        format!("/api/v1/methods/{method_id}"),
        format!("/methods/{method_id}"),
    ] {
        let url = format!("{base}{path}");
        assert_eq!(get_as(&url, &owner).status(), 200, "{kind:?} {path}");
        for token in [bob.as_str(), ""] {
            assert_eq!(get_as(&url, token).status(), 404, "{kind:?} {path}");
        }
    }
    let of_method: Value = get_as(&format!("{base}/api/v1/methods/{method_id}"), &owner)
        .json()
        .expect("json");
    assert_eq!(of_method["method"]["name"], "quiet-net", "{kind:?}");
    // The owner's own private submission is listed to the owner (and to nobody else).
    assert_eq!(
        of_method["submissions"][0]["id"], id,
        "{kind:?}: the owner sees its private submission: {of_method}"
    );
    assert_eq!(
        of_method["submissions"].as_array().map(Vec::len),
        Some(1),
        "{kind:?}"
    );
    let downloads = [
        format!("{base}/api/v1/submissions/{id}"),
        format!("{base}/api/v1/submissions/{id}/file"),
        format!("{base}/api/v1/submissions/{id}/report"),
        format!("{base}/api/v1/submissions/{id}/errors/bop19"),
    ];
    for url in &downloads {
        for token in [bob.as_str(), ""] {
            assert_eq!(get_as(url, token).status(), 404, "{kind:?} {url}");
        }
    }
    assert_eq!(
        set_visibility(&server, &bob, id, &[("visibility", "public")]).0,
        404,
        "{kind:?}"
    );
    let r = client()
        .delete(&downloads[0])
        .bearer_auth(&bob)
        .send()
        .expect("answered");
    assert_eq!(r.status(), 404, "{kind:?}");

    // The owner downloads what they sent, the report and the errors `poseboard eval` gives.
    let sent = get_as(&downloads[1], &owner);
    assert_eq!(sent.status(), 200);
    assert_eq!(
        sent.bytes().expect("body").to_vec(),
        std::fs::read(&file).expect("file"),
        "{kind:?}: the uploaded bytes"
    );
    let got: Value = get_as(&downloads[2], &owner).json().expect("json");
    assert_eq!(
        got["bop19"]["bop19_average_recall"],
        report["bop19_average_recall"]
    );
    let got: Value = get_as(&downloads[3], &owner).json().expect("json");
    assert!(!errors.as_array().expect("rows").is_empty());
    assert_eq!(got, errors, "{kind:?}: the per-estimate errors");
    assert_eq!(
        get_as(
            &format!("{base}/api/v1/submissions/{id}/errors/eccv18"),
            &owner
        )
        .json::<Value>()
        .expect("json")
        .as_array()
        .map(Vec::len),
        Some(
            cli_eval(&datasets.join("synthA"), &file, "eccv18")
                .1
                .as_array()
                .expect("rows")
                .len()
        )
    );

    // Publishing and withdrawing change the board.
    let (status, answer) = set_visibility(&server, &owner, id, &[("visibility", "shared")]);
    assert_eq!(status, 400, "{kind:?}: {answer}");
    let (status, answer) = set_visibility(&server, &owner, id, &[("visibility", "public")]);
    assert_eq!(status, 200, "{kind:?}: {answer}");
    let row = board_row(&server, "quiet-net").expect("published");
    assert_eq!(
        row["scores"]["synthA"]["score"],
        report["bop19_average_recall"]
    );
    assert_eq!(get_as(&downloads[0], "").status(), 200, "{kind:?}: public");
    let r = client()
        .post(format!("{base}/api/v1/submissions/{id}/visibility"))
        .bearer_auth(&owner)
        .json(&json!({ "visibility": "private" }))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200, "{kind:?}");
    assert_eq!(board_row(&server, "quiet-net"), None, "{kind:?}: withdrawn");
    assert_eq!(get_as(&downloads[0], "").status(), 404, "{kind:?}");

    // Deleting a published one takes it off the board, with its file, scores and errors.
    set_visibility(&server, &owner, id, &[("visibility", "public")]);
    assert!(board_row(&server, "quiet-net").is_some());
    let r = client()
        .delete(&downloads[0])
        .bearer_auth(&owner)
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200, "{kind:?}");
    assert_eq!(board_row(&server, "quiet-net"), None, "{kind:?}: deleted");
    for url in &downloads {
        assert_eq!(get_as(url, &owner).status(), 404, "{kind:?} {url}");
    }
    let mine: Value = get_as(&format!("{base}/api/v1/me/submissions"), &owner)
        .json()
        .expect("json");
    assert_eq!(mine["submissions"], json!([]), "{kind:?}");
}
both_databases!(api_default_private_publish_withdraw_and_the_owners_list);

/// The fixture with every translation divided by 1000: metres instead of millimetres.
pub(crate) fn in_metres(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(fixtures().join("results/noisemedium_synthA-test.csv"))
        .expect("fixture");
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let mut cols: Vec<String> = line.split(',').map(str::to_string).collect();
        if i > 0 {
            cols[5] = cols[5]
                .split_whitespace()
                .map(|v| (v.parse::<f64>().expect("number") / 1000.0).to_string())
                .collect::<Vec<_>>()
                .join(" ");
        }
        out.push_str(&cols.join(","));
        out.push('\n');
    }
    let path = dir.join("metres_synthA-test.csv");
    std::fs::write(&path, out).expect("write");
    path
}

fn red_flags_hold_publication_and_the_form_publishes(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let metres = in_metres(dir.path());

    // The command line does not say OK to it.
    let check = Command::new(BIN)
        .arg("check-results")
        .arg(&metres)
        .arg("--dataset")
        .arg(datasets.join("synthA"))
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&check.stdout);
    assert!(!check.status.success(), "{stdout}");
    assert!(
        stdout.contains("red flag: translations look like metres"),
        "{stdout}"
    );
    assert!(!stdout.contains("OK"), "{stdout}");

    let db = TestDb::new(kind, "held");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let (base, owner) = (server.base.clone(), server.token.clone());
    let r = upload(&server, "metric-net", "synthA", &metres, None);
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    let id = body["id"].as_i64().expect("id");
    assert_eq!(
        body["submission"]["visibility"], "private",
        "{kind:?}: held back"
    );
    assert_eq!(body["submission"]["held"], true);
    assert_eq!(body["preflight"]["red_flags"][0]["kind"], "metres");
    let done = wait_owner(&server, &owner, id);
    let state = done["publication"].as_str().expect("state");
    assert!(
        state.starts_with("held: translations look like metres"),
        "{state}"
    );
    assert_eq!(board_row(&server, "metric-net"), None, "{kind:?}");
    let page = get_as(&format!("{base}/submissions/{id}"), &owner)
        .text()
        .expect("html");
    assert!(
        page.contains("held: translations look like metres"),
        "{kind:?}"
    );
    // Held is visible: a "held" badge, not a green "done", and the reason by the scores.
    assert!(
        page.contains(
            r#"<span class="status held" id="status-text">held: needs your confirmation</span>"#
        ),
        "{kind:?}: {page}"
    );
    assert!(!page.contains(r#"class="status done""#), "{kind:?}");
    let reason = page
        .find(r#"<p class="alert held" id="held-reason">"#)
        .expect("the reason it is held");
    let scores = page.find("<h2>BOP'19 scores</h2>").expect("the scores");
    assert!(
        reason < scores,
        "{kind:?}: the reason comes with the scores"
    );
    assert!(
        page[reason..scores].contains("translations look like metres"),
        "{kind:?}: {}",
        &page[reason..scores]
    );
    assert_eq!(
        get_as(&format!("{base}/submissions/{id}"), "").status(),
        404
    );

    // Publishing needs the owner's confirmation.
    let (status, answer) = set_visibility(&server, &owner, id, &[("visibility", "public")]);
    assert_eq!(status, 409, "{kind:?}: {answer}");
    assert!(answer["error"].as_str().expect("error").contains("metres"));
    assert_eq!(board_row(&server, "metric-net"), None, "{kind:?}");
    let form = [("visibility", "public"), ("confirm", "true")];
    let (status, answer) = set_visibility(&server, &owner, id, &form);
    assert_eq!(status, 200, "{kind:?}: {answer}");
    assert_eq!(answer["visibility"], "public");
    let row = board_row(&server, "metric-net").expect("confirmed: on the board");
    // The board's row says it was published despite its red flag, in the JSON and the page.
    let flagged: Vec<&Value> = row["scores"]
        .as_object()
        .expect("scores")
        .values()
        .filter(|c| c["submission_id"] == id)
        .collect();
    assert_eq!(flagged.len(), 1, "{kind:?}: {row}");
    assert_eq!(
        flagged[0]["red_flags"][0]["kind"], "metres",
        "{kind:?}: {row}"
    );
    let board = get_as(&format!("{base}/leaderboards/bop19"), "")
        .text()
        .expect("html");
    assert!(
        board.contains(r#"<span class="red-flag" title="published despite a red flag: translations look like metres"#),
        "{kind:?}: {board}"
    );
    let page = get_as(&format!("{base}/submissions/{id}"), &owner)
        .text()
        .expect("html");
    assert!(
        page.contains(r#"<span class="status done" id="status-text">done</span>"#),
        "{kind:?}: no longer held"
    );

    // The form's "publish when evaluated" is ticked by default, and publishes.
    let (b, _) = browser(&server, "carol");
    let form_page = b
        .get(format!("{base}/submit"))
        .send()
        .expect("form")
        .text()
        .expect("html");
    assert!(
        form_page.contains(r#"<input type="checkbox" name="publish" value="yes" checked>"#),
        "{kind:?}"
    );
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let multipart = multipart::Form::new()
        .text("csrf", csrf_of(&form_page))
        .text("method", "form-net")
        .text("dataset", "synthA")
        .text("publish", "yes")
        .file("file", &file)
        .expect("file");
    let r = b
        .post(format!("{base}/submit"))
        .multipart(multipart)
        .send()
        .expect("posted");
    assert!(r.status().is_success(), "{kind:?}: {}", r.status());
    let id: i64 = r
        .url()
        .path()
        .strip_prefix("/submissions/")
        .and_then(|s| s.parse().ok())
        .expect("redirected to the submission");
    common::wait_done(&base, id, Duration::from_secs(60));
    let row = board_row(&server, "form-net").expect("published");
    assert!(
        !row.to_string().contains("red_flags"),
        "{kind:?}: no flag on a clean file: {row}"
    );
}
both_databases!(red_flags_hold_publication_and_the_form_publishes);

/// A dataset and a result file big enough for an evaluation of a few seconds on one thread.
fn big_job(datasets: &Path, dir: &Path) -> PathBuf {
    let run = |args: &[&str], paths: &[&Path]| {
        let status = Command::new(BIN)
            .args(args)
            .args(paths)
            .stdout(Stdio::null())
            .status()
            .expect("runs");
        assert!(status.success(), "{args:?}");
    };
    let big = datasets.join("synthbig");
    run(
        &[
            "dataset",
            "synth",
            "--scenes",
            "40",
            "--images-per-scene",
            "10",
        ],
        &[&big],
    );
    let results = dir.join("big-results");
    run(&["dataset", "demo-results"], &[&big, &results]);
    std::fs::read_dir(&results)
        .expect("results")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().contains("noisy"))
        .expect("a noisy demo result")
}

fn progress_moves_while_a_job_runs(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let big = big_job(&datasets, dir.path());
    let db = TestDb::new(kind, "progress");
    let server = start(
        &dir.path().join("data"),
        &datasets,
        &db,
        &["--eval-threads", "1"],
    );
    let base = server.base.clone();
    let small = fixtures().join("results/noisesmall_synthA-test.csv");
    let id_of = |r: reqwest::blocking::Response| -> i64 {
        assert_eq!(r.status(), 202);
        r.json::<Value>().expect("json")["id"].as_i64().expect("id")
    };
    let running = id_of(upload(&server, "big-net", "synthbig", &big, None));
    let start_wait = Instant::now();
    while get_json(&format!("{base}/api/v1/submissions/{running}"))["status"] == "queued" {
        assert!(
            start_wait.elapsed() < Duration::from_secs(30),
            "{kind:?}: never claimed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let next = id_of(upload(&server, "next-net", "synthA", &small, None));
    let last = id_of(upload(&server, "last-net", "synthA", &small, None));

    // While the big job runs: the queue in words, and its progress moving.
    let words = |id: i64| {
        get_json(&format!("{base}/api/v1/submissions/{id}"))["progress_text"]
            .as_str()
            .unwrap_or_default()
            .to_string()
    };
    assert!(
        words(next).starts_with("next in the queue; 1 being evaluated now; scores expected in "),
        "{kind:?}: {}",
        words(next)
    );
    assert!(
        words(last).starts_with("1 submission ahead of yours; 1 being evaluated now"),
        "{kind:?}: {}",
        words(last)
    );
    let mut seen = Vec::new();
    loop {
        let s = get_json(&format!("{base}/api/v1/submissions/{running}"));
        if s["status"] != "running" {
            break;
        }
        let (done, work) = (s["work_done"].as_i64(), s["work"].as_i64().expect("work"));
        if seen.last() != Some(&done) {
            // Evaluations, an estimate counting once under each protocol, with the estimates
            // each protocol evaluates as the pre-flight gave them (in the pre-flight's order).
            let text = s["progress_text"].as_str().expect("progress text");
            let per = &s["preflight"]["estimates_evaluated"];
            assert!(
                text.contains(&format!(
                    " of {work} evaluations done ({} estimates under eccv18, {} under bop19); \
                     scores expected in ",
                    per["eccv18"], per["bop19"]
                )),
                "{kind:?}: {text}"
            );
            seen.push(done);
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let moving: Vec<i64> = seen.iter().flatten().copied().filter(|d| *d > 0).collect();
    assert!(
        moving.len() >= 2 && moving.windows(2).all(|w| w[0] < w[1]),
        "{kind:?}: progress seen {seen:?}"
    );

    // Once done, waits are estimated from the speed measured here, counting only the
    // estimates that will be evaluated.
    for id in [running, next, last] {
        common::wait_done(&base, id, Duration::from_secs(120));
    }
    let mine: Value = get_as(&format!("{base}/api/v1/me/submissions"), &server.token)
        .json()
        .expect("json");
    let (work, ms) = mine["submissions"]
        .as_array()
        .expect("list")
        .iter()
        .map(|s| {
            (
                s["work"].as_i64().expect("work"),
                s["eval_ms"].as_i64().expect("measured"),
            )
        })
        .filter(|(_, ms)| *ms > 0)
        .fold((0, 0), |(w, m), (sw, sm)| (w + sw, m + sm));
    let speed = work as f64 * 1000.0 / ms as f64;
    let extra = fixtures().join("results/extra_synthA-test.csv");
    let r = upload(&server, "extra-net", "synthA", &extra, None);
    let body: Value = r.json().expect("json");
    let id = body["id"].as_i64().expect("id");
    let pre = &body["preflight"];
    let evaluated: i64 = pre["estimates_evaluated"]
        .as_object()
        .expect("per protocol")
        .values()
        .map(|v| v.as_i64().expect("count"))
        .sum();
    assert!(
        evaluated < 2 * pre["estimates"].as_i64().expect("estimates"),
        "{kind:?}: the extra estimates are not counted: {pre}"
    );
    let expected = evaluated as f64 / speed;
    let eta = pre["estimated_seconds"].as_f64().expect("eta");
    assert!(
        (eta - expected).abs() < 1e-6 * expected,
        "{kind:?}: {eta} vs {expected}"
    );
    let done = common::wait_done(&base, id, Duration::from_secs(60));
    assert_eq!(
        done["work"], evaluated,
        "{kind:?}: what the evaluator evaluated"
    );
    let page = client()
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains("to evaluate; at upload, scores were expected after"),
        "{kind:?}: the pre-flight's wait is shown"
    );
}
both_databases!(progress_moves_while_a_job_runs);
