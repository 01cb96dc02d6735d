//! Recall of the 6D localisation task (bop_toolkit's `score.calc_localization_scores`): the
//! fraction of expected instances matched by a correct estimate, overall, per object and per
//! scene, and the means the reference reports (with numpy's summation order, so that means
//! agree to the last bit).

use std::collections::BTreeMap;

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize};

use crate::matching::{EstimateErrors, NTop, match_image_object};
use crate::stats::{mean, recall};

/// A target image ready for scoring.
#[derive(Clone, Debug)]
pub struct ScoredImage {
    pub scene_id: u32,
    pub im_id: u32,
    /// Per gt id: object, visible fraction, and whether it is expected to be found.
    pub gts: Vec<(u32, f64, bool)>,
    /// Per target object of the image, the indices (into the errors slice) of its evaluated
    /// estimates in decreasing score order.
    pub estimates: Vec<(u32, Vec<usize>)>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    pub recall: f64,
    #[serde(deserialize_with = "id_keyed")]
    pub obj_recalls: BTreeMap<u32, f64>,
    pub mean_obj_recall: f64,
    #[serde(deserialize_with = "id_keyed")]
    pub scene_recalls: BTreeMap<u32, f64>,
    pub mean_scene_recall: f64,
    pub gt_count: usize,
    pub targets_count: usize,
    pub tp_count: usize,
}

/// Reads a map keyed by object or scene id. The report flattens `Scores` into itself, and
/// through `#[serde(flatten)]` serde hands JSON keys over as strings that its integer
/// deserializer refuses, so a stored report would come back without its scores.
fn id_keyed<'de, D: Deserializer<'de>>(d: D) -> Result<BTreeMap<u32, f64>, D::Error> {
    BTreeMap::<String, f64>::deserialize(d)?
        .into_iter()
        .map(|(k, v)| k.parse().map(|k| (k, v)).map_err(D::Error::custom))
        .collect()
}

/// Everything matching produced for one threshold: the scores and, per image and gt id,
/// whether the instance was matched (for the recall-vs-visibility curve), and per image its
/// targets and true positives (what the recall sums, for the bootstrap of [`crate::bootstrap`]).
pub struct Scored {
    pub scores: Scores,
    pub matched: Vec<Vec<bool>>,
    pub image_targets: Vec<u32>,
    pub image_tps: Vec<u32>,
}

/// The instances of one image that count as targets, given which were matched: per object,
/// its valid instances up to n_top of them, the matched ones first, then the most visible of
/// the rest (ties: the lower gt id). Every matched instance is among them, so the matched ones
/// over these are the recall's true positives over its targets; the visibility curve and the
/// outcomes of single targets both count these.
pub fn counted_instances(gts: &[(u32, f64, bool)], matched: &[bool], n_top: NTop) -> Vec<usize> {
    let mut per_obj: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (gt_id, g) in gts.iter().enumerate().filter(|(_, g)| g.2) {
        per_obj.entry(g.0).or_default().push(gt_id);
    }
    let mut counted = Vec::new();
    for mut gt_ids in per_obj.into_values() {
        let targets = n_top.targets(gt_ids.len());
        // Stable: equal keys keep the lower gt id first.
        gt_ids.sort_by(|&a, &b| {
            matched[b]
                .cmp(&matched[a])
                .then(gts[b].1.total_cmp(&gts[a].1))
        });
        counted.extend_from_slice(&gt_ids[..targets]);
    }
    counted
}

/// Scores at one threshold. `object_ids` and `scene_ids` are every object and scene of the
/// dataset: like the reference, one without targets reports recall 0 and counts in the means.
pub fn localization_scores(
    images: &[ScoredImage],
    errors: &[EstimateErrors],
    object_ids: &[u32],
    scene_ids: &[u32],
    n_top: NTop,
    threshold: f64,
    error: impl Fn(&EstimateErrors, usize) -> f64 + Copy,
) -> Scored {
    Targets::new(images, object_ids, scene_ids, n_top).scores(errors, threshold, error)
}

/// What matching at one threshold has counted so far.
struct Tally {
    obj_tps: BTreeMap<u32, usize>,
    scene_tps: BTreeMap<u32, usize>,
    tps: usize,
    matched: Vec<Vec<bool>>,
    image_tps: Vec<u32>,
}

/// The targets of the images, counted once: they do not depend on the threshold, and a
/// report scores at up to 120 thresholds.
pub struct Targets<'a> {
    images: &'a [ScoredImage],
    n_top: NTop,
    /// Per image, per gt id: whether the instance is expected to be found.
    valid: Vec<Vec<bool>>,
    obj_targets: BTreeMap<u32, usize>,
    scene_targets: BTreeMap<u32, usize>,
    /// Per image, its targets.
    image_targets: Vec<u32>,
    targets: usize,
    gt_count: usize,
}

impl<'a> Targets<'a> {
    /// `object_ids` and `scene_ids` are every object and scene of the dataset: like the
    /// reference, one without targets reports recall 0 and counts in the means.
    pub fn new(
        images: &'a [ScoredImage],
        object_ids: &[u32],
        scene_ids: &[u32],
        n_top: NTop,
    ) -> Self {
        let mut obj_targets: BTreeMap<u32, usize> = object_ids.iter().map(|&o| (o, 0)).collect();
        let mut scene_targets: BTreeMap<u32, usize> = scene_ids.iter().map(|&s| (s, 0)).collect();
        let (mut targets, mut gt_count) = (0usize, 0usize);
        let mut valid = Vec::with_capacity(images.len());
        let mut image_targets = Vec::with_capacity(images.len());
        for im in images {
            let targets_before = targets;
            gt_count += im.gts.len();
            valid.push(im.gts.iter().map(|g| g.2).collect());
            // Per object of the image, its valid instances, at most n_top of them.
            let mut per_obj: BTreeMap<u32, usize> = BTreeMap::new();
            for g in im.gts.iter().filter(|g| g.2) {
                *per_obj.entry(g.0).or_default() += 1;
            }
            for (obj, count) in per_obj {
                let count = n_top.targets(count);
                targets += count;
                *obj_targets.entry(obj).or_default() += count;
                *scene_targets.entry(im.scene_id).or_default() += count;
            }
            image_targets.push((targets - targets_before) as u32);
        }
        Targets {
            images,
            n_top,
            valid,
            obj_targets,
            scene_targets,
            image_targets,
            targets,
            gt_count,
        }
    }

    /// Scores at one threshold of correctness.
    pub fn scores(
        &self,
        errors: &[EstimateErrors],
        threshold: f64,
        error: impl Fn(&EstimateErrors, usize) -> f64 + Copy,
    ) -> Scored {
        let mut scored = self.scores_at(errors, &[threshold], error);
        scored.swap_remove(0)
    }

    /// Scores at each of `thresholds`, in their order. Every image is matched at every
    /// threshold while its estimates' errors are in the cache: a report scores up to 120
    /// thresholds, and visiting all estimates once per threshold was bound by memory.
    pub fn scores_at(
        &self,
        errors: &[EstimateErrors],
        thresholds: &[f64],
        error: impl Fn(&EstimateErrors, usize) -> f64 + Copy,
    ) -> Vec<Scored> {
        let mut tallies: Vec<Tally> = thresholds
            .iter()
            .map(|_| Tally {
                obj_tps: self.obj_targets.keys().map(|&o| (o, 0)).collect(),
                scene_tps: self.scene_targets.keys().map(|&s| (s, 0)).collect(),
                tps: 0,
                matched: Vec::with_capacity(self.images.len()),
                image_tps: Vec::with_capacity(self.images.len()),
            })
            .collect();
        for (im, valid) in self.images.iter().zip(&self.valid) {
            for (tally, &threshold) in tallies.iter_mut().zip(thresholds) {
                let tps_before = tally.tps;
                let mut matched = vec![false; im.gts.len()];
                for (_, ests) in &im.estimates {
                    match_image_object(
                        ests.iter().map(|&i| &errors[i]),
                        self.n_top,
                        threshold,
                        valid,
                        &mut matched,
                        error,
                    );
                }
                for (g, _) in im.gts.iter().zip(&matched).filter(|(g, m)| g.2 && **m) {
                    tally.tps += 1;
                    *tally.obj_tps.entry(g.0).or_default() += 1;
                    *tally.scene_tps.entry(im.scene_id).or_default() += 1;
                }
                tally.matched.push(matched);
                tally.image_tps.push((tally.tps - tps_before) as u32);
            }
        }
        tallies.into_iter().map(|t| self.finish(t)).collect()
    }

    fn finish(&self, tally: Tally) -> Scored {
        let (obj_targets, scene_targets) = (&self.obj_targets, &self.scene_targets);
        let Tally {
            obj_tps,
            scene_tps,
            tps,
            matched: all_matched,
            image_tps,
        } = tally;
        let targets = self.targets;
        let gt_count = self.gt_count;

        let obj_recalls: BTreeMap<u32, f64> = obj_targets
            .iter()
            .map(|(&o, &n)| (o, recall(obj_tps[&o], n)))
            .collect();
        let scene_recalls: BTreeMap<u32, f64> = scene_targets
            .iter()
            .map(|(&s, &n)| (s, recall(scene_tps[&s], n)))
            .collect();
        Scored {
            scores: Scores {
                recall: recall(tps, targets),
                mean_obj_recall: mean(&obj_recalls.values().copied().collect::<Vec<_>>()),
                mean_scene_recall: mean(&scene_recalls.values().copied().collect::<Vec<_>>()),
                obj_recalls,
                scene_recalls,
                gt_count,
                targets_count: targets,
                tp_count: tps,
            },
            matched: all_matched,
            image_targets: self.image_targets.clone(),
            image_tps,
        }
    }
}
