//! The smaller things a researcher trips over in the first hour (issue 27, item 14), seen over
//! real HTTP: the menu lists the 2D boards; a finished submission's page shows its scores before
//! the file's hash and no progress bar, and its delete button looks destructive; a target's
//! overlay caption names the colours of the ground truth and the estimates, and its page says
//! why an instance is not counted; the visibility
//! endpoint takes the multipart form the upload takes as well as a plain form and JSON.
//!
//! The pages do not depend on the database kind, so this runs on SQLite only.

use std::time::Duration;

use crate::common::{
    Db, TestDb, client, fixtures, get_as, post_as, reference_datasets, signed_in, start,
    upload_with,
};
use reqwest::blocking::multipart;
use serde_json::{Value, json};

#[test]
fn the_first_hour_has_no_rough_edges() {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(Db::Sqlite, "polish");
    let server = start(&data, &datasets, &db, &["--no-demo"]);
    let base = server.base.as_str();
    let file = fixtures().join("results/noisesmall_synthA-test.csv");
    let r = upload_with(
        &server,
        &server.token,
        &[
            ("method", "polished"),
            ("dataset", "synthA"),
            ("protocol", "bop19"),
        ],
        &file,
    );
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().expect("JSON")["id"].as_i64().expect("id");
    let start = std::time::Instant::now();
    loop {
        let s: Value = get_as(&format!("{base}/api/v1/submissions/{id}"), &server.token)
            .json()
            .expect("JSON");
        if s["status"] == "done" {
            break;
        }
        assert!(s["status"] != "failed", "{s}");
        assert!(start.elapsed() < Duration::from_secs(60), "not done: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }

    // The menu of every page lists the 6D detection and 2D boards.
    let home = client().get(format!("{base}/")).send().expect("home");
    let home = home.text().expect("page");
    let nav = &home[home.find("<nav>").expect("nav")..home.find("</nav>").expect("/nav")];
    for board in ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] {
        assert!(
            nav.contains(&format!("href=\"/leaderboards/{board}\"")),
            "{board} in the menu: {nav}"
        );
    }

    // The owner's page of a finished submission: scores first, no progress bar, a red delete.
    let b = signed_in(&server, "tester");
    let page = b
        .get(format!("{base}/submissions/{id}"))
        .send()
        .expect("page")
        .text()
        .expect("page");
    assert!(page.contains("id=\"status-text\">done<"), "done");
    assert!(
        !page.contains("<progress"),
        "a finished submission shows a progress bar"
    );
    let scores = page.find("BOP'19 scores").expect("the scores");
    let hash = page.find("sha256").expect("the file's hash");
    assert!(scores < hash, "the scores come before the file's hash");
    let delete = &page[page
        .find(&format!("action=\"/submissions/{id}/delete\""))
        .expect("the delete form")..];
    let button = &delete[delete.find("<button").expect("button")..];
    let button = &button[..button.find('>').expect(">")];
    assert!(button.contains("class=\"danger\""), "{button}");

    // A target's page names the overlay's colours.
    let gallery = b
        .get(format!("{base}/submissions/{id}/targets"))
        .send()
        .expect("gallery")
        .text()
        .expect("page");
    let needle = "<a class=\"thumb\" href=\"";
    let at = gallery.find(needle).expect("a target") + needle.len();
    let target = gallery[at..]
        .split('"')
        .next()
        .expect("href")
        .replace("&amp;", "&");
    let page = b
        .get(format!("{base}{target}"))
        .send()
        .expect("target")
        .text()
        .expect("page");
    let caption = &page[page.find("<figcaption>").expect("caption")..];
    let caption = &caption[..caption.find("</figcaption>").expect("/caption")];
    assert!(
        caption.contains("the ground truth in green")
            && caption.contains("the estimates in magenta"),
        "{caption}"
    );

    // A target's page says why an instance of its object is not counted: in scene 2, image 1,
    // object 2's second instance (gt 4) is 9.1 % visible, and the targets file counts one.
    let page = b
        .get(format!("{base}/submissions/{id}/targets/2/1/2"))
        .send()
        .expect("target")
        .text()
        .expect("page");
    assert!(
        page.contains(
            "Instance 4 is not counted: 9.1 % visible: the targets file counts 1 instance of \
             the object in this image"
        ),
        "{page}"
    );

    // Withdraw with the upload's multipart form, publish with a plain form, withdraw with JSON.
    let url = format!("{base}/api/v1/submissions/{id}/visibility");
    let multi = client()
        .post(&url)
        .bearer_auth(&server.token)
        .multipart(multipart::Form::new().text("visibility", "private"))
        .send()
        .expect("answered");
    assert_eq!(multi.status(), 200, "multipart");
    assert_eq!(
        multi.json::<Value>().expect("JSON")["visibility"],
        "private"
    );
    let plain = client()
        .post(&url)
        .bearer_auth(&server.token)
        .form(&[("visibility", "private")])
        .send()
        .expect("answered");
    assert_eq!(plain.status(), 200, "plain form");
    assert_eq!(
        plain.json::<Value>().expect("JSON")["visibility"],
        "private"
    );
    let as_json = post_as(&url, &server.token, Some(json!({ "visibility": "public" })));
    assert_eq!(as_json.status(), 200, "JSON");
    assert_eq!(
        as_json.json::<Value>().expect("JSON")["visibility"],
        "public"
    );
    // A multipart form without the field is refused, saying which.
    let empty = client()
        .post(&url)
        .bearer_auth(&server.token)
        .multipart(multipart::Form::new().text("confirm", "true"))
        .send()
        .expect("answered");
    assert_eq!(empty.status(), 400);
    let error = empty.json::<Value>().expect("JSON")["error"].to_string();
    assert!(error.contains("`visibility`"), "{error}");
}
