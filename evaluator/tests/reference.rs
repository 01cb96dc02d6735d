//! Reproduces the scores and per-estimate errors that bop_toolkit (commit cea62d6) computed on
//! the reference dataset and result files in `tests/fixtures/reference` (see its README).
//!
//! Tolerances: recalls and counts exactly (they are ratios of small integers); average
//! recalls to 1e-6 (in practice they agree to the bit, numpy's summation order is reproduced);
//! MSSD, MSPD, ADD, ADI and AD to 1e-6 relative; VSD to 1e-12 (see `VSD_TOLERANCE`).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use evaluator::matching::EstimateErrors;
use evaluator::pipeline::Evaluation;
use evaluator::protocol::{ErrorKind, ErrorSpec, NTop, Protocol, ProtocolName};
use evaluator::visibility::VisibMode;
use evaluator::{Dataset, NoProgress, evaluate, results};
use serde_json::Value;

const RESULT_NAMES: [&str; 9] = [
    "extra_synthA-test",
    "gtexact_synthA-test",
    "missing_synthA-test",
    "multi_synthA-test",
    "noiselarge_synthA-test",
    "noisemedium_synthA-test",
    "noisesmall_synthA-test",
    "random_synthA-test",
    "symflip_synthA-test",
];

/// Per-estimate VSD values equal bop_toolkit's to the last bit: the renderer reproduces the
/// toolkit's llvmpipe rasterisation and 16-bit depth buffer (see `evaluator::render` and
/// `tests/vsd_agreement.rs`). The bound only absorbs summation-order noise; the test prints
/// the largest difference it sees.
const VSD_TOLERANCE: f64 = 1e-12;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

fn dataset() -> &'static Dataset {
    static DS: OnceLock<Dataset> = OnceLock::new();
    DS.get_or_init(|| Dataset::load(&fixtures().join("dataset")).expect("reference dataset loads"))
}

fn run(name: &str, protocol: &Protocol) -> Evaluation {
    let path = fixtures().join("results").join(format!("{name}.csv"));
    run_results(
        &results::load_results(&path).expect("reference results parse"),
        protocol,
    )
}

fn run_results(results: &results::Results, protocol: &Protocol) -> Evaluation {
    evaluate(
        dataset(),
        results,
        protocol,
        &NoProgress,
        &AtomicBool::new(false),
    )
    .expect("evaluation succeeds")
}

fn expected(name: &str, file: &str) -> Value {
    let path = fixtures().join("expected").join(name).join(file);
    read_json(&path)
}

/// Python's json writes infinity as a bare `Infinity`, which is not JSON.
fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text.replace("Infinity", "\"inf\"")).expect("expected JSON parses")
}

fn num(v: &Value) -> f64 {
    match v {
        Value::String(s) if s == "inf" => f64::INFINITY,
        v => v.as_f64().unwrap_or_else(|| panic!("not a number: {v}")),
    }
}

fn id_map(v: &Value) -> BTreeMap<u32, f64> {
    v.as_object()
        .expect("an object")
        .iter()
        .map(|(k, v)| (k.parse().expect("an id"), num(v)))
        .collect()
}

fn eccv18(mode: VisibMode) -> Protocol {
    let mut p = Protocol::eccv18();
    p.set_vsd(15.0, vec![20.0], false, mode, vec![0.3]);
    p
}

#[test]
fn eccv18_recalls_match_bop_toolkit_in_both_visibility_modes() {
    for (mode, file) in [
        (VisibMode::Bop19, "ecc18_bop19vis.json"),
        (VisibMode::Bop18, "ecc18_bop18vis.json"),
    ] {
        for name in RESULT_NAMES {
            let ev = run(name, &eccv18(mode));
            let exp = expected(name, file);
            let got = ev
                .report
                .localization
                .as_ref()
                .expect("eccv18 reports a recall");
            let ctx = format!("{name} {file}");
            assert_eq!(got.recall, num(&exp["recall"]), "{ctx}: recall");
            assert_eq!(
                got.tp_count as f64,
                num(&exp["tp_count"]),
                "{ctx}: tp_count"
            );
            assert_eq!(
                got.targets_count as f64,
                num(&exp["targets_count"]),
                "{ctx}: targets"
            );
            assert_eq!(
                got.gt_count as f64,
                num(&exp["gt_count"]),
                "{ctx}: gt_count"
            );
            assert_eq!(
                got.obj_recalls,
                id_map(&exp["obj_recalls"]),
                "{ctx}: obj_recalls"
            );
            assert_eq!(
                got.scene_recalls,
                id_map(&exp["scene_recalls"]),
                "{ctx}: scene_recalls"
            );
            assert_eq!(
                got.mean_obj_recall,
                num(&exp["mean_obj_recall"]),
                "{ctx}: mean_obj_recall"
            );
        }
    }
}

/// The recall-vs-visibility curve counts what the recall counts: bop_toolkit's targets (valid
/// instances, at most n_top per image and object) and its true positives, none of them less
/// visible than visib_gt_min.
#[test]
fn the_visibility_curve_counts_the_protocols_targets() {
    for name in RESULT_NAMES {
        let protocol = eccv18(VisibMode::Bop19);
        let ev = run(name, &protocol);
        let exp = expected(name, "ecc18_bop19vis.json");
        let bins = &ev.report.recall_vs_visib;
        assert_eq!(bins.len(), 10, "{name}");
        let instances: usize = bins.iter().map(|b| b.instances).sum();
        let matched: usize = bins.iter().map(|b| b.matched).sum();
        assert_eq!(
            instances as f64,
            num(&exp["targets_count"]),
            "{name}: targets"
        );
        assert_eq!(
            matched as f64,
            num(&exp["tp_count"]),
            "{name}: true positives"
        );
        for b in bins.iter().filter(|b| b.visib_to <= protocol.visib_gt_min) {
            assert_eq!(b.instances, 0, "{name}: a bin below visib_gt_min");
        }
    }
}

#[test]
fn bop19_average_recalls_match_bop_toolkit() {
    for name in RESULT_NAMES {
        let ev = run(name, &Protocol::bop19());
        let exp = expected(name, "bop19.json");
        let r = &ev.report;
        for (key, got) in [
            ("bop19_average_recall", r.bop19_average_recall),
            ("bop19_average_recall_vsd", r.bop19_average_recall_vsd),
            ("bop19_average_recall_mssd", r.bop19_average_recall_mssd),
            ("bop19_average_recall_mspd", r.bop19_average_recall_mspd),
            (
                "bop19_average_time_per_image",
                r.bop19_average_time_per_image,
            ),
        ] {
            let got = got.unwrap_or_else(|| panic!("{name}: {key} missing"));
            let want = num(&exp[key]);
            assert!((got - want).abs() <= 1e-6, "{name}: {key} {got} != {want}");
        }
        // Every recall behind the averages, exactly.
        let exp_per = exp["per_error_recall_per_threshold"]
            .as_object()
            .expect("per threshold");
        assert_eq!(
            exp_per.len(),
            r.per_error_recall_per_threshold.len(),
            "{name}"
        );
        for (sig, ths) in exp_per {
            let got = &r.per_error_recall_per_threshold[sig];
            for (th, want) in ths.as_object().expect("thresholds") {
                assert_eq!(got[th], num(want), "{name}: {sig} {th}");
            }
        }
    }
}

/// Errors keyed by (scene, image, object, est_id), then gt id.
type ErrorTable = HashMap<(u32, u32, u32, u32), BTreeMap<u32, f64>>;

fn expected_errors(dir: &Path) -> ErrorTable {
    let mut table = ErrorTable::new();
    for scene in ["000001", "000002"] {
        let path = dir.join(format!("errors_{scene}.json"));
        for e in read_json(&path).as_array().expect("a list") {
            let key = (
                num(&e["scene_id"]) as u32,
                num(&e["im_id"]) as u32,
                num(&e["obj_id"]) as u32,
                num(&e["est_id"]) as u32,
            );
            let errs = e["errors"]
                .as_object()
                .expect("errors")
                .iter()
                .map(|(g, v)| (g.parse().expect("gt id"), num(&v[0])))
                .collect();
            table.insert(key, errs);
        }
    }
    table
}

fn computed_errors(errors: &[EstimateErrors], column: usize) -> ErrorTable {
    errors
        .iter()
        .map(|e| {
            let key = (e.scene_id, e.im_id, e.obj_id, e.est_id);
            let errs = e
                .gt_ids
                .iter()
                .zip(&e.errors[column])
                .map(|(&g, &v)| (g, v))
                .collect();
            (key, errs)
        })
        .collect()
}

/// Compares two error tables with `close`, returning the largest absolute difference.
fn compare(
    ctx: &str,
    got: &ErrorTable,
    want: &ErrorTable,
    close: impl Fn(f64, f64) -> bool,
) -> f64 {
    assert_eq!(
        got.len(),
        want.len(),
        "{ctx}: number of evaluated estimates"
    );
    let mut worst = 0.0f64;
    for (key, w) in want {
        let g = got
            .get(key)
            .unwrap_or_else(|| panic!("{ctx}: estimate {key:?} not evaluated"));
        assert_eq!(
            g.keys().collect::<Vec<_>>(),
            w.keys().collect::<Vec<_>>(),
            "{ctx} {key:?}"
        );
        for (gt, &wv) in w {
            let gv = g[gt];
            assert!(
                close(gv, wv),
                "{ctx}: estimate {key:?} vs gt {gt}: {gv} != {wv}"
            );
            if gv.is_finite() && wv.is_finite() {
                worst = worst.max((gv - wv).abs());
            }
        }
    }
    worst
}

fn relative_close(a: f64, b: f64) -> bool {
    if a.is_infinite() || b.is_infinite() {
        return a == b;
    }
    (a - b).abs() <= 1e-6 * b.abs() + 1e-9
}

#[test]
fn per_estimate_errors_match_bop_toolkit() {
    let mut worst_vsd = 0.0f64;
    for name in RESULT_NAMES {
        let ev = run(name, &Protocol::bop19());
        let base = fixtures().join("expected").join(name).join("errors/bop19");
        for (c, col) in ev.columns.iter().enumerate() {
            let want = expected_errors(&base.join(&col.signature));
            let got = computed_errors(&ev.errors, c);
            let ctx = format!("{name} {}", col.signature);
            if col.tau.is_some() {
                let d = compare(&ctx, &got, &want, |a, b| (a - b).abs() <= VSD_TOLERANCE);
                worst_vsd = worst_vsd.max(d);
            } else {
                compare(&ctx, &got, &want, relative_close);
            }
        }
        for (mode, dir) in [
            (VisibMode::Bop19, "ecc18_bop19vis"),
            (VisibMode::Bop18, "ecc18_bop18vis"),
        ] {
            let ev = run(name, &eccv18(mode));
            let want = expected_errors(
                &fixtures()
                    .join("expected")
                    .join(name)
                    .join("errors")
                    .join(dir),
            );
            let got = computed_errors(&ev.errors, 0);
            let d = compare(&format!("{name} {dir}"), &got, &want, |a, b| {
                (a - b).abs() <= VSD_TOLERANCE
            });
            worst_vsd = worst_vsd.max(d);
        }
    }
    eprintln!("largest per-estimate VSD difference from bop_toolkit: {worst_vsd:.6}");
}

#[test]
fn add_adi_and_ad_match_bop_toolkit() {
    for name in ["noisemedium_synthA-test", "symflip_synthA-test"] {
        for (kind, dir) in [
            (ErrorKind::Ad, "ad"),
            (ErrorKind::Add, "add"),
            (ErrorKind::Adi, "adi"),
        ] {
            let protocol = Protocol {
                name: ProtocolName::Bop19,
                n_top: NTop::InstCount,
                visib_gt_min: -1.0,
                max_sym_disc_step: 0.01,
                errors: vec![ErrorSpec {
                    kind,
                    thresholds: vec![0.1],
                }],
                main_tau: 0.0,
                main_theta: 0.1,
            };
            let ev = run(name, &protocol);
            let base = fixtures()
                .join("expected")
                .join(name)
                .join("errors")
                .join(dir);
            let ctx = format!("{name} {dir}");
            compare(
                &ctx,
                &computed_errors(&ev.errors, 0),
                &expected_errors(&base),
                relative_close,
            );
            let got = ev.scores(dataset(), &protocol, 0, 0.1);
            let exp = read_json(&base.join("scores_th=0.100_min-visib=-1.000.json"));
            assert_eq!(got.recall, num(&exp["recall"]), "{ctx}");
            assert_eq!(got.tp_count as f64, num(&exp["tp_count"]), "{ctx}");
            assert_eq!(
                got.targets_count as f64,
                num(&exp["targets_count"]),
                "{ctx}"
            );
            assert_eq!(got.obj_recalls, id_map(&exp["obj_recalls"]), "{ctx}");
            assert_eq!(got.scene_recalls, id_map(&exp["scene_recalls"]), "{ctx}");
            assert_eq!(got.mean_obj_recall, num(&exp["mean_obj_recall"]), "{ctx}");
            assert_eq!(
                got.mean_scene_recall,
                num(&exp["mean_scene_recall"]),
                "{ctx}"
            );
        }
    }
}

#[test]
fn estimates_for_non_targets_are_ignored_and_reported() {
    let small = run("noisesmall_synthA-test", &Protocol::bop19());
    let extra = run("extra_synthA-test", &Protocol::bop19());
    assert_eq!(
        small.report.bop19_average_recall,
        extra.report.bop19_average_recall
    );
    // `extra` adds one estimate for each object absent from an image.
    assert_eq!(
        extra.report.estimates_ignored,
        small.report.estimates_ignored + 3
    );
    assert!(
        extra
            .report
            .warnings
            .iter()
            .any(|w| w.contains("not test targets"))
    );
}

#[test]
fn a_file_with_no_usable_estimate_scores_zero_with_a_warning() {
    let csv = "scene_id,im_id,obj_id,score,R,t,time\n9,9,1,0.5,1 0 0 0 1 0 0 0 1,0 0 500,0.1\n";
    let results = results::parse_results(csv.as_bytes()).expect("valid file");
    for protocol in [Protocol::eccv18(), Protocol::bop19()] {
        let ev = evaluate(
            dataset(),
            &results,
            &protocol,
            &NoProgress,
            &AtomicBool::new(false),
        )
        .expect("evaluation succeeds");
        assert_eq!(ev.report.headline(), 0.0);
        assert_eq!(ev.report.estimates_ignored, 1);
        assert!(
            ev.report
                .warnings
                .iter()
                .any(|w| w.contains("every score is 0"))
        );
    }
}

#[test]
fn cancelling_stops_the_evaluation() {
    let path = fixtures().join("results/noisesmall_synthA-test.csv");
    let results = results::load_results(&path).expect("reference results parse");
    let cancelled = AtomicBool::new(true);
    let outcome = evaluate(
        dataset(),
        &results,
        &Protocol::bop19(),
        &NoProgress,
        &cancelled,
    );
    assert!(matches!(outcome, Err(evaluator::Error::Cancelled)));
}

/// The service stores reports as JSON and reads them back: nothing may be lost on the way
/// (the flattened eccv18 scores included).
#[test]
fn reports_read_back_from_json_unchanged() {
    for protocol in [
        Protocol::named(ProtocolName::Eccv18),
        Protocol::named(ProtocolName::Bop19),
    ] {
        let report = run("noisemedium_synthA-test", &protocol).report;
        let json = serde_json::to_string(&report).expect("serialises");
        let back: evaluator::Report = serde_json::from_str(&json).expect("deserialises");
        assert_eq!(back, report, "{:?}", protocol.name);
    }
}

#[test]
fn bop19_reports_minus_one_as_the_average_time_when_the_file_gives_none() {
    // Two estimates of the reference file's first target, with times -1 (not measured).
    let csv = "scene_id,im_id,obj_id,score,R,t,time\n\
               1,0,1,0.5,1 0 0 0 1 0 0 0 1,0 0 500,-1\n\
               1,0,3,0.4,1 0 0 0 1 0 0 0 1,0 0 600,-1\n";
    let results = results::parse_results(csv.as_bytes()).expect("valid file");
    let bop19 = run_results(&results, &Protocol::bop19()).report;
    assert_eq!(bop19.bop19_average_time_per_image, Some(-1.0));
    let json = serde_json::to_value(&bop19).expect("report serialises");
    assert_eq!(
        json["bop19_average_time_per_image"],
        serde_json::json!(-1.0)
    );
    // bop_toolkit's ECCV'18 scores have no such key.
    let eccv18 = serde_json::to_value(run_results(&results, &Protocol::eccv18()).report)
        .expect("report serialises");
    assert!(eccv18.get("bop19_average_time_per_image").is_none());
}

/// Bootstrap intervals (`evaluator::bootstrap`) on every reference file under both protocols:
/// the same seed gives the same bounds to the bit, unit weights give the headline itself to the
/// bit, and the interval contains the headline.
#[test]
fn bootstrap_intervals_are_reproducible_and_contain_the_score() {
    use evaluator::bootstrap::{REPLICATES, dataset_seed};
    let seed = dataset_seed(&dataset().name);
    for protocol in [Protocol::bop19(), Protocol::eccv18()] {
        for name in RESULT_NAMES {
            let mut ev = run(name, &protocol);
            let ctx = format!("{name} {}", protocol.name.as_str());
            let headline = ev.report.headline();
            let ones = vec![1; ev.counts.images()];
            assert_eq!(
                ev.counts.weighted_score(&ones).map(f64::to_bits),
                Some(headline.to_bits()),
                "{ctx}: unit weights"
            );
            let a = ev.bootstrap(seed, REPLICATES).expect("replicates");
            let b = ev.bootstrap(seed, REPLICATES).expect("replicates");
            assert_eq!(a.replicates.len(), REPLICATES);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a.replicates), bits(&b.replicates), "{ctx}");
            let [lo, hi] = a.ci95();
            assert_eq!(
                ev.report.bootstrap.as_ref().map(|s| s.ci95),
                Some([lo, hi]),
                "{ctx}: recorded in the report"
            );
            assert!(
                lo <= headline && headline <= hi,
                "{ctx}: {lo} {headline} {hi}"
            );
            // Another seed draws other images.
            let c = ev.bootstrap(seed ^ 1, REPLICATES).expect("replicates");
            assert!(
                lo == hi || c.replicates != a.replicates,
                "{ctx}: seed ignored"
            );
        }
    }
}
