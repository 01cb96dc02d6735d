//! HOT3D's fisheye cameras project as bop_toolkit projects them: the values in
//! `tests/fixtures/fisheye/mspd.json` were computed with the toolkit's `pose_error_htt` and the
//! Hand Tracking Toolkit (`generate.py` beside them), and poseboard's projection and MSPD must
//! equal them to 1e-6 px.

use std::path::Path;

use evaluator::fisheye::Fisheye624;
use evaluator::math::{Pose, Pt3};
use evaluator::pose_error::mspd_fisheye;
use serde_json::Value;

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../tests/fixtures/fisheye/mspd.json"
);

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("an array")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

fn pose(r: &Value, t: &Value) -> Pose {
    let (r, t) = (numbers(r), numbers(t));
    Pose::from_row_major(&r.try_into().unwrap(), &t.try_into().unwrap())
}

#[test]
fn projection_and_mspd_equal_the_toolkits() {
    let fixture: Value =
        serde_json::from_slice(&std::fs::read(Path::new(FIXTURE)).unwrap()).unwrap();
    let pts: Vec<Pt3> = fixture["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let p = numbers(p);
            Pt3::new(p[0], p[1], p[2])
        })
        .collect();
    let syms: Vec<Pose> = fixture["syms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| pose(&s["R"], &s["t"]))
        .collect();
    let cases = fixture["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 10);
    let mut scratch = Vec::new();
    for (n, case) in cases.iter().enumerate() {
        let model = &fixture["cameras"][case["camera"].as_str().unwrap()];
        let cam = Fisheye624::from_projection(
            model["projection_model_type"].as_str().unwrap(),
            &numbers(&model["projection_params"]),
        )
        .unwrap();
        let est = pose(&case["R_est"], &case["t_est"]);
        let gt = pose(&case["R_gt"], &case["t_gt"]);
        for (p, expected) in pts.iter().zip(case["proj_est"].as_array().unwrap()) {
            let [u, v] = cam.project(&est.transform(p));
            let expected = numbers(expected);
            assert!(
                (u - expected[0]).abs() < 1e-6 && (v - expected[1]).abs() < 1e-6,
                "case {n}: ({u}, {v}) != {expected:?}"
            );
        }
        let e = mspd_fisheye(&est, &gt, &cam, &pts, &syms, &mut scratch);
        let expected = case["mspd"].as_f64().unwrap();
        assert!((e - expected).abs() < 1e-6, "case {n}: {e} != {expected}");
    }
}
