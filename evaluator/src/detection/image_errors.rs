//! The errors BOP'24 thresholds: for each kept estimate of an object present in a target
//! image, its MSSD (mm) and MSPD (px) against every instance of that object in the image.
//! Computed once; every threshold and both MSSD normalisations read them.

use std::collections::{BTreeMap, HashMap};

use crate::dataset::Dataset;
use crate::math::Pose;
use crate::pose_error::{self, spheres_overlap};
use crate::results::Results;

use super::MAX_SYM_DISC_STEP;

/// One target image: its objects in the order of their first instance in the ground truth,
/// each with its kept estimates (indices into the results, in decreasing score).
pub struct ImageWork {
    pub scene_id: u32,
    pub im_id: u32,
    pub objects: Vec<(u32, Vec<usize>)>,
}

impl ImageWork {
    pub fn new(
        dataset: &Dataset,
        scene_id: u32,
        im_id: u32,
        estimates: &HashMap<(u32, u32, u32), Vec<usize>>,
    ) -> Self {
        let image = &dataset.scenes[&scene_id].images[&im_id];
        let mut objects: Vec<(u32, Vec<usize>)> = Vec::new();
        for g in &image.gt {
            if !objects.iter().any(|(o, _)| *o == g.obj_id) {
                let ests = estimates
                    .get(&(scene_id, im_id, g.obj_id))
                    .cloned()
                    .unwrap_or_default();
                objects.push((g.obj_id, ests));
            }
        }
        ImageWork {
            scene_id,
            im_id,
            objects,
        }
    }

    pub fn estimate_count(&self) -> usize {
        self.objects.iter().map(|(_, e)| e.len()).sum()
    }

    pub fn errors(
        &self,
        dataset: &Dataset,
        results: &Results,
        symmetries: &BTreeMap<u32, Vec<Pose>>,
    ) -> ImageErrors {
        let image = &dataset.scenes[&self.scene_id].images[&self.im_id];
        let mut pts_scratch = Vec::new();
        let mut px_scratch = Vec::new();
        let objects = self
            .objects
            .iter()
            .map(|(obj_id, ests)| {
                let object = &dataset.objects[obj_id];
                let syms = &symmetries[obj_id];
                let gt_ids: Vec<usize> = image
                    .gt
                    .iter()
                    .enumerate()
                    .filter(|(_, g)| g.obj_id == *obj_id)
                    .map(|(i, _)| i)
                    .collect();
                let estimates = ests
                    .iter()
                    .map(|&idx| {
                        let est = &results.estimates[idx];
                        let mut mssd = Vec::with_capacity(gt_ids.len());
                        let mut mspd = Vec::with_capacity(gt_ids.len());
                        for &gi in &gt_ids {
                            let gt = &image.gt[gi].pose;
                            mssd.push(
                                if spheres_overlap(&est.pose.t, &gt.t, object.info.diameter) {
                                    pose_error::mssd(
                                        &est.pose,
                                        gt,
                                        &object.mesh.vertices,
                                        syms,
                                        &mut pts_scratch,
                                    )
                                } else {
                                    f64::INFINITY
                                },
                            );
                            let pts = &object.mesh.vertices;
                            mspd.push(match &image.fisheye {
                                Some(cam) => pose_error::mspd_fisheye(
                                    &est.pose,
                                    gt,
                                    cam,
                                    pts,
                                    syms,
                                    &mut px_scratch,
                                ),
                                None => pose_error::mspd(
                                    &est.pose,
                                    gt,
                                    &image.camera,
                                    pts,
                                    syms,
                                    &mut px_scratch,
                                ),
                            });
                        }
                        EstimateErrors {
                            score: est.score,
                            mssd,
                            mspd,
                        }
                    })
                    .collect();
                ObjectErrors {
                    obj_id: *obj_id,
                    gt_ids,
                    estimates,
                }
            })
            .collect();
        ImageErrors {
            scene_id: self.scene_id,
            im_id: self.im_id,
            objects,
        }
    }
}

/// The symmetries of each object some target image holds.
pub fn symmetries(dataset: &Dataset, work: &[ImageWork]) -> BTreeMap<u32, Vec<Pose>> {
    let mut out = BTreeMap::new();
    for w in work {
        for (obj_id, _) in &w.objects {
            out.entry(*obj_id).or_insert_with(|| {
                pose_error::symmetry_transformations(
                    &dataset.objects[obj_id].info,
                    MAX_SYM_DISC_STEP,
                )
            });
        }
    }
    out
}

pub struct ImageErrors {
    pub scene_id: u32,
    pub im_id: u32,
    pub objects: Vec<ObjectErrors>,
}

/// One object of an image: its instances (gt ids) and its estimates in decreasing score.
pub struct ObjectErrors {
    pub obj_id: u32,
    pub gt_ids: Vec<usize>,
    pub estimates: Vec<EstimateErrors>,
}

/// Raw errors against each of the object's instances, in the order of `gt_ids`.
pub struct EstimateErrors {
    pub score: f64,
    pub mssd: Vec<f64>,
    pub mspd: Vec<f64>,
}
