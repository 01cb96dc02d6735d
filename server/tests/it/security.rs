//! Hardening against abuse (issue 11): limits that hold under parallel requests and cannot be
//! turned against an account's owner, the same work for unknown names as for known ones.
//!
//! Requests from different addresses come from different loopback addresses (every
//! `127.x.y.z` is this machine), so per-address limits are exercised without a proxy.

use std::net::IpAddr;

use crate::common::{
    Db, TestDb, admin, both_databases, browser, client, csrf_of, fixtures, get_as,
    reference_datasets, start, upload,
};
use reqwest::blocking::Client;
use serde_json::Value;

/// A client whose requests come from `ip`, without cookies and not following redirects.
fn from(ip: &str) -> Client {
    Client::builder()
        .local_address(ip.parse::<IpAddr>().expect("address"))
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .expect("client")
}

fn login(client: &Client, base: &str, name: &str, password: &str) -> u16 {
    client
        .post(format!("{base}/login"))
        .form(&[("name", name), ("password", password)])
        .send()
        .expect("login answered")
        .status()
        .as_u16()
}

fn parallel_guesses_stay_within_the_limit(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "guesses");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    // dave registers from 127.0.0.1.
    browser(&server, "dave");
    let attacker = from("127.0.0.2");
    let statuses: Vec<u16> = std::thread::scope(|s| {
        let guesses: Vec<_> = (0..25)
            .map(|i| {
                let (attacker, base) = (&attacker, &server.base);
                s.spawn(move || login(attacker, base, "dave", &format!("guess number {i}")))
            })
            .collect();
        guesses
            .into_iter()
            .map(|g| g.join().expect("guess"))
            .collect()
    });
    let checked = statuses.iter().filter(|&&s| s == 401).count();
    assert!(
        checked <= 5,
        "{kind:?}: {checked} guesses checked: {statuses:?}"
    );
    assert!(
        statuses.iter().all(|&s| s == 401 || s == 429),
        "{kind:?}: {statuses:?}"
    );
    // From a third address the right password waits too: the account is delayed...
    assert_eq!(
        login(
            &from("127.0.0.3"),
            &server.base,
            "dave",
            "correct horse battery"
        ),
        429,
        "{kind:?}"
    );
    // ...but not for its owner, from the address it was used from before.
    assert_eq!(
        login(
            &from("127.0.0.1"),
            &server.base,
            "dave",
            "correct horse battery"
        ),
        303,
        "{kind:?}: the owner was locked out"
    );
}
both_databases!(parallel_guesses_stay_within_the_limit);

fn addresses_are_limited_whatever_the_names(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "addrlimit");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    browser(&server, "erin");
    let sprayer = from("127.0.0.4");
    // Unknown names are answered like wrong passwords, and count like them.
    for i in 0..20 {
        assert_eq!(
            login(
                &sprayer,
                &server.base,
                &format!("nobody{i}"),
                "some password"
            ),
            401,
            "{kind:?}: attempt {i}"
        );
    }
    assert_eq!(
        login(&sprayer, &server.base, "nobody-else", "some password"),
        429,
        "{kind:?}"
    );
    assert_eq!(
        login(&sprayer, &server.base, "erin", "correct horse battery"),
        429,
        "{kind:?}"
    );
    // Other addresses are not affected.
    assert_eq!(
        login(
            &from("127.0.0.5"),
            &server.base,
            "erin",
            "correct horse battery"
        ),
        303,
        "{kind:?}"
    );
}
both_databases!(addresses_are_limited_whatever_the_names);

fn register(client: &Client, base: &str, name: &str) -> u16 {
    client
        .post(format!("{base}/register"))
        .form(&[("name", name), ("password", "correct horse battery")])
        .send()
        .expect("register answered")
        .status()
        .as_u16()
}

/// The server's peak resident memory, from the kernel's record of it.
fn peak_rss_mb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).expect("status");
    let kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM");
    kb / 1024
}

fn registrations_are_limited_per_address(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "reglimit");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let farm = from("127.0.0.6");
    for i in 0..5 {
        assert_eq!(
            register(&farm, &server.base, &format!("farmed{i}")),
            303,
            "{kind:?}"
        );
    }
    assert_eq!(register(&farm, &server.base, "farmed5"), 429, "{kind:?}");
    assert_eq!(
        register(&from("127.0.0.7"), &server.base, "honest"),
        303,
        "{kind:?}"
    );
}
both_databases!(registrations_are_limited_per_address);

/// 50 sign-ups at once, each from its own address so that no limit refuses them: argon2's
/// memory (~19 MiB a hash) stays bounded because hashes run in turn.
#[test]
fn parallel_sign_ups_keep_memory_bounded() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "memory");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let statuses: Vec<u16> = std::thread::scope(|s| {
        let sign_ups: Vec<_> = (1..=50)
            .map(|i| {
                let base = &server.base;
                s.spawn(move || register(&from(&format!("127.0.1.{i}")), base, &format!("user{i}")))
            })
            .collect();
        sign_ups
            .into_iter()
            .map(|h| h.join().expect("sign-up"))
            .collect()
    });
    assert!(statuses.iter().all(|&s| s == 303), "{statuses:?}");
    let peak = peak_rss_mb(server.child.id());
    assert!(peak < 300, "peak resident memory {peak} MB");
}

/// Signs `name` in with a cookie-keeping browser; returns it and its session's CSRF token.
fn signed_in(base: &str, name: &str, password: &str) -> (Client, String) {
    let b = Client::builder()
        .cookie_store(true)
        .build()
        .expect("client");
    let page = b
        .post(format!("{base}/login"))
        .form(&[("name", name), ("password", password), ("next", "/account")])
        .send()
        .expect("login")
        .text()
        .expect("html");
    (b, csrf_of(&page))
}

fn api_takes_cookies_only_with_csrf_and_origin(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "apicsrf");
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).expect("mkdir");
    std::fs::write(data.join("root.pw"), "root-secret-password\n").expect("pw");
    let pw = data.join("root.pw");
    admin(
        &data,
        &db,
        &[
            "create-user",
            "root",
            "--password-file",
            pw.to_str().expect("path"),
            "--admin",
        ],
    );
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload(&server, "moderated", "synthA", &file, None);
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let (root, csrf) = signed_in(&base, "root", "root-secret-password");
    let hide = format!("{base}/api/v1/admin/submissions/{id}/hide");
    let ours = base.clone();
    for (origin, token) in [
        (Some("https://evil.example"), Some(csrf.as_str())),
        (Some("http://127.0.0.1:1"), Some(csrf.as_str())),
        (None, Some(csrf.as_str())),
        (Some(ours.as_str()), None),
        (Some(ours.as_str()), Some("forged")),
    ] {
        let mut r = root.post(&hide);
        if let Some(o) = origin {
            r = r.header("Origin", o);
        }
        if let Some(t) = token {
            r = r.header("X-CSRF-Token", t);
        }
        let status = r.send().expect("answered").status();
        assert_eq!(status, 404, "{kind:?}: origin {origin:?}, token {token:?}");
    }
    assert_eq!(
        get_as(&format!("{base}/api/v1/submissions/{id}"), "").status(),
        200,
        "{kind:?}: hidden by a forged request"
    );
    let r = root
        .post(&hide)
        .header("Origin", ours.as_str())
        .header("X-CSRF-Token", csrf.as_str())
        .send()
        .expect("answered");
    assert_eq!(r.status(), 200, "{kind:?}");

    // An upload with a user's cookie alone is not signed in.
    let (user, user_csrf) = browser(&server, "uploader");
    let form = || {
        reqwest::blocking::multipart::Form::new()
            .text("method", "cookie-net")
            .text("dataset", "synthA")
            .file("file", &file)
            .expect("file")
    };
    // (Without a body: credentials are refused before one is read, and a body could race that.)
    let r = user
        .post(format!("{base}/api/v1/submissions"))
        .send()
        .expect("answered");
    assert_eq!(r.status(), 401, "{kind:?}");
    let r = user
        .post(format!("{base}/api/v1/submissions"))
        .header("Origin", ours.as_str())
        .header("X-CSRF-Token", user_csrf.as_str())
        .multipart(form())
        .send()
        .expect("answered");
    assert_eq!(r.status(), 202, "{kind:?}");
}
both_databases!(api_takes_cookies_only_with_csrf_and_origin);

/// To anyone but an administrator, the admin routes answer like a path that does not exist,
/// whatever the method or body.
fn admin_routes_do_not_exist_for_others(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "adminhidden");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = &server.base;
    let missing = client()
        .get(format!("{base}/no/such/page"))
        .send()
        .expect("answered")
        .text()
        .expect("body");
    let paths = [
        "/api/v1/admin/submissions/1/hide",
        "/api/v1/admin/submissions/x/hide",
        "/api/v1/admin/datasets",
        "/api/v1/admin/datasets/synthA/retire",
        "/api/v1/admin/audit",
        "/admin/submissions/1/hide",
        "/admin/datasets",
        "/admin/datasets/synthA/retire",
    ];
    for token in ["", server.token.as_str()] {
        for path in paths {
            for method in ["GET", "POST", "PUT", "DELETE", "PATCH"] {
                let mut r = client()
                    .request(method.parse().expect("method"), format!("{base}{path}"))
                    .header("Content-Type", "application/json")
                    .body("{");
                if !token.is_empty() {
                    r = r.bearer_auth(token);
                }
                let r = r.send().expect("answered");
                assert_eq!(r.status(), 404, "{kind:?}: {method} {path}");
                assert_eq!(
                    r.text().expect("body"),
                    missing,
                    "{kind:?}: {method} {path}"
                );
            }
        }
    }
}
both_databases!(admin_routes_do_not_exist_for_others);

/// `next` is followed only as a path of this site: tricks browsers resolve to another host,
/// or characters no header may hold, send the browser to its account page instead.
fn next_stays_on_this_site(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "next");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = &server.base;
    browser(&server, "nina");
    let page = client()
        .get(format!("{base}/login?next=/%09/evil.example"))
        .send()
        .expect("answered")
        .text()
        .expect("html");
    assert!(!page.contains("evil.example"), "{kind:?}");
    let local = from("127.0.0.1");
    for (next, to) in [
        ("/\t/evil.example", "/account"),
        ("/\n/evil.example", "/account"),
        ("/\\evil.example", "/account"),
        ("//evil.example", "/account"),
        ("https://evil.example/", "/account"),
        ("/submissions/3?x=1", "/submissions/3?x=1"),
    ] {
        let r = local
            .post(format!("{base}/login"))
            .form(&[
                ("name", "nina"),
                ("password", "correct horse battery"),
                ("next", next),
            ])
            .send()
            .expect("login answered");
        assert_eq!(r.status(), 303, "{kind:?}: next {next:?}");
        assert_eq!(r.headers()["location"], to, "{kind:?}: next {next:?}");
    }
}
both_databases!(next_stays_on_this_site);

/// Every answer (pages, errors, JSON, static files) forbids framing, sniffing, inline scripts
/// and styles, and leaking its address to other sites.
#[test]
fn every_response_carries_security_headers() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(Db::Sqlite, "headers");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = &server.base;
    let answers = [
        client().get(format!("{base}/")).send(),
        client().get(format!("{base}/no/such/page")).send(),
        client().get(format!("{base}/api/v1/datasets")).send(),
        client()
            .get(format!("{base}/api/v1/submissions/999"))
            .send(),
        client().get(format!("{base}/static/style.css")).send(),
        client().post(format!("{base}/api/v1/submissions")).send(),
    ];
    for r in answers {
        let r = r.expect("answered");
        let h = r.headers();
        let what = format!("{} {}", r.url(), r.status());
        let csp = h["content-security-policy"].to_str().expect("ascii");
        for part in [
            "default-src 'self'",
            "script-src 'self'",
            "style-src 'self'",
            "frame-ancestors 'none'",
            "object-src 'none'",
            "base-uri 'none'",
        ] {
            assert!(csp.contains(part), "{what}: {csp}");
        }
        assert!(!csp.contains("unsafe-inline"), "{what}: {csp}");
        assert_eq!(h["x-content-type-options"], "nosniff", "{what}");
        assert_eq!(h["referrer-policy"], "same-origin", "{what}");
        assert_eq!(h["x-frame-options"], "DENY", "{what}");
    }
}
