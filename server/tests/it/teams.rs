//! Teams, over real HTTP against the real binary on both databases: an account creates a team
//! and invites others by name, who accept (on their account page or through the API); any
//! member submits to the team's method (the API, the upload form's field and `poseboard submit
//! --team`) and edits it, and sees its private submissions; the boards, the method's page and
//! its JSON name the team as the owner; anyone else submitting with the team's name, or reading
//! its private things, gets 404; leaving and removing are in the audit log; the fair-use limit
//! counts each uploader's own submissions.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use reqwest::blocking::multipart;
use serde_json::{Value, json};

use crate::common::{
    BIN, Db, Server, TestDb, account, admin_token, both_databases, client, column, csrf_of,
    fixtures, get_as, post_as, reference_datasets, signed_in, start, upload_with,
};

const TEAM: &str = "vision-lab";

fn file(name: &str) -> std::path::PathBuf {
    fixtures().join(format!("results/{name}_synthA-test.csv"))
}

/// The JSON of a successful answer, its status checked.
fn ok(r: reqwest::blocking::Response, status: u16, what: &str) -> Value {
    let got = r.status().as_u16();
    let text = r.text().expect("body");
    assert_eq!(got, status, "{what}: {text}");
    serde_json::from_str(&text).unwrap_or(Value::Null)
}

/// Polls submission `id` as `token` until its scores are in.
fn wait_done_as(base: &str, token: &str, id: i64) -> Value {
    let start = Instant::now();
    loop {
        let s: Value = get_as(&format!("{base}/api/v1/submissions/{id}"), token)
            .json()
            .expect("JSON");
        match s["status"].as_str() {
            Some("done") => return s,
            Some("failed") => panic!("submission {id} failed: {}", s["error"]),
            _ => {}
        }
        assert!(start.elapsed() < Duration::from_secs(120), "{s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// `alice` creates the team and `others` join it: invited through the API, accepting through it.
fn team_of(server: &Server, alice: &str, others: &[(&str, &str)]) {
    let base = &server.base;
    let created = post_as(
        &format!("{base}/api/v1/teams"),
        alice,
        Some(json!({ "name": TEAM })),
    );
    let body = ok(created, 201, "create");
    assert_eq!(body["team"]["name"], TEAM);
    assert_eq!(body["team"]["creator"], "alice");
    for (name, token) in others {
        let invited = post_as(
            &format!("{base}/api/v1/teams/{TEAM}/invitations"),
            alice,
            Some(json!({ "user": name })),
        );
        ok(invited, 200, "invite");
        ok(
            post_as(&format!("{base}/api/v1/teams/{TEAM}/accept"), token, None),
            200,
            "accept",
        );
    }
}

fn team_upload(
    server: &Server,
    token: &str,
    method: &str,
    f: &Path,
    extra: &[(&str, &str)],
) -> reqwest::blocking::Response {
    let mut fields = vec![("method", method), ("dataset", "synthA"), ("team", TEAM)];
    fields.extend_from_slice(extra);
    upload_with(server, token, &fields, f)
}

fn submit_cli(server: &Server, token: &str, f: &Path, args: &[&str]) -> Output {
    Command::new(BIN)
        .arg("submit")
        .arg(f)
        .args(args)
        .env("POSEBOARD_SERVER", &server.base)
        .env("POSEBOARD_TOKEN", token)
        .stdin(Stdio::null())
        .output()
        .expect("poseboard submit runs")
}

fn members_submit_edit_and_see(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "teams");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let alice = account(&data, &db, "alice");
    let bob = account(&data, &db, "bob");
    let carol = account(&data, &db, "carol");

    // Alice creates the team; a taken name is refused; she invites Bob by name.
    team_of(&server, &alice, &[]);
    let again = post_as(
        &format!("{base}/api/v1/teams"),
        &carol,
        Some(json!({ "name": TEAM })),
    );
    let refused = ok(again, 409, "a taken name");
    assert!(
        refused["error"].as_str().unwrap().contains(TEAM),
        "{refused}"
    );
    ok(
        post_as(
            &format!("{base}/api/v1/teams/{TEAM}/invitations"),
            &alice,
            Some(json!({ "user": "bob" })),
        ),
        200,
        "invite bob",
    );
    // Carol, not a member, can neither invite nor accept an invitation she does not have.
    let not_hers = post_as(
        &format!("{base}/api/v1/teams/{TEAM}/invitations"),
        &carol,
        Some(json!({ "user": "carol" })),
    );
    assert_eq!(not_hers.status(), 404);
    assert_eq!(
        post_as(&format!("{base}/api/v1/teams/{TEAM}/accept"), &carol, None).status(),
        404
    );

    // Bob sees the invitation on his account page and accepts it with its button.
    let browser = signed_in(&server, "bob");
    let page = browser
        .get(format!("{base}/account"))
        .send()
        .expect("account page")
        .text()
        .expect("html");
    let accept_action = format!("action=\"/teams/{TEAM}/accept\"");
    assert!(
        page.contains(&accept_action),
        "the invitation's button: {page}"
    );
    let accepted = browser
        .post(format!("{base}/teams/{TEAM}/accept"))
        .form(&[("csrf", csrf_of(&page).as_str())])
        .send()
        .expect("accept");
    assert!(accepted.status().is_success(), "{}", accepted.status());
    let team = ok(
        get_as(&format!("{base}/api/v1/teams/{TEAM}"), ""),
        200,
        "team",
    );
    let members: Vec<&str> = team["members"]
        .as_array()
        .expect("members")
        .iter()
        .map(|m| m["name"].as_str().expect("name"))
        .collect();
    assert_eq!(members, ["alice", "bob"]);
    let page = browser
        .get(format!("{base}/account"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(!page.contains(&accept_action), "the invitation is used up");
    assert!(
        page.contains(&format!("href=\"/teams/{TEAM}\"")),
        "his teams"
    );

    // Alice submits privately to the team's method through the API.
    let r = team_upload(
        &server,
        &alice,
        "joint-net",
        &file("noisesmall"),
        &[("visibility", "private")],
    );
    let first = ok(r, 202, "alice's team upload");
    let private_id = first["id"].as_i64().expect("id");
    let method_id = first["submission"]["method_id"]
        .as_i64()
        .expect("method id");
    wait_done_as(&base, &alice, private_id);
    // Bob, a member, sees it; Carol and a reader without an account get 404, as for nothing.
    let url = format!("{base}/api/v1/submissions/{private_id}");
    assert_eq!(get_as(&url, &bob).status(), 200, "a member sees it");
    assert_eq!(get_as(&url, &carol).status(), 404);
    assert_eq!(get_as(&url, "").status(), 404);
    let method_url = format!("{base}/api/v1/methods/{method_id}");
    assert_eq!(get_as(&method_url, &bob).status(), 200);
    assert_eq!(get_as(&method_url, &carol).status(), 404);
    assert_eq!(
        get_as(&format!("{base}/methods/{method_id}"), &carol).status(),
        404
    );
    // Carol's edit of the private method is told nothing either.
    let edit = post_as(&method_url, &carol, Some(json!({ "description": "mine" })));
    assert_eq!(edit.status(), 404);

    // Anyone else submitting with the team's name is told it is not one of theirs (404), as is
    // a name no team has; nothing is stored.
    for name in [TEAM, "no-such-team"] {
        let r = upload_with(
            &server,
            &carol,
            &[
                ("method", "joint-net"),
                ("dataset", "synthA"),
                ("team", name),
            ],
            &file("noisemedium"),
        );
        let body = ok(r, 404, "a non-member's upload");
        let message = body["error"].as_str().expect("error");
        assert!(
            message.contains(&format!("team `{name}` is not one of your teams")),
            "{message}"
        );
    }
    let carols = column(
        &db,
        &data,
        "SELECT CAST(COUNT(*) AS TEXT) FROM submissions s JOIN users u ON u.id = s.owner_id \
         WHERE u.name = 'carol'",
    );
    assert_eq!(carols, ["0"]);

    // Bob submits to the same method with `poseboard submit --team`, publicly.
    let out = submit_cli(
        &server,
        &bob,
        &file("noisemedium"),
        &[
            "--method",
            "joint-net",
            "--team",
            TEAM,
            "--visibility",
            "public",
            "--json",
        ],
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "submit --team: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed: Value =
        serde_json::from_str(stdout.lines().last().expect("a line")).expect("JSON last line");
    assert_eq!(
        printed["method_id"], method_id,
        "the team's method, not a new one of Bob's"
    );
    let owners = column(
        &db,
        &data,
        "SELECT u.name FROM submissions s JOIN users u ON u.id = s.owner_id ORDER BY s.id",
    );
    assert_eq!(
        owners,
        ["alice", "bob"],
        "each submission is its uploader's"
    );

    // Bob, another member, edits the method; Carol cannot (the method is public now: 403).
    let edited = post_as(
        &method_url,
        &bob,
        Some(json!({ "description": "edited by bob", "authors": "Alice, Bob" })),
    );
    let edited = ok(edited, 200, "a member's edit");
    assert_eq!(edited["method"]["description"], "edited by bob");
    let edit = post_as(&method_url, &carol, Some(json!({ "description": "mine" })));
    assert_eq!(edit.status(), 403);

    // The board, the method's JSON and its page name the team as the owner.
    let board = ok(
        get_as(
            &format!("{base}/api/v1/leaderboards/bop19?dataset=synthA"),
            "",
        ),
        200,
        "board",
    );
    let row = board["rows"]
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| r["method"] == "joint-net")
        .expect("the team's method on the board")
        .clone();
    assert_eq!(row["owner"], TEAM, "{row}");
    let method = ok(get_as(&method_url, ""), 200, "method");
    assert_eq!(method["method"]["owner"], TEAM);
    assert_eq!(method["method"]["team"], TEAM);
    let page = client()
        .get(format!("{base}/methods/{method_id}"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(page.contains(&format!("href=\"/teams/{TEAM}\"")), "{page}");
    let csv = client()
        .get(format!(
            "{base}/leaderboards/bop19/export.csv?dataset=synthA"
        ))
        .send()
        .expect("export");
    assert_eq!(csv.status(), 200);
    let csv = csv.text().expect("csv");
    let line = csv
        .lines()
        .find(|l| l.contains("joint-net"))
        .expect("its row");
    assert!(line.contains(TEAM), "{line}");
    // The team's page lists its members and its public method to anyone.
    let page = client()
        .get(format!("{base}/teams/{TEAM}"))
        .send()
        .expect("team page")
        .text()
        .expect("html");
    assert!(page.contains("alice") && page.contains("bob"), "{page}");
    assert!(
        page.contains(&format!("href=\"/methods/{method_id}\"")),
        "{page}"
    );

    // A member submits through the upload form too, with its Team field.
    let page = browser
        .get(format!("{base}/submit"))
        .send()
        .expect("form")
        .text()
        .expect("html");
    assert!(page.contains("name=\"team\""), "the form's Team field");
    let form = multipart::Form::new()
        .text("csrf", csrf_of(&page))
        .text("method", "joint-net")
        .text("dataset", "synthA")
        .text("team", TEAM)
        .file("file", file("noiselarge"))
        .expect("file");
    let r = browser
        .post(format!("{base}/submit"))
        .multipart(form)
        .send()
        .expect("form upload");
    assert!(r.status().is_success(), "{}", r.status());
    let methods = column(
        &db,
        &data,
        "SELECT CAST(COUNT(DISTINCT method_id) AS TEXT) FROM submissions",
    );
    assert_eq!(methods, ["1"], "every upload went to the team's one method");
}
both_databases!(members_submit_edit_and_see);

fn leaving_and_removing_are_audited(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "team_audit");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let root = admin_token(&data, &db, "root");
    let alice = account(&data, &db, "alice");
    let bob = account(&data, &db, "bob");
    let carol = account(&data, &db, "carol");
    team_of(&server, &alice, &[("bob", &bob), ("carol", &carol)]);

    // Bob, a member who did not create the team, may not remove Carol.
    let remove_carol = format!("{base}/api/v1/teams/{TEAM}/members/carol/remove");
    let refused = post_as(&remove_carol, &bob, None);
    assert_eq!(refused.status(), 403);
    // Alice, its creator, may; Carol can then no longer submit with the team's name.
    ok(post_as(&remove_carol, &alice, None), 200, "remove carol");
    let r = team_upload(&server, &carol, "joint-net", &file("noisesmall"), &[]);
    assert_eq!(r.status(), 404);
    assert_eq!(
        post_as(&remove_carol, &alice, None).status(),
        404,
        "not a member any more"
    );
    // Bob leaves.
    ok(
        post_as(&format!("{base}/api/v1/teams/{TEAM}/leave"), &bob, None),
        200,
        "leave",
    );
    assert_eq!(
        post_as(&format!("{base}/api/v1/teams/{TEAM}/leave"), &bob, None).status(),
        404,
        "left already"
    );
    let team = ok(
        get_as(&format!("{base}/api/v1/teams/{TEAM}"), ""),
        200,
        "team",
    );
    assert_eq!(team["members"].as_array().expect("members").len(), 1);

    // Both are in the audit log, with who did it to whom.
    let audit = ok(
        get_as(&format!("{base}/api/v1/admin/audit"), &root),
        200,
        "audit",
    );
    let entries: Vec<(String, String, String)> = audit["audit"]
        .as_array()
        .expect("audit")
        .iter()
        .map(|e| {
            let s = |k: &str| e[k].as_str().expect("text").to_string();
            (s("actor"), s("action"), s("target"))
        })
        .collect();
    assert_eq!(
        entries,
        [
            ("bob".into(), "leave team".into(), format!("team {TEAM}")),
            (
                "alice".into(),
                "remove team member".into(),
                format!("team {TEAM}: carol")
            ),
        ],
        "newest first"
    );
    let rows = column(
        &db,
        &data,
        "SELECT a.action || '|' || a.target FROM audit_log a ORDER BY a.id",
    );
    assert_eq!(
        rows,
        [
            format!("remove team member|team {TEAM}: carol"),
            format!("leave team|team {TEAM}"),
        ]
    );
    // An administrator may remove a member of any team.
    ok(
        post_as(
            &format!("{base}/api/v1/teams/{TEAM}/members/alice/remove"),
            &root,
            None,
        ),
        200,
        "an administrator removes",
    );
}
both_databases!(leaving_and_removing_are_audited);

fn fair_use_counts_the_uploader(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "team_limit");
    let data = dir.path().join("data");
    let args = [
        "--submissions-per-window",
        "1",
        "--limit-window-secs",
        "3600",
    ];
    let server = start(&data, &datasets, &db, &args);
    let alice = account(&data, &db, "alice");
    let bob = account(&data, &db, "bob");
    team_of(&server, &alice, &[("bob", &bob)]);

    // One submission each per dataset: Alice's to the team's method uses hers, not Bob's.
    let r = team_upload(&server, &alice, "joint-net", &file("noisesmall"), &[]);
    assert_eq!(r.status(), 202, "{}", r.text().unwrap_or_default());
    let r = team_upload(&server, &bob, "joint-net", &file("noisemedium"), &[]);
    assert_eq!(r.status(), 202, "{}", r.text().unwrap_or_default());
    // Alice's limit is used, on the team's method and on her own alike.
    let r = team_upload(&server, &alice, "joint-net", &file("noiselarge"), &[]);
    assert_eq!(r.status(), 429);
    let r = upload_with(
        &server,
        &alice,
        &[("method", "solo"), ("dataset", "synthA")],
        &file("noiselarge"),
    );
    assert_eq!(r.status(), 429);
    // Another account's limit is its own.
    let r = upload_with(
        &server,
        &server.token,
        &[("method", "solo"), ("dataset", "synthA")],
        &file("noiselarge"),
    );
    assert_eq!(r.status(), 202);
}
both_databases!(fair_use_counts_the_uploader);

/// The pages' forms: the account page creates a team, the team page invites, the invited
/// account accepts on its account page, the creator removes with the member's button; a form
/// without the session's CSRF token is refused.
fn the_pages_forms(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "team_forms");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    account(&data, &db, "alice");
    account(&data, &db, "bob");
    let alice = signed_in(&server, "alice");
    let bob = signed_in(&server, "bob");
    let page = |b: &reqwest::blocking::Client, path: &str| {
        let r = b.get(format!("{base}{path}")).send().expect("page");
        assert_eq!(r.status(), 200, "{path}");
        r.text().expect("html")
    };

    let account_page = page(&alice, "/account");
    assert!(
        account_page.contains("action=\"/teams\""),
        "the create form"
    );
    let forged = alice
        .post(format!("{base}/teams"))
        .form(&[("csrf", "forged"), ("name", "form-lab")])
        .send()
        .expect("forged");
    assert_eq!(forged.status(), 403);
    let created = alice
        .post(format!("{base}/teams"))
        .form(&[
            ("csrf", csrf_of(&account_page).as_str()),
            ("name", "form-lab"),
        ])
        .send()
        .expect("create");
    assert_eq!(created.status(), 200);
    assert!(created.url().path().ends_with("/teams/form-lab"));
    let team_page = created.text().expect("html");
    assert!(team_page.contains("Team form-lab"), "{team_page}");
    let invited = alice
        .post(format!("{base}/teams/form-lab/invitations"))
        .form(&[("csrf", csrf_of(&team_page).as_str()), ("user", "bob")])
        .send()
        .expect("invite");
    assert_eq!(invited.status(), 200);
    // Bob, not yet a member, is offered neither the invitation form nor removal.
    let seen_by_bob = page(&bob, "/teams/form-lab");
    assert!(!seen_by_bob.contains("/invitations\""), "{seen_by_bob}");
    assert!(!seen_by_bob.contains("/remove\""), "{seen_by_bob}");
    let bobs_account = page(&bob, "/account");
    assert!(
        bobs_account.contains("alice invites you to team"),
        "{bobs_account}"
    );
    let accepted = bob
        .post(format!("{base}/teams/form-lab/accept"))
        .form(&[("csrf", csrf_of(&bobs_account).as_str())])
        .send()
        .expect("accept");
    assert_eq!(accepted.status(), 200);
    let seen_by_bob = page(&bob, "/teams/form-lab");
    assert!(
        seen_by_bob.contains("/teams/form-lab/invitations\""),
        "a member invites"
    );
    assert!(
        !seen_by_bob.contains("/remove\""),
        "only the creator removes"
    );

    let seen_by_alice = page(&alice, "/teams/form-lab");
    let remove = "/teams/form-lab/members/bob/remove";
    assert!(seen_by_alice.contains(remove), "{seen_by_alice}");
    let removed = alice
        .post(format!("{base}{remove}"))
        .form(&[("csrf", csrf_of(&seen_by_alice).as_str())])
        .send()
        .expect("remove");
    assert_eq!(removed.status(), 200);
    let rows = column(
        &db,
        &data,
        "SELECT u.name || '|' || a.action || '|' || a.target FROM audit_log a \
         JOIN users u ON u.id = a.actor_id ORDER BY a.id",
    );
    assert_eq!(rows, ["alice|remove team member|team form-lab: bob"]);
    let refused = bob
        .post(format!("{base}/teams/form-lab/leave"))
        .form(&[("csrf", csrf_of(&bobs_account).as_str())])
        .send()
        .expect("leave");
    assert_eq!(refused.status(), 404, "not a member any more");
}
both_databases!(the_pages_forms);

/// A team's method under double-blind review names no team on any public page: the boards, the
/// method's page and JSON, the recent list and its feed show "anonymous", the team's page does
/// not list it, and a non-member's refused edit does not name the team.
fn an_anonymous_team_method_names_no_team(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "teamsanon");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let alice = account(&data, &db, "alice");
    let carol = account(&data, &db, "carol");
    team_of(&server, &alice, &[]);
    let r = team_upload(
        &server,
        &alice,
        "blind-net",
        &file("noisesmall"),
        &[("visibility", "public"), ("anonymous", "true")],
    );
    let body = ok(r, 202, "anonymous team upload");
    let id = body["id"].as_i64().expect("id");
    let method_id = body["submission"]["method_id"].as_i64().expect("method");
    wait_done_as(&base, &alice, id);

    let public = |path: &str| {
        let r = client()
            .get(format!("{base}{path}"))
            .send()
            .expect("answered");
        assert_eq!(r.status(), 200, "{path}");
        r.text().expect("body")
    };
    for path in [
        "/leaderboards/bop19".to_string(),
        "/api/v1/leaderboards/bop19".to_string(),
        "/leaderboards/bop19/export.csv".to_string(),
        format!("/methods/{method_id}"),
        format!("/api/v1/methods/{method_id}"),
        format!("/submissions/{id}"),
        "/submissions".to_string(),
        "/api/v1/submissions".to_string(),
        "/submissions.atom".to_string(),
    ] {
        let text = public(&path);
        assert!(text.contains("blind-net"), "{path} shows the method");
        assert!(!text.contains(TEAM), "{path} names the team: {text}");
        assert!(!text.contains("alice"), "{path} names the uploader");
    }
    let team_page = public(&format!("/teams/{TEAM}"));
    assert!(!team_page.contains("blind-net"), "{team_page}");
    let team_json = public(&format!("/api/v1/teams/{TEAM}"));
    assert!(!team_json.contains("blind-net"), "{team_json}");
    // Its members still see it listed as the team's.
    let as_member: Value = get_as(&format!("{base}/api/v1/teams/{TEAM}"), &alice)
        .json()
        .expect("JSON");
    assert!(as_member.to_string().contains("blind-net"), "{as_member}");

    let refused = post_as(
        &format!("{base}/api/v1/methods/{method_id}"),
        &carol,
        Some(json!({ "description": "mine now" })),
    );
    assert_eq!(refused.status(), 403);
    let text = refused.text().expect("body");
    assert!(!text.contains(TEAM), "the refusal names the team: {text}");
}

both_databases!(an_anonymous_team_method_names_no_team);
