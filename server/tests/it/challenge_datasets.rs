//! The datasets the BOP challenge added in 2024, BOP-Industrial (IPD, XYZ-IBD, ITODD-MV) and
//! BOP-H3 (HOPEv2, HANDAL, HOT3D): miniatures made by `poseboard dataset synth --layout` are laid
//! out as bop_toolkit's `dataset_params.py` reads them and load with the evaluated sensor's
//! files; a file of their ground-truth poses scores 1.0 under every protocol each supports; and
//! a protocol needing VSD is refused, saying why, where the toolkit computes none.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::sync::atomic::AtomicBool;

use crate::common::{BIN, cli_report};
use evaluator::protocol::{ErrorKind, Protocol};
use evaluator::results::load_results;
use evaluator::{Dataset, NoProgress, evaluate};

/// (layout, whether bop_toolkit computes VSD on it).
const LAYOUTS: [(&str, bool); 6] = [
    ("hopev2", true),
    ("handal", true),
    ("ipd", false),
    ("xyzibd", false),
    ("itoddmv", false),
    ("hot3d", false),
];

/// A protocol of `poseboard eval` under which a file of ground-truth poses must score 1.0 on
/// every layout the protocol serves, and the report keys that say so. Adding a protocol to
/// these checks is one line here.
struct Check {
    protocol: &'static str,
    keys: &'static [&'static str],
    needs_vsd: bool,
}

const CHECKS: &[Check] = &[
    Check {
        protocol: "bop19",
        keys: &[
            "bop19_average_recall",
            "bop19_average_recall_vsd",
            "bop19_average_recall_mssd",
            "bop19_average_recall_mspd",
        ],
        needs_vsd: true,
    },
    Check {
        protocol: "bop24",
        keys: &[
            "bop24_mAP",
            "bop24_mAP_mssd",
            "bop24_mAP_mssd_mm",
            "bop24_mAP_mspd",
        ],
        needs_vsd: false,
    },
];

/// The protocols that need VSD.
const VSD_PROTOCOLS: [&str; 2] = ["bop19", "eccv18"];

/// The six miniatures (two scenes of two images each), made once for all tests.
fn miniatures() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        for (name, _) in LAYOUTS {
            let target = dir.path().join(name);
            let out = std::process::Command::new(BIN)
                .args(["dataset", "synth", path(&target), "--layout", name])
                .args(["--scenes", "2", "--images-per-scene", "2"])
                .output()
                .expect("poseboard runs");
            assert!(
                out.status.success(),
                "{name}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        dir
    })
    .path()
}

fn path(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

/// `gt_{name}-test.csv` beside the dataset: every ground-truth instance of every target, its
/// score its visible fraction (so the most visible instances are the ones a target keeps).
fn ground_truth_file(dataset: &Dataset, dir: &Path) -> PathBuf {
    let mut csv = String::from("scene_id,im_id,obj_id,score,R,t,time\n");
    for t in &dataset.targets {
        let image = &dataset.scenes[&t.scene_id].images[&t.im_id];
        for gt in image.gt.iter().filter(|g| g.obj_id == t.obj_id) {
            let r = gt.pose.r;
            let rows: Vec<String> = (0..3)
                .flat_map(|i| (0..3).map(move |j| r[(i, j)].to_string()))
                .collect();
            let t_mm: Vec<String> = gt.pose.t.iter().map(f64::to_string).collect();
            writeln!(
                csv,
                "{},{},{},{},{},{},1.0",
                t.scene_id,
                t.im_id,
                t.obj_id,
                gt.visib_fract,
                rows.join(" "),
                t_mm.join(" ")
            )
            .expect("write to a string");
        }
    }
    let file = dir.join(format!("gt_{}-test.csv", dataset.name));
    std::fs::write(&file, csv).expect("write the result file");
    file
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .expect("json")
}

#[test]
fn layouts_are_published_as_dataset_params_reads_them() {
    let root = miniatures();
    let has = |p: &str| assert!(root.join(p).is_file(), "{p} is missing");
    let lacks = |p: &str| assert!(!root.join(p).exists(), "{p} should not exist");
    // BOP-Industrial: per-sensor annotations and camera files; the evaluated sensor's images.
    for p in [
        "ipd/camera_photoneo.json",
        "ipd/camera_cam1.json",
        "ipd/test/000001/scene_gt_photoneo.json",
        "ipd/test/000001/scene_camera_photoneo.json",
        "ipd/test/000001/scene_gt_info_photoneo.json",
        "ipd/test/000001/scene_gt_cam3.json",
        "ipd/test/000001/rgb_photoneo/000000.png",
        "ipd/test/000001/depth_photoneo/000000.png",
        "xyzibd/camera_xyz.json",
        "xyzibd/test/000002/scene_gt_realsense.json",
        "xyzibd/test/000002/gray_xyz/000001.png",
        "xyzibd/test/000002/depth_xyz/000001.png",
        "itoddmv/test/000001/gray_3dlong/000000.tif",
        "itoddmv/test/000001/depth_3dlong/000000.tif",
        "itoddmv/test/000001/scene_camera_cam0.json",
        "hopev2/test/000001/rgb/000000.png",
        "handal/test/000001/rgb/000000.jpg",
        "hot3d/test/001288/scene_gt_gray1.json",
        "hot3d/test/001288/scene_gt_gray2.json",
        "hot3d/test/001288/gray1/000000.jpg",
        "hot3d/test/003366/scene_gt_rgb.json",
        "hot3d/test/003366/scene_gt_info_rgb.json",
        "hot3d/test/003366/scene_camera_gray1.json",
        "hot3d/test/003366/rgb/000001.jpg",
        "hot3d/test_targets_bop24.json",
    ] {
        has(p);
    }
    for p in [
        "ipd/camera.json",
        "ipd/test/000001/scene_gt.json",
        "ipd/test/000001/depth",
        "xyzibd/test/000002/rgb",
        "handal/test/000001/rgb/000000.png",
        "hot3d/camera.json",
        "hot3d/test/001288/depth",
        "hot3d/test/003366/scene_gt.json",
        "hot3d/.parts",
    ] {
        lacks(p);
    }
    // JPEG and TIFF by their magic numbers.
    let head = |p: &str| std::fs::read(root.join(p)).expect("read")[..4].to_vec();
    assert_eq!(head("handal/test/000001/rgb/000000.jpg")[..2], [0xff, 0xd8]);
    assert_eq!(head("hot3d/test/003366/rgb/000000.jpg")[..2], [0xff, 0xd8]);
    assert_eq!(
        head("itoddmv/test/000001/depth_3dlong/000000.tif"),
        b"II*\0"
    );
    // HOT3D's cameras are fisheye models, not cam_K.
    let cameras = read_json(&root.join("hot3d/test/003366/scene_camera_rgb.json"));
    assert!(cameras["0"].get("cam_K").is_none());
    assert_eq!(
        cameras["0"]["cam_model"]["projection_model_type"],
        "CameraModelType.FISHEYE624"
    );
    assert_eq!(cameras["0"]["cam_model"]["image_width"], 1408);
    let camera = read_json(&root.join("xyzibd/camera_realsense.json"));
    assert_eq!(
        (camera["width"].as_u64(), camera["height"].as_u64()),
        (Some(1280), Some(720))
    );
}

#[test]
fn each_miniature_loads_with_the_evaluated_sensors_files() {
    let root = miniatures();
    for (name, size, suffix) in [
        ("hopev2", (1920, 1080), None),
        ("handal", (1920, 1440), None),
        ("ipd", (2064, 1544), Some("photoneo")),
        ("xyzibd", (1440, 1080), Some("xyz")),
        ("itoddmv", (1280, 960), Some("3dlong")),
        ("hot3d", (1280, 1024), Some("gray1")),
    ] {
        let d = Dataset::load(&root.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(d.image_size, size, "{name}");
        let first = d.scenes.values().next().expect("a scene");
        assert_eq!(first.sensor.map(|s| s.suffix), suffix, "{name}");
        assert!(!d.targets.is_empty(), "{name}");
        // The evaluated sensor's intrinsics, not another sensor's.
        if let Some(s) = suffix.filter(|_| name != "hot3d") {
            let cameras = read_json(
                &d.split_dir
                    .join(format!("{:06}", first.id))
                    .join(format!("scene_camera_{s}.json")),
            );
            assert_eq!(
                first.images[&0].camera.fx(),
                cameras["0"]["cam_K"][0].as_f64().expect("fx"),
                "{name}"
            );
        }
    }
    // HOT3D: Quest 3 scenes on the gray1 stream, Aria scenes on rgb, both fisheye; MSPD is
    // normalised by each stream's width.
    let hot3d = Dataset::load(&root.join("hot3d")).expect("hot3d loads");
    assert_eq!(
        hot3d.scenes.keys().copied().collect::<Vec<_>>(),
        [1288, 3366]
    );
    let aria = &hot3d.scenes[&3366];
    assert_eq!(
        aria.sensor.map(|s| (s.suffix, s.size)),
        Some(("rgb", (1408, 1408)))
    );
    assert!(aria.images.values().all(|i| i.fisheye.is_some()));
    assert_eq!(
        (hot3d.image_width(1288), hot3d.image_width(3366)),
        (1280, 1408)
    );
    // No depth file decides a score where no VSD is computed.
    let files = hot3d.score_files().expect("score files");
    assert!(files.iter().all(|f| !f.to_string_lossy().contains("depth")));
    assert!(
        files
            .iter()
            .any(|f| f.ends_with("test/003366/scene_gt_rgb.json"))
    );
}

#[test]
fn ground_truth_scores_one_under_every_supported_protocol() {
    let root = miniatures();
    let out = tempfile::tempdir().expect("tempdir");
    for (name, vsd) in LAYOUTS {
        let dataset = Dataset::load(&root.join(name)).expect("loads");
        let results = ground_truth_file(&dataset, out.path());
        for check in CHECKS.iter().filter(|c| vsd || !c.needs_vsd) {
            let report = cli_report(&root.join(name), &results, check.protocol);
            for key in check.keys {
                assert_eq!(report[key], 1.0, "{name} {}: {key}", check.protocol);
            }
        }
        // MSSD and MSPD, which every dataset supports, through the evaluator itself.
        let mut protocol = Protocol::bop19();
        protocol
            .errors
            .retain(|e| matches!(e.kind, ErrorKind::Mssd | ErrorKind::Mspd));
        let report = evaluate(
            &dataset,
            &load_results(&results).expect("results"),
            &protocol,
            &NoProgress,
            &AtomicBool::new(false),
        )
        .expect("evaluates")
        .report;
        assert_eq!(report.bop19_average_recall_mssd, Some(1.0), "{name}");
        assert_eq!(report.bop19_average_recall_mspd, Some(1.0), "{name}");
    }
}

#[test]
fn vsd_is_refused_where_the_toolkit_computes_none() {
    let root = miniatures();
    let out = tempfile::tempdir().expect("tempdir");
    for (name, _) in LAYOUTS.iter().filter(|(_, vsd)| !vsd) {
        let dataset = Dataset::load(&root.join(name)).expect("loads");
        let results = ground_truth_file(&dataset, out.path());
        for protocol in VSD_PROTOCOLS {
            let run = std::process::Command::new(BIN)
                .args(["eval", "--dataset", path(&root.join(name))])
                .args(["--results", path(&results), "--protocol", protocol])
                .output()
                .expect("poseboard runs");
            let stderr = String::from_utf8_lossy(&run.stderr);
            assert!(!run.status.success(), "{name} {protocol}");
            assert!(
                stderr.contains(&format!(
                    "protocol {protocol} needs VSD, which {name} cannot be scored with"
                )),
                "{name}: {stderr}"
            );
            let why = if *name == "hot3d" {
                "HOT3D has no depth images"
            } else {
                "only ad, add, adi, mssd and mspd on the BOP-Industrial datasets"
            };
            assert!(stderr.contains(why), "{name}: {stderr}");
        }
    }
}

#[test]
fn sensor_files_under_another_name_are_explained() {
    let root = miniatures();
    let copy = tempfile::tempdir().expect("tempdir");
    let renamed = copy.path().join("my-ipd");
    let status = std::process::Command::new("cp")
        .args(["-r", path(&root.join("ipd")), path(&renamed)])
        .status()
        .expect("cp runs");
    assert!(status.success());
    let msg = Dataset::load(&renamed)
        .expect_err("unknown name")
        .to_string();
    assert!(
        msg.contains("scene_gt.json: no such file, but the scene holds per-sensor annotations")
            && msg.contains("scene_gt_cam1.json")
            && msg.contains("(ipd, xyzibd, itoddmv, hot3d)"),
        "{msg}"
    );
}
