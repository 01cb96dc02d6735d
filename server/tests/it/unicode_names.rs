//! Names in Unicode normal form C: "é" typed as one character or as "e" and a combining accent
//! names one method and one account, whichever way it is typed at upload, sign-up or sign-in,
//! and is stored composed. Run on both databases, as names are compared there.

use crate::common::{Db, TestDb, both_databases, fixtures, reference_datasets, start, upload_with};
use reqwest::blocking::Client;
use serde_json::Value;

const COMPOSED: &str = "Caf\u{e9}Pose";
const DECOMPOSED: &str = "Cafe\u{301}Pose";

fn browser() -> Client {
    Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .expect("client")
}

fn form(client: &Client, url: &str, name: &str) -> (u16, String) {
    let r = client
        .post(url)
        .form(&[("name", name), ("password", "correct horse battery")])
        .send()
        .expect("answered");
    (r.status().as_u16(), r.text().expect("body"))
}

fn names_are_nfc(kind: Db) {
    assert_ne!(COMPOSED, DECOMPOSED);
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "nfc");
    let server = start(&dir.path().join("data"), &datasets, &db, &[]);
    let base = server.base.clone();

    // One method, whichever way its name is typed.
    let mut methods = Vec::new();
    for (name, file) in [
        (COMPOSED, "noisesmall_synthA-test.csv"),
        (DECOMPOSED, "noisemedium_synthA-test.csv"),
    ] {
        let r = upload_with(
            &server,
            &server.token,
            &[("method", name), ("dataset", "synthA")],
            &fixtures().join("results").join(file),
        );
        assert_eq!(r.status(), 202, "{kind:?} {name:?}");
        let body: Value = r.json().expect("json");
        assert_eq!(
            body["submission"]["method"], COMPOSED,
            "{kind:?}: stored composed"
        );
        methods.push(body["submission"]["method_id"].clone());
    }
    assert_eq!(methods[0], methods[1], "{kind:?}: one method, not two");

    // One account: the other spelling is taken, and signs in to it.
    let (status, _) = form(&browser(), &format!("{base}/register"), "Jos\u{e9}");
    assert_eq!(status, 303, "{kind:?}: registered");
    let (status, page) = form(&browser(), &format!("{base}/register"), "Jose\u{301}");
    assert_eq!(status, 409, "{kind:?}: {page}");
    assert!(page.contains("is taken"), "{kind:?}");
    let (status, _) = form(&browser(), &format!("{base}/login"), "Jose\u{301}");
    assert_eq!(
        status, 303,
        "{kind:?}: signed in with the decomposed spelling"
    );
}
both_databases!(names_are_nfc);
