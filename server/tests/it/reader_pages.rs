//! What readers are told, over plain HTTP: answers over a limit say the limit (JSON on the
//! API, a page elsewhere), the API page lists every route of the OpenAPI document with its
//! error answers, and the recall-vs-visibility curve shows how many target instances each of
//! its points stands for. The browser tests (`browser.rs`) check the layout.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

use crate::common::{
    Db, Server, TestDb, both_databases, cli_report, client, fixtures, get_json, reference_datasets,
    start, upload, wait_done,
};
use serde_json::Value;

/// Announces a body of 50 MiB on `path` and sends none of it: the answer comes at once.
/// Returns the status, the content type and the body.
fn announce_huge_body(server: &Server, path: &str) -> (u16, String, String) {
    let addr = server.base.trim_start_matches("http://");
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    write!(
        stream,
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: multipart/form-data; boundary=x\r\n\
         Content-Length: {}\r\n\r\n",
        50u64 << 20
    )
    .expect("headers sent");
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        let n = stream.read(&mut buf).expect("an answer before the body");
        answer.extend_from_slice(&buf[..n]);
        let text = String::from_utf8_lossy(&answer).to_string();
        if let Some((head, body)) = text.split_once("\r\n\r\n") {
            let length = head
                .lines()
                .find_map(|l| {
                    l.to_ascii_lowercase()
                        .strip_prefix("content-length:")
                        .map(|v| v.trim().to_string())
                })
                .and_then(|v| v.parse::<usize>().ok());
            if n == 0 || length.is_some_and(|len| body.len() >= len) {
                let status = head[9..12].parse().expect("status");
                let kind = head
                    .lines()
                    .find_map(|l| {
                        l.to_ascii_lowercase()
                            .strip_prefix("content-type:")
                            .map(|v| v.trim().to_string())
                    })
                    .unwrap_or_default();
                return (status, kind, body.to_string());
            }
        }
        assert!(n > 0, "the connection closed mid-answer: {text}");
    }
}

fn limits_are_stated(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "limits");
    let args = [
        "--no-demo",
        "--workers",
        "0",
        "--max-upload-mb",
        "1",
        "--submissions-per-window",
        "1",
    ];
    let server = start(&dir.path().join("data"), &datasets, &db, &args);

    // 413 on the API: JSON with the limit.
    let (status, content, body) = announce_huge_body(&server, "/api/v1/submissions");
    assert_eq!(status, 413, "{kind:?}: {body}");
    assert!(content.starts_with("application/json"), "{content}");
    let body: Value = serde_json::from_str(&body).expect("JSON");
    assert_eq!(body["limit_bytes"], 1 << 20, "{body}");
    let message = body["error"].as_str().expect("error");
    assert!(message.contains("1 MiB"), "{message}");

    // 413 on a page: a page, with the limit.
    let (status, content, body) = announce_huge_body(&server, "/submit");
    assert_eq!(status, 413, "{kind:?}");
    assert!(content.starts_with("text/html"), "{content}");
    assert!(body.contains("1 MiB"), "{body}");

    // 429 on the API: JSON with the limit and when to retry.
    let first = fixtures().join("results/noisesmall_synthA-test.csv");
    let second = fixtures().join("results/noisemedium_synthA-test.csv");
    assert_eq!(upload(&server, "m", "synthA", &first, None).status(), 202);
    let refused = upload(&server, "m", "synthA", &second, None);
    assert_eq!(refused.status(), 429, "{kind:?}");
    let content = refused.headers()["content-type"].to_str().expect("type");
    assert!(content.starts_with("application/json"), "{content}");
    let body: Value = refused.json().expect("JSON");
    assert!(body["retry_at"].is_i64(), "{body}");
    let message = body["error"].as_str().expect("error");
    assert!(message.contains("at most 1 "), "{message}");

    // The API page: every route of the OpenAPI document, the error answers, the limits.
    let doc = get_json(&format!("{}/api/v1/openapi.json", server.base));
    let r = client()
        .get(format!("{}/docs/api", server.base))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200);
    let page = r.text().expect("html");
    let paths = doc["paths"].as_object().expect("paths");
    assert!(paths.len() >= 7, "{doc}");
    for (path, item) in paths {
        for method in item.as_object().expect("operations").keys() {
            let heading = format!(
                "<span class=\"verb\">{}</span> {path}</h3>",
                method.to_uppercase()
            );
            assert!(page.contains(&heading), "{heading} on /docs/api");
        }
    }
    let upload_op = &doc["paths"]["/api/v1/submissions"]["post"]["responses"];
    for code in ["401", "413", "422", "429"] {
        let answer = &upload_op[code];
        assert_eq!(
            answer["content"]["application/json"]["schema"]["$ref"], "#/components/schemas/Error",
            "{code}: {answer}"
        );
        assert!(
            page.contains(&format!("<td class=\"num\">{code}</td>")),
            "{code}"
        );
    }
    assert_eq!(
        doc["paths"]["/api/v1/submissions/{id}"]["get"]["responses"]["404"]["content"]["application/json"]
            ["schema"]["$ref"],
        "#/components/schemas/Error"
    );
    assert!(
        page.contains("uploads of at most 1 MiB"),
        "the page states the limit"
    );
    assert!(
        page.contains("at most 1 submission per dataset"),
        "and the fair use"
    );
    let footer = page.split("<footer>").nth(1).expect("a footer");
    assert!(
        footer.contains("href=\"/docs/api\""),
        "linked from the footer"
    );
}
both_databases!(limits_are_stated);

/// The curve's points carry the number of target instances they stand for, and these add up
/// to the targets of the recall `poseboard eval` reports.
fn visibility_curve_counts_targets(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "curve");
    let server = start(&dir.path().join("data"), &datasets, &db, &["--no-demo"]);
    let file = fixtures().join("results/noisemedium_synthA-test.csv");
    let r = upload(&server, "curved", "synthA", &file, Some("eccv18"));
    assert_eq!(r.status(), 202, "{kind:?}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
    let page = client()
        .get(format!("{}/submissions/{id}", server.base))
        .send()
        .expect("answered")
        .text()
        .expect("html");
    let counts: usize = page
        .split("class=\"count\" text-anchor=\"middle\">")
        .skip(1)
        .map(|s| {
            s.split('<')
                .next()
                .expect("text")
                .parse::<usize>()
                .expect("a count")
        })
        .sum();
    let expected = cli_report(&fixtures().join("dataset"), &file, "eccv18");
    let targets = expected["targets_count"].as_u64().expect("targets_count") as usize;
    assert!(targets > 0);
    assert_eq!(
        counts, targets,
        "{kind:?}: the counts shown add up to the targets"
    );
    assert!(
        page.contains(&format!(
            "target instances per bin ({targets} in all, visible at least 0.1)"
        )),
        "{kind:?}: the caption says what is counted"
    );
}
both_databases!(visibility_curve_counts_targets);
