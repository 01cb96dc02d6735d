//! How closely per-estimate VSD follows bop_toolkit, value by value, and the renderer
//! properties that agreement rests on, checked on the reference data.
//!
//! Every VSD value of the reference files' bop19 error files (9 files, 10 taus, every
//! estimate against every ground truth of its object: 3850 values) is compared with
//! bop_toolkit's, and counted as equal when |d| < 1e-12. All 3850 are equal. How the count got
//! there, as causes of the values that differed:
//! - 3403 (88.4%) with an exact float64 rasteriser: pixel centres within rounding of an edge
//!   decided differently from GL, which snaps window coordinates to 1/256 pixel;
//! - 3839 (99.7%) with llvmpipe's vertex path, snap and tie rule, and a 24-bit depth buffer;
//!   the 11 left were single taus, a pixel whose |dist_gt - dist_est| lay within 1e-3 mm of
//!   tau: depth resolution, because vispy's depth render buffer is GL_DEPTH_COMPONENT16;
//! - 3850 (100%) with the 16-bit buffer quantised and read back as llvmpipe and Mesa do.
//!
//! What could still make a value differ on other data (not seen here): triangles the toolkit's
//! OpenGL clips geometrically (a vertex rounded beyond the near or far plane, or a pose a few
//! millimetres from the camera), see `evaluator::render`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use evaluator::protocol::Protocol;
use evaluator::render::{Model, PixelBox, Renderer, screen_box};
use evaluator::{Dataset, NoProgress, evaluate, results};
use serde_json::Value;

const RESULT_NAMES: [&str; 9] = [
    "extra",
    "gtexact",
    "missing",
    "multi",
    "noiselarge",
    "noisemedium",
    "noisesmall",
    "random",
    "symflip",
];

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

fn dataset() -> &'static Dataset {
    static DS: OnceLock<Dataset> = OnceLock::new();
    DS.get_or_init(|| Dataset::load(&fixtures().join("dataset")).expect("reference dataset loads"))
}

fn load(name: &str) -> results::Results {
    let path = fixtures().join(format!("results/{name}_synthA-test.csv"));
    results::load_results(&path).expect("reference results parse")
}

/// bop_toolkit's errors of one error signature: (scene, image, object, est_id, gt) -> error.
fn expected(name: &str, signature: &str) -> BTreeMap<(u32, u32, u32, u32, u32), f64> {
    let dir = fixtures()
        .join("expected")
        .join(format!("{name}_synthA-test"))
        .join("errors/bop19")
        .join(signature);
    let mut out = BTreeMap::new();
    for scene in ["000001", "000002"] {
        let text = std::fs::read_to_string(dir.join(format!("errors_{scene}.json")))
            .expect("expected errors");
        let rows: Value = serde_json::from_str(&text).expect("expected errors parse");
        for e in rows.as_array().expect("a list") {
            let id = |k: &str| e[k].as_u64().expect("an id") as u32;
            for (gt, v) in e["errors"].as_object().expect("errors") {
                let key = (
                    id("scene_id"),
                    id("im_id"),
                    id("obj_id"),
                    id("est_id"),
                    gt.parse().expect("gt id"),
                );
                out.insert(key, v[0].as_f64().expect("a number"));
            }
        }
    }
    out
}

#[test]
fn every_bop19_vsd_value_of_the_reference_files_is_bit_equal_to_bop_toolkits() {
    let (mut equal, mut total) = (0usize, 0usize);
    let mut differing = Vec::new();
    for name in RESULT_NAMES {
        let ev = evaluate(
            dataset(),
            &load(name),
            &Protocol::bop19(),
            &NoProgress,
            &AtomicBool::new(false),
        )
        .expect("evaluation succeeds");
        for (c, col) in ev.columns.iter().enumerate() {
            if col.tau.is_none() {
                continue;
            }
            let want = expected(name, &col.signature);
            for e in &ev.errors {
                for (gi, &gt) in e.gt_ids.iter().enumerate() {
                    let w = want[&(e.scene_id, e.im_id, e.obj_id, e.est_id, gt)];
                    let got = e.errors[c][gi];
                    total += 1;
                    if (got - w).abs() < 1e-12 {
                        equal += 1;
                    } else {
                        differing.push(format!(
                            "{name} {} {:?} gt {gt}: {got} != {w}",
                            col.signature,
                            (e.scene_id, e.im_id, e.obj_id, e.est_id)
                        ));
                    }
                }
            }
        }
    }
    eprintln!(
        "VSD values bit-equal to bop_toolkit's: {equal} of {total} ({:.1}%)",
        100.0 * equal as f64 / total as f64
    );
    for d in &differing {
        eprintln!("  differs: {d}");
    }
    assert_eq!(
        total, 3850,
        "the reference error files hold 3850 VSD values"
    );
    assert!(differing.is_empty(), "{} values differ", differing.len());
}

/// Every pose of the reference result files and ground truth, per object.
fn poses() -> Vec<(u32, evaluator::math::Pose, evaluator::math::Intrinsics)> {
    let mut out = Vec::new();
    for name in RESULT_NAMES {
        for e in &load(name).estimates {
            if let Some(im) = dataset()
                .scenes
                .get(&e.scene_id)
                .and_then(|s| s.images.get(&e.im_id))
            {
                out.push((e.obj_id, e.pose, im.camera));
            }
        }
    }
    for scene in dataset().scenes.values() {
        for im in scene.images.values() {
            out.extend(im.gt.iter().map(|g| (g.obj_id, g.pose, im.camera)));
        }
    }
    out
}

#[test]
fn renders_stay_within_their_screen_boxes() {
    let mut renderer = Renderer::new();
    for (obj_id, pose, k) in poses() {
        let model = Model::new(&dataset().objects[&obj_id].mesh);
        let render = renderer.render_model(&model, &pose, &k, 640, 480);
        let Some(window) = PixelBox::of_window(&render) else {
            continue;
        };
        let b = screen_box(&model, &pose, &k, 640, 480).expect("a box around a non-empty render");
        // The window spans the vertices; the box must hold every covered pixel.
        for y in window.y0..=window.y1 {
            for x in window.x0..=window.x1 {
                if render.at(x, y) > 0.0 {
                    assert!(
                        (b.x0..=b.x1).contains(&x) && (b.y0..=b.y1).contains(&y),
                        "pixel {x},{y} outside {b:?}"
                    );
                }
            }
        }
    }
}
