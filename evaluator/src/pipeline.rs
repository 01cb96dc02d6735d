//! From a dataset, a result file and a protocol to a report: selects the estimates each
//! target considers, computes their errors image by image in parallel (rayon, on the caller's
//! pool), then matches and scores at every threshold.

use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use crate::bootstrap::{self, Bootstrap, ImageCounts};
use crate::dataset::{Dataset, Image, TargetsForm};
use crate::error::{Error, Result};
use crate::matching::{EstimateErrors, valid_gts};
use crate::math::Pose;
use crate::pose_error::vsd::{GtView, TestImage, vsd};
use crate::pose_error::{self, sphere_projections_overlap, spheres_overlap};
use crate::prepared::Prepared;
use crate::prepared::file::PreparedImage;
use crate::protocol::{Column, ErrorKind, Protocol, columns, normalised_error};
use crate::render::{DepthWindow, Model, PixelBox, Renderer, screen_box};
use crate::report::{self, Report};
use crate::results::Results;
use crate::score::{ScoredImage, Scores, localization_scores};
use crate::selection::{ImageWork, select_estimates};
use crate::supported_errors;

pub use crate::progress::{NoProgress, Progress};

/// Everything an evaluation computed: the report, and the raw errors behind it.
pub struct Evaluation {
    pub report: Report,
    pub columns: Vec<Column>,
    pub errors: Vec<EstimateErrors>,
    /// The target images as matched, to score the errors at other thresholds.
    pub images: Vec<ScoredImage>,
    /// Per target image, what the headline score sums: what a bootstrap resamples.
    pub counts: ImageCounts,
}

impl Evaluation {
    /// Bootstrap replicates of the headline score (see [`crate::bootstrap`]), recorded in the
    /// report's `bootstrap`; `None` when there is nothing to resample.
    pub fn bootstrap(&mut self, seed: u64, replicates: usize) -> Option<Bootstrap> {
        let b = bootstrap::bootstrap(&self.counts, seed, replicates)?;
        self.report.bootstrap = Some(b.summary());
        Some(b)
    }

    /// Every evaluated estimate with its errors against each ground-truth instance of its
    /// object, keyed by bop_toolkit's error signature: the layout of `--errors-out`.
    pub fn error_rows(&self) -> Vec<serde_json::Value> {
        self.errors
            .iter()
            .map(|e| {
                let errors: serde_json::Map<String, serde_json::Value> = self
                    .columns
                    .iter()
                    .enumerate()
                    .map(|(c, col)| (col.signature.clone(), serde_json::json!(e.errors[c])))
                    .collect();
                serde_json::json!({
                    "scene_id": e.scene_id, "im_id": e.im_id, "obj_id": e.obj_id,
                    "est_id": e.est_id, "score": e.score, "gt_ids": e.gt_ids, "errors": errors,
                })
            })
            .collect()
    }

    /// Full scores of one error column at one threshold of correctness (normalised as the
    /// protocol normalises that error).
    pub fn scores(
        &self,
        dataset: &Dataset,
        protocol: &Protocol,
        column: usize,
        threshold: f64,
    ) -> Scores {
        let object_ids: Vec<u32> = dataset.objects.keys().copied().collect();
        let scene_ids: Vec<u32> = dataset.scenes.keys().copied().collect();
        let kind = &protocol.errors[self.columns[column].error].kind;
        localization_scores(
            &self.images,
            &self.errors,
            &object_ids,
            &scene_ids,
            protocol.n_top,
            threshold,
            |e, i| normalised_error(dataset, kind, e, e.errors[column][i]),
        )
        .scores
    }
}

/// Evaluates `results` on `dataset` under `protocol`. Stops early with `Error::Cancelled`
/// when `cancel` is set.
pub fn evaluate(
    dataset: &Dataset,
    results: &Results,
    protocol: &Protocol,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<Evaluation> {
    evaluate_prepared(dataset, results, protocol, None, progress, cancel)
}

/// [`evaluate`], reading each image's depth and ground-truth renders from `prepared` (opened
/// for this dataset's content) instead of computing them; the scores are the same bit for bit.
/// An image whose prepared file is refused is computed from the dataset, and the file is
/// recorded in [`Prepared::damaged`].
pub fn evaluate_prepared(
    dataset: &Dataset,
    results: &Results,
    protocol: &Protocol,
    prepared: Option<&Prepared>,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<Evaluation> {
    protocol.validate().map_err(Error::Parameters)?;
    supported_errors::check_errors(dataset, protocol)?;
    if dataset.targets_form == TargetsForm::Images {
        return Err(Error::format(
            &dataset.targets_path,
            format!(
                "a list of images (BOP'24 detection targets) cannot be evaluated per object by \
                 {}: expected targets as in test_targets_bop19.json, or score with bop24",
                protocol.name.as_str()
            ),
        ));
    }
    let columns = columns(protocol);
    let selection = select_estimates(dataset, results, protocol.n_top);
    progress.start(selection.evaluated as u64);

    let objects = ObjectData::prepare(dataset, protocol);
    let ctx = Context {
        dataset,
        results,
        protocol,
        columns: &columns,
        objects: &objects,
        prepared,
    };
    let per_image: Vec<Vec<EstimateErrors>> = selection
        .images
        .par_iter()
        .map(|work| {
            if cancel.load(Ordering::Relaxed) {
                return Err(Error::Cancelled);
            }
            let errs = ctx.image_errors(work)?;
            progress.advance(errs.len() as u64);
            Ok(errs)
        })
        .collect::<Result<_>>()?;

    // Flatten, remembering where each (image, object)'s estimates went.
    let mut errors = Vec::with_capacity(selection.evaluated);
    let mut scored = Vec::with_capacity(selection.images.len());
    for (work, errs) in selection.images.iter().zip(per_image) {
        let image = &dataset.scenes[&work.scene_id].images[&work.im_id];
        let valid = valid_gts(image, &work.targets, protocol.visib_gt_min);
        let mut estimates: Vec<(u32, Vec<usize>)> = work
            .targets
            .iter()
            .map(|&(obj, _)| (obj, Vec::new()))
            .collect();
        for e in errs {
            if let Some(slot) = estimates.iter_mut().find(|(o, _)| *o == e.obj_id) {
                slot.1.push(errors.len());
            }
            errors.push(e);
        }
        scored.push(ScoredImage {
            scene_id: work.scene_id,
            im_id: work.im_id,
            gts: image
                .gt
                .iter()
                .zip(valid)
                .map(|(g, v)| (g.obj_id, g.visib_fract, v))
                .collect(),
            estimates,
        });
    }

    let (report, counts) = report::build(
        dataset, results, protocol, &columns, &scored, &errors, &selection,
    );
    Ok(Evaluation {
        report,
        columns,
        errors,
        images: scored,
        counts,
    })
}

/// What every error needs of an object, computed once per evaluation.
struct ObjectData {
    /// Meshes prepared for rendering (closedness proven once), for VSD.
    models: HashMap<u32, Model>,
    symmetries: HashMap<u32, Vec<Pose>>,
}

impl ObjectData {
    fn prepare(dataset: &Dataset, protocol: &Protocol) -> Self {
        let needs_syms = protocol
            .errors
            .iter()
            .any(|e| matches!(e.kind, ErrorKind::Mssd | ErrorKind::Mspd));
        ObjectData {
            models: if protocol.vsd().is_some() {
                dataset
                    .objects
                    .iter()
                    .map(|(&id, o)| (id, Model::new(&o.mesh)))
                    .collect()
            } else {
                HashMap::new()
            },
            symmetries: if needs_syms {
                dataset
                    .objects
                    .iter()
                    .map(|(&id, o)| {
                        let syms = pose_error::symmetry_transformations(
                            &o.info,
                            protocol.max_sym_disc_step,
                        );
                        (id, syms)
                    })
                    .collect()
            } else {
                HashMap::new()
            },
        }
    }
}

struct Context<'a> {
    dataset: &'a Dataset,
    results: &'a Results,
    protocol: &'a Protocol,
    columns: &'a [Column],
    objects: &'a ObjectData,
    prepared: Option<&'a Prepared>,
}

/// The renders VSD needs in one image, made before the test depth image is available.
#[derive(Default)]
struct ImageRenders {
    /// Per estimate (index into the results), its render.
    estimates: HashMap<usize, DepthWindow>,
    /// Per ground-truth instance, its render.
    gts: HashMap<usize, DepthWindow>,
    /// (estimate, ground truth) pairs whose VSD must be computed; every other pair's is 1.
    pairs: HashSet<(usize, usize)>,
}

impl ImageRenders {
    /// The image rows some render covers.
    fn rows(&self) -> std::ops::Range<u32> {
        let (y0, y1) = self
            .estimates
            .values()
            .chain(self.gts.values())
            .filter(|w| !w.is_empty())
            .fold((u32::MAX, 0), |(y0, y1), w| {
                (y0.min(w.y0), y1.max(w.y0 + w.height))
            });
        y0.min(y1)..y1
    }

    /// The pixels each render covers.
    fn boxes(&self) -> Vec<PixelBox> {
        self.estimates
            .values()
            .chain(self.gts.values())
            .filter_map(PixelBox::of_window)
            .collect()
    }
}

impl Context<'_> {
    /// The (object, estimate, ground truth) triples of an image whose VSD needs renders. A pair
    /// needs nothing when the projected bounding spheres (bop_toolkit's test) or the screen
    /// boxes of the two renders do not overlap: no pixel is then in both, and the error is 1
    /// for every tau.
    fn vsd_pairs(
        &self,
        work: &ImageWork,
        image: &Image,
        size: (u32, u32),
    ) -> Vec<(u32, usize, usize)> {
        let (w, h) = size;
        let mut pairs = Vec::new();
        for (obj_id, ests) in &work.estimates {
            let model = &self.objects.models[obj_id];
            let radius = 0.5 * self.dataset.objects[obj_id].info.diameter;
            let gts: Vec<(usize, Option<PixelBox>)> = image
                .gt
                .iter()
                .enumerate()
                .filter(|(_, g)| g.obj_id == *obj_id)
                .map(|(i, g)| (i, screen_box(model, &g.pose, &image.camera, w, h)))
                .collect();
            for &(idx, _) in ests {
                let pose = &self.results.estimates[idx].pose;
                let Some(est_box) = screen_box(model, pose, &image.camera, w, h) else {
                    continue;
                };
                for &(gi, gt_box) in &gts {
                    if sphere_projections_overlap(radius, &pose.t, &image.gt[gi].pose.t)
                        && gt_box.is_some_and(|b| b.overlaps(&est_box))
                    {
                        pairs.push((*obj_id, idx, gi));
                    }
                }
            }
        }
        pairs
    }

    /// Renders each estimate of `pairs` once, and takes each ground truth's render from
    /// `gt_render` (which renders it, or reads it from a prepared file).
    fn render_pairs<E>(
        &self,
        pairs: &[(u32, usize, usize)],
        image: &Image,
        size: (u32, u32),
        mut gt_render: impl FnMut(&mut Renderer, &Model, usize) -> std::result::Result<DepthWindow, E>,
    ) -> std::result::Result<ImageRenders, E> {
        let mut renders = ImageRenders::default();
        let mut renderer = Renderer::new();
        let (w, h) = size;
        for &(obj_id, idx, gi) in pairs {
            let model = &self.objects.models[&obj_id];
            renders.pairs.insert((idx, gi));
            renders.estimates.entry(idx).or_insert_with(|| {
                let pose = &self.results.estimates[idx].pose;
                renderer.render_model(model, pose, &image.camera, w, h)
            });
            if let std::collections::hash_map::Entry::Vacant(slot) = renders.gts.entry(gi) {
                slot.insert(gt_render(&mut renderer, model, gi)?);
            }
        }
        Ok(renders)
    }

    /// The test image and the renders of `pairs` (found at `size`), from the dataset: the
    /// depth image is decoded only down to the last row a render covers (see `DepthPng`); its
    /// header comes first, as the renders must be made at its size.
    fn read_dataset(
        &self,
        work: &ImageWork,
        image: &Image,
        size: (u32, u32),
        pairs: Vec<(u32, usize, usize)>,
    ) -> Result<(TestImage, ImageRenders)> {
        let png = self.dataset.open_depth(work.scene_id, work.im_id)?;
        let actual = png.size();
        // A depth image of another size than the camera files state: render at its size.
        let pairs = if actual == size {
            pairs
        } else {
            self.vsd_pairs(work, image, actual)
        };
        let (w, h) = actual;
        let renders = self.render_pairs(&pairs, image, actual, |renderer, model, gi| {
            Ok::<_, Error>(renderer.render_model(model, &image.gt[gi].pose, &image.camera, w, h))
        })?;
        let test = TestImage::from_rows(png.read_rows(renders.rows())?, &image.camera);
        Ok((test, renders))
    }

    /// The same from a prepared image: its depth tiles and ground-truth renders are read, not
    /// computed.
    fn read_prepared(
        &self,
        prepared: &PreparedImage,
        work: &ImageWork,
        image: &Image,
        size: (u32, u32),
        pairs: Vec<(u32, usize, usize)>,
    ) -> std::result::Result<(TestImage, ImageRenders), String> {
        let actual = prepared.size();
        let pairs = if actual == size {
            pairs
        } else {
            self.vsd_pairs(work, image, actual)
        };
        let renders = self.render_pairs(&pairs, image, actual, |_, _, gi| prepared.gt(gi))?;
        let test = TestImage::from_region(prepared.region(&renders.boxes())?, &image.camera);
        Ok((test, renders))
    }

    fn image_errors(&self, work: &ImageWork) -> Result<Vec<EstimateErrors>> {
        let image = &self.dataset.scenes[&work.scene_id].images[&work.im_id];
        let size = self.dataset.image_size;
        let pairs = match self.protocol.vsd() {
            Some(_) => self.vsd_pairs(work, image, size),
            None => Vec::new(),
        };
        // The depth image is read only when some pair needs it.
        let (test, mut renders) = if pairs.is_empty() {
            (None, ImageRenders::default())
        } else {
            let from_prepared = self.prepared.and_then(|prepared| {
                prepared
                    .image(work.scene_id, work.im_id)
                    .and_then(|p| self.read_prepared(&p, work, image, size, pairs.clone()))
                    .map_err(|problem| prepared.note_damaged(problem))
                    .ok()
            });
            let (test, renders) = match from_prepared {
                Some(done) => done,
                None => self.read_dataset(work, image, size, pairs)?,
            };
            (Some(test), renders)
        };
        let mut pts_scratch = Vec::new();
        let mut px_scratch = Vec::new();
        let mut gt_views: HashMap<usize, GtView> = HashMap::new();
        let mut out = Vec::new();

        for (obj_id, ests) in &work.estimates {
            let object = &self.dataset.objects[obj_id];
            let diameter = object.info.diameter;
            let gt_ids: Vec<u32> = image
                .gt
                .iter()
                .enumerate()
                .filter(|(_, g)| g.obj_id == *obj_id)
                .map(|(i, _)| i as u32)
                .collect();
            for &(idx, est_id) in ests {
                let est = &self.results.estimates[idx];
                let mut errors = vec![vec![0.0; gt_ids.len()]; self.columns.len()];
                for (gi, &gt_id) in gt_ids.iter().enumerate() {
                    let gt = &image.gt[gt_id as usize];
                    let mut c = 0;
                    for spec in &self.protocol.errors {
                        match &spec.kind {
                            ErrorKind::Vsd(params) => {
                                let n = params.taus.len();
                                let mut vals = vec![1.0; n];
                                let gt_id = gt_id as usize;
                                if let (Some(test), true) =
                                    (&test, renders.pairs.contains(&(idx, gt_id)))
                                {
                                    let view = gt_views.entry(gt_id).or_insert_with(|| {
                                        let r = renders.gts.remove(&gt_id).unwrap_or_default();
                                        GtView::new(test, r, params)
                                    });
                                    let est_depth = &renders.estimates[&idx];
                                    vsd(test, view, est_depth, diameter, params, &mut vals);
                                }
                                for v in vals {
                                    errors[c][gi] = v;
                                    c += 1;
                                }
                                continue;
                            }
                            ErrorKind::Mssd => {
                                errors[c][gi] =
                                    if spheres_overlap(&est.pose.t, &gt.pose.t, diameter) {
                                        pose_error::mssd(
                                            &est.pose,
                                            &gt.pose,
                                            &object.mesh.vertices,
                                            &self.objects.symmetries[obj_id],
                                            &mut pts_scratch,
                                        )
                                    } else {
                                        f64::INFINITY
                                    };
                            }
                            ErrorKind::Mspd => {
                                let (pts, syms) =
                                    (&object.mesh.vertices, &self.objects.symmetries[obj_id]);
                                errors[c][gi] = match &image.fisheye {
                                    Some(cam) => pose_error::mspd_fisheye(
                                        &est.pose,
                                        &gt.pose,
                                        cam,
                                        pts,
                                        syms,
                                        &mut px_scratch,
                                    ),
                                    None => pose_error::mspd(
                                        &est.pose,
                                        &gt.pose,
                                        &image.camera,
                                        pts,
                                        syms,
                                        &mut px_scratch,
                                    ),
                                };
                            }
                            kind @ (ErrorKind::Add | ErrorKind::Adi | ErrorKind::Ad) => {
                                errors[c][gi] =
                                    if !spheres_overlap(&est.pose.t, &gt.pose.t, diameter) {
                                        f64::INFINITY
                                    } else if matches!(kind, ErrorKind::Adi)
                                        || (matches!(kind, ErrorKind::Ad)
                                            && object.info.is_symmetric())
                                    {
                                        pose_error::adi(&est.pose, &gt.pose, &object.mesh.vertices)
                                    } else {
                                        pose_error::add(&est.pose, &gt.pose, &object.mesh.vertices)
                                    };
                            }
                        }
                        c += 1;
                    }
                }
                out.push(EstimateErrors {
                    scene_id: work.scene_id,
                    im_id: work.im_id,
                    obj_id: *obj_id,
                    est_id,
                    score: est.score,
                    gt_ids: gt_ids.clone(),
                    errors,
                });
            }
            // GT renders are per object instance; free them once the object is done.
            gt_views.clear();
        }
        Ok(out)
    }
}
