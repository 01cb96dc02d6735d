//! BOP'24 detections image by image through the real HTTP API on both databases: a bop24
//! submission's target images (`/submissions/{id}/targets`), one image's estimates
//! (`/submissions/{id}/targets/{scene}/{im}`) and two submissions side by side (`/compare`),
//! as pages and JSON, give the counts `evaluator::detection::verdicts` gives for the same files
//! (whose true positives make the report's AP: `evaluator/tests/bop24_reference.rs`), at the
//! default criterion and at a chosen one; another account's private submission is missing; a
//! criterion bop24 does not have is refused with a message saying what it has.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use evaluator::detection::verdicts::{Criterion, ImageVerdicts, Tally, inspect};
use serde_json::{Value, json};

use crate::bop24_cli::{datasets, result_file};
use crate::common::{
    Db, Server, TestDb, account, both_databases, get_as, start, upload_scored, upload_with,
};

/// What the evaluator gives for the fixture file `case` on the dataset `synthA` at `root`.
fn verdicts(root: &Path, case: &str, criterion: &Criterion) -> Vec<ImageVerdicts> {
    let options = evaluator::dataset::DatasetOptions {
        targets_file: "test_targets_bop24.json".into(),
        ..Default::default()
    };
    let dataset = evaluator::Dataset::load_with(&root.join("synthA"), &options).expect("loads");
    let results = evaluator::results::load_results(&result_file(case)).expect("parses");
    inspect(&dataset, &results, 100, None, &AtomicBool::new(false))
        .expect("inspects")
        .verdicts(&dataset, criterion)
}

fn total(images: &[ImageVerdicts]) -> Tally {
    let mut t = Tally::default();
    for i in images {
        t.add(i.tally());
    }
    t
}

/// The status and body of a GET with `token` (none when empty).
fn get(server: &Server, path: &str, token: &str) -> (u16, String) {
    let r = get_as(&format!("{}{path}", server.base), token);
    (r.status().as_u16(), r.text().expect("body"))
}

fn json_of(server: &Server, path: &str, token: &str) -> Value {
    let (status, body) = get(server, path, token);
    assert_eq!(status, 200, "{path}: {body}");
    serde_json::from_str(&body).expect("JSON")
}

/// The counts of a JSON row that flattens a tally.
fn counts(v: &Value) -> Value {
    json!({
        "counted": v["counted"], "true_positives": v["true_positives"],
        "false_positives": v["false_positives"], "ignored": v["ignored"], "missed": v["missed"],
        "beyond_cap": v["beyond_cap"], "object_absent": v["object_absent"],
    })
}

fn id_of(v: &Value) -> i64 {
    v["id"].as_i64().expect("id")
}

fn bop24_pages(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let root = datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "bop24pages");
    let server = start(&data, &root, &db, &["--no-demo"]);
    let tester = server.token.clone();
    let noisy = id_of(&upload_scored(
        &server,
        "noisy",
        "synthA",
        &result_file("noisy"),
        Some("bop24"),
    ));
    let capped = id_of(&upload_scored(
        &server,
        "capped",
        "synthA",
        &result_file("capped"),
        Some("bop24"),
    ));
    // Another account's private submission.
    let alice = account(&data, &db, "alice");
    let fields = [
        ("method", "alice-net"),
        ("dataset", "synthA"),
        ("protocol", "bop24"),
        ("visibility", "private"),
    ];
    let r = upload_with(&server, &alice, &fields, &result_file("extra"));
    assert_eq!(r.status().as_u16(), 202);
    let alices = id_of(&r.json::<Value>().expect("JSON"));
    let started = Instant::now();
    while json_of(&server, &format!("/api/v1/submissions/{alices}"), &alice)["status"] != "done" {
        assert!(started.elapsed() < Duration::from_secs(120), "alice's file");
        std::thread::sleep(Duration::from_millis(100));
    }

    // The gallery at the default criterion (MSSD at 0.3 of the diameter) and at a chosen one:
    // the evaluator's counts, image by image, the most mistakes first.
    let report = |id: i64| {
        json_of(&server, &format!("/api/v1/submissions/{id}/report"), "")["bop24"].clone()
    };
    for (query, criterion, map_key) in [
        ("", Criterion::choose(None, None).unwrap(), "bop24_mAP_mssd"),
        (
            "error=mspd&threshold=15",
            Criterion::choose(Some("mspd"), Some(15.0)).unwrap(),
            "bop24_mAP_mspd",
        ),
    ] {
        let want = verdicts(&root, "noisy", &criterion);
        let g = json_of(
            &server,
            &format!("/api/v1/submissions/{noisy}/targets?{query}"),
            "",
        );
        assert_eq!(g["task"], "bop24", "{g}");
        assert_eq!(g["criterion"]["error"], criterion.error.name());
        assert_eq!(g["criterion"]["threshold"], criterion.threshold);
        assert_eq!(
            g["totals"],
            serde_json::to_value(total(&want)).unwrap(),
            "{query}"
        );
        assert_eq!(g["map"], report(noisy)[map_key]);
        let images = g["images"].as_array().expect("images");
        assert_eq!(images.len(), want.len());
        for i in images {
            let w = want
                .iter()
                .find(|w| json!([w.scene_id, w.im_id]) == json!([i["scene_id"], i["im_id"]]))
                .expect("a target image");
            assert_eq!(counts(i), serde_json::to_value(w.tally()).unwrap(), "{i}");
        }
        let mistakes: Vec<u64> = images
            .iter()
            .map(|i| i["missed"].as_u64().unwrap() + i["false_positives"].as_u64().unwrap())
            .collect();
        assert!(mistakes.windows(2).all(|w| w[0] >= w[1]), "{mistakes:?}");
        let per_object: u64 = g["objects"]
            .as_array()
            .expect("objects")
            .iter()
            .map(|o| o["true_positives"].as_u64().unwrap())
            .sum();
        assert_eq!(per_object as usize, total(&want).true_positives);
        let t = total(&want);
        assert!(t.true_positives > 0 && t.mistakes() > 0, "{t:?}");
        let (status, page) = get(
            &server,
            &format!("/submissions/{noisy}/targets?{query}"),
            "",
        );
        assert_eq!(status, 200, "{page}");
        assert!(
            page.contains(&format!(
                "<tr id=\"bop24-totals\"><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>",
                t.counted, t.true_positives, t.false_positives, t.ignored
            )),
            "{page}"
        );
        assert!(page.contains(&criterion.description()), "{page}");

        // The worst image alone: every estimate and instance as the evaluator gives them.
        let (scene, im) = (images[0]["scene_id"].clone(), images[0]["im_id"].clone());
        let w = want
            .iter()
            .find(|w| json!([w.scene_id, w.im_id]) == json!([scene, im]))
            .expect("the image");
        let one = json_of(
            &server,
            &format!("/api/v1/submissions/{noisy}/targets/{scene}/{im}?{query}"),
            "",
        );
        assert_eq!(
            one["estimates"],
            serde_json::to_value(&w.estimates).unwrap()
        );
        assert_eq!(
            one["instances"],
            serde_json::to_value(&w.instances).unwrap()
        );
        assert_eq!(one["tally"], serde_json::to_value(w.tally()).unwrap());
        let (status, page) = get(
            &server,
            &format!("/submissions/{noisy}/targets/{scene}/{im}?{query}"),
            "",
        );
        assert_eq!(status, 200, "{page}");
        assert!(page.contains("id=\"image-estimates\""), "{page}");
        let first = one["estimates"][0]["verdict"].as_str().expect("a verdict");
        assert!(
            page.contains(&format!("<td>{}</td>", first.replace('_', " "))),
            "{first}: {page}"
        );
    }
    // The capped file has estimates beyond the cap in a target image, and says so.
    let c = Criterion::choose(None, None).unwrap();
    let capped_want = verdicts(&root, "capped", &c);
    let g = json_of(
        &server,
        &format!("/api/v1/submissions/{capped}/targets"),
        "",
    );
    assert_eq!(
        g["totals"],
        serde_json::to_value(total(&capped_want)).unwrap()
    );
    assert!(total(&capped_want).beyond_cap > 0);

    // Two submissions side by side, image by image.
    let noisy_want = verdicts(&root, "noisy", &c);
    let cmp = json_of(
        &server,
        &format!("/api/v1/compare?a={noisy}&b={capped}"),
        "",
    );
    assert_eq!(cmp["task"], "bop24", "{cmp}");
    assert_eq!(
        cmp["a_total"],
        serde_json::to_value(total(&noisy_want)).unwrap()
    );
    assert_eq!(
        cmp["b_total"],
        serde_json::to_value(total(&capped_want)).unwrap()
    );
    assert_eq!(cmp["scores"][0]["name"], "bop24_mAP");
    assert_eq!(cmp["scores"][0]["a"], report(noisy)["bop24_mAP"]);
    assert_eq!(cmp["scores"][0]["b"], report(capped)["bop24_mAP"]);
    let pairs = cmp["images"].as_array().expect("images");
    assert_eq!(pairs.len(), noisy_want.len());
    for p in pairs {
        for (side, want) in [("a", &noisy_want), ("b", &capped_want)] {
            let w = want
                .iter()
                .find(|w| json!([w.scene_id, w.im_id]) == json!([p["scene_id"], p["im_id"]]))
                .expect("a target image");
            assert_eq!(p[side], serde_json::to_value(w.tally()).unwrap(), "{p}");
        }
    }
    let mspd = Criterion::choose(Some("mspd"), Some(50.0)).unwrap();
    let loose = json_of(
        &server,
        &format!("/api/v1/compare?a={noisy}&b={capped}&error=mspd&threshold=50"),
        "",
    );
    assert_eq!(
        loose["a_total"],
        serde_json::to_value(total(&verdicts(&root, "noisy", &mspd))).unwrap()
    );
    let (status, page) = get(&server, &format!("/compare?a={noisy}&b={capped}"), "");
    assert_eq!(status, 200, "{page}");
    let t = total(&noisy_want);
    assert!(
        page.contains(&format!(
            "<tr id=\"bop24-a-total\"><th>A</th><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>",
            t.counted, t.true_positives, t.false_positives
        )),
        "{page}"
    );
    // The submission page links the images and offers the other bop24 submission.
    let (_, page) = get(&server, &format!("/submissions/{noisy}"), "");
    assert!(
        page.contains(&format!("href=\"/submissions/{noisy}/targets\"")),
        "{page}"
    );
    assert!(
        page.contains(&format!("<option value=\"{capped}\">")),
        "{page}"
    );

    // Another account's private submission is missing, to the public and to another account;
    // its owner sees its pages.
    for token in ["", tester.as_str()] {
        for path in [
            format!("/api/v1/submissions/{alices}/targets"),
            format!("/submissions/{alices}/targets"),
            format!("/api/v1/submissions/{alices}/targets/1/0"),
            format!("/submissions/{alices}/targets/1/0"),
            format!("/api/v1/compare?a={noisy}&b={alices}"),
            format!("/compare?a={alices}&b={noisy}"),
        ] {
            assert_eq!(get(&server, &path, token).0, 404, "{path}");
        }
    }
    let own = json_of(
        &server,
        &format!("/api/v1/compare?a={alices}&b={noisy}"),
        &alice,
    );
    assert_eq!(
        own["a_total"],
        serde_json::to_value(total(&verdicts(&root, "extra", &c))).unwrap()
    );
    assert!(total(&verdicts(&root, "extra", &c)).object_absent > 0);

    // A criterion bop24 does not have is refused, saying what it has.
    for (query, message) in [
        (
            "error=vsd",
            "bop24 has no error `vsd` (it has mssd, mssd_mm, mspd)",
        ),
        (
            "threshold=0.33",
            "0.33 is not a threshold of mssd (0.05, 0.1, 0.15",
        ),
        (
            "error=mspd&threshold=0.3",
            "0.3 is not a threshold of mspd (5, 10, 15",
        ),
        ("threshold=abc", "`threshold` must be a number, not `abc`"),
        (
            "tau=20",
            "`tau` applies to VSD, which bop24 does not compute",
        ),
        ("protocol=bop19", "scored under bop24 only, not `bop19`"),
    ] {
        for path in [
            format!("/api/v1/submissions/{noisy}/targets?{query}"),
            format!("/api/v1/submissions/{noisy}/targets/1/0?{query}"),
            format!("/api/v1/compare?a={noisy}&b={capped}&{query}"),
            format!("/compare?a={noisy}&b={capped}&{query}"),
        ] {
            let (status, body) = get(&server, &path, "");
            assert_eq!(status, 400, "{path}: {body}");
            assert!(body.contains(message), "{path}: {body}");
        }
    }
    // An image that is not a target, and a localization target's address, are missing; the
    // latter says where a bop24 submission's targets are.
    let (status, _) = get(
        &server,
        &format!("/api/v1/submissions/{noisy}/targets/1/999"),
        "",
    );
    assert_eq!(status, 404);
    let (status, page) = get(&server, &format!("/submissions/{noisy}/targets/1/0/1"), "");
    assert_eq!(status, 404);
    assert!(page.contains("its targets are whole"), "{page}");
}

both_databases!(bop24_pages);
