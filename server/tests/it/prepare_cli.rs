//! `poseboard dataset prepare` and `poseboard eval` with a prepared dataset, run as a user runs
//! them: the scores are the same with and without it, and one that cannot be used is named on
//! stderr and left alone.

use std::path::Path;

use crate::common::{eval_report, fixtures, poseboard};

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

#[test]
fn eval_reads_a_prepared_dataset_and_gives_the_same_report() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = dir.path().join("synthA");
    copy_dir(&fixtures().join("dataset"), &dataset);
    let ds = dataset.to_str().unwrap();
    let results = fixtures().join("results/noisemedium_synthA-test.csv");

    let (plain_output, plain) = eval_report(&dataset, &results, &["--protocol", "bop19"]);
    let out = poseboard(&["dataset", "prepare", ds, "--threads", "2"]);
    assert!(out.status.success(), "{out:?}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("synthA: 8 images"), "{stdout}");
    assert!(stdout.ends_with(": prepared\n"), "{stdout}");
    assert!(dataset.join("poseboard_prepared/manifest.json").is_file());
    // The first preparation keeps the file digests for `eval`.
    let cache = dataset
        .join("poseboard_prepared")
        .join(evaluator::content_hash::CACHE_FILE);
    assert!(cache.is_file());

    let (output, prepared) = eval_report(&dataset, &results, &["--protocol", "bop19"]);
    assert_eq!(prepared, plain);
    // Nothing said about the prepared form: the same warnings as without one.
    assert_eq!(output.stderr, plain_output.stderr);

    // A damaged file: named, its image computed from the dataset, the report unchanged.
    let one = dataset.join("poseboard_prepared/000001/000001.pbprep");
    let bytes = std::fs::read(&one).unwrap();
    std::fs::write(&one, &bytes[..bytes.len() / 2]).unwrap();
    let (output, damaged) = eval_report(&dataset, &results, &["--protocol", "bop19"]);
    assert_eq!(damaged, plain);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("000001.pbprep: truncated"), "{stderr}");
    assert!(stderr.contains("`poseboard dataset prepare"), "{stderr}");

    let out = poseboard(&["dataset", "prepare", ds]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("rebuilt 1 damaged or missing file(s)"),
        "{stdout}"
    );
    assert_eq!(std::fs::read(&one).unwrap(), bytes);

    // Another dataset content (a changed targets file): the whole form is refused.
    let targets = dataset.join("test_targets_bop19.json");
    let mut list: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&targets).unwrap()).unwrap();
    list.as_array_mut().unwrap().pop();
    std::fs::write(&targets, list.to_string()).unwrap();
    let (output, _) = eval_report(&dataset, &results, &["--protocol", "bop19"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("prepared form not used, foreign"),
        "{stderr}"
    );
    let out = poseboard(&["dataset", "prepare", ds]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("rebuilt, the previous one was foreign"),
        "{stdout}"
    );
}

#[test]
fn a_prepared_form_named_elsewhere_is_used_and_unprepared_ignores_it() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let dataset = fixtures().join("dataset");
    let out = poseboard(&[
        "dataset",
        "prepare",
        dataset.to_str().unwrap(),
        "--out",
        cache.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{out:?}");
    let results = fixtures().join("results/noisesmall_synthA-test.csv");
    let (plain_output, plain) = eval_report(
        &dataset,
        &results,
        &["--protocol", "eccv18", "--unprepared"],
    );
    let (output, prepared) = eval_report(
        &dataset,
        &results,
        &[
            "--protocol",
            "eccv18",
            "--prepared",
            cache.to_str().unwrap(),
        ],
    );
    assert_eq!(prepared, plain);
    assert_eq!(output.stderr, plain_output.stderr);
    // The manifest of another evaluator version: stale, said, not used.
    let manifest = cache.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["evaluator"] = "0.0.1 format 0".into();
    std::fs::write(&manifest, json.to_string()).unwrap();
    let (output, stale) = eval_report(
        &dataset,
        &results,
        &[
            "--protocol",
            "eccv18",
            "--prepared",
            cache.to_str().unwrap(),
        ],
    );
    assert_eq!(stale, plain);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("prepared form not used, stale: made by evaluator 0.0.1"),
        "{stderr}"
    );
}
