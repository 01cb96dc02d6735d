//! Throughput of the evaluator on the reference data, printed as figures:
//! VSD evaluations per second on one core, and the time to evaluate each reference result file.
//!
//! `cargo bench -p evaluator --bench throughput`
//!
//! A VSD evaluation here is what bop_toolkit does per (estimate, ground truth) pair: render the
//! model at both poses into a 640x480 depth map and compute the error for all ten BOP'19 taus.
//! The pipeline renders each ground-truth instance once per image instead; that figure is
//! printed too.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use evaluator::pose_error::sphere_projections_overlap;
use evaluator::pose_error::vsd::{GtView, TestImage, vsd};
use evaluator::protocol::{ErrorKind, Protocol};
use evaluator::render::{Model, Renderer};
use evaluator::{Dataset, NoProgress, evaluate, results};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/reference")
}

/// Runs `f` repeatedly for at least `min` and returns calls per second.
fn rate(min: Duration, mut f: impl FnMut() -> usize) -> f64 {
    let start = Instant::now();
    let mut n = 0usize;
    while start.elapsed() < min {
        n += f();
    }
    n as f64 / start.elapsed().as_secs_f64()
}

fn main() {
    let dataset = Dataset::load(&fixtures().join("dataset")).expect("reference dataset");
    let bop19 = Protocol::bop19();
    let params = match &bop19.errors[0].kind {
        ErrorKind::Vsd(p) => p.clone(),
        _ => unreachable!("bop19 starts with VSD"),
    };
    let results = results::load_results(&fixtures().join("results/noisemedium_synthA-test.csv"))
        .expect("reference results");

    // Every (estimate, GT of the same object) pair whose sphere projections overlap, with
    // the test image prepared once per image (as every implementation does).
    let mut pairs = Vec::new();
    let mut tests = Vec::new();
    for est in &results.estimates {
        let image = &dataset.scenes[&est.scene_id].images[&est.im_id];
        let diameter = dataset.objects[&est.obj_id].info.diameter;
        for gt in image.gt.iter().filter(|g| g.obj_id == est.obj_id) {
            if sphere_projections_overlap(diameter / 2.0, &est.pose.t, &gt.pose.t) {
                let depth = dataset.load_depth(est.scene_id, est.im_id).expect("depth");
                tests.push(TestImage::new(depth, &image.camera));
                pairs.push((est, gt, image));
            }
        }
    }

    let models: std::collections::HashMap<u32, Model> = dataset
        .objects
        .iter()
        .map(|(&id, o)| (id, Model::new(&o.mesh)))
        .collect();
    let mut renderer = Renderer::new();
    let mut out = vec![0.0; params.taus.len()];
    let full = rate(Duration::from_secs(3), || {
        for ((est, gt, image), test) in pairs.iter().zip(&tests) {
            let obj = &dataset.objects[&est.obj_id];
            let model = &models[&est.obj_id];
            let (w, h) = (test.rays.width, test.rays.height);
            let gt_depth = renderer.render_model(model, &gt.pose, &image.camera, w, h);
            let view = GtView::new(test, gt_depth, &params);
            let est_depth = renderer.render_model(model, &est.pose, &image.camera, w, h);
            vsd(
                test,
                &view,
                &est_depth,
                obj.info.diameter,
                &params,
                &mut out,
            );
        }
        pairs.len()
    });
    let views: Vec<GtView> = pairs
        .iter()
        .zip(&tests)
        .map(|((est, gt, image), test)| {
            let r = renderer.render_model(
                &models[&est.obj_id],
                &gt.pose,
                &image.camera,
                test.rays.width,
                test.rays.height,
            );
            GtView::new(test, r, &params)
        })
        .collect();
    let cached = rate(Duration::from_secs(3), || {
        for (((est, _, image), test), view) in pairs.iter().zip(&tests).zip(&views) {
            let obj = &dataset.objects[&est.obj_id];
            let (w, h) = (test.rays.width, test.rays.height);
            let est_depth =
                renderer.render_model(&models[&est.obj_id], &est.pose, &image.camera, w, h);
            vsd(test, view, &est_depth, obj.info.diameter, &params, &mut out);
        }
        pairs.len()
    });
    println!(
        "VSD at 640x480, 10 taus, one core, {} pairs of noisemedium:",
        pairs.len()
    );
    println!("  rendering estimate and ground truth per pair: {full:>8.0} evaluations/s");
    println!("  ground truth rendered once (as the pipeline): {cached:>8.0} evaluations/s");
    println!("  bop_toolkit on this machine class: about 47 evaluations/s (issue 2)");
    println!("  ratio to bop_toolkit: {:.0}x", full / 47.0);

    println!();
    println!("time to evaluate each reference file (one thread / all threads):");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let all = rayon::ThreadPoolBuilder::new().build().expect("pool");
    let mut names: Vec<_> = std::fs::read_dir(fixtures().join("results"))
        .expect("results dir")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    names.sort();
    for path in names {
        let res = results::load_results(&path).expect("reference results");
        for protocol in [Protocol::eccv18(), Protocol::bop19()] {
            let time = |pool: &rayon::ThreadPool| {
                let start = Instant::now();
                pool.install(|| {
                    evaluate(
                        &dataset,
                        &res,
                        &protocol,
                        &NoProgress,
                        &AtomicBool::new(false),
                    )
                    .expect("evaluation")
                });
                start.elapsed().as_secs_f64() * 1e3
            };
            let (t1, tn) = (time(&one), time(&all));
            println!(
                "  {:<28} {:<7} {t1:>8.1} ms / {tn:>8.1} ms",
                path.file_stem().unwrap_or_default().to_string_lossy(),
                protocol.name.as_str()
            );
        }
    }
}
