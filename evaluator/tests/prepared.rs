//! Prepared datasets: every score with and without the prepared form is the same to the bit, on
//! every reference result file under both protocols, and a stale, foreign or damaged prepared
//! form is never scored from (it is refused, the image is computed from the dataset, and
//! `prepare` rebuilds it).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use evaluator::content_hash::content_hash;
use evaluator::pipeline::Evaluation;
use evaluator::prepared::file::{PreparedImage, Stamp, evaluator_version};
use evaluator::prepared::{Outcome, Prepared, Unusable, prepare};
use evaluator::protocol::Protocol;
use evaluator::{Dataset, NoProgress, evaluate, evaluate_prepared, results};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

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

/// A copy of the reference dataset (tests edit it) and a folder for its prepared form.
struct Setup {
    _dir: tempfile::TempDir,
    dataset: Dataset,
    hash: String,
    prepared: PathBuf,
}

fn setup() -> Setup {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("synthA");
    copy_dir(&fixtures().join("dataset"), &root);
    let dataset = Dataset::load(&root).unwrap();
    let hash = content_hash(&dataset).unwrap();
    let prepared = dir.path().join("cache");
    Setup {
        _dir: dir,
        dataset,
        hash,
        prepared,
    }
}

fn prepare_now(s: &Setup) -> Outcome {
    prepare(
        &s.dataset,
        &s.hash,
        &s.prepared,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .unwrap()
    .outcome
}

fn result_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(fixtures().join("results"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    files
}

fn run(ds: &Dataset, file: &Path, protocol: &Protocol, prepared: Option<&Prepared>) -> Evaluation {
    let res = results::load_results(file).unwrap();
    let cancel = AtomicBool::new(false);
    match prepared {
        Some(p) => evaluate_prepared(ds, &res, protocol, Some(p), &NoProgress, &cancel),
        None => evaluate(ds, &res, protocol, &NoProgress, &cancel),
    }
    .unwrap()
}

/// Every per-estimate error to the bit, and the whole report.
fn assert_identical(a: &Evaluation, b: &Evaluation, what: &str) {
    assert_eq!(a.errors.len(), b.errors.len(), "{what}");
    for (x, y) in a.errors.iter().zip(&b.errors) {
        assert_eq!(
            (x.scene_id, x.im_id, x.obj_id, x.est_id, &x.gt_ids),
            (y.scene_id, y.im_id, y.obj_id, y.est_id, &y.gt_ids),
            "{what}"
        );
        let bits = |e: &Vec<Vec<f64>>| -> Vec<Vec<u64>> {
            e.iter()
                .map(|c| c.iter().map(|v| v.to_bits()).collect())
                .collect()
        };
        assert_eq!(bits(&x.errors), bits(&y.errors), "{what}: {x:?}");
    }
    assert_eq!(
        serde_json::to_string(&a.report).unwrap(),
        serde_json::to_string(&b.report).unwrap(),
        "{what}"
    );
}

#[test]
fn every_reference_score_is_bit_identical_with_the_prepared_form() {
    let s = setup();
    assert_eq!(prepare_now(&s), Outcome::Created);
    let prepared = Prepared::open(&s.prepared, &s.hash).unwrap();
    let mut vsd_pairs = 0;
    for file in result_files() {
        for protocol in [Protocol::eccv18(), Protocol::bop19()] {
            let plain = run(&s.dataset, &file, &protocol, None);
            let fast = run(&s.dataset, &file, &protocol, Some(&prepared));
            let what = format!("{} {}", file.display(), protocol.name.as_str());
            assert_identical(&plain, &fast, &what);
            vsd_pairs += fast.errors.iter().filter(|e| e.errors[0][0] < 1.0).count();
        }
    }
    assert!(vsd_pairs > 100, "the files exercise VSD: {vsd_pairs}");
    assert_eq!(prepared.damaged(), Vec::<String>::new());
}

#[test]
fn the_prepared_form_replaces_the_depth_images() {
    let s = setup();
    prepare_now(&s);
    let prepared = Prepared::open(&s.prepared, &s.hash).unwrap();
    let file = fixtures().join("results/noisemedium_synthA-test.csv");
    let before = run(&s.dataset, &file, &Protocol::bop19(), None);
    // With the depth images gone, only the prepared form can give the same scores.
    for scene in ["000001", "000002"] {
        std::fs::remove_dir_all(s.dataset.root.join("test").join(scene).join("depth")).unwrap();
    }
    let after = run(&s.dataset, &file, &Protocol::bop19(), Some(&prepared));
    assert_identical(&before, &after, "without depth images");
    let res = results::load_results(&file).unwrap();
    let cancel = AtomicBool::new(false);
    assert!(evaluate(&s.dataset, &res, &Protocol::bop19(), &NoProgress, &cancel).is_err());
}

#[test]
fn a_current_form_is_kept_and_a_stale_one_is_refused_and_rebuilt() {
    let s = setup();
    assert_eq!(
        Prepared::open(&s.prepared, &s.hash).unwrap_err(),
        Unusable::Missing
    );
    assert_eq!(prepare_now(&s), Outcome::Created);
    assert_eq!(prepare_now(&s), Outcome::Current);

    let manifest = s.prepared.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let old = text.replace(&evaluator_version(), "0.0.1 format 0");
    assert_ne!(old, text);
    std::fs::write(&manifest, old).unwrap();
    let refused = Prepared::open(&s.prepared, &s.hash).unwrap_err();
    assert!(matches!(refused, Unusable::Stale { .. }), "{refused}");
    assert!(refused.to_string().contains("made by evaluator 0.0.1"));
    assert_eq!(prepare_now(&s), Outcome::Rebuilt(refused));
    Prepared::open(&s.prepared, &s.hash).unwrap();

    std::fs::write(&manifest, "{ not json").unwrap();
    assert!(matches!(
        Prepared::open(&s.prepared, &s.hash).unwrap_err(),
        Unusable::Unreadable(_)
    ));
}

#[test]
fn a_form_made_for_other_content_is_refused_and_rebuilt() {
    let mut s = setup();
    prepare_now(&s);
    // The dataset changes: a ground-truth pose moves.
    let gt_path = s.dataset.root.join("test/000001/scene_gt.json");
    let text = std::fs::read_to_string(&gt_path).unwrap();
    let mut gt: serde_json::Value = serde_json::from_str(&text).unwrap();
    let t = &mut gt["2"][0]["cam_t_m2c"][0];
    *t = serde_json::json!(t.as_f64().unwrap() + 1.5);
    std::fs::write(&gt_path, serde_json::to_string(&gt).unwrap()).unwrap();
    s.dataset = Dataset::load(&s.dataset.root).unwrap();
    let old_hash = std::mem::replace(&mut s.hash, content_hash(&s.dataset).unwrap());
    assert_ne!(old_hash, s.hash);

    let refused = Prepared::open(&s.prepared, &s.hash).unwrap_err();
    assert_eq!(
        refused,
        Unusable::Foreign {
            content_hash: old_hash.clone()
        }
    );
    // Each file also names its content: one copied from the old form is refused on its own.
    let one = s.prepared.join("000001/000002.pbprep");
    let old_file = std::fs::read(&one).unwrap();
    assert_eq!(prepare_now(&s), Outcome::Rebuilt(refused));
    let prepared = Prepared::open(&s.prepared, &s.hash).unwrap();
    std::fs::write(&one, &old_file).unwrap();
    let file = fixtures().join("results/noisemedium_synthA-test.csv");
    let plain = run(&s.dataset, &file, &Protocol::bop19(), None);
    let fast = run(&s.dataset, &file, &Protocol::bop19(), Some(&prepared));
    assert_identical(&plain, &fast, "one foreign file");
    let damaged = prepared.damaged();
    assert_eq!(damaged.len(), 1, "{damaged:?}");
    assert!(damaged[0].contains(&format!("made for dataset content {old_hash}")));
}

#[test]
fn a_truncated_file_is_never_scored_from_and_is_rebuilt() {
    let s = setup();
    prepare_now(&s);
    let prepared = Prepared::open(&s.prepared, &s.hash).unwrap();
    let file = fixtures().join("results/noisemedium_synthA-test.csv");
    let plain = run(&s.dataset, &file, &Protocol::eccv18(), None);

    let one = s.prepared.join("000002/000003.pbprep");
    let bytes = std::fs::read(&one).unwrap();
    std::fs::write(&one, &bytes[..bytes.len() - 100]).unwrap();
    let fast = run(&s.dataset, &file, &Protocol::eccv18(), Some(&prepared));
    assert_identical(&plain, &fast, "one truncated file");
    let damaged = prepared.damaged();
    assert_eq!(damaged.len(), 1, "{damaged:?}");
    assert!(
        damaged[0].contains("000003.pbprep: truncated"),
        "{damaged:?}"
    );

    // The second half of the file damaged (its ground-truth renders follow the depth bands): an
    // evaluation reads only the blocks it needs, and each block's checksum refuses it.
    let mut flipped = bytes.clone();
    let mid = bytes.len() / 2;
    for b in &mut flipped[mid..] {
        *b ^= 0x01;
    }
    std::fs::write(&one, &flipped).unwrap();
    let again = Prepared::open(&s.prepared, &s.hash).unwrap();
    let fast = run(&s.dataset, &file, &Protocol::eccv18(), Some(&again));
    assert_identical(&plain, &fast, "one damaged file");
    assert!(again.damaged()[0].contains("checksum mismatch"));

    let outcome = prepare_now(&s);
    let Outcome::Repaired { files } = outcome else {
        panic!("{outcome:?}")
    };
    assert_eq!(files.len(), 1);
    assert_eq!(std::fs::read(&one).unwrap(), bytes, "rebuilt as it was");
    assert_eq!(prepare_now(&s), Outcome::Current);
}

#[test]
fn a_form_made_by_other_code_of_the_same_version_is_stale() {
    let s = setup();
    prepare_now(&s);
    // The same version number and format, built from other source (a renderer changed between
    // releases): the manifest and every file name that evaluator.
    let this = evaluator_version();
    let (version, fingerprint) = this.rsplit_once(" source ").unwrap();
    assert_eq!(fingerprint.len(), 16, "{this}");
    let other = format!("{version} source {}", "0".repeat(16));
    let manifest = s.prepared.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(&manifest, text.replace(&this, &other)).unwrap();
    let refused = Prepared::open(&s.prepared, &s.hash).unwrap_err();
    assert_eq!(
        refused,
        Unusable::Stale {
            evaluator: other.clone()
        }
    );
    // A file of that evaluator copied into a current form is refused on its own.
    assert_eq!(prepare_now(&s), Outcome::Rebuilt(refused));
    let path = s.prepared.join("000001/000000.pbprep");
    let stamp = Stamp {
        content_hash: &s.hash,
        evaluator: &this,
        scene_id: 1,
        im_id: 0,
    };
    let data = PreparedImage::open(&path, &stamp)
        .unwrap()
        .decode()
        .unwrap();
    let foreign = Stamp {
        evaluator: &other,
        ..stamp
    };
    std::fs::write(&path, data.encode(&foreign)).unwrap();
    let error = PreparedImage::open(&path, &stamp).unwrap_err();
    assert!(error.contains(&other), "{error}");
}
