//! Accounts and what they protect: uploads need a valid API token; private submissions are
//! visible to their owner only and indistinguishable from missing ones for everyone else;
//! method names are per account; forms need the session's CSRF token; tokens can be created and
//! revoked from the account page; secrets never reach the log and are stored only hashed;
//! repeated failed sign-ins delay the account, but not for its owner's own address; and sign-ins
//! posted from another site are refused. Run on both databases, as these rules are enforced partly in queries.

use std::time::{Duration, Instant};

use crate::common::{
    Db, TestDb, account, both_databases, browser, client, column, fixtures, get_as,
    post_without_file, reference_datasets, start, upload_with,
};
use reqwest::blocking::Client;
use serde_json::Value;

fn accounts_privacy_and_tokens(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "acct");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let fields = [
        ("method", "secret-net"),
        ("dataset", "synthA"),
        ("visibility", "private"),
    ];

    // No credentials, or a token that is not one: 401 before the body is read.
    for token in ["", "pbt_0000"] {
        assert_eq!(
            post_without_file(&server, token),
            401,
            "{kind:?}: token {token:?}"
        );
    }

    // A private submission is visible to its owner only.
    let r = upload_with(&server, &server.token, &fields, &file);
    assert_eq!(r.status(), 202, "{kind:?}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let url = format!("{base}/api/v1/submissions/{id}");
    let start_wait = Instant::now();
    while get_as(&url, &server.token).json::<Value>().expect("json")["status"] != "done" {
        assert!(start_wait.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(100));
    }
    let bob = account(&data, &db, "bob");
    let missing = format!("{base}/api/v1/submissions/999999");
    for token in ["", bob.as_str()] {
        let hidden = get_as(&url, token);
        assert_eq!(hidden.status(), 404, "{kind:?}: private submission leaked");
        assert_eq!(
            hidden.text().expect("body"),
            get_as(&missing, token).text().expect("body")
        );
        let page = get_as(&format!("{base}/submissions/{id}"), token);
        assert_eq!(page.status(), 404);
        assert!(!page.text().expect("html").contains("secret-net"));
    }
    for listing in [
        format!("{base}/api/v1/submissions"),
        format!("{base}/api/v1/methods"),
        format!("{base}/api/v1/leaderboards/bop19"),
        format!("{base}/api/v1/leaderboards/eccv18?dataset=synthA"),
        format!("{base}/leaderboards/bop19"),
    ] {
        let text = get_as(&listing, &bob).text().expect("body");
        assert!(
            !text.contains("secret-net"),
            "{kind:?}: {listing} lists a private method"
        );
    }
    // Method names are per account: the same name elsewhere is a different method, and
    // nothing tells bob that a private one of that name exists.
    let own = upload_with(
        &server,
        &bob,
        &[("method", "secret-net"), ("dataset", "synthA")],
        &file,
    );
    assert_eq!(own.status(), 202, "{kind:?}");
    let own: Value = own.json().expect("json");
    assert_eq!(
        own["duplicate"], false,
        "not matched to the other account's submission"
    );
    assert_ne!(
        own["submission"]["method_id"],
        get_as(&url, &server.token).json::<Value>().expect("json")["method_id"]
    );

    // Forms need the session's CSRF token: missing or forged ones change nothing.
    let (carol, csrf) = browser(&server, "carol");
    for sent in [None, Some("forged")] {
        let mut form = vec![("name", "script")];
        if let Some(c) = sent {
            form.push(("csrf", c));
        }
        let r = carol
            .post(format!("{base}/account/tokens"))
            .form(&form)
            .send()
            .expect("post");
        assert_eq!(r.status(), 403, "{kind:?}: CSRF {sent:?}");
    }
    let tokens_page = carol
        .get(format!("{base}/account"))
        .send()
        .expect("page")
        .text()
        .expect("html");
    assert!(
        !tokens_page.contains("<td>script</td>"),
        "{kind:?}: a token was created"
    );
    let page = carol
        .post(format!("{base}/account/tokens"))
        .form(&[("name", "script"), ("csrf", csrf.as_str())])
        .send()
        .expect("post")
        .text()
        .expect("html");
    let at = page
        .find("<code id=\"new-token\">")
        .expect("the new token is shown")
        + 21;
    let token = page[at..].split('<').next().expect("token").to_string();
    let r = upload_with(
        &server,
        &token,
        &[("method", "carol-net"), ("dataset", "synthA")],
        &file,
    );
    assert_eq!(r.status(), 202);
    // Revoked, it gets 401.
    let token_id = page
        .split("/account/tokens/")
        .nth(1)
        .and_then(|s| s.split('/').next())
        .expect("a revoke form")
        .to_string();
    let r = carol
        .post(format!("{base}/account/tokens/{token_id}/revoke"))
        .form(&[("csrf", csrf.as_str())])
        .send()
        .expect("revoke");
    assert!(r.status().is_success());
    assert_eq!(
        post_without_file(&server, &token),
        401,
        "{kind:?}: revoked token accepted"
    );

    // Secrets never reach the log, and are never stored in clear.
    let log = std::fs::read_to_string(data.join("server.log")).expect("log");
    assert!(
        log.contains("/api/v1/submissions"),
        "the log has the requests"
    );
    for secret in [
        token.as_str(),
        server.token.as_str(),
        bob.as_str(),
        "correct horse battery",
    ] {
        assert!(!log.contains(secret), "{kind:?}: a secret is in the log");
    }
    let hashes = column(
        &db,
        &data,
        "SELECT password_hash FROM users WHERE name = 'carol'",
    );
    assert!(hashes[0].starts_with("$argon2id$") && !hashes[0].contains("correct horse"));
    let tokens = column(&db, &data, "SELECT token_hash FROM api_tokens");
    assert!(
        tokens
            .iter()
            .all(|t| t.len() == 64 && !token.contains(t.as_str()))
    );
    assert!(!tokens.contains(&token));
}
both_databases!(accounts_privacy_and_tokens);

fn login_attempts_are_limited(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "login");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    browser(&server, "dave");
    browser(&server, "erin");
    let login = |from: &str, name: &str, password: &str| {
        Client::builder()
            .local_address(from.parse::<std::net::IpAddr>().expect("address"))
            .redirect(reqwest::redirect::Policy::none())
            .build()
            .expect("client")
            .post(format!("{}/login", server.base))
            .form(&[("name", name), ("password", password)])
            .send()
            .expect("login")
            .status()
            .as_u16()
    };
    for _ in 0..5 {
        assert_eq!(
            login("127.0.0.2", "dave", "wrong password!"),
            401,
            "{kind:?}"
        );
    }
    // The account now waits, even with the right password...
    assert_eq!(
        login("127.0.0.2", "dave", "correct horse battery"),
        429,
        "{kind:?}"
    );
    // ...except from where its owner registered.
    assert_eq!(
        login("127.0.0.1", "dave", "correct horse battery"),
        303,
        "{kind:?}"
    );
    // A sign-in posted from another site's page is refused.
    let cross = client()
        .post(format!("{}/login", server.base))
        .header("Origin", "http://evil.example")
        .form(&[("name", "erin"), ("password", "correct horse battery")])
        .send()
        .expect("login");
    assert_eq!(cross.status(), 403, "{kind:?}");
    // Other accounts from the same address are not delayed.
    assert_eq!(
        login("127.0.0.2", "erin", "correct horse battery"),
        303,
        "{kind:?}"
    );
}
both_databases!(login_attempts_are_limited);
