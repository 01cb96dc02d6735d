//! Snapshots of the leaderboards: taken by administrators only, they hold every board as the
//! live pages rendered it at that moment, and serve exactly those bytes afterwards, whatever is
//! submitted later. Their pages are self-contained (tabs, JSON and exports stay in the snapshot,
//! the one link to the live board is marked) and carry an absolute permalink. Run on both
//! databases.

use crate::common;

use std::io::Read;
use std::time::Duration;

use crate::common::{
    Db, TestDb, admin_token, both_databases, client, fixtures, get_json, post_as,
    reference_datasets, start, upload, wait_done,
};
use serde_json::Value;

/// The body of `url` (no credentials), asserting success.
fn bytes(url: &str) -> Vec<u8> {
    let r = client().get(url).send().expect("answered");
    assert!(r.status().is_success(), "{url}: {}", r.status());
    r.bytes().expect("body").to_vec()
}

fn status(url: &str) -> u16 {
    client()
        .get(url)
        .send()
        .expect("answered")
        .status()
        .as_u16()
}

fn done_upload(server: &common::Server, method: &str, file: &str) {
    let r = upload(
        server,
        method,
        "synthA",
        &fixtures().join("results").join(file),
        None,
    );
    assert!(r.status().is_success(), "upload: {}", r.status());
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    wait_done(&server.base, id, Duration::from_secs(120));
}

fn a_snapshot_keeps_its_bytes(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let datasets = reference_datasets(dir.path());
    let db = TestDb::new(kind, "snapshots");
    let data = dir.path().join("data");
    let server = start(&data, &datasets, &db, &[]);
    let base = server.base.clone();
    let boss = admin_token(&data, &db, "boss");
    done_upload(&server, "early-method", "noisemedium_synthA-test.csv");

    // Anyone but an administrator finds no such route.
    let take = format!("{base}/api/v1/admin/snapshots");
    assert_eq!(post_as(&take, &server.token, None).status().as_u16(), 404);
    assert_eq!(
        client()
            .post(&take)
            .send()
            .expect("answered")
            .status()
            .as_u16(),
        404
    );
    assert!(
        get_json(&format!("{base}/api/v1/snapshots"))["snapshots"]
            .as_array()
            .expect("list")
            .is_empty()
    );

    let r = post_as(&take, &boss, None);
    assert_eq!(r.status().as_u16(), 201);
    let taken: Value = r.json().expect("json");
    let id = taken["id"].as_i64().expect("an id");
    // Each 6D protocol, 6D detection and each 2D task, all datasets and the one dataset.
    let boards = taken["boards"].as_array().expect("boards");
    assert_eq!(boards.len(), 10, "{taken}");

    // The stored JSON is what the live board served at that moment, byte for byte.
    let board_queries = [
        ("bop19", ""),
        ("bop19", "synthA"),
        ("eccv18", ""),
        ("eccv18", "synthA"),
        ("bop24", ""),
        ("bop24", "synthA"),
        ("bop22-det", ""),
        ("bop22-det", "synthA"),
        ("bop22-seg", ""),
        ("bop22-seg", "synthA"),
    ];
    let live_json = |protocol: &str, dataset: &str| {
        bytes(&format!(
            "{base}/api/v1/leaderboards/{protocol}{}",
            if dataset.is_empty() {
                String::new()
            } else {
                format!("?dataset={dataset}")
            }
        ))
    };
    let query = |protocol: &str, dataset: &str| {
        if dataset.is_empty() {
            format!("?protocol={protocol}")
        } else {
            format!("?protocol={protocol}&dataset={dataset}")
        }
    };
    let mut before = Vec::new();
    let mut kept_exports = Vec::new();
    for (protocol, dataset) in board_queries {
        let q = query(protocol, dataset);
        assert!(
            boards
                .iter()
                .any(|b| b["url"] == format!("/snapshots/{id}{q}")
                    && b["json_url"] == format!("/api/v1/snapshots/{id}{q}")),
            "{protocol} {dataset}: {taken}"
        );
        let json = bytes(&format!("{base}/api/v1/snapshots/{id}{q}"));
        assert_eq!(json, live_json(protocol, dataset), "{protocol} {dataset}");
        let html = bytes(&format!("{base}/snapshots/{id}{q}"));
        let text = String::from_utf8(html.clone()).expect("utf-8");
        // The 2D and bop24 boards are empty: the method has 6D localization results only.
        if !protocol.starts_with("bop22") && protocol != "bop24" {
            assert!(text.contains("early-method"), "{text}");
        }
        assert!(text.contains(&format!("Snapshot {id} of ")), "{text}");
        let tab = format!("/snapshots/{id}?protocol=eccv18");
        assert!(
            text.contains(&tab),
            "{protocol} {dataset}: no {tab} tab: {text}"
        );
        // The page is self-contained: its tabs, its JSON link and its exports stay in the
        // snapshot, the one link to today's board is marked, and the orders and filters it
        // did not keep are not offered.
        let permalink = format!("{base}/snapshots/{id}{q}");
        assert!(
            text.contains(&format!("href=\"{}\"", permalink.replace('&', "&amp;")))
                || text.contains(&format!("href=\"{}\"", permalink.replace('&', "&#38;"))),
            "{protocol} {dataset}: the banner lacks the absolute permalink {permalink}: {text}"
        );
        assert_self_contained(&text, &base, id);
        let live_q = if dataset.is_empty() {
            String::new()
        } else {
            format!("?dataset={dataset}")
        };
        let live = String::from_utf8(bytes(&format!("{base}/leaderboards/{protocol}{live_q}")))
            .expect("utf-8");
        assert!(!live.contains("?\""), "a live link ends in `?`: {live}");
        // The exports download the rows the snapshot kept: today's, until the boards change.
        let mut exports = Vec::new();
        for extension in ["csv", "json"] {
            let url = format!("{base}/snapshots/{id}/export.{extension}{q}");
            let r = client().get(&url).send().expect("answered");
            assert_eq!(r.status(), 200, "{url}");
            let disposition = r.headers()["content-disposition"]
                .to_str()
                .expect("ascii")
                .to_string();
            assert!(
                disposition.starts_with(&format!(
                    "attachment; filename=\"poseboard-snapshot-{id}-{protocol}"
                )),
                "{url}: {disposition}"
            );
            let kept = r.bytes().expect("body").to_vec();
            assert_eq!(
                kept,
                bytes(&format!(
                    "{base}/leaderboards/{protocol}/export.{extension}{live_q}"
                )),
                "{url}"
            );
            exports.push((url, kept));
        }
        kept_exports.extend(exports);
        before.push((q, json, html));
    }
    // Without a query: the BOP'19 board of all datasets, like the home page.
    assert_eq!(
        bytes(&format!("{base}/snapshots/{id}")),
        before[0].2,
        "the default board"
    );

    // Gzip to clients that take it: the same bytes once unpacked.
    let r = client()
        .get(format!("{base}/api/v1/snapshots/{id}{}", before[1].0))
        .header("accept-encoding", "gzip")
        .send()
        .expect("answered");
    assert_eq!(
        r.headers().get("content-encoding").map(|v| v.as_bytes()),
        Some(&b"gzip"[..])
    );
    let mut unpacked = Vec::new();
    flate2::read::GzDecoder::new(r.bytes().expect("body").as_ref())
        .read_to_end(&mut unpacked)
        .expect("gzip");
    assert_eq!(unpacked, before[1].1);

    // A later submission changes the live boards, not the snapshot.
    done_upload(&server, "later-method", "noisesmall_synthA-test.csv");
    let live = String::from_utf8(live_json("bop19", "synthA")).expect("utf-8");
    assert!(live.contains("later-method"), "{live}");
    for (q, json, html) in &before {
        assert_eq!(
            &bytes(&format!("{base}/api/v1/snapshots/{id}{q}")),
            json,
            "{q}"
        );
        assert_eq!(&bytes(&format!("{base}/snapshots/{id}{q}")), html, "{q}");
    }
    for (url, kept) in &kept_exports {
        assert_eq!(&bytes(url), kept, "{url}");
    }
    let live_csv = String::from_utf8(bytes(&format!(
        "{base}/leaderboards/bop19/export.csv?dataset=synthA"
    )))
    .expect("utf-8");
    let kept_csv = String::from_utf8(bytes(&format!(
        "{base}/snapshots/{id}/export.csv?protocol=bop19&dataset=synthA"
    )))
    .expect("utf-8");
    assert!(live_csv.contains("later-method"), "{live_csv}");
    assert!(!kept_csv.contains("later-method"), "{kept_csv}");
    assert!(kept_csv.contains("early-method"), "{kept_csv}");

    // Listed, as a page linked from the leaderboards and as JSON.
    let list = get_json(&format!("{base}/api/v1/snapshots"));
    assert_eq!(list["snapshots"][0]["id"], id);
    assert_eq!(list["snapshots"][0]["taken_by"], "boss");
    let page = String::from_utf8(bytes(&format!("{base}/snapshots"))).expect("utf-8");
    assert!(
        page.contains(&format!("/snapshots/{id}?protocol=bop19")),
        "{page}"
    );
    let board = String::from_utf8(bytes(&format!("{base}/leaderboards/bop19"))).expect("utf-8");
    assert!(board.contains("href=\"/snapshots\""), "{board}");

    // Unknown snapshots and boards do not exist.
    for path in [
        format!("/snapshots/{}", id + 1),
        format!("/api/v1/snapshots/{}", id + 1),
        "/snapshots/nine".to_string(),
        format!("/snapshots/{id}?protocol=bop20"),
        format!("/api/v1/snapshots/{id}?protocol=bop19&dataset=nosuch"),
        format!("/snapshots/{id}/export.csv?protocol=bop19&dataset=nosuch"),
        format!("/snapshots/{id}/export.tex"),
    ] {
        assert_eq!(status(&format!("{base}{path}")), 404, "{path}");
    }
}
both_databases!(a_snapshot_keeps_its_bytes);

/// Every link in the main part of a snapshot's page stays in snapshot `id` (its boards, their
/// JSON, its exports, its absolute permalinks, its place in the list) or is the one marked link
/// to the live board; no link ends in a bare `?`, and no order or filter is offered.
fn assert_self_contained(text: &str, base: &str, id: i64) {
    let main = &text[text.find("<main>").expect("main")..text.find("</main>").expect("main end")];
    let inside = [
        format!("/snapshots/{id}?protocol="),
        format!("/snapshots/{id}/export.csv?protocol="),
        format!("/snapshots/{id}/export.json?protocol="),
        format!("/api/v1/snapshots/{id}?protocol="),
        format!("/snapshots#snapshot-{id}"),
        format!("{base}/snapshots/{id}?protocol="),
    ];
    let mut live = 0;
    for (at, _) in main.match_indices("<a ") {
        let tag = &main[at..at + main[at..].find('>').expect("tag end")];
        let href = tag
            .split("href=\"")
            .nth(1)
            .and_then(|h| h.split('"').next())
            .unwrap_or_else(|| panic!("a link without href: {tag}"));
        assert!(!href.ends_with('?'), "{href}");
        if inside.iter().any(|p| href.starts_with(p.as_str())) {
            continue;
        }
        assert!(
            tag.contains("class=\"live\""),
            "a link out of the snapshot, unmarked: {tag}"
        );
        assert!(
            main[at + tag.len() + 1..].starts_with("live board ↗</a>"),
            "{tag}"
        );
        live += 1;
    }
    assert_eq!(live, 1, "one marked link to the live board: {main}");
    // As a query parameter (after `?`, `&`, or `&` escaped as `&amp;` or `&#38;`).
    for key in ["sort=", "training=", "modality=", "curves="] {
        for before in ['?', '&', ';'] {
            let offered = format!("{before}{key}");
            assert!(
                !main.contains(&offered),
                "{offered} offered in a snapshot: {main}"
            );
        }
    }
}
