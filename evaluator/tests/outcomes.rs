//! The outcomes of single targets are the scores' own verdicts: on the reference fixtures, the
//! correct ones over all of them are the recall the report gives, under each protocol and at
//! each error column and threshold, overall and per object.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use evaluator::outcomes::{Criterion, TargetOutcome, outcomes};
use evaluator::pipeline::Evaluation;
use evaluator::protocol::{Protocol, columns};
use evaluator::report::score_signature;
use evaluator::{Dataset, NoProgress, evaluate, results};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

fn dataset() -> &'static Dataset {
    static DS: OnceLock<Dataset> = OnceLock::new();
    DS.get_or_init(|| Dataset::load(&fixtures().join("dataset")).expect("reference dataset loads"))
}

fn run(name: &str, protocol: &Protocol) -> Evaluation {
    let path = fixtures().join("results").join(format!("{name}.csv"));
    let results = results::load_results(&path).expect("reference results parse");
    evaluate(
        dataset(),
        &results,
        protocol,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .expect("evaluation succeeds")
}

fn recall(list: &[TargetOutcome]) -> f64 {
    list.iter().filter(|o| o.correct).count() as f64 / list.len() as f64
}

#[test]
fn eccv18_outcomes_add_up_to_the_recall_overall_and_per_object() {
    let protocol = Protocol::eccv18();
    let criterion = Criterion::default_for(&protocol).expect("a default");
    assert_eq!(
        (criterion.error.as_str(), criterion.tau, criterion.threshold),
        ("vsd", Some(20.0), 0.3),
        "the paper's tau and theta"
    );
    // `multi` has three estimates per instance (only the top one counts), `missing` targets
    // without any, `random` mostly misses.
    for name in [
        "multi_synthA-test",
        "missing_synthA-test",
        "noisemedium_synthA-test",
        "random_synthA-test",
    ] {
        let ev = run(name, &protocol);
        let scores = ev.report.localization.as_ref().expect("eccv18 scores");
        let list = outcomes(dataset(), &protocol, &ev.errors, &criterion);
        assert_eq!(list.len(), scores.targets_count, "{name}: targets");
        let correct = list.iter().filter(|o| o.correct).count();
        assert_eq!(correct, scores.tp_count, "{name}: true positives");
        assert_eq!(recall(&list), scores.recall, "{name}: recall");
        let mut per_obj: BTreeMap<u32, Vec<TargetOutcome>> = BTreeMap::new();
        for o in &list {
            per_obj.entry(o.obj_id).or_default().push(o.clone());
        }
        for (obj, l) in &per_obj {
            assert_eq!(recall(l), scores.obj_recalls[obj], "{name}: object {obj}");
        }
        for o in &list {
            assert_eq!(o.correct, o.est_id.is_some(), "{name}: {o:?}");
            if o.correct {
                let e = o.error.expect("a matched instance has its error");
                assert!(e < criterion.threshold, "{name}: {o:?}");
            }
            assert!(o.visib_fract >= protocol.visib_gt_min, "{name}: {o:?}");
        }
    }
}

#[test]
fn bop19_outcomes_give_the_recall_at_every_column_and_threshold() {
    let protocol = Protocol::bop19();
    let ev = run("noisemedium_synthA-test", &protocol);
    let cols = columns(&protocol);
    for col in &cols {
        let spec = &protocol.errors[col.error];
        for &th in &spec.thresholds {
            let criterion = Criterion::choose(&protocol, Some(spec.kind.name()), col.tau, Some(th))
                .expect("a protocol setting");
            let list = outcomes(dataset(), &protocol, &ev.errors, &criterion);
            let expected = ev.report.per_error_recall_per_threshold[&col.signature]
                [&score_signature(th, protocol.visib_gt_min)];
            assert_eq!(recall(&list), expected, "{} at {th}", col.signature);
        }
    }
    // The default is VSD's central setting; 0.3 written plainly is bop19's 0.05 + 5 * 0.05.
    let default = Criterion::default_for(&protocol).expect("a default");
    assert_eq!(default.error, "vsd");
    let plain = Criterion::choose(&protocol, Some("vsd"), Some(0.3), Some(0.3)).expect("0.3");
    assert_eq!(plain, default);
    let mspd = Criterion::choose(&protocol, Some("mspd"), None, None).expect("mspd");
    assert_eq!(mspd.threshold, 30.0, "MSPD at the middle of its thresholds");
    assert!(Criterion::choose(&protocol, Some("add"), None, None).is_err());
    assert!(Criterion::choose(&protocol, Some("vsd"), Some(0.33), None).is_err());
    assert!(Criterion::choose(&protocol, Some("mssd"), Some(0.3), None).is_err());
    assert!(Criterion::choose(&protocol, None, None, Some(-1.0)).is_err());
}
