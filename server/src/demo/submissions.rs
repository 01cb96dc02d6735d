//! Result files of fictitious methods of known quality, derived from the ground truth, so a
//! fresh leaderboard shows a spread of scores and every column of the BOP'19 report means
//! something: a near-perfect method, a noisy one that misses some targets, a poor one with
//! wild guesses and tied scores, and one that answers symmetric objects with a different but
//! equivalent pose, which scores as well as the near-perfect method because the BOP errors
//! are symmetry-aware. A 6D detector, for the bop24 board, is told nothing of what an image
//! holds: it finds most instances, whatever their visibility, and reports a few objects that
//! are not there.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use evaluator::Dataset;
use evaluator::dataset::{GtInstance, ModelInfo, Target};
use evaluator::math::{Mat3, Pose, Vec3};
use nalgebra::UnitQuaternion;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal, UnitSphere};

use super::shapes::rotation;

/// One demo result file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DemoResult {
    /// Method name, without `_` as BOP result file names require.
    pub method: String,
    pub description: String,
    pub path: PathBuf,
}

/// How a fictitious method errs.
struct Style {
    method: &'static str,
    description: &'static str,
    /// Standard deviation of the rotation error (about a random axis), degrees.
    rotation_deg: f64,
    /// Standard deviation of the translation error's length, mm.
    translation_mm: f64,
    /// Probability that a target gets no estimate at all.
    missing: f64,
    /// Probability that an estimate is a random pose instead.
    random: f64,
    /// Probability that an estimate is followed by a random one with the same score.
    tied: f64,
    /// Whether symmetric objects get a random pose among the equivalent ones.
    symmetric: bool,
    /// Range of the reported time per image, s.
    seconds: (f64, f64),
}

const STYLES: [Style; 4] = [
    Style {
        method: "demo-precise",
        description: "Synthetic demo: the ground truth with small errors \
                      (about 0.5 degrees and 1.5 mm). Near-perfect.",
        rotation_deg: 0.5,
        translation_mm: 1.5,
        missing: 0.0,
        random: 0.0,
        tied: 0.0,
        symmetric: false,
        seconds: (0.6, 1.0),
    },
    Style {
        method: "demo-noisy",
        description: "Synthetic demo: the ground truth with errors of about 5 degrees and \
                      10 mm, and a few targets without an estimate.",
        rotation_deg: 5.0,
        translation_mm: 10.0,
        missing: 0.1,
        random: 0.0,
        tied: 0.0,
        symmetric: false,
        seconds: (0.15, 0.3),
    },
    Style {
        method: "demo-rough",
        description: "Synthetic demo: errors of about 20 degrees and 40 mm, some random \
                      poses, and extra wrong estimates with tied scores.",
        rotation_deg: 20.0,
        translation_mm: 40.0,
        missing: 0.0,
        random: 0.2,
        tied: 0.3,
        symmetric: false,
        seconds: (0.03, 0.06),
    },
    Style {
        method: "demo-symmetric",
        description: "Synthetic demo: like demo-precise, but symmetric objects are given any \
                      of their equivalent poses under the declared symmetries. BOP's errors \
                      are symmetry-aware, so it scores as well.",
        rotation_deg: 0.5,
        translation_mm: 1.5,
        missing: 0.0,
        random: 0.0,
        tied: 0.0,
        symmetric: true,
        seconds: (0.6, 1.0),
    },
];

/// Writes the demo result files for the dataset in `dataset_dir` into `out_dir` (created if
/// needed) as `{method}_{dataset}-test.csv`, the dataset being the folder name of
/// `dataset_dir`. Estimates are made for the instances each target expects (its `inst_count`
/// most visible ones). Deterministic in `seed`.
pub fn write_demo_results(
    dataset_dir: &Path,
    out_dir: &Path,
    seed: u64,
) -> Result<Vec<DemoResult>> {
    let dataset = Dataset::load(dataset_dir)
        .with_context(|| format!("cannot load the dataset in {}", dataset_dir.display()))?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    STYLES
        .iter()
        .enumerate()
        .map(|(n, style)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(n as u64);
            let path = out_dir.join(format!("{}_{}-test.csv", style.method, dataset.name));
            std::fs::write(&path, results_csv(&dataset, style, &mut rng))
                .with_context(|| format!("cannot write {}", path.display()))?;
            Ok(DemoResult {
                method: style.method.to_string(),
                description: style.description.to_string(),
                path,
            })
        })
        .collect()
}

/// The demo 6D detector (BOP'24 detection): its method name.
pub const DETECTOR: &str = "demo-6d-detector";

/// Writes the demo detector's result file for the dataset in `dataset_dir` into `out_dir` as
/// `demo-6d-detector_{dataset}-test.csv`: in every image of the targets, an estimate of most
/// ground-truth instances (errors of about 3 degrees and 6 mm, the less visible ones scored
/// lower and sometimes missed) and one estimate of an object the image does not hold (a low
/// score). Deterministic in `seed`.
pub fn write_demo_detection_results(
    dataset_dir: &Path,
    out_dir: &Path,
    seed: u64,
) -> Result<DemoResult> {
    let dataset = Dataset::load(dataset_dir)
        .with_context(|| format!("cannot load the dataset in {}", dataset_dir.display()))?;
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("cannot create {}", out_dir.display()))?;
    let style = Style {
        method: DETECTOR,
        description: "",
        rotation_deg: 3.0,
        translation_mm: 6.0,
        missing: 0.0,
        random: 0.0,
        tied: 0.0,
        symmetric: false,
        seconds: (0.2, 0.4),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(STYLES.len() as u64);
    let mut images: Vec<(u32, u32)> = dataset
        .targets
        .iter()
        .map(|t| (t.scene_id, t.im_id))
        .collect();
    images.dedup();
    let mut out = String::from(HEADER);
    for (scene_id, im_id) in images {
        let time = (rng.random_range(style.seconds.0..style.seconds.1) * 1000.0).round() / 1000.0;
        let image = &dataset.scenes[&scene_id].images[&im_id];
        let line = |obj_id: u32| Target {
            scene_id,
            im_id,
            obj_id,
            inst_count: 1,
        };
        for gt in &image.gt {
            // A detector misses more of what it hardly sees.
            if rng.random_bool((0.3 * (1.0 - gt.visib_fract)).clamp(0.0, 1.0)) {
                continue;
            }
            let score = round4(0.3 + 0.6 * gt.visib_fract + rng.random_range(-0.05..0.05));
            let pose = perturb(&gt.pose, &style, &mut rng);
            csv_line(&mut out, &line(gt.obj_id), score, &pose, time);
        }
        let absent: Vec<u32> = dataset
            .objects
            .keys()
            .copied()
            .filter(|o| image.gt.iter().all(|g| g.obj_id != *o))
            .collect();
        if !absent.is_empty() {
            let obj_id = absent[rng.random_range(0..absent.len())];
            let score = round4(rng.random_range(0.05..0.3));
            csv_line(&mut out, &line(obj_id), score, &random_pose(&mut rng), time);
        }
    }
    let path = out_dir.join(format!("{DETECTOR}_{}-test.csv", dataset.name));
    std::fs::write(&path, out).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(DemoResult {
        method: DETECTOR.to_string(),
        description: "Synthetic demo of 6D detection (bop24): not told which objects an image \
                      holds, it finds most instances with errors of about 3 degrees and 6 mm, \
                      misses more of the hardly visible ones, and reports one object per image \
                      that is not there."
            .to_string(),
        path,
    })
}

pub(super) const HEADER: &str = "scene_id,im_id,obj_id,score,R,t,time\n";

/// One line of a BOP'19 result file; `{}` prints the shortest text that reads back as the
/// same `f64`.
pub(super) fn csv_line(out: &mut String, t: &Target, score: f64, pose: &Pose, time: f64) {
    let r = pose.r;
    let _ = write!(out, "{},{},{},{score},", t.scene_id, t.im_id, t.obj_id);
    for i in 0..9 {
        let sep = if i == 8 { "," } else { " " };
        let _ = write!(out, "{}{sep}", r[(i / 3, i % 3)]);
    }
    let _ = writeln!(out, "{} {} {},{time}", pose.t.x, pose.t.y, pose.t.z);
}

/// The ground-truth instances a target asks for: its `inst_count` most visible ones (stable
/// order among equals, like bop_toolkit).
pub(super) fn expected_instances(dataset: &Dataset, t: &Target) -> Vec<GtInstance> {
    let image = &dataset.scenes[&t.scene_id].images[&t.im_id];
    let mut gts: Vec<GtInstance> = image
        .gt
        .iter()
        .filter(|g| g.obj_id == t.obj_id)
        .copied()
        .collect();
    gts.sort_by(|a, b| b.visib_fract.total_cmp(&a.visib_fract));
    gts.truncate(t.inst_count as usize);
    gts
}

fn results_csv(dataset: &Dataset, style: &Style, rng: &mut ChaCha8Rng) -> String {
    let mut out = String::from(HEADER);
    let mut time = 0.0;
    let mut image = None;
    for t in &dataset.targets {
        // One time per image, however many targets it has.
        if image != Some((t.scene_id, t.im_id)) {
            image = Some((t.scene_id, t.im_id));
            time = (rng.random_range(style.seconds.0..style.seconds.1) * 1000.0).round() / 1000.0;
        }
        if rng.random_bool(style.missing) {
            continue;
        }
        let info = &dataset.objects[&t.obj_id].info;
        for gt in expected_instances(dataset, t) {
            let (pose, score) = if rng.random_bool(style.random) {
                (random_pose(rng), round4(rng.random_range(0.05..0.6)))
            } else {
                let mut pose = gt.pose;
                if style.symmetric {
                    pose = pose.compose(&random_symmetry(info, rng));
                }
                let score = 0.4 + 0.55 * gt.visib_fract + rng.random_range(-0.05..0.05);
                (perturb(&pose, style, rng), round4(score))
            };
            csv_line(&mut out, t, score, &pose, time);
            if rng.random_bool(style.tied) {
                csv_line(&mut out, t, score, &random_pose(rng), time);
            }
        }
    }
    out
}

fn round4(x: f64) -> f64 {
    (x.clamp(0.0001, 0.9999) * 1e4).round() / 1e4
}

/// `pose` turned about a random axis through the model origin by a normally distributed
/// angle, and shifted by a normally distributed vector.
fn perturb(pose: &Pose, style: &Style, rng: &mut ChaCha8Rng) -> Pose {
    let axis: [f64; 3] = UnitSphere.sample(rng);
    let angle = style.rotation_deg.to_radians() * rng.sample::<f64, _>(StandardNormal);
    // Per axis sigma / sqrt(3), so that the length of the shift has about sigma's size.
    let sigma = style.translation_mm / 3f64.sqrt();
    let shift = Vec3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal));
    Pose::new(pose.r * rotation(Vec3::from(axis), angle), pose.t + shift)
}

/// A uniformly random rotation, somewhere in front of the camera.
fn random_pose(rng: &mut ChaCha8Rng) -> Pose {
    let q: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
    let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
    let t = Vec3::new(
        rng.random_range(-200.0..200.0),
        rng.random_range(-150.0..150.0),
        rng.random_range(600.0..1000.0),
    );
    Pose::new(r.to_rotation_matrix().into_inner(), t)
}

/// A random transformation among those that map the model onto itself: the identity or a
/// declared discrete symmetry, then any angle about a declared continuous axis.
fn random_symmetry(info: &ModelInfo, rng: &mut ChaCha8Rng) -> Pose {
    let mut sym = Pose::identity();
    let discrete = &info.symmetries_discrete;
    let pick = rng.random_range(0..=discrete.len());
    if let Some(m) = discrete.get(pick) {
        sym = Pose::new(
            Mat3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]),
            Vec3::new(m[3], m[7], m[11]),
        );
    }
    for c in &info.symmetries_continuous {
        let offset = Vec3::from(c.offset);
        let r = rotation(
            Vec3::from(c.axis),
            rng.random_range(0.0..std::f64::consts::TAU),
        );
        sym = sym.compose(&Pose::new(r, offset - r * offset));
    }
    sym
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demo::{SynthOptions, write_dataset};
    use evaluator::results::load_results;
    use evaluator::{NoProgress, Protocol, evaluate};
    use std::sync::atomic::AtomicBool;

    fn score(dataset: &Dataset, path: &Path, protocol: &Protocol) -> f64 {
        let results = load_results(path).unwrap();
        evaluate(
            dataset,
            &results,
            protocol,
            &NoProgress,
            &AtomicBool::new(false),
        )
        .unwrap()
        .report
        .headline()
    }

    #[test]
    fn demo_results_score_in_their_intended_order() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("synthdemo");
        write_dataset(&dir, &SynthOptions::default()).unwrap();
        let dataset = Dataset::load(&dir).unwrap();
        let out = tmp.path().join("results");
        let demos = write_demo_results(&dir, &out, 11).unwrap();
        let names: Vec<&str> = demos.iter().map(|d| d.method.as_str()).collect();
        assert_eq!(
            names,
            ["demo-precise", "demo-noisy", "demo-rough", "demo-symmetric"]
        );

        let bop19 = Protocol::bop19();
        let ar: Vec<f64> = demos
            .iter()
            .map(|d| {
                assert_eq!(
                    d.path.file_name().unwrap().to_str().unwrap(),
                    format!("{}_synthdemo-test.csv", d.method)
                );
                assert!(!d.method.contains('_') && !d.description.is_empty());
                score(&dataset, &d.path, &bop19)
            })
            .collect();
        eprintln!("AR: {:?}", names.iter().zip(&ar).collect::<Vec<_>>());
        let [precise, noisy, rough, symmetric] = ar[..] else {
            unreachable!()
        };
        assert!(precise > 0.9, "{precise}");
        assert!(noisy < precise && noisy > rough, "{noisy}");
        assert!(rough < 0.5, "{rough}");
        assert!(
            (symmetric - precise).abs() < 0.05,
            "{symmetric} vs {precise}"
        );

        // Deterministic.
        let again = write_demo_results(&dir, &tmp.path().join("again"), 11).unwrap();
        for (a, b) in demos.iter().zip(&again) {
            assert_eq!(
                std::fs::read(&a.path).unwrap(),
                std::fs::read(&b.path).unwrap()
            );
        }
    }

    #[test]
    fn the_demo_detector_scores_for_bop24_between_nothing_and_perfect() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("synthdemo");
        write_dataset(&dir, &SynthOptions::default()).unwrap();
        let demo = write_demo_detection_results(&dir, &tmp.path().join("out"), 11).unwrap();
        assert_eq!(demo.method, DETECTOR);
        let opts = evaluator::dataset::DatasetOptions {
            targets_file: "test_targets_bop24.json".into(),
            ..Default::default()
        };
        let dataset = Dataset::load_with(&dir, &opts).unwrap();
        let results = load_results(&demo.path).unwrap();
        let report = evaluator::detection::evaluate(
            &dataset,
            &results,
            100,
            &NoProgress,
            &AtomicBool::new(false),
        )
        .unwrap();
        // Estimates of absent objects are neither true nor false positives.
        assert!(report.estimates_ignored > 0, "{}", report.estimates_ignored);
        assert!(
            report.bop24_map > 0.3 && report.bop24_map < 1.0,
            "{}",
            report.bop24_map
        );
        let again = write_demo_detection_results(&dir, &tmp.path().join("again"), 11).unwrap();
        assert_eq!(
            std::fs::read(&demo.path).unwrap(),
            std::fs::read(&again.path).unwrap()
        );
    }

    #[test]
    fn the_ground_truth_itself_scores_perfectly() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("synthdemo");
        write_dataset(&dir, &SynthOptions::default()).unwrap();
        let dataset = Dataset::load(&dir).unwrap();
        let mut csv = String::from(HEADER);
        for t in &dataset.targets {
            for gt in expected_instances(&dataset, t) {
                csv_line(&mut csv, t, gt.visib_fract, &gt.pose, 0.5);
            }
        }
        let path = tmp.path().join("gt_synthdemo-test.csv");
        std::fs::write(&path, csv).unwrap();
        // The file reads back as exactly the ground-truth poses.
        let results = load_results(&path).unwrap();
        let expected: u32 = dataset.targets.iter().map(|t| t.inst_count).sum();
        assert_eq!(results.estimates.len(), expected as usize);
        let first =
            &dataset.scenes[&results.estimates[0].scene_id].images[&results.estimates[0].im_id];
        assert!(first.gt.iter().any(|g| g.pose == results.estimates[0].pose));
        assert_eq!(score(&dataset, &path, &Protocol::bop19()), 1.0);
        assert_eq!(score(&dataset, &path, &Protocol::eccv18()), 1.0);
    }
}
