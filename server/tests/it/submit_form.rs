//! The upload form offers what the service accepts (issue 27, item 4): every task the `protocol`
//! field takes, every kind of result file, and how many submissions are left on each dataset,
//! the number `GET /api/v1/me/quota` answers and the fair-use limit enforces. Over the limit the
//! refusal says when the next one is allowed as a date and time, and `poseboard submit` prints
//! what is left. The count comes from the database, so this runs on both.

use std::process::{Command, Stdio};

use crate::common::{
    BIN, Db, TestDb, both_databases, browser, csrf_of, fixtures, reference_datasets, start,
};
use reqwest::blocking::{Client, multipart};
use serde_json::Value;

/// Every value the upload's `protocol` field takes, and the kinds of file it reads.
const TASKS: [&str; 7] = [
    "",
    "bop19",
    "eccv18",
    "bop19,eccv18",
    "bop24",
    "bop22-det",
    "bop22-seg",
];
const FILE_KINDS: [&str; 3] = [".csv", ".json", ".zip"];

/// The options of the form's select `name`: (value, text) in order.
fn options(page: &str, name: &str) -> Vec<(String, String)> {
    let start = page
        .find(&format!("<select name=\"{name}\">"))
        .unwrap_or_else(|| panic!("no select {name}"));
    let select = &page[start..start + page[start..].find("</select>").expect("</select>")];
    select
        .split("<option value=\"")
        .skip(1)
        .map(|o| {
            let value = o.split('"').next().expect("value").to_string();
            let text = o[o.find('>').expect(">") + 1..]
                .split("</option>")
                .next()
                .expect("text")
                .to_string();
            (value, text)
        })
        .collect()
}

/// The text of the form's `dataset` option for `name`.
fn dataset_option(page: &str, name: &str) -> String {
    options(page, "dataset")
        .into_iter()
        .find(|(v, _)| v == name)
        .unwrap_or_else(|| panic!("no option for {name}"))
        .1
}

/// The value of the first attribute `attr` after `after` in `page`.
fn attribute<'a>(page: &'a str, after: &str, attr: &str) -> &'a str {
    let at = page.find(after).unwrap_or_else(|| panic!("no {after}"));
    let rest = &page[at..];
    let from = rest.find(&format!("{attr}=\"")).expect("attribute") + attr.len() + 2;
    rest[from..].split('"').next().expect("value")
}

/// Uploads `file` through the form as the signed-in browser `b`.
fn form_upload(b: &Client, base: &str, file: &str) -> reqwest::blocking::Response {
    let page = b.get(format!("{base}/submit")).send().expect("form");
    let csrf = csrf_of(&page.text().expect("page"));
    let form = multipart::Form::new()
        .text("csrf", csrf)
        .text("method", "form-net")
        .text("dataset", "synthA")
        .text("protocol", "bop19")
        .file("file", fixtures().join("results").join(file))
        .expect("file");
    b.post(format!("{base}/submit"))
        .multipart(form)
        .send()
        .expect("answered")
}

fn quota(b: &Client, base: &str) -> Value {
    let r = b
        .get(format!("{base}/api/v1/me/quota?dataset=synthA"))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200);
    r.json().expect("JSON")
}

fn the_form_offers_what_the_service_accepts(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "submitform");
    let server = start(
        &data,
        &datasets,
        &db,
        &[
            "--no-demo",
            "--workers",
            "0",
            "--submissions-per-window",
            "2",
        ],
    );
    let base = server.base.as_str();
    let (b, _) = browser(&server, "former");

    // Every task and every file kind.
    let page = b.get(format!("{base}/submit")).send().expect("form");
    let page = page.text().expect("page");
    let offered: Vec<String> = options(&page, "protocol")
        .into_iter()
        .map(|o| o.0)
        .collect();
    assert_eq!(offered, TASKS, "the form's tasks");
    let accept = attribute(&page, "<input type=\"file\"", "accept");
    let list = &page[page
        .find("<ul class=\"hint file-kinds\">")
        .expect("the file kinds")..];
    let list = &list[..list.find("</ul>").expect("</ul>")];
    let described: Vec<&str> = list
        .split("<li>")
        .skip(1)
        .map(|li| li.split("</li>").next().expect("li"))
        .collect();
    for kind in FILE_KINDS {
        assert!(accept.split(',').any(|a| a == kind), "{kind} in {accept}");
        assert!(
            described
                .iter()
                .any(|d| d.starts_with(&format!("<code>{kind}</code>: "))),
            "{kind} described: {described:?}"
        );
    }
    // The API takes each task the form offers (and names them when it does not know one).
    let refused = crate::common::upload_with(
        &server,
        &server.token,
        &[
            ("method", "x"),
            ("dataset", "synthA"),
            ("protocol", "bop23"),
        ],
        &fixtures().join("results/noisesmall_synthA-test.csv"),
    );
    assert_eq!(refused.status(), 400);
    let error = refused.json::<Value>().expect("JSON")["error"].to_string();
    for task in TASKS.iter().filter(|t| !t.is_empty()) {
        assert!(error.contains(task), "{task} named in {error}");
    }

    // What is left, on the form and from the API, counts down with each upload.
    assert!(
        dataset_option(&page, "synthA").ends_with(": 2 of 2 submissions left today"),
        "{}",
        dataset_option(&page, "synthA")
    );
    assert_eq!(quota(&b, base)["left"], 2);
    // The quota is the caller's, on a served dataset the request names.
    let anonymous = crate::common::client()
        .get(format!("{base}/api/v1/me/quota?dataset=synthA"))
        .send()
        .expect("answered");
    assert_eq!(anonymous.status(), 401);
    for (query, says) in [("", "`dataset`"), ("?dataset=tless", "synthA")] {
        let r = b
            .get(format!("{base}/api/v1/me/quota{query}"))
            .send()
            .expect("answered");
        assert_eq!(r.status(), 400, "{query}");
        let error = r.json::<Value>().expect("JSON")["error"].to_string();
        assert!(error.contains(says), "{query}: {error}");
    }
    let sent = form_upload(&b, base, "noisesmall_synthA-test.csv");
    assert!(sent.status().is_success(), "{}", sent.status());
    let q = quota(&b, base);
    assert_eq!((q["used"].as_u64(), q["left"].as_u64()), (Some(1), Some(1)));
    let page = b.get(format!("{base}/submit")).send().expect("form");
    let option = dataset_option(&page.text().expect("page"), "synthA");
    assert!(
        option.ends_with(&format!(": {}", q["summary"].as_str().expect("summary"))),
        "{option} / {q}"
    );
    assert!(
        option.ends_with(": 1 of 2 submissions left today"),
        "{option}"
    );
    assert!(
        form_upload(&b, base, "noisemedium_synthA-test.csv")
            .status()
            .is_success()
    );

    // None left: the form, the API and the refusal name the same minute.
    let q = quota(&b, base);
    assert_eq!(q["left"], 0, "{q}");
    let at = q["next_at_utc"].as_str().expect("next_at_utc").to_string();
    assert!(
        at.len() == "2026-12-04 17:20 UTC".len() && at.ends_with(" UTC"),
        "{at}"
    );
    let page = b.get(format!("{base}/submit")).send().expect("form");
    let option = dataset_option(&page.text().expect("page"), "synthA");
    assert!(
        option.ends_with(&format!("none left today: the next at {at}")),
        "{option}"
    );
    let refused = form_upload(&b, base, "noiselarge_synthA-test.csv");
    assert_eq!(refused.status(), 429);
    let page = refused.text().expect("page");
    assert!(
        page.contains(&format!("the next one is allowed at {at}")),
        "the refusal names the time: {page}"
    );
    assert!(!page.contains(" allowed in "), "{page}");

    // The CLI, refused, prints what is left.
    let tester_file = fixtures().join("results/noisesmall_synthA-test.csv");
    for n in 0..2 {
        let sent = crate::common::upload_with(
            &server,
            &server.token,
            &[("method", &format!("cli-{n}")), ("dataset", "synthA")],
            &tester_file,
        );
        assert!(sent.status().is_success(), "{}", sent.status());
    }
    let over = crate::common::upload_with(
        &server,
        &server.token,
        &[("method", "cli-2"), ("dataset", "synthA")],
        &fixtures().join("results/noisemedium_synthA-test.csv"),
    );
    assert_eq!(over.status(), 429);
    let retry = over
        .headers()
        .get("retry-after")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok())
        .expect("Retry-After in seconds");
    assert!((80_000..=86_400).contains(&retry), "{retry}");
    let error = over.json::<Value>().expect("JSON")["error"].to_string();
    assert!(
        error.contains("within 24 hours: the next one is allowed at "),
        "{error}"
    );
    let out = Command::new(BIN)
        .arg("submit")
        .arg(fixtures().join("results/noisemedium_synthA-test.csv"))
        .args(["--method", "cli-2", "--dataset", "synthA"])
        .env("POSEBOARD_SERVER", base)
        .env("POSEBOARD_TOKEN", &server.token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("429") && stderr.contains("synthA: none left today: the next at "),
        "{stderr}"
    );
}
both_databases!(the_form_offers_what_the_service_accepts);
