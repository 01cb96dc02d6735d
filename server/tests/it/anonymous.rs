//! Anonymous entries (double-blind review): while a method is anonymous, no public byte names
//! its owner or shows its authors, paper or code links: not a page, an API answer, an export,
//! a snapshot, the recent list or its feed, nor a 404 or 403 answer about it. Its owner and the
//! administrators still see everything; once the owner reveals it, the live boards (cached
//! as they are) name the owner again, while a snapshot taken meanwhile stays as it was taken.
//! Run on both databases.

use serde_json::{Value, json};

use crate::common::{
    Db, Server, TestDb, account, admin_token, both_databases, client, csrf_of, fixtures, get_as,
    get_json, post_as, reference_datasets, signed_in, start, upload, upload_with, wait_done,
};
use crate::publishing::wait_owner;

/// The owner's account name, and what the method's details say of who is behind it.
const OWNER: &str = "zq_owner_secret";
const AUTHORS: &str = "Zq Secret Author";
const PAPER: &str = "https://example.org/zq-paper-secret";
const CODE: &str = "https://example.org/zq-code-secret";

/// The first of the secrets `body` gives away, if any.
fn leak(body: &str) -> Option<&'static str> {
    [OWNER, AUTHORS, "zq-paper-secret", "zq-code-secret"]
        .into_iter()
        .find(|s| body.contains(s))
}

/// GETs `path` as a reader without an account: the status and the body.
fn public(base: &str, path: &str) -> (u16, String) {
    let r = client()
        .get(format!("{base}{path}"))
        .send()
        .expect("answered");
    (r.status().as_u16(), r.text().expect("body"))
}

/// Every `path` answers a reader without an account with `status` and names no one.
fn tells_no_one(kind: Db, base: &str, paths: &[String], status: u16) {
    for path in paths {
        let (got, body) = public(base, path);
        assert_eq!(got, status, "{kind:?} {path}: {body}");
        assert_eq!(leak(&body), None, "{kind:?} {path} leaks: {body}");
    }
}

/// The owner named by the row of `method` of a board's JSON.
fn board_owner(board: &Value, method: &str) -> String {
    board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == method)
        .unwrap_or_else(|| panic!("{method} is not on the board: {board}"))["owner"]
        .as_str()
        .expect("owner")
        .to_string()
}

/// Every live page, API answer and download about the method and its public submission
/// `sid` (compared with `rival`) that a reader without an account can fetch.
fn live_paths(server: &Server, method: i64, sid: i64, rival: i64) -> Vec<String> {
    let mut paths: Vec<String> = [
        "/",
        "/datasets",
        "/submissions",
        "/api/v1/submissions",
        "/submissions.atom",
        "/api/v1/methods",
        "/rescoring",
        "/api/v1/rescoring",
    ]
    .map(String::from)
    .to_vec();
    paths.extend([
        format!("/methods/{method}"),
        format!("/api/v1/methods/{method}"),
        format!("/submissions/{sid}"),
        format!("/api/v1/submissions/{sid}"),
        format!("/api/v1/submissions/{sid}/report"),
        format!("/compare?a={sid}&b={rival}"),
        format!("/api/v1/compare?a={sid}&b={rival}"),
        format!("/submissions/{sid}/targets"),
        format!("/api/v1/submissions/{sid}/targets"),
    ]);
    for protocol in ["bop19", "eccv18"] {
        for q in ["", "?dataset=synthA"] {
            paths.push(format!("/leaderboards/{protocol}{q}"));
            paths.push(format!("/api/v1/leaderboards/{protocol}{q}"));
            for extension in ["csv", "json", "tex"] {
                paths.push(format!("/leaderboards/{protocol}/export.{extension}{q}"));
            }
        }
    }
    // One target's page, as the gallery links it.
    let (_, gallery) = public(&server.base, &format!("/submissions/{sid}/targets"));
    let needle = format!("href=\"/submissions/{sid}/targets/");
    let at = gallery.find(&needle).expect("the gallery links a target") + "href=\"".len();
    let target = gallery[at..].split('"').next().expect("a link");
    paths.push(target.to_string());
    paths
}

fn an_anonymous_owner_is_named_in_no_public_byte(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "anonymous");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let owner = account(&data, &db, OWNER);
    let boss = admin_token(&data, &db, "boss");
    let fixture = |name: &str| fixtures().join("results").join(name);

    // Anonymous from its first upload, with links; the authors through the API.
    let r = upload_with(
        &server,
        &owner,
        &[
            ("method", "blind-net"),
            ("dataset", "synthA"),
            ("visibility", "public"),
            ("anonymous", "true"),
            ("paper_url", PAPER),
            ("code_url", CODE),
            ("description", "a method under review"),
        ],
        &fixture("noisesmall_synthA-test.csv"),
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    let sid = body["id"].as_i64().expect("id");
    let method = body["submission"]["method_id"].as_i64().expect("method");
    wait_done(&base, sid, std::time::Duration::from_secs(120));
    let edit = format!("{base}/api/v1/methods/{method}");
    let r = post_as(&edit, &owner, Some(json!({ "authors": AUTHORS })));
    assert_eq!(r.status(), 200, "{kind:?}");
    let mine: Value = r.json().expect("json");
    assert_eq!(mine["method"]["anonymous"], true, "{kind:?}: {mine}");
    assert_eq!(mine["method"]["owner"], OWNER, "{kind:?}: {mine}");
    // A private submission of it, and a rival's public one to compare with.
    let r = upload_with(
        &server,
        &owner,
        &[("method", "blind-net"), ("dataset", "synthA")],
        &fixture("noisemedium_synthA-test.csv"),
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let private = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_owner(&server, &owner, private);
    let r = upload(
        &server,
        "rival-net",
        "synthA",
        &fixture("noisemedium_synthA-test.csv"),
        None,
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let rival = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&base, rival, std::time::Duration::from_secs(120));

    // Every live page and answer: 200, and no one named.
    let paths = live_paths(&server, method, sid, rival);
    tells_no_one(kind, &base, &paths, 200);
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board_owner(&board, "blind-net"), "anonymous", "{kind:?}");
    assert_eq!(board_owner(&board, "rival-net"), "tester", "{kind:?}");
    let seen = get_json(&edit);
    assert_eq!(seen["method"]["owner"], "anonymous", "{kind:?}: {seen}");
    assert_eq!(
        seen["method"]["description"], "a method under review",
        "{kind:?}: the description stays"
    );
    let (_, page) = public(&base, &format!("/methods/{method}"));
    assert!(!page.contains("/reveal"), "{kind:?}: no reveal button");
    let recent = get_json(&format!("{base}/api/v1/submissions"));
    let listed = recent["submissions"]
        .as_array()
        .expect("list")
        .iter()
        .find(|s| s["id"] == sid)
        .unwrap_or_else(|| panic!("{kind:?}: not listed: {recent}"));
    assert_eq!(listed["owner"], "anonymous", "{kind:?}");

    // The 404 of its private submission and the 403s of someone else's attempts.
    tells_no_one(
        kind,
        &base,
        &[
            format!("/submissions/{private}"),
            format!("/api/v1/submissions/{private}"),
            format!("/submissions/{private}/targets"),
        ],
        404,
    );
    for (path, body) in [
        (format!("/api/v1/submissions/{sid}/pin"), None),
        (
            format!("/api/v1/methods/{method}"),
            Some(json!({ "authors": "x" })),
        ),
        (format!("/api/v1/methods/{method}/reveal"), None),
    ] {
        let r = post_as(&format!("{base}{path}"), &server.token, body);
        assert_eq!(r.status(), 403, "{kind:?} {path}");
        let text = r.text().expect("body");
        assert_eq!(leak(&text), None, "{kind:?} {path} leaks: {text}");
    }
    let r = get_as(
        &format!("{base}/api/v1/submissions/{private}/file"),
        &server.token,
    );
    assert_eq!(r.status(), 404, "{kind:?}");
    assert_eq!(leak(&r.text().expect("body")), None, "{kind:?}");

    // A snapshot taken now: every board and export it keeps is anonymous.
    let r = post_as(&format!("{base}/api/v1/admin/snapshots"), &boss, None);
    assert_eq!(r.status(), 201, "{kind:?}");
    let taken: Value = r.json().expect("json");
    let snapshot = taken["id"].as_i64().expect("id");
    let mut kept = vec!["/snapshots".to_string(), "/api/v1/snapshots".to_string()];
    for b in taken["boards"].as_array().expect("boards") {
        let url = b["url"].as_str().expect("url");
        let query = &url[url.find('?').expect("a query")..];
        kept.push(url.to_string());
        kept.push(b["json_url"].as_str().expect("json url").to_string());
        for extension in ["csv", "json"] {
            kept.push(format!("/snapshots/{snapshot}/export.{extension}{query}"));
        }
    }
    tells_no_one(kind, &base, &kept, 200);
    let kept_board = format!("{base}/api/v1/snapshots/{snapshot}?protocol=bop19");
    assert_eq!(
        board_owner(&get_json(&kept_board), "blind-net"),
        "anonymous",
        "{kind:?}"
    );

    // Its owner and the administrators see everything.
    for token in [&owner, &boss] {
        let r = get_as(&edit, token);
        assert_eq!(r.status(), 200, "{kind:?}");
        let full: Value = r.json().expect("json");
        let m = &full["method"];
        assert_eq!(
            [&m["owner"], &m["authors"], &m["paper_url"], &m["code_url"]],
            [OWNER, AUTHORS, PAPER, CODE],
            "{kind:?}: {full}"
        );
    }
    let browser = signed_in(&server, OWNER);
    let page = browser
        .get(format!("{base}/methods/{method}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains(OWNER) && page.contains(AUTHORS), "{kind:?}");
    assert!(
        page.contains(&format!("action=\"/methods/{method}/reveal\"")),
        "{kind:?}: the owner's page offers the reveal button"
    );

    // The owner reveals it with the button: the cached boards name the owner at once.
    let r = browser
        .post(format!("{base}/methods/{method}/reveal"))
        .form(&[("csrf", "not-the-token")])
        .send()
        .expect("answered");
    assert_eq!(r.status(), 403, "{kind:?}: a forged form is refused");
    let r = browser
        .post(format!("{base}/methods/{method}/reveal"))
        .form(&[("csrf", csrf_of(&page))])
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200, "{kind:?}");
    for q in ["", "?dataset=synthA"] {
        let board = get_json(&format!("{base}/api/v1/leaderboards/bop19{q}"));
        assert_eq!(board_owner(&board, "blind-net"), OWNER, "{kind:?} {q}");
    }
    let (_, csv) = public(&base, "/leaderboards/bop19/export.csv");
    assert!(csv.contains(OWNER), "{kind:?}: {csv}");
    let seen = get_json(&edit);
    assert_eq!(
        [&seen["method"]["owner"], &seen["method"]["authors"]],
        [OWNER, AUTHORS],
        "{kind:?}"
    );
    let (_, feed) = public(&base, "/submissions.atom");
    assert!(feed.contains(OWNER), "{kind:?}: {feed}");
    // The snapshot is a frozen record: as anonymous as when it was taken.
    tells_no_one(kind, &base, &kept, 200);

    // Anonymous again through the API (as any method field), revealed through the API.
    let r = post_as(&edit, &owner, Some(json!({ "anonymous": true })));
    assert_eq!(r.status(), 200, "{kind:?}");
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board_owner(&board, "blind-net"), "anonymous", "{kind:?}");
    let r = post_as(&edit, &owner, Some(json!({ "anonymous": "maybe" })));
    assert_eq!(r.status(), 400, "{kind:?}");
    assert!(
        r.text().expect("body").contains("anonymous"),
        "{kind:?}: the answer names the field"
    );
    let r = post_as(&format!("{edit}/reveal"), &owner, None);
    assert_eq!(r.status(), 200, "{kind:?}");
    assert_eq!(
        r.json::<Value>().expect("json")["method"]["anonymous"],
        false
    );
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board_owner(&board, "blind-net"), OWNER, "{kind:?}");
}
both_databases!(an_anonymous_owner_is_named_in_no_public_byte);

/// The upload form's box makes a new method anonymous; leaving it unticked on a later upload
/// keeps it so (revealing is its own action).
fn the_upload_form_makes_a_method_anonymous(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "anonform");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    account(&data, &db, OWNER);
    let browser = signed_in(&server, OWNER);
    let fixture = |name: &str| fixtures().join("results").join(name);
    let form_page = browser
        .get(format!("{base}/submit"))
        .send()
        .expect("form")
        .text()
        .expect("html");
    assert!(form_page.contains("name=\"anonymous\""), "{kind:?}");
    let csrf = csrf_of(&form_page);
    let send = |file: &str, anonymous: bool| {
        let mut form = reqwest::blocking::multipart::Form::new()
            .text("csrf", csrf.clone())
            .text("method", "form-blind")
            .text("dataset", "synthA")
            .text("publish", "yes")
            .file("file", fixture(file))
            .expect("file");
        if anonymous {
            form = form.text("anonymous", "true");
        }
        let r = browser
            .post(format!("{base}/submit"))
            .multipart(form)
            .send()
            .expect("upload");
        assert_eq!(r.status(), 200, "{kind:?}");
        let at = r.url().path().to_string();
        at.rsplit('/')
            .next()
            .and_then(|id| id.parse::<i64>().ok())
            .unwrap_or_else(|| panic!("{kind:?}: landed on {at}"))
    };
    let first = send("noisesmall_synthA-test.csv", true);
    wait_done(&base, first, std::time::Duration::from_secs(120));
    let second = send("noisemedium_synthA-test.csv", false);
    wait_done(&base, second, std::time::Duration::from_secs(120));
    let board = get_json(&format!("{base}/api/v1/leaderboards/bop19"));
    assert_eq!(board_owner(&board, "form-blind"), "anonymous", "{kind:?}");
    let (_, page) = public(&base, &format!("/submissions/{second}"));
    assert_eq!(leak(&page), None, "{kind:?}");

    // No account may pass for an anonymous method's owner.
    for name in ["anonymous", "Anonymous"] {
        let r = client()
            .post(format!("{base}/register"))
            .form(&[("name", name), ("password", "correct horse battery")])
            .send()
            .expect("answered");
        assert_eq!(r.status(), 409, "{kind:?} {name}");
        assert!(r.text().expect("page").contains("reserved"), "{kind:?}");
    }
}
both_databases!(the_upload_form_makes_a_method_anonymous);
