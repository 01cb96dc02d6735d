//! The seven core BOP datasets as published: miniatures of their layouts (made by
//! `poseboard dataset synth --layout`) load and score exactly as the plain layout does, on the
//! command line and in the service; uploads named the BOP way (`METHOD_DATASET-test.csv`) need
//! no dataset field, a name that contradicts the field is refused, and one upload of seven
//! files makes seven submissions, or none when one file is bad.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::common::{BIN, Db, TestDb, both_databases, cli_report, client, start, wait_done};
use reqwest::blocking::multipart;
use serde_json::Value;

const CORE: [&str; 7] = ["lmo", "tless", "tudl", "icbin", "itodd", "hb", "ycbv"];

/// The published test image sizes, after bop_toolkit's `dataset_params.py` (T-LESS and HB:
/// the Primesense split type).
fn published_size(dataset: &str) -> (u32, u32) {
    match dataset {
        "tless" => (720, 540),
        "itodd" => (1280, 960),
        _ => (640, 480),
    }
}

fn poseboard(args: &[&str]) -> std::process::Output {
    let out = Command::new(BIN)
        .args(args)
        .output()
        .expect("poseboard runs");
    assert!(
        out.status.success(),
        "poseboard {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// Plain synthetic datasets (one scene of two images) at each published size, a folder
/// `core` with the seven miniatures of the same content at their published sizes, and the
/// demo result files of the plain one at 640 x 480.
struct Miniatures {
    _dir: tempfile::TempDir,
    /// The plain dataset at 640 x 480.
    plain: PathBuf,
    core: PathBuf,
    results: PathBuf,
}

/// The folder of the plain dataset of `size`: `plain` at 640 x 480 (the demo result files
/// are named for it), `plain720x540` and so on.
fn plain_name((w, h): (u32, u32)) -> String {
    if (w, h) == (640, 480) {
        "plain".to_string()
    } else {
        format!("plain{w}x{h}")
    }
}

fn miniatures() -> Miniatures {
    let dir = tempfile::tempdir().expect("tmp");
    let small = ["--scenes", "1", "--images-per-scene", "2"];
    for size in [(640, 480), (720, 540), (1280, 960)] {
        let plain = dir.path().join(plain_name(size));
        let size = format!("{}x{}", size.0, size.1);
        let mut args = vec!["dataset", "synth", path(&plain), "--size", &size];
        args.extend(small);
        poseboard(&args);
    }
    let plain = dir.path().join("plain");
    let core = dir.path().join("core");
    for name in CORE {
        let target = core.join(name);
        let mut args = vec!["dataset", "synth", path(&target), "--layout", name];
        args.extend(small);
        poseboard(&args);
    }
    let results = dir.path().join("results");
    poseboard(&["dataset", "demo-results", path(&plain), path(&results)]);
    Miniatures {
        _dir: dir,
        plain,
        core,
        results,
    }
}

impl Miniatures {
    /// The plain dataset of the size of core dataset `dataset`.
    fn plain_like(&self, dataset: &str) -> PathBuf {
        self.plain
            .with_file_name(plain_name(published_size(dataset)))
    }

    /// What `poseboard eval` reports for the noisy demo file on the plain dataset of the size
    /// of `dataset`: what the miniature of `dataset` must score.
    fn expected(&self, dataset: &str, protocol: &str) -> Value {
        scores(cli_report(
            &self.plain_like(dataset),
            &self.result_for("plain"),
            protocol,
        ))
    }

    /// The noisy demo result file under the BOP name for `dataset`.
    fn result_for(&self, dataset: &str) -> PathBuf {
        let to = self.results.join(format!("noisy_{dataset}-test.csv"));
        if !to.exists() {
            std::fs::copy(self.results.join("demo-noisy_plain-test.csv"), &to).expect("copy");
        }
        to
    }
}

/// The submissions an upload of the seven core files answered with: one per core dataset, in
/// order, all of one method.
fn seven_of_one_method(r: reqwest::blocking::Response) -> Vec<Value> {
    let body: Value = r.json().expect("json");
    let made = body["submissions"].as_array().expect("list").clone();
    let datasets: Vec<&str> = made
        .iter()
        .map(|s| s["submission"]["dataset"].as_str().expect("dataset"))
        .collect();
    assert_eq!(datasets, CORE);
    let methods: Vec<&Value> = made.iter().map(|s| &s["submission"]["method_id"]).collect();
    assert!(methods.iter().all(|m| *m == methods[0]));
    made
}

/// Each submission, once evaluated, has the scores its file has on the plain layout
/// (`checks`: protocol and report key).
fn assert_scored_as_plain(base: &str, m: &Miniatures, made: &[Value], checks: &[(&str, &str)]) {
    for s in made {
        let done = wait_done(
            base,
            s["id"].as_i64().expect("id"),
            Duration::from_secs(120),
        );
        let dataset = s["submission"]["dataset"].as_str().expect("dataset");
        for (protocol, key) in checks {
            assert_eq!(
                done["scores"][protocol][key],
                m.expected(dataset, protocol)[key],
                "{dataset} {protocol}"
            );
        }
    }
}

/// The scores of a report, without what names the dataset.
fn scores(mut report: Value) -> Value {
    let o = report.as_object_mut().expect("object");
    o.remove("dataset");
    report
}

#[test]
fn core_layouts_are_published_as_bop_does() {
    let m = miniatures();
    let tless = m.core.join("tless");
    for p in [
        "test_primesense/000001/scene_camera.json",
        "camera_primesense.json",
        "test_targets_bop19.json",
        "test_targets_bop24.json",
    ] {
        assert!(tless.join(p).is_file(), "{p}");
    }
    assert!(!tless.join("test").exists() && !tless.join("camera.json").exists());
    assert!(m.core.join("hb/test_primesense").is_dir());
    assert!(m.core.join("ycbv/camera_uw.json").is_file());
    // ITODD: gray and depth images as TIFF, as dataset_params.py names them.
    let itodd = m.core.join("itodd/test/000001");
    for p in ["gray/000000.tif", "depth/000000.tif", "depth/000001.tif"] {
        assert!(itodd.join(p).is_file(), "{p}");
    }
    assert!(!itodd.join("rgb").exists() && !itodd.join("depth/000000.png").exists());
    assert_eq!(
        &std::fs::read(itodd.join("depth/000000.tif")).expect("read")[..4],
        b"II*\0"
    );
    // The published image sizes, in the camera files and the images.
    for (name, camera) in [
        ("lmo", "camera.json"),
        ("tless", "camera_primesense.json"),
        ("tudl", "camera.json"),
        ("icbin", "camera.json"),
        ("itodd", "camera.json"),
        ("hb", "camera_primesense.json"),
        ("ycbv", "camera_uw.json"),
    ] {
        let camera: Value =
            serde_json::from_slice(&std::fs::read(m.core.join(name).join(camera)).expect("read"))
                .expect("json");
        let (w, h) = published_size(name);
        assert_eq!(
            (camera["width"].as_u64(), camera["height"].as_u64()),
            (Some(w.into()), Some(h.into())),
            "{name}"
        );
    }
    let rgb = std::fs::read(tless.join("test_primesense/000001/rgb/000000.png")).expect("read");
    // The PNG header: width and height, big-endian, at bytes 16 and 20.
    assert_eq!(rgb[16..24], [0, 0, 0x02, 0xd0, 0, 0, 0x02, 0x1c]);
    // The intrinsics scale with the size: T-LESS's 720 x 540 is LINEMOD's 640 x 480 x 1.125.
    let cameras: Value = serde_json::from_slice(
        &std::fs::read(tless.join("test_primesense/000001/scene_camera.json")).expect("read"),
    )
    .expect("json");
    assert_eq!(cameras["0"]["cam_K"][0], 572.4 * 1.125);
    let camera: Value = serde_json::from_slice(
        &std::fs::read(m.core.join("lmo/test/000001/scene_camera.json")).expect("read"),
    )
    .expect("json");
    assert_eq!(camera["0"]["depth_scale"], 1.0);
    let camera: Value = serde_json::from_slice(
        &std::fs::read(tless.join("test_primesense/000001/scene_camera.json")).expect("read"),
    )
    .expect("json");
    assert_eq!(camera["1"]["depth_scale"], 0.1);
}

#[test]
fn every_core_layout_scores_as_the_plain_layout() {
    let m = miniatures();
    for protocol in ["bop19", "eccv18"] {
        for name in CORE {
            // `--dataset` names the folder of datasets: the file name picks the dataset.
            let report = cli_report(&m.core, &m.result_for(name), protocol);
            assert_eq!(report["dataset"], name);
            assert_eq!(
                scores(report),
                m.expected(name, protocol),
                "{name} {protocol}"
            );
        }
    }
}

#[test]
fn split_choices_and_unloadable_layouts_are_explained() {
    let m = miniatures();
    let results = m.result_for("tless");
    let tless = m.core.join("tless");
    let run = |args: &[&str]| {
        let mut all = vec!["check-results", path(&results)];
        all.extend(args);
        Command::new(BIN).args(&all).output().expect("runs")
    };
    let ok = run(&["--dataset", path(&tless), "--split-type", "primesense"]);
    assert!(ok.status.success());
    assert!(String::from_utf8_lossy(&ok.stdout).contains("tless: 4 targets"));

    let out = run(&["--dataset", path(&tless), "--split-type", "kinect"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "test_kinect: no such folder: expected the split `test` of split type `kinect`"
        ),
        "{err}"
    );
    assert_eq!(err.matches("no such folder").count(), 1, "said once: {err}");

    std::fs::create_dir(tless.join("test_kinect")).expect("mkdir");
    let out = run(&["--dataset", path(&tless)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("several folders hold the split `test` (test_kinect, test_primesense)"),
        "{err}"
    );
    // The folder's own choice settles it, for the CLI as for the service.
    std::fs::write(
        tless.join("poseboard-dataset.json"),
        r#"{"split_type": "primesense"}"#,
    )
    .expect("write");
    assert!(run(&["--dataset", path(&tless)]).status.success());

    let out = run(&[
        "--dataset",
        path(&tless),
        "--targets-file",
        "test_targets_bop24.json",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "test_targets_bop24.json lists images (BOP'24 detection targets): check with \
             --protocol bop24"
        ),
        "{err}"
    );

    let out = run(&["--dataset", path(&m.core.join("nothing"))]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("has no folder `tless`") || err.contains("no such folder"),
        "{err}"
    );
}

/// Uploads `files` in one request with `fields`, published (these tests follow the public
/// lists).
fn upload_files(
    server: &common::Server,
    fields: &[(&str, &str)],
    files: &[PathBuf],
) -> reqwest::blocking::Response {
    let mut form = multipart::Form::new().text("visibility", "public");
    for f in files {
        form = form.file("file", f).expect("result file");
    }
    for (k, v) in fields {
        form = form.text(k.to_string(), v.to_string());
    }
    client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
        .expect("upload answered")
}

/// How many submissions `tester` has stored, whatever their state (the public list shows
/// finished ones only, and these are counted as soon as an upload is answered).
fn submissions_count(server: &common::Server) -> usize {
    let r = client()
        .get(format!("{}/api/v1/me/submissions", server.base))
        .bearer_auth(&server.token)
        .send()
        .expect("answered");
    let body: Value = r.json().expect("json");
    body["submissions"].as_array().expect("list").len()
}

fn serves_the_core_datasets(kind: Db) {
    let m = miniatures();
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "core");
    let server = start(
        &dir.path().join("data"),
        &m.core,
        &db,
        &["--no-demo", "--submissions-per-window", "0"],
    );
    let base = server.base.clone();

    let listed: Value = client()
        .get(format!("{base}/api/v1/datasets"))
        .send()
        .expect("answered")
        .json()
        .expect("json");
    let mut names: Vec<&str> = listed["datasets"]
        .as_array()
        .expect("list")
        .iter()
        .map(|d| d["name"].as_str().expect("name"))
        .collect();
    names.sort();
    let mut core = CORE.to_vec();
    core.sort();
    assert_eq!(names, core, "{kind:?}");
    let page = client()
        .get(format!("{base}/datasets"))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    for display in ["LM-O", "T-LESS", "TUD-L", "IC-BIN", "ITODD", "HB", "YCB-V"] {
        assert!(page.contains(&format!(">{display}</a>")), "{display}");
    }

    // No dataset field: the file name says it; the service scores it as the plain layout.
    let tless_file = m.result_for("tless");
    let r = upload_files(
        &server,
        &[("method", "named"), ("protocol", "bop19")],
        std::slice::from_ref(&tless_file),
    );
    assert_eq!(r.status(), 202, "{kind:?}");
    let body: Value = r.json().expect("json");
    assert_eq!(body["submission"]["dataset"], "tless");
    assert_eq!(body["submissions"].as_array().expect("list").len(), 1);
    let done = wait_done(
        &base,
        body["id"].as_i64().expect("id"),
        Duration::from_secs(60),
    );
    assert_eq!(
        done["scores"]["bop19"]["bop19_average_recall"],
        m.expected("tless", "bop19")["bop19_average_recall"]
    );
    let page = client()
        .get(format!("{base}/submissions/{}", body["id"]))
        .send()
        .expect("answered")
        .text()
        .expect("page");
    assert!(page.contains(" on T-LESS</h1>"), "{page}");

    // A name that contradicts the field.
    let r = upload_files(
        &server,
        &[("method", "named"), ("dataset", "lmo")],
        &[tless_file],
    );
    assert_eq!(r.status(), 422);
    let text = r.text().expect("body");
    assert!(
        text.contains(
            "noisy_tless-test.csv is named for dataset `tless`, but the field `dataset` says `lmo`"
        ),
        "{text}"
    );
    let before = submissions_count(&server);
    assert_eq!(before, 1);

    // Seven files, one bad: nothing is submitted, and every problem names its file and line.
    let mut files: Vec<PathBuf> = CORE.iter().map(|n| m.result_for(n)).collect();
    let good_icbin = std::fs::read_to_string(&files[3]).expect("read");
    let bad = m.results.join("bad_icbin-test.csv");
    let mut lines: Vec<&str> = good_icbin.lines().collect();
    lines[2] = "1,0,1,0.5,1 0 0 0 1 0 0 0 1,0 0 500";
    std::fs::write(&bad, lines.join("\n") + "\n").expect("write");
    files[3] = bad;
    let r = upload_files(&server, &[("method", "all-seven")], &files);
    assert_eq!(r.status(), 422, "{kind:?}");
    let body: Value = r.json().expect("json");
    assert!(
        body["error"]
            .as_str()
            .expect("error")
            .contains("1 of 7 files are refused"),
        "{body}"
    );
    let problems = body["problems"].as_array().expect("problems");
    assert!(
        problems.iter().any(|p| p["file"] == "bad_icbin-test.csv"
            && p["line"] == 3
            && p["message"]
                .as_str()
                .expect("message")
                .starts_with("bad_icbin-test.csv: line 3")),
        "{body}"
    );
    assert_eq!(submissions_count(&server), before);

    // The seven good ones: seven submissions of one method.
    files[3] = m.result_for("icbin");
    let r = upload_files(&server, &[("method", "all-seven")], &files);
    assert_eq!(r.status(), 202, "{kind:?}");
    let made = seven_of_one_method(r);
    assert_eq!(submissions_count(&server), before + 7);
    assert_scored_as_plain(&base, &m, &made, &[("bop19", "bop19_average_recall")]);
}
both_databases!(serves_the_core_datasets);

/// A fair-use limit met part-way through an upload of several files stores none of them:
/// limit 3 per dataset, three submissions on IC-BIN already, then five files of which the
/// fourth is for IC-BIN.
fn a_limit_part_way_stores_nothing(kind: Db) {
    let m = miniatures();
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "partway");
    let data = dir.path().join("data");
    let server = start(
        &data,
        &m.core,
        &db,
        &["--no-demo", "--submissions-per-window", "3"],
    );
    let icbin = m.result_for("icbin");
    for method in ["first", "second", "third"] {
        let r = upload_files(&server, &[("method", method)], std::slice::from_ref(&icbin));
        assert_eq!(r.status(), 202, "{kind:?}");
    }
    let files: Vec<PathBuf> = ["lmo", "tless", "tudl", "icbin", "itodd"]
        .iter()
        .map(|n| m.result_for(n))
        .collect();
    let r = upload_files(&server, &[("method", "five")], &files);
    assert_eq!(r.status(), 429, "{kind:?}");
    let body: Value = r.json().expect("json");
    let error = body["error"].as_str().expect("error");
    assert!(
        error.contains("at most 3 submissions per dataset")
            && error.contains("noisy_icbin-test.csv")
            && error.contains("none of the 5 files was submitted"),
        "{error}"
    );
    assert_eq!(submissions_count(&server), 3, "{kind:?}");
    let methods = common::column(&db, &data, "SELECT name FROM methods ORDER BY name");
    assert_eq!(methods, ["first", "second", "third"], "{kind:?}");
}
both_databases!(a_limit_part_way_stores_nothing);

/// A zip archive of `entries` (name, content), Deflate-compressed as archivers do.
fn zip_of(entries: &[(String, Vec<u8>)]) -> Vec<u8> {
    use std::io::Write;
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in entries {
        w.start_file(name, options).expect("entry");
        w.write_all(bytes).expect("write");
    }
    w.finish().expect("zip").into_inner()
}

/// Uploads the zip `bytes` as `name` for `method`.
fn upload_zip(
    server: &common::Server,
    method: &str,
    name: &str,
    bytes: Vec<u8>,
) -> reqwest::blocking::Response {
    let part = multipart::Part::bytes(bytes)
        .file_name(name.to_string())
        .mime_str("application/zip")
        .expect("mime");
    let form = multipart::Form::new()
        .text("method", method.to_string())
        .text("visibility", "public")
        .part("file", part);
    client()
        .post(format!("{}/api/v1/submissions", server.base))
        .bearer_auth(&server.token)
        .multipart(form)
        .send()
        .expect("upload answered")
}

/// One zip of the seven core files makes seven submissions of one method, scored as the files
/// uploaded one by one; a zip with a malformed file, a zip bomb, too many entries, other
/// files or paths leaving the archive make none, and the answer names the entry.
fn zip_uploads(kind: Db) {
    let m = miniatures();
    let dir = tempfile::tempdir().expect("tmp");
    let db = TestDb::new(kind, "zips");
    let server = start(
        &dir.path().join("data"),
        &m.core,
        &db,
        &[
            "--no-demo",
            "--submissions-per-window",
            "0",
            "--max-upload-mb",
            "1",
        ],
    );
    let base = server.base.clone();
    // In a folder, as archivers make them, with macOS's resource forks beside.
    let mut entries: Vec<(String, Vec<u8>)> = CORE
        .iter()
        .map(|n| {
            let bytes = std::fs::read(m.result_for(n)).expect("read");
            (format!("results/noisy_{n}-test.csv"), bytes)
        })
        .collect();
    entries.push(("__MACOSX/results/._noisy_lmo-test.csv".into(), vec![0; 10]));

    // One malformed file: nothing is submitted, and the problem names the entry and line.
    let mut bad = entries.clone();
    let text = String::from_utf8(bad[3].1.clone()).expect("utf-8");
    let mut lines: Vec<&str> = text.lines().collect();
    lines[2] = "1,0,1,0.5,1 0 0 0 1 0 0 0 1,0 0 500";
    bad[3] = (
        "results/bad_icbin-test.csv".into(),
        (lines.join("\n") + "\n").into_bytes(),
    );
    let r = upload_zip(&server, "zipped", "all.zip", zip_of(&bad));
    assert_eq!(r.status(), 422, "{kind:?}");
    let body: Value = r.json().expect("json");
    assert!(
        body["error"]
            .as_str()
            .expect("error")
            .contains("1 of 7 files are refused"),
        "{body}"
    );
    assert!(
        body["problems"]
            .as_array()
            .expect("problems")
            .iter()
            .any(|p| p["file"] == "bad_icbin-test.csv"
                && p["line"] == 3
                && p["message"]
                    .as_str()
                    .expect("message")
                    .starts_with("bad_icbin-test.csv: line 3")),
        "{body}"
    );
    assert_eq!(submissions_count(&server), 0);

    // A bomb: 64 MiB of one repeated line inflate from a few hundred KiB; the 1 MiB upload
    // limit holds for what comes out, whatever the headers say.
    let line = b"1,0,1,0.5,1 0 0 0 1 0 0 0 1,0 0 500,1\n";
    let bomb: Vec<u8> = line.iter().copied().cycle().take(64 << 20).collect();
    let bomb = zip_of(&[("bomb_lmo-test.csv".into(), bomb)]);
    assert!(bomb.len() < 1 << 20, "{}", bomb.len());
    let r = upload_zip(&server, "zipped", "bomb.zip", bomb);
    assert_eq!(r.status(), 422, "{kind:?}");
    let body: Value = r.json().expect("json");
    let error = body["error"].as_str().expect("error");
    assert!(
        error.contains("bomb.zip: unpacks to more than 1048576 bytes, the upload limit")
            && error.contains("bomb_lmo-test.csv"),
        "{error}"
    );

    // Too many entries, refused before any is read.
    let many: Vec<(String, Vec<u8>)> = (0..100)
        .map(|i| (format!("e{i}_lmo-test.csv"), Vec::new()))
        .collect();
    let r = upload_zip(&server, "zipped", "many.zip", zip_of(&many));
    assert_eq!(r.status(), 422, "{kind:?}");
    let body: Value = r.json().expect("json");
    assert!(
        body["error"]
            .as_str()
            .expect("error")
            .contains("many.zip: 100 entries, more than the 64"),
        "{body}"
    );

    // Other files and paths leaving the archive are named.
    let mut odd = entries.clone();
    odd.push(("results/readme.txt".into(), b"hello".to_vec()));
    odd.push(("../noisy_lmo-test.csv".into(), b"x".to_vec()));
    odd.push(("inner.zip".into(), zip_of(&entries[..1])));
    let r = upload_zip(&server, "zipped", "odd.zip", zip_of(&odd));
    assert_eq!(r.status(), 422, "{kind:?}");
    let body: Value = r.json().expect("json");
    let error = body["error"].as_str().expect("error");
    for named in [
        "odd.zip: 3 entries are refused",
        "entry results/readme.txt is not a result file",
        "entry ../noisy_lmo-test.csv has a path that leaves the archive",
        "entry inner.zip is not a result file",
    ] {
        assert!(error.contains(named), "{named}: {error}");
    }
    let r = upload_zip(&server, "zipped", "garbage.zip", b"not a zip".to_vec());
    assert_eq!(r.status(), 422, "{kind:?}");
    assert_eq!(submissions_count(&server), 0, "{kind:?}");

    // The seven good ones: seven submissions of one method, scored as plain uploads.
    let r = upload_zip(&server, "zipped", "all.zip", zip_of(&entries));
    assert_eq!(r.status(), 202, "{kind:?}");
    let made = seven_of_one_method(r);
    assert_eq!(made[0]["submission"]["file_name"], "noisy_lmo-test.csv");
    assert_eq!(submissions_count(&server), 7);
    assert_scored_as_plain(
        &base,
        &m,
        &made,
        &[("bop19", "bop19_average_recall"), ("eccv18", "recall")],
    );
}
both_databases!(zip_uploads);
