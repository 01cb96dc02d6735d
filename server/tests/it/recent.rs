//! The recent submissions: `/submissions`, `GET /api/v1/submissions` and the Atom feed
//! `/submissions.atom` list the public finished submissions, newest first, 50 a page, each
//! "date – method – dataset – task by owner" (or "by anonymous") with its headline score;
//! private and unfinished ones are left out. The feed is read back with a real XML parser
//! (Python's ElementTree, as the CI machine has Python): the Atom namespace, the elements RFC
//! 4287 requires, RFC 3339 dates, and a method name full of markup read back exactly. Run on
//! both databases.

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;

use crate::common::{
    Db, TestDb, account, both_databases, client, execute, fixtures, get_json, reference_datasets,
    start, upload_scored, upload_with, wait_done,
};
use crate::publishing::wait_owner;

/// A method name that is markup in HTML and XML alike.
const MARKUP: &str = "R&D <blind> \"net\" 'x'";

/// The Atom document `xml` as JSON, parsed by Python's ElementTree: the feed's tag, its `id`,
/// `title`, `updated`, authors' names and links, and each entry's.
fn parse_atom(xml: &[u8]) -> Value {
    const SCRIPT: &str = r#"
import json, sys
import xml.etree.ElementTree as ET
A = "{http://www.w3.org/2005/Atom}"
root = ET.fromstring(sys.stdin.buffer.read())
def text(e, tag):
    x = e.find(A + tag)
    return None if x is None else (x.text or "")
def links(e):
    return [{"rel": l.get("rel", "alternate"), "href": l.get("href")} for l in e.findall(A + "link")]
def authors(e):
    return [a.findtext(A + "name") for a in e.findall(A + "author")]
def node(e):
    return {k: text(e, k) for k in ("id", "title", "updated", "published", "summary")} | {
        "authors": authors(e), "links": links(e)}
print(json.dumps(node(root) | {"tag": root.tag, "entries": [node(e) for e in root.findall(A + "entry")]}))
"#;
    let mut child = Command::new("python3")
        .args(["-c", SCRIPT])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs (the CI machine has it)");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(xml)
        .expect("feed written");
    let out = child.wait_with_output().expect("python3 ends");
    assert!(
        out.status.success(),
        "the feed is not well-formed XML: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(xml)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

/// Whether `s` is an RFC 3339 date-time in UTC as `2026-12-02T15:10:05Z`.
fn rfc3339(s: &str) -> bool {
    let b = s.as_bytes();
    let digits = |r: std::ops::Range<usize>| b[r].iter().all(u8::is_ascii_digit);
    let number = |r: std::ops::Range<usize>| s[r].parse::<u32>().unwrap_or(99);
    b.len() == 20
        && digits(0..4)
        && b[4] == b'-'
        && digits(5..7)
        && b[7] == b'-'
        && digits(8..10)
        && b[10] == b'T'
        && digits(11..13)
        && b[13] == b':'
        && digits(14..16)
        && b[16] == b':'
        && digits(17..19)
        && b[19] == b'Z'
        && (1..=12).contains(&number(5..7))
        && (1..=31).contains(&number(8..10))
        && number(11..13) < 24
        && number(14..16) < 60
        && number(17..19) < 61
}

/// GETs `path`: the status and the body.
fn get(base: &str, path: &str) -> (u16, String) {
    let r = client()
        .get(format!("{base}{path}"))
        .send()
        .expect("answered");
    (r.status().as_u16(), r.text().expect("body"))
}

/// The ids a page of the list's JSON holds, in order.
fn ids(page: &Value) -> Vec<i64> {
    page["submissions"]
        .as_array()
        .expect("submissions")
        .iter()
        .map(|s| s["id"].as_i64().expect("id"))
        .collect()
}

fn the_recent_list_pages_newest_first(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "recent");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let fixture = |name: &str| fixtures().join("results").join(name);

    // The oldest: a public finished submission of `tester`.
    let first = upload_scored(
        &server,
        "recent-a",
        "synthA",
        &fixture("noisesmall_synthA-test.csv"),
        None,
    )["id"]
        .as_i64()
        .expect("id");
    // 52 more like it and one that failed, public all, straight in the database (evaluating
    // 52 files would only make the test slow), ...
    let columns = "method_id, dataset_id, protocols, public, file_name, file_sha256, file_size, \
                   estimates_count, preflight_json, status, created_at, started_at, finished_at, \
                   evaluator_version, hardware, owner_id, hidden, held, work, work_done, eval_ms";
    execute(
        &db,
        &data,
        &format!(
            "WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 52) \
             INSERT INTO submissions ({columns}) SELECT method_id, dataset_id, protocols, public, \
             file_name, 'copy-' || CAST(n.i AS TEXT), file_size, estimates_count, preflight_json, \
             status, created_at + n.i, started_at, finished_at, evaluator_version, hardware, \
             owner_id, hidden, held, work, work_done, eval_ms FROM submissions s, n WHERE s.id = {first}"
        ),
    );
    execute(
        &db,
        &data,
        &format!(
            "INSERT INTO submissions ({columns}) SELECT method_id, dataset_id, protocols, public, \
             file_name, 'failed-copy', file_size, estimates_count, preflight_json, 'failed', \
             created_at + 100, started_at, finished_at, evaluator_version, hardware, owner_id, \
             hidden, held, work, work_done, eval_ms FROM submissions WHERE id = {first}"
        ),
    );
    // ... a private one (of another account: the copies count against `tester`'s fair-use
    // limit), and the newest: an anonymous method named in markup.
    let shy = account(&data, &db, "shy");
    let r = upload_with(
        &server,
        &shy,
        &[("method", "recent-private"), ("dataset", "synthA")],
        &fixture("noisemedium_synthA-test.csv"),
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let private = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_owner(&server, &shy, private);
    let owner = account(&data, &db, "zq_recent_owner");
    let r = upload_with(
        &server,
        &owner,
        &[
            ("method", MARKUP),
            ("dataset", "synthA"),
            ("visibility", "public"),
            ("anonymous", "true"),
        ],
        &fixture("noisemedium_synthA-test.csv"),
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let newest = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&base, newest, Duration::from_secs(120));

    // Page 1: the newest 50, newest first, none private or unfinished; page 2 the rest.
    let one = get_json(&format!("{base}/api/v1/submissions"));
    let listed = ids(&one);
    assert_eq!(listed.len(), 50, "{kind:?}: {one}");
    assert_eq!(listed[0], newest, "{kind:?}");
    assert!(
        listed.windows(2).all(|w| w[0] > w[1]),
        "{kind:?}: {listed:?}"
    );
    assert!(!listed.contains(&private), "{kind:?}");
    assert_eq!(
        (&one["page"], &one["per_page"], &one["newer"], &one["older"]),
        (
            &Value::from(1),
            &Value::from(50),
            &Value::Null,
            &Value::from(2)
        ),
        "{kind:?}"
    );
    let two = get_json(&format!("{base}/api/v1/submissions?page=2"));
    let rest = ids(&two);
    assert_eq!(rest.len(), 4, "{kind:?}: {two}");
    assert_eq!(rest.last(), Some(&first), "{kind:?}");
    assert!(rest[0] < listed[49], "{kind:?}");
    assert_eq!(
        (&two["newer"], &two["older"], &two["more"]),
        (&Value::from(1), &Value::Null, &Value::Bool(false)),
        "{kind:?}"
    );
    let three = get_json(&format!("{base}/api/v1/submissions?page=3"));
    assert!(ids(&three).is_empty(), "{kind:?}");
    let everyone: Vec<i64> = listed.iter().chain(&rest).copied().collect();
    let failed = everyone.iter().max().copied().filter(|id| *id > newest);
    assert_eq!(failed, None, "{kind:?}: the failed copy is not listed");

    // Who and what each row says: the owner, or anonymous; the headline score of its board.
    let newest_row = &one["submissions"][0];
    assert_eq!(newest_row["owner"], "anonymous", "{kind:?}");
    assert_eq!(newest_row["method"], MARKUP, "{kind:?}");
    assert_eq!(newest_row["task"], "bop19, eccv18", "{kind:?}");
    let first_row = &two["submissions"][3];
    assert_eq!(first_row["owner"], "tester", "{kind:?}");
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"));
    let score = board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == "recent-a")
        .expect("on the board")["scores"]["synthA"]["score"]
        .clone();
    assert_eq!(
        (
            &first_row["score"]["board"],
            &first_row["score"]["name"],
            &first_row["score"]["value"]
        ),
        (&Value::from("bop19"), &Value::from("AR"), &score),
        "{kind:?}: {first_row}"
    );

    // The page says the same, escaped, with the links to its neighbours and its feed.
    let (status, page) = get(&base, "/submissions");
    assert_eq!(status, 200, "{kind:?}");
    assert_eq!(page.matches("<li id=\"submission-").count(), 50, "{kind:?}");
    assert!(
        page.contains("R&#38;D &#60;blind&#62; &#34;net&#34;") && !page.contains("<blind>"),
        "{kind:?}: the name is escaped"
    );
    assert!(
        page.contains("by <span class=\"who\">anonymous</span>"),
        "{kind:?}"
    );
    assert!(
        page.contains("rel=\"next\" href=\"/submissions?page=2\""),
        "{kind:?}"
    );
    let (_, second) = get(&base, "/submissions?page=2");
    assert!(
        second.contains("rel=\"prev\" href=\"/submissions\""),
        "{kind:?}"
    );
    assert!(!second.contains("rel=\"next\""), "{kind:?}");
    assert!(
        second.contains("by <span class=\"who\">tester</span>"),
        "{kind:?}"
    );
    for path in ["/", "/submissions"] {
        let (_, html) = get(&base, path);
        assert!(
            html.contains(
                "<link rel=\"alternate\" type=\"application/atom+xml\" title=\"poseboard: recent submissions\" href=\"/submissions.atom\">"
            ),
            "{kind:?} {path}"
        );
        assert!(
            html.contains("<a href=\"/submissions\">"),
            "{kind:?} {path}"
        );
    }
    for bad in ["0", "x", "-1", "100001"] {
        for path in ["/submissions", "/api/v1/submissions"] {
            let (status, body) = get(&base, &format!("{path}?page={bad}"));
            assert_eq!(status, 400, "{kind:?} {path} {bad}");
            assert!(body.contains("page"), "{kind:?}: {body}");
        }
    }

    // The feed: Atom 1.0, the newest 50 as the first page lists them.
    let r = client()
        .get(format!("{base}/submissions.atom"))
        .send()
        .expect("feed");
    assert_eq!(r.status(), 200, "{kind:?}");
    let content_type = r
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_string();
    assert!(
        content_type.starts_with("application/atom+xml"),
        "{kind:?}: {content_type}"
    );
    let feed = parse_atom(&r.bytes().expect("bytes"));
    assert_eq!(feed["tag"], "{http://www.w3.org/2005/Atom}feed", "{kind:?}");
    for key in ["id", "title", "updated"] {
        assert!(
            feed[key].as_str().is_some_and(|v| !v.is_empty()),
            "{kind:?}: feed {key}: {feed}"
        );
    }
    assert!(
        rfc3339(feed["updated"].as_str().expect("updated")),
        "{kind:?}"
    );
    assert_eq!(
        feed["authors"],
        serde_json::json!(["poseboard"]),
        "{kind:?}"
    );
    assert!(
        feed["links"]
            .as_array()
            .expect("links")
            .iter()
            .any(|l| l["rel"] == "self" && l["href"] == format!("{base}/submissions.atom")),
        "{kind:?}: {feed}"
    );
    let entries = feed["entries"].as_array().expect("entries");
    let entry_ids: Vec<String> = entries
        .iter()
        .map(|e| e["id"].as_str().expect("entry id").to_string())
        .collect();
    let expected: Vec<String> = listed
        .iter()
        .map(|id| format!("{base}/submissions/{id}"))
        .collect();
    assert_eq!(entry_ids, expected, "{kind:?}");
    for e in entries {
        assert!(rfc3339(e["updated"].as_str().expect("updated")), "{e}");
        assert!(rfc3339(e["published"].as_str().expect("published")), "{e}");
        assert!(e["title"].as_str().is_some_and(|t| !t.is_empty()), "{e}");
        assert_eq!(e["links"][0]["href"], e["id"], "{e}");
        assert!(e["summary"].as_str().is_some_and(|s| !s.is_empty()), "{e}");
    }
    let top = &entries[0];
    assert_eq!(
        top["title"],
        format!("{MARKUP} – synthA – bop19, eccv18 by anonymous"),
        "{kind:?}"
    );
    assert_eq!(top["authors"], serde_json::json!(["anonymous"]), "{kind:?}");
    assert!(
        top["summary"]
            .as_str()
            .is_some_and(|s| s.starts_with("bop19 AR ")),
        "{kind:?}: {top}"
    );
}
both_databases!(the_recent_list_pages_newest_first);
