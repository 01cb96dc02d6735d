//! Single targets through the real HTTP API on both databases: two submissions compared target
//! by target (checked against an independent recomputation from both submissions' downloaded
//! per-estimate errors and the dataset's ground truth, and against their reports' true
//! positives), the visibility rules (another account's private submission is missing) and the
//! refusal of submissions on different datasets; one target's page and the gallery of the worst
//! targets answer with the stored errors.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::{
    Db, Server, TestDb, account, both_databases, fixtures, get_as, start, upload_with,
};
use serde_json::Value;

/// The ECCV'18 paper's setting: VSD at tau 20 mm, correct below 0.3, one estimate per target,
/// instances at least 10 % visible.
const VSD_TAU20: &str = "error=vsd_ntop=1_delta=15.000_tau=20.000";
const THETA: f64 = 0.3;
const VISIB_MIN: f64 = 0.1;

/// A datasets folder serving the reference dataset as `synthA` and `synthB`.
fn two_datasets(dir: &Path) -> PathBuf {
    let datasets = dir.join("datasets");
    std::fs::create_dir_all(&datasets).expect("mkdir");
    let reference = fixtures().join("dataset").canonicalize().expect("fixture");
    for name in ["synthA", "synthB"] {
        std::os::unix::fs::symlink(&reference, datasets.join(name)).expect("symlink");
    }
    datasets
}

/// Uploads the reference result file `stem` on `dataset` and waits (as `token`) until it is
/// evaluated; returns its id.
fn submit(server: &Server, token: &str, dir: &Path, fields: &[(&str, &str)], stem: &str) -> i64 {
    let dataset = fields
        .iter()
        .find(|(k, _)| *k == "dataset")
        .map(|(_, v)| *v)
        .expect("dataset");
    let file = dir.join(format!("{stem}_{dataset}-test.csv"));
    if !file.exists() {
        std::fs::copy(
            fixtures().join(format!("results/{stem}_synthA-test.csv")),
            &file,
        )
        .expect("copy");
    }
    let r = upload_with(server, token, fields, &file);
    assert_eq!(r.status(), 202, "{stem} on {dataset}");
    let id = r.json::<Value>().expect("json")["id"].as_i64().expect("id");
    let start = Instant::now();
    loop {
        let s: Value = get_as(&format!("{}/api/v1/submissions/{id}", server.base), token)
            .json()
            .expect("json");
        match s["status"].as_str() {
            Some("done") => return id,
            Some("failed") => panic!("submission {id} failed: {}", s["error"]),
            _ => {}
        }
        assert!(start.elapsed() < Duration::from_secs(180), "{id}: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn get(server: &Server, path: &str, token: &str) -> (u16, String) {
    let r = get_as(&format!("{}{path}", server.base), token);
    (r.status().as_u16(), r.text().expect("body"))
}

fn json(server: &Server, path: &str, token: &str) -> Value {
    let (status, body) = get(server, path, token);
    assert_eq!(status, 200, "{path}: {body}");
    serde_json::from_str(&body).expect("JSON")
}

type Key = (u32, u32, u32);

/// Of one side of a target: the instances found, and the error shown.
type Found = (usize, Option<f64>);

/// The dataset's ground truth: per (scene, image), each instance's object and visible fraction.
fn ground_truth() -> BTreeMap<(u32, u32), Vec<(u32, f64)>> {
    let mut out = BTreeMap::new();
    for scene in [1u32, 2] {
        let dir = fixtures().join(format!("dataset/test/{scene:06}"));
        let read = |f: &str| -> Value {
            serde_json::from_str(&std::fs::read_to_string(dir.join(f)).expect("gt file"))
                .expect("json")
        };
        let (gt, info) = (read("scene_gt.json"), read("scene_gt_info.json"));
        for (im, list) in gt.as_object().expect("images") {
            let instances = list
                .as_array()
                .expect("instances")
                .iter()
                .zip(info[im].as_array().expect("info"))
                .map(|(g, i)| {
                    (
                        g["obj_id"].as_u64().expect("obj") as u32,
                        i["visib_fract"].as_f64().expect("visib"),
                    )
                })
                .collect();
            out.insert((scene, im.parse().expect("image id")), instances);
        }
    }
    out
}

fn targets() -> BTreeSet<Key> {
    let text = std::fs::read_to_string(fixtures().join("dataset/test_targets_bop19.json"))
        .expect("targets");
    let list: Vec<Value> = serde_json::from_str(&text).expect("json");
    list.iter()
        .map(|t| {
            let n = |k: &str| t[k].as_u64().expect("id") as u32;
            (n("scene_id"), n("im_id"), n("obj_id"))
        })
        .collect()
}

/// Per target, the ECCV'18 verdict recomputed from the downloaded errors: the instances the
/// recall counts (one if any instance is visible enough), whether the top-scored estimate's
/// VSD is below theta against one of them, and the error shown: against the instance it
/// matched, or for a miss against the most visible valid instance (the one counted).
fn eccv18_verdicts(errors: &Value) -> BTreeMap<Key, (usize, usize, Option<f64>)> {
    let gt = ground_truth();
    let mut top: BTreeMap<Key, &Value> = BTreeMap::new();
    for row in errors.as_array().expect("rows") {
        let n = |k: &str| row[k].as_u64().expect("id") as u32;
        let key = (n("scene_id"), n("im_id"), n("obj_id"));
        let better = |old: &&Value| {
            let (s, o) = (row["score"].as_f64(), old["score"].as_f64());
            s > o || (s == o && row["est_id"].as_u64() < old["est_id"].as_u64())
        };
        if top.get(&key).is_none_or(better) {
            top.insert(key, row);
        }
    }
    let mut out = BTreeMap::new();
    for key @ (scene, im, obj) in targets() {
        let instances = &gt[&(scene, im)];
        let mut valid: Vec<usize> = (0..instances.len())
            .filter(|&g| instances[g].0 == obj && instances[g].1 >= VISIB_MIN)
            .collect();
        if valid.is_empty() {
            continue;
        }
        // Most visible first; ties keep the lower gt id.
        valid.sort_by(|&a, &b| instances[b].1.total_cmp(&instances[a].1));
        let error_against = |row: &Value, g: usize| -> f64 {
            let at = row["gt_ids"]
                .as_array()
                .expect("gt ids")
                .iter()
                .position(|x| x.as_u64() == Some(g as u64))
                .expect("the gt among the row's");
            row["errors"][VSD_TAU20][at]
                .as_f64()
                .unwrap_or(f64::INFINITY)
        };
        let (found, error) = match top.get(&key) {
            None => (0, None),
            Some(row) => {
                let best = valid
                    .iter()
                    .map(|&g| error_against(row, g))
                    .fold(f64::INFINITY, f64::min);
                if best < THETA {
                    (1, Some(best))
                } else {
                    (0, Some(error_against(row, valid[0])))
                }
            }
        };
        out.insert(key, (1, found, error.filter(|e| e.is_finite())));
    }
    out
}

fn close(a: Option<f64>, b: &Value) -> bool {
    match (a, b.as_f64()) {
        (None, None) => true,
        (Some(x), Some(y)) => (x - y).abs() <= 1e-9 * x.abs().max(1.0),
        _ => false,
    }
}

fn compare_and_inspect_targets(kind: Db) {
    let dir = tempfile::tempdir().expect("tmp");
    let files = dir.path().join("files");
    std::fs::create_dir_all(&files).expect("mkdir");
    let datasets = two_datasets(dir.path());
    let data = dir.path().join("data");
    let db = TestDb::new(kind, "compare");
    let server = start(
        &data,
        &datasets,
        &db,
        &["--no-demo", "--submissions-per-window", "0"],
    );
    let tester = server.token.clone();
    let alice = account(&data, &db, "alice");
    let f = files.as_path();
    let public = |method| {
        vec![
            ("method", method),
            ("dataset", "synthA"),
            ("visibility", "public"),
        ]
    };
    let a = submit(&server, &tester, f, &public("medium-net"), "noisemedium");
    let b = submit(&server, &tester, f, &public("large-net"), "noiselarge");
    let eccv18_only = |method, dataset| {
        vec![
            ("method", method),
            ("dataset", dataset),
            ("protocol", "eccv18"),
            ("visibility", "private"),
        ]
    };
    let other_dataset = submit(
        &server,
        &tester,
        f,
        &eccv18_only("b-net", "synthB"),
        "noisesmall",
    );
    let alices = submit(
        &server,
        &alice,
        f,
        &eccv18_only("alice-net", "synthA"),
        "multi",
    );

    // The comparison, against both submissions' own errors and reports.
    let view = json(&server, &format!("/api/v1/compare?a={a}&b={b}"), "");
    assert_eq!(
        view["protocol"], "eccv18",
        "the paper's protocol by default"
    );
    assert_eq!(view["criterion"]["error"], "vsd");
    assert_eq!(view["criterion"]["threshold"], THETA);
    let errors = |id| {
        json(
            &server,
            &format!("/api/v1/submissions/{id}/errors/eccv18"),
            &tester,
        )
    };
    let (va, vb) = (eccv18_verdicts(&errors(a)), eccv18_verdicts(&errors(b)));
    let (mut both, mut only_a, mut only_b, mut neither, mut instances) = (0, 0, 0, 0, 0);
    let mut expected: BTreeMap<Key, (Found, Found)> = BTreeMap::new();
    for (key, &(n, fa, ea)) in &va {
        let (_, fb, eb) = vb[key];
        instances += n;
        match (fa, fb) {
            (1, 1) => both += 1,
            (1, 0) => only_a += 1,
            (0, 1) => only_b += 1,
            _ => neither += 1,
        }
        if fa != fb {
            expected.insert(*key, ((fa, ea), (fb, eb)));
        }
    }
    let counts = &view["counts"];
    assert_eq!(
        [
            &counts["instances"],
            &counts["both"],
            &counts["only_a"],
            &counts["only_b"],
            &counts["neither"]
        ]
        .map(|v| v.as_u64().expect("a count") as usize),
        [instances, both, only_a, only_b, neither],
        "{counts}"
    );
    assert!(!expected.is_empty(), "the two files differ on some targets");
    let listed = view["targets"].as_array().expect("targets");
    assert_eq!(listed.len(), expected.len(), "{listed:?}");
    for t in listed {
        let n = |k: &str| t[k].as_u64().expect("id") as u32;
        let key = (n("scene_id"), n("im_id"), n("obj_id"));
        let ((fa, ea), (fb, eb)) = expected[&key];
        assert_eq!(t["instances"], 1, "{t}");
        assert_eq!(t["a"]["found"].as_u64(), Some(fa as u64), "{t}");
        assert_eq!(t["b"]["found"].as_u64(), Some(fb as u64), "{t}");
        assert!(close(ea, &t["a"]["error"]), "{t}: a's error {ea:?}");
        assert!(close(eb, &t["b"]["error"]), "{t}: b's error {eb:?}");
    }
    // The verdicts are the scores' own: found by a = a's true positives.
    let report = |id| json(&server, &format!("/api/v1/submissions/{id}"), "")["scores"].clone();
    let (ra, rb) = (report(a), report(b));
    assert_eq!(
        ra["eccv18"]["tp_count"].as_u64(),
        Some((both + only_a) as u64)
    );
    assert_eq!(
        rb["eccv18"]["tp_count"].as_u64(),
        Some((both + only_b) as u64)
    );
    assert_eq!(
        ra["eccv18"]["targets_count"].as_u64(),
        Some(instances as u64)
    );
    let scores = view["scores"].as_array().expect("scores");
    assert_eq!(scores.len(), 2, "both protocols side by side");
    let eccv = scores
        .iter()
        .find(|s| s["protocol"] == "eccv18")
        .expect("eccv18");
    assert_eq!(eccv["scores"][0]["a"], ra["eccv18"]["recall"]);
    assert_eq!(eccv["scores"][0]["b"], rb["eccv18"]["recall"]);
    assert_eq!(eccv["visibility"].as_array().map(Vec::len), Some(10));
    assert_eq!(eccv["objects"].as_array().map(Vec::len), Some(4));
    // Another criterion: BOP'19's MSPD at 30 px gives the recall its report has there.
    let mspd = json(
        &server,
        &format!("/api/v1/compare?a={a}&b={b}&protocol=bop19&error=mspd&threshold=30"),
        "",
    );
    let c = |k: &str| mspd["counts"][k].as_u64().expect("a count") as f64;
    let at30 = |r: &Value| {
        r["bop19"]["per_error_recall_per_threshold"]["error=mspd_ntop=-1"]
            ["th=30.000_min-visib=-1.000"]
            .as_f64()
            .expect("a recall")
    };
    assert_eq!((c("both") + c("only_a")) / c("instances"), at30(&ra));
    assert_eq!((c("both") + c("only_b")) / c("instances"), at30(&rb));
    let (status, page) = get(&server, &format!("/compare?a={a}&b={b}"), "");
    assert_eq!(status, 200, "{page}");
    assert!(
        page.contains(&format!("id=\"paired-both\">{both}<")),
        "{page}"
    );

    // Visibility and refusals.
    let (status, _) = get(
        &server,
        &format!("/api/v1/compare?a={a}&b={alices}"),
        &tester,
    );
    assert_eq!(
        status, 404,
        "another account's private submission is missing"
    );
    let (status, _) = get(&server, &format!("/compare?a={alices}&b={a}"), "");
    assert_eq!(status, 404);
    let own = json(
        &server,
        &format!("/api/v1/compare?a={alices}&b={a}"),
        &alice,
    );
    assert_eq!(
        own["protocols"],
        serde_json::json!(["eccv18"]),
        "its owner compares it"
    );
    let (status, body) = get(
        &server,
        &format!("/api/v1/compare?a={a}&b={other_dataset}"),
        &tester,
    );
    assert_eq!(status, 400, "{body}");
    assert!(body.contains("same dataset"), "{body}");
    let (status, body) = get(
        &server,
        &format!("/api/v1/compare?a={a}&b={b}&error=nope"),
        "",
    );
    assert_eq!(status, 400, "{body}");

    // One target: its page and JSON show the stored errors and the verdict.
    let (&(scene, im, obj), &((fa, ea), _)) = expected.iter().next().expect("a target");
    let target = json(
        &server,
        &format!("/api/v1/submissions/{a}/errors/eccv18/{scene}/{im}/{obj}"),
        "",
    );
    let rows = errors(a);
    let row = rows
        .as_array()
        .expect("rows")
        .iter()
        .find(|r| {
            (
                r["scene_id"].as_u64(),
                r["im_id"].as_u64(),
                r["obj_id"].as_u64(),
            ) == (Some(scene.into()), Some(im.into()), Some(obj.into()))
        })
        .expect("a's estimate of the target");
    let column = target["columns"]
        .as_array()
        .expect("columns")
        .iter()
        .position(|c| c["signature"] == VSD_TAU20)
        .expect("the VSD column");
    let shown = &target["estimates"][0]["against"];
    for (i, gt) in row["gt_ids"].as_array().expect("gt ids").iter().enumerate() {
        assert_eq!(shown[i]["gt_id"], *gt);
        assert!(
            close(
                row["errors"][VSD_TAU20][i].as_f64(),
                &shown[i]["errors"][column]
            ),
            "{target}"
        );
    }
    let verdict = &target["verdicts"][0]["outcomes"][0];
    assert_eq!(verdict["correct"].as_bool(), Some(fa == 1), "{target}");
    assert!(close(ea, &verdict["error"]), "{target}");
    let (status, page) = get(
        &server,
        &format!("/submissions/{a}/targets/{scene}/{im}/{obj}"),
        "",
    );
    assert_eq!(status, 200, "{page}");
    assert!(page.contains(&format!(
        "/api/v1/submissions/{a}/targets/{scene}/{im}/{obj}.png"
    )));
    if let Some(e) = ea {
        assert!(
            page.contains(&format!("{e:.3}")),
            "the error on the page: {page}"
        );
    }
    assert_eq!(
        get(&server, &format!("/submissions/{a}/targets/9/0/1"), "").0,
        404
    );
    assert_eq!(
        get(&server, &format!("/submissions/{alices}/targets/1/0/1"), "").0,
        404
    );

    // The gallery: every counted instance per object, the missed ones first.
    let gallery = json(&server, &format!("/api/v1/submissions/{a}/targets"), "");
    let objects = gallery["objects"].as_array().expect("objects");
    let sum = |k: &str| {
        objects
            .iter()
            .map(|o| o[k].as_u64().expect("n"))
            .sum::<u64>()
    };
    assert_eq!(sum("instances"), instances as u64);
    assert_eq!(sum("correct"), (both + only_a) as u64);
    for o in objects {
        let worst: Vec<bool> = o["worst"]
            .as_array()
            .expect("worst")
            .iter()
            .map(|w| w["correct"].as_bool().expect("bool"))
            .collect();
        let missed = o["instances"].as_u64().expect("n") - o["correct"].as_u64().expect("n");
        assert!(
            worst.iter().take(missed as usize).all(|c| !c),
            "missed first: {o}"
        );
    }
    let (status, page) = get(&server, &format!("/submissions/{a}/targets"), "");
    assert_eq!(status, 200, "{page}");
    assert!(
        page.contains(&format!("href=\"/submissions/{a}/targets/")),
        "{page}"
    );
    assert!(page.contains(".png?crop=object\""), "{page}");
    // The submission's page links the gallery and offers b to compare with, not alice's.
    let (_, page) = get(&server, &format!("/submissions/{a}"), "");
    assert!(page.contains(&format!("href=\"/submissions/{a}/targets\"")));
    assert!(page.contains(&format!("<option value=\"{b}\">")), "{page}");
    assert!(
        !page.contains(&format!("<option value=\"{alices}\">")),
        "{page}"
    );
}
both_databases!(compare_and_inspect_targets);
