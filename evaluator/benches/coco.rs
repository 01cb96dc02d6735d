//! Time to score a segmentation result file of a full BOP dataset's size (BOP'22 `bop22-seg`):
//! 1,000 target images of 640x480 in 10 scenes, 8 ground-truth instances and 20 detections
//! with masks per image (20,000 in all, half with list counts, half compressed), 21 objects.
//! Reading the ground truth, reading the result file and COCOeval are timed separately, on a
//! pool of one thread per core (the budget: 10 s on 2 cores), with the CPU time the
//! process spent meanwhile, so that a run on a loaded machine can still be judged.
//!
//! `cargo bench -p evaluator --bench coco`

use std::time::Instant;

use evaluator::coco::rle::Rle;
use evaluator::coco::{self, BboxType, CocoGt, CocoTask, load_coco_results};
use evaluator::dataset::DatasetOptions;
use serde_json::{Value, json};

const W: u32 = 640;
const H: u32 = 480;
const SCENES: u32 = 10;
const IMAGES_PER_SCENE: u32 = 100;
const GT_PER_IMAGE: usize = 8;
const DETECTIONS_PER_IMAGE: usize = 20;
const OBJECTS: u64 = 21;

/// A small seeded generator (xorshift), so every run scores the same file.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// An ellipse mask, encoded column by column straight into runs (a pass over every pixel
/// of 28,000 masks would take longer than the evaluation).
fn ellipse(cx: f64, cy: f64, rx: f64, ry: f64) -> Rle {
    let mut counts: Vec<u32> = Vec::new();
    let mut last_end = 0u32;
    for x in 0..W {
        let dx = (x as f64 - cx) / rx;
        if dx * dx > 1.0 {
            continue;
        }
        let half = ry * (1.0 - dx * dx).sqrt();
        let ya = (cy - half).ceil().max(0.0) as u32;
        let yb = (cy + half).floor().min((H - 1) as f64);
        if yb < 0.0 || ya as f64 > yb {
            continue;
        }
        let (start, end) = (x * H + ya, x * H + yb as u32 + 1);
        if start == last_end && !counts.is_empty() {
            *counts.last_mut().expect("a run") += end - start;
        } else {
            counts.push(start - last_end);
            counts.push(end - start);
        }
        last_end = end;
    }
    counts.push(W * H - last_end);
    Rle::from_counts(H, W, counts).expect("a 640x480 mask")
}

fn rle_json(rle: &Rle, compressed: bool) -> Value {
    if compressed {
        json!({"counts": rle.to_compressed(), "size": [H, W]})
    } else {
        json!({"counts": rle.counts(), "size": [H, W]})
    }
}

fn main() {
    let dir = tempfile::tempdir().expect("tempdir");
    let root = dir.path().join("bench");
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let mut targets = Vec::new();
    let mut entries = Vec::new();
    let categories: Vec<Value> = (1..=OBJECTS).map(|id| json!({"id": id})).collect();
    let made = Instant::now();
    for scene in 1..=SCENES {
        let mut images = Vec::new();
        let mut annotations = Vec::new();
        for im in 1..=IMAGES_PER_SCENE {
            images.push(json!({"id": im, "width": W, "height": H}));
            let mut shapes = Vec::new();
            for _ in 0..GT_PER_IMAGE {
                let obj = 1 + rng.below(OBJECTS);
                let (rx, ry) = (8.0 + rng.below(90) as f64, 8.0 + rng.below(90) as f64);
                let (cx, cy) = (rng.below(W as u64) as f64, rng.below(H as u64) as f64);
                let rle = ellipse(cx, cy, rx, ry);
                targets
                    .push(json!({"scene_id": scene, "im_id": im, "obj_id": obj, "inst_count": 1}));
                annotations.push(json!({
                    "id": annotations.len() + 1, "image_id": im, "category_id": obj,
                    "iscrowd": 0, "area": rle.area(), "bbox": rle.to_bbox(),
                    "segmentation": rle_json(&rle, false), "ignore": rng.below(10) == 0,
                }));
                shapes.push((obj, cx, cy, rx, ry));
            }
            for d in 0..DETECTIONS_PER_IMAGE {
                let (obj, cx, cy, rx, ry) = if d < shapes.len() {
                    let (o, cx, cy, rx, ry) = shapes[d];
                    let jitter = |r: &mut Rng| r.below(9) as f64 - 4.0;
                    (o, cx + jitter(&mut rng), cy + jitter(&mut rng), rx, ry)
                } else {
                    (
                        1 + rng.below(OBJECTS),
                        rng.below(W as u64) as f64,
                        rng.below(H as u64) as f64,
                        5.0 + rng.below(80) as f64,
                        5.0 + rng.below(80) as f64,
                    )
                };
                let rle = ellipse(cx, cy, rx, ry);
                entries.push(json!({
                    "scene_id": scene, "image_id": im, "category_id": obj,
                    "score": rng.below(1000) as f64 / 1000.0, "bbox": rle.to_bbox(),
                    "segmentation": rle_json(&rle, d % 2 == 0), "time": 0.25,
                }));
            }
        }
        let scene_dir = root.join(format!("test/{scene:06}"));
        std::fs::create_dir_all(&scene_dir).expect("scene folder");
        let file = json!({"images": images, "annotations": annotations, "categories": categories});
        std::fs::write(scene_dir.join("scene_gt_coco.json"), file.to_string()).expect("write");
    }
    std::fs::create_dir_all(root.join("models")).expect("models folder");
    std::fs::write(
        root.join("test_targets_bop19.json"),
        Value::from(targets).to_string(),
    )
    .expect("write");
    let results_path = dir.path().join("bench_bench-test.json");
    let count = entries.len();
    std::fs::write(&results_path, Value::from(entries).to_string()).expect("write");
    println!(
        "made {count} detections on {} images in {:.1} s (not timed below)",
        SCENES * IMAGES_PER_SCENE,
        made.elapsed().as_secs_f64()
    );

    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    pool.install(|| {
        let cpu_start = cpu_seconds();
        let start = Instant::now();
        let gt = CocoGt::load(&root, &DatasetOptions::default(), BboxType::Amodal, true)
            .expect("ground truth");
        let t_gt = start.elapsed();
        let results = load_coco_results(&results_path).expect("results");
        let t_results = start.elapsed() - t_gt;
        let report = coco::evaluate(&gt, &results, CocoTask::Segmentation).expect("evaluates");
        let total = start.elapsed();
        let cpu = match (cpu_start, cpu_seconds()) {
            (Some(a), Some(b)) => format!(", CPU time {:.2} s", b - a),
            _ => String::new(),
        };
        println!(
            "bop22-seg, {count} detections, {threads} threads: ground truth {:.2} s, result file \
             {:.2} s, COCOeval {:.2} s, total {:.2} s{cpu} (AP {:.4})",
            t_gt.as_secs_f64(),
            t_results.as_secs_f64(),
            (total - t_gt - t_results).as_secs_f64(),
            total.as_secs_f64(),
            report.ap
        );
    });
}

/// User and system CPU time of this process so far, from `/proc/self/stat` (Linux; its clock
/// ticks are USER_HZ, 100 per second); `None` elsewhere.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces.
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    // utime and stime are the 14th and 15th fields of the line, the 12th and 13th after it.
    Some((ticks(11)? + ticks(12)?) / 100.0)
}
