//! Compare and targets follow the task (issue 27 item 2), over real HTTP on both databases:
//! a submission's compare picker offers only the submissions scored under a protocol in common
//! with it, newest first (a 6D submission's default is a 6D one, never a 2D segmenter); two 2D
//! submissions of one task compare image by image and category (matched, missed and false
//! positives at IoU 0.5, as COCOeval counts them, with the AP/AR numbers side by side); a 6D and
//! a 2D submission are refused with the reason; and a 2D submission links no target pages, whose
//! route answers a 404 page that says why and where to go instead.

use std::path::Path;

use evaluator::coco::{self, BboxType, CocoGt, CocoTask};
use evaluator::dataset::DatasetOptions;
use serde_json::Value;

use crate::common::{
    Db, Server, SynthDemo, TestDb, both_databases, client, get_json, start, upload_scored,
};

/// Uploads `file` publicly as `method` and waits until it is scored; its id.
fn scored(server: &Server, method: &str, file: &Path, protocol: Option<&str>) -> i64 {
    upload_scored(server, method, "synthdemo", file, protocol)["id"]
        .as_i64()
        .expect("id")
}

/// The status and body of a GET without credentials.
fn get(url: &str) -> (u16, String) {
    let r = client().get(url).send().expect("answered");
    (r.status().as_u16(), r.text().expect("body"))
}

/// The submission ids a submission page's compare picker offers, in order.
fn picker(base: &str, id: i64) -> Vec<i64> {
    let (status, page) = get(&format!("{base}/submissions/{id}"));
    assert_eq!(status, 200);
    let Some(start) = page.find("id=\"compare-form\"") else {
        return Vec::new();
    };
    let form = &page[start..page[start..].find("</form>").expect("form end") + start];
    form.split("<option value=\"")
        .skip(1)
        .map(|o| o.split('"').next().expect("value").parse().expect("an id"))
        .collect()
}

/// What COCOeval counts at IoU 0.5 for `file`, summed: (instances, matched, false positives).
fn counted(dataset: &Path, file: &Path) -> (usize, usize, usize) {
    let gt = CocoGt::load(dataset, &DatasetOptions::default(), BboxType::Amodal, false)
        .expect("ground truth");
    let results = coco::load_coco_results(file).expect("results");
    let task = CocoTask::Detection(BboxType::Amodal);
    let evaluation = coco::evaluation(&gt, &results, task).expect("evaluates");
    let outcomes = evaluation.images.expect("images").outcomes_at_50(&gt);
    (
        outcomes.iter().map(|o| o.instances).sum(),
        outcomes.iter().map(|o| o.matched).sum(),
        outcomes.iter().map(|o| o.false_positives).sum(),
    )
}

fn compare_tasks(kind: Db) {
    let set = SynthDemo::new();
    let (dataset, file) = (&set.dataset, |name: &str| set.file(name));
    let db = TestDb::new(kind, "comparetasks");
    let server = start(&set.data(), &set.datasets, &db, &["--no-demo"]);
    let base = &server.base;

    let precise = scored(
        &server,
        "precise",
        &file("demo-precise_synthdemo-test.csv"),
        None,
    );
    let rough = scored(
        &server,
        "rough",
        &file("demo-rough_synthdemo-test.csv"),
        None,
    );
    let seg_file = file("demo-segmenter_synthdemo-test.json");
    let det_file = file("demo-detector_synthdemo-test.json");
    let det = scored(&server, "boxes", &det_file, Some("bop22-det"));
    let seg = scored(&server, "masks", &seg_file, Some("bop22-seg"));
    // The masks file scored on its boxes: a second detector, the newest submission.
    let seg_as_det = scored(&server, "masks", &seg_file, Some("bop22-det"));

    // The picker offers what compares, newest first: a 6D submission's default is 6D.
    assert_eq!(picker(base, precise), [rough]);
    assert_eq!(picker(base, rough), [precise]);
    assert_eq!(picker(base, det), [seg_as_det]);
    assert_eq!(picker(base, seg_as_det), [det]);
    // The only segmentation: nothing to compare with, so no picker.
    assert_eq!(picker(base, seg), Vec::<i64>::new());

    // Two detectors compare image by image, with their numbers side by side.
    let view = get_json(&format!("{base}/api/v1/compare?a={det}&b={seg_as_det}"));
    assert_eq!(view["task"], "bop22-det", "{view}");
    let report =
        |id: i64| get_json(&format!("{base}/api/v1/submissions/{id}/report"))["bop22-det"].clone();
    let (ra, rb) = (report(det), report(seg_as_det));
    assert_eq!(view["scores"][0]["name"], "AP");
    assert_eq!(view["scores"][0]["a"], ra["AP"]);
    assert_eq!(view["scores"][0]["b"], rb["AP"]);
    assert_eq!(view["scores"][1]["name"], "AP50");
    assert_eq!(view["scores"][1]["b"], rb["AP50"]);
    let instances = view["instances"].as_u64().expect("instances") as usize;
    for (side, file) in [("a", &det_file), ("b", &seg_file)] {
        let total = &view[format!("{side}_total")];
        let (n, matched, fp) = counted(dataset, file);
        assert_eq!(instances, n);
        assert_eq!(total["matched"], matched, "{side}: {total}");
        assert_eq!(total["false_positives"], fp, "{side}: {total}");
        assert_eq!(total["missed"], n - matched, "{side}: {total}");
        assert!(matched > 0, "{side}: {total}");
    }
    // Each listed image and category differs between them and adds up.
    for i in view["images"].as_array().expect("images") {
        assert_ne!(i["a"], i["b"], "{i}");
        for side in ["a", "b"] {
            let c = &i[side];
            assert_eq!(
                c["matched"].as_u64().unwrap() + c["missed"].as_u64().unwrap(),
                i["instances"].as_u64().unwrap(),
                "{i}"
            );
        }
    }
    let (status, page) = get(&format!("{base}/compare?a={det}&b={seg_as_det}"));
    assert_eq!(status, 200, "{page}");
    assert!(page.contains("Image by image, at IoU 0.5"), "{page}");
    assert!(
        page.contains(&format!("<tr id=\"coco-totals\"><td>{instances}</td>")),
        "{page}"
    );

    // A 6D and a 2D submission, or two 2D tasks, do not compare: the reason, not a mystery.
    for (a, b) in [(precise, seg), (seg, precise), (det, seg)] {
        let (status, body) = get(&format!("{base}/api/v1/compare?a={a}&b={b}"));
        assert_eq!(status, 400, "{body}");
        assert!(
            body.contains("only submissions with a protocol in common compare"),
            "{body}"
        );
    }

    // A 2D submission links no target pages; asking for them says why and where to go.
    let (_, page) = get(&format!("{base}/submissions/{det}"));
    assert!(
        !page.contains(&format!("/submissions/{det}/targets")),
        "{page}"
    );
    assert!(page.contains("id=\"compare-note\""), "{page}");
    let (_, page) = get(&format!("{base}/submissions/{precise}"));
    assert!(page.contains(&format!("href=\"/submissions/{precise}/targets\"")));
    let (status, page) = get(&format!("{base}/submissions/{det}/targets"));
    assert_eq!(status, 404, "{page}");
    assert!(
        page.contains("(2D) submission: it has no 6D targets"),
        "{page}"
    );
    assert!(
        page.contains(&format!("<a href=\"/submissions/{det}\">")),
        "{page}"
    );
    assert!(
        page.contains("<a href=\"/leaderboards/bop22-det?dataset=synthdemo\">"),
        "{page}"
    );
    let r = client()
        .get(format!("{base}/api/v1/submissions/{det}/targets"))
        .send()
        .expect("answered");
    assert_eq!(r.status().as_u16(), 404);
    let body: Value = r.json().expect("JSON");
    assert_eq!(body["links"][0]["href"], format!("/submissions/{det}"));
    let (status, _) = get(&format!("{base}/submissions/{det}/targets/1/0/1"));
    assert_eq!(status, 404);
}
both_databases!(compare_tasks);
