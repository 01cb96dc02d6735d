//! Challenges: created by an administrator (each bad field named), shown as a page and its JSON
//! with their boards, snapshotted by the service itself at the deadline (at the next start
//! when no server ran then, dated at the deadline, and once with two servers on one
//! PostgreSQL database), entries submitted later marked "after the deadline", awards decided
//! on the method fields as they stood at the deadline, an override audited, and an anonymous
//! owner named nowhere. Run on both databases.

use std::time::{Duration, Instant};

use serde_json::{Value, json};
use server::wording::rfc3339;

use crate::common::{
    self, Db, TestDb, account, admin_token, both_databases, client, column, fixtures, get_json,
    post_as, reference_datasets, start, upload_scored, upload_with, wait_done,
};

/// Servers look for passed deadlines every second here (30 by default).
const CHECK: [&str; 2] = ["--challenge-check-secs", "1"];

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock")
        .as_millis() as i64
}

/// A deadline `secs` seconds ahead, on a whole second: (epoch ms, RFC 3339).
fn deadline_in(secs: i64) -> (i64, String) {
    let ms = (now_ms() / 1000 + secs) * 1000;
    (ms, rfc3339(ms))
}

/// Sleeps until `ms` (epoch) has passed.
fn sleep_past(ms: i64) {
    let left = ms + 200 - now_ms();
    if left > 0 {
        std::thread::sleep(Duration::from_millis(left as u64));
    }
}

/// Polls the challenge's JSON until its snapshot is taken (panicking after `limit`).
fn wait_snapshot(base: &str, slug: &str, limit: Duration) -> Value {
    let start = Instant::now();
    loop {
        let c = get_json(&format!("{base}/api/v1/challenges/{slug}"));
        if c["snapshot_id"].is_i64() {
            return c;
        }
        assert!(start.elapsed() < limit, "no snapshot in {limit:?}: {c}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The listed snapshot `id`.
fn listed_snapshot(base: &str, id: i64) -> Value {
    get_json(&format!("{base}/api/v1/snapshots"))["snapshots"]
        .as_array()
        .expect("snapshots")
        .iter()
        .find(|s| s["id"] == id)
        .cloned()
        .unwrap_or_else(|| panic!("snapshot {id} not listed"))
}

/// The winner's method of `award` on `task`, if any.
fn winner(challenge: &Value, task: &str, award: &str) -> Option<String> {
    let a = challenge["awards"]
        .as_array()
        .expect("awards")
        .iter()
        .find(|a| a["task"] == task && a["award"] == award)
        .unwrap_or_else(|| panic!("no award {task} {award}: {challenge}"));
    assert!(
        a["rule"].as_str().is_some_and(|r| !r.is_empty()),
        "a rule is written next to {award}: {a}"
    );
    a["winner"]["method"].as_str().map(str::to_string)
}

/// The row of `method` on the challenge's first board.
fn row(challenge: &Value, method: &str) -> Value {
    challenge["boards"][0]["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == method)
        .cloned()
        .unwrap_or_else(|| panic!("no row {method}: {challenge}"))
}

fn create(base: &str, token: &str, body: Value) -> reqwest::blocking::Response {
    post_as(
        &format!("{base}/api/v1/admin/challenges"),
        token,
        Some(body),
    )
}

/// Uploads `file` publicly as `token`'s method with `fields`, and waits until it is scored:
/// the method's id.
fn scored(server: &common::Server, token: &str, fields: &[(&str, &str)], file: &str) -> i64 {
    let mut all = vec![("dataset", "synthA"), ("visibility", "public")];
    all.extend_from_slice(fields);
    let r = upload_with(server, token, &all, &fixtures().join("results").join(file));
    assert_eq!(r.status(), 202, "{}", r.text().unwrap_or_default());
    let body: Value = r.json().expect("json");
    wait_done(
        &server.base,
        body["id"].as_i64().expect("id"),
        Duration::from_secs(120),
    );
    body["submission"]["method_id"].as_i64().expect("method")
}

fn a_challenge_closes_at_its_deadline(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "challenges");
    let server = start(&data, &datasets, &db, &CHECK);
    let base = server.base.clone();
    let boss = admin_token(&data, &db, "boss");

    // The best scores, from depth: best overall.
    scored(
        &server,
        &server.token,
        &[("method", "deep-net"), ("modality", "rgb-d")],
        "gtexact_synthA-test.csv",
    );
    // Lower scores from RGB only, open source, one model, synthetic images and the default
    // detections: those awards.
    let rgb = scored(
        &server,
        &server.token,
        &[
            ("method", "rgb-net"),
            ("modality", "rgb"),
            ("training_data", "synthetic"),
            ("code_url", "https://github.com/example/rgb-net"),
        ],
        "noisesmall_synthA-test.csv",
    );
    let r = post_as(
        &format!("{base}/api/v1/methods/{rgb}"),
        &server.token,
        Some(
            json!({ "detection_modality": "rgb", "model_scope": "all", "detections": "CNOS (default detections of BOP'23)" }),
        ),
    );
    assert_eq!(r.status(), 200);

    // Only administrators create one; each bad field is named.
    let (deadline, at) = deadline_in(8);
    let good = json!({ "slug": "bop-test", "name": "BOP test challenge", "tasks": ["bop19"], "groups": ["core"], "deadline": at, "fast_seconds": 1000 });
    assert_eq!(create(&base, &server.token, good.clone()).status(), 404);
    for (field, value) in [
        ("slug", json!("Not A Slug")),
        ("name", json!("")),
        ("tasks", json!(["bop99"])),
        ("groups", json!(["no-such-group"])),
        ("deadline", json!("next friday")),
        ("deadline", json!(rfc3339(now_ms() - 60_000))),
        ("awards", json!(["prettiest"])),
        ("fast_seconds", json!(-1)),
    ] {
        let mut body = good.clone();
        body[field] = value.clone();
        let r = create(&base, &boss, body);
        assert_eq!(r.status(), 400, "{field} = {value}");
        let error = r.json::<Value>().expect("json")["error"].to_string();
        assert!(error.contains(field), "{field} = {value}: {error}");
    }
    let r = create(&base, &boss, good.clone());
    assert_eq!(r.status(), 201);
    let created: Value = r.json().expect("json");
    assert_eq!(created["challenge"]["deadline"], deadline, "{created}");
    assert_eq!(create(&base, &boss, good).status(), 409);

    // Its page, its JSON and the list, before the deadline: the boards, no snapshot, no award.
    let c = get_json(&format!("{base}/api/v1/challenges/bop-test"));
    assert_eq!(c["snapshot_id"], Value::Null, "{c}");
    assert_eq!(c["awards"], json!([]), "{c}");
    assert_eq!(c["boards"][0]["protocol"], "bop19", "{c}");
    assert_eq!(c["boards"][0]["group"], "core", "{c}");
    assert_eq!(row(&c, "deep-net")["after_deadline"], false, "{c}");
    let page = client()
        .get(format!("{base}/challenges/bop-test"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        page.contains("BOP test challenge") && page.contains("rgb-net"),
        "{page}"
    );
    let list = get_json(&format!("{base}/api/v1/challenges"));
    assert_eq!(list["challenges"][0]["slug"], "bop-test", "{list}");
    let list_page = client()
        .get(format!("{base}/challenges"))
        .send()
        .expect("list page")
        .text()
        .expect("html");
    assert!(list_page.contains("/challenges/bop-test"), "{list_page}");
    assert_eq!(
        client()
            .get(format!("{base}/api/v1/challenges/no-such"))
            .send()
            .expect("answered")
            .status(),
        404
    );

    // The running server takes the snapshot at the deadline, dated at the deadline.
    sleep_past(deadline);
    let c = wait_snapshot(&base, "bop-test", Duration::from_secs(60));
    let id = c["snapshot_id"].as_i64().expect("id");
    assert_eq!(listed_snapshot(&base, id)["taken_at"], deadline);
    assert_eq!(c["snapshot_url"], format!("/snapshots/{id}"), "{c}");
    // Both are under the threshold of 1000 s: the better is the fast one.
    assert_eq!(winner(&c, "bop19", "overall").as_deref(), Some("deep-net"));
    assert_eq!(winner(&c, "bop19", "fast").as_deref(), Some("deep-net"));
    for award in [
        "rgb-only",
        "open-source",
        "single-model",
        "synthetic",
        "default-detections",
    ] {
        assert_eq!(
            winner(&c, "bop19", award).as_deref(),
            Some("rgb-net"),
            "{award}: {c}"
        );
    }

    // Later: an edit of a method changes no award, and a new entry is welcome and marked.
    let r = post_as(
        &format!("{base}/api/v1/methods/{rgb}"),
        &server.token,
        Some(json!({ "modality": "depth", "code_url": "" })),
    );
    assert_eq!(r.status(), 200);
    upload_scored(
        &server,
        "late-net",
        "synthA",
        &fixtures()
            .join("results")
            .join("noisemedium_synthA-test.csv"),
        None,
    );
    let c = get_json(&format!("{base}/api/v1/challenges/bop-test"));
    assert_eq!(row(&c, "late-net")["after_deadline"], true, "{c}");
    assert_eq!(row(&c, "deep-net")["after_deadline"], false, "{c}");
    assert_eq!(winner(&c, "bop19", "rgb-only").as_deref(), Some("rgb-net"));
    assert_eq!(
        winner(&c, "bop19", "open-source").as_deref(),
        Some("rgb-net")
    );
    let page = client()
        .get(format!("{base}/challenges/bop-test"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains("after the deadline"), "{page}");

    // An override: administrators only, with a note, shown and audited.
    let awards = format!("{base}/api/v1/admin/challenges/bop-test/awards");
    let body = json!({ "task": "bop19", "award": "overall", "method_id": rgb, "note": "deep-net broke rule 4" });
    assert_eq!(
        post_as(&awards, &server.token, Some(body.clone())).status(),
        404
    );
    let r = post_as(
        &awards,
        &boss,
        Some(json!({ "task": "bop19", "award": "overall", "method_id": rgb, "note": "" })),
    );
    assert_eq!(r.status(), 400);
    assert!(r.text().expect("body").contains("note"));
    let r = post_as(
        &awards,
        &boss,
        Some(json!({ "task": "bop19", "award": "overall", "method_id": 999_999, "note": "x" })),
    );
    assert_eq!(r.status(), 400);
    let r = post_as(&awards, &boss, Some(body));
    assert_eq!(r.status(), 200);
    let c = get_json(&format!("{base}/api/v1/challenges/bop-test"));
    assert_eq!(winner(&c, "bop19", "overall").as_deref(), Some("rgb-net"));
    let overall = c["awards"]
        .as_array()
        .expect("awards")
        .iter()
        .find(|a| a["award"] == "overall")
        .expect("overall")
        .clone();
    assert_eq!(
        overall["override"]["note"], "deep-net broke rule 4",
        "{overall}"
    );
    assert_eq!(overall["override"]["by"], "boss", "{overall}");
    let page = client()
        .get(format!("{base}/challenges/bop-test"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains("Overridden by the organisers"), "{page}");
    let audit = common::get_as(&format!("{base}/api/v1/admin/audit"), &boss)
        .json::<Value>()
        .expect("audit");
    let actions: Vec<&str> = audit["audit"]
        .as_array()
        .expect("audit")
        .iter()
        .filter_map(|a| a["action"].as_str())
        .collect();
    assert!(actions.contains(&"create challenge"), "{audit}");
    assert!(actions.contains(&"override award"), "{audit}");
}
both_databases!(a_challenge_closes_at_its_deadline);

fn the_next_start_takes_a_missed_snapshot(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "challenges_missed");
    let server = start(&data, &datasets, &db, &CHECK);
    let base = server.base.clone();
    let boss = admin_token(&data, &db, "boss");
    // An entry under double-blind review: its owner is named nowhere on the challenge.
    let secret = account(&data, &db, "secretowner");
    scored(
        &server,
        &secret,
        &[("method", "blind-net"), ("anonymous", "true")],
        "noisesmall_synthA-test.csv",
    );
    let (deadline, at) = deadline_in(3);
    let r = create(
        &base,
        &boss,
        json!({ "slug": "missed", "name": "Missed deadline", "tasks": ["bop19", "eccv18"], "deadline": at, "fast_seconds": 0.5 }),
    );
    assert_eq!(r.status(), 201);
    // No server runs at the deadline.
    drop(server);
    sleep_past(deadline);
    let count = || column(&db, &data, "SELECT CAST(COUNT(*) AS TEXT) FROM snapshots");
    assert_eq!(count(), ["0"]);

    let server = start(&data, &datasets, &db, &CHECK);
    let base = server.base.clone();
    let c = wait_snapshot(&base, "missed", Duration::from_secs(60));
    let id = c["snapshot_id"].as_i64().expect("id");
    assert_eq!(listed_snapshot(&base, id)["taken_at"], deadline);
    assert_eq!(winner(&c, "bop19", "overall").as_deref(), Some("blind-net"));
    assert_eq!(
        winner(&c, "eccv18", "overall").as_deref(),
        Some("blind-net")
    );
    // Its time (0.88 s per image) is over the challenge's threshold: nobody is fast.
    assert_eq!(winner(&c, "bop19", "fast"), None);
    assert_eq!(row(&c, "blind-net")["owner"], "anonymous", "{c}");
    for url in [
        format!("{base}/challenges/missed"),
        format!("{base}/api/v1/challenges/missed"),
        format!("{base}/snapshots/{id}?protocol=bop19"),
        format!("{base}/api/v1/snapshots/{id}?protocol=bop19"),
    ] {
        let body = client()
            .get(&url)
            .send()
            .expect("answered")
            .text()
            .expect("body");
        assert!(body.contains("blind-net"), "{url}: {body}");
        assert!(!body.contains("secretowner"), "{url}: {body}");
    }
    // Once: a further start takes no other.
    drop(server);
    let server = start(&data, &datasets, &db, &CHECK);
    let again = get_json(&format!("{}/api/v1/challenges/missed", server.base));
    assert_eq!(again["snapshot_id"], id);
    assert_eq!(count(), ["1"]);
}
both_databases!(the_next_start_takes_a_missed_snapshot);

/// Two servers on one PostgreSQL database both watch the deadline; one snapshot is taken.
#[test]
fn two_servers_take_one_snapshot() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(Db::Postgres, "challenges_two");
    let first = start(&data, &datasets, &db, &CHECK);
    let second = start(&data, &datasets, &db, &CHECK);
    let boss = admin_token(&data, &db, "boss");
    upload_scored(
        &first,
        "some-net",
        "synthA",
        &fixtures()
            .join("results")
            .join("noisesmall_synthA-test.csv"),
        None,
    );
    let (deadline, at) = deadline_in(3);
    let r = create(
        &first.base,
        &boss,
        json!({ "slug": "twice", "name": "Two servers", "tasks": ["bop19"], "deadline": at }),
    );
    assert_eq!(r.status(), 201);
    sleep_past(deadline);
    let c = wait_snapshot(&second.base, "twice", Duration::from_secs(60));
    let id = c["snapshot_id"].as_i64().expect("id");
    // Both servers have looked again since.
    std::thread::sleep(Duration::from_secs(3));
    for server in [&first, &second] {
        let c = get_json(&format!("{}/api/v1/challenges/twice", server.base));
        assert_eq!(c["snapshot_id"], id, "{c}");
    }
    assert_eq!(
        column(&db, &data, "SELECT CAST(COUNT(*) AS TEXT) FROM snapshots"),
        ["1"]
    );
    assert_eq!(
        column(&db, &data, "SELECT CAST(taken_at AS TEXT) FROM snapshots"),
        [deadline.to_string()]
    );
}
