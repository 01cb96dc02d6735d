//! Which estimates count for which target, decided in one place: the pipeline evaluates what
//! this selects, and the pre-flight check of an upload and `poseboard check-results` report the
//! same coverage before any evaluation, so that the three can never disagree.

use std::collections::{BTreeMap, HashMap, HashSet};

use crate::dataset::{Dataset, Target};
use crate::matching::NTop;
use crate::results::Results;

/// How a result file covers a dataset's test targets.
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// Distinct targets `(scene, image, object, inst_count)`, in the targets file's order.
    targets: Vec<(u32, u32, u32, u32)>,
    /// Per target, the indices of its estimates in the result file, in file order.
    rows: HashMap<(u32, u32, u32), Vec<usize>>,
    pub targets_without_estimate: usize,
    /// Estimates for images or objects that are not test targets (ignored, as bop_toolkit does).
    pub estimates_ignored: usize,
    /// Of the ignored ones, estimates for an object that does not appear in its image at all.
    pub estimates_for_absent_objects: usize,
    /// Distinct images with at least one estimate.
    pub images_with_estimates: usize,
}

impl Coverage {
    pub fn of(dataset: &Dataset, results: &Results) -> Coverage {
        let mut targets = Vec::with_capacity(dataset.targets.len());
        let mut rows: HashMap<(u32, u32, u32), Vec<usize>> = HashMap::new();
        for t in &dataset.targets {
            let key = (t.scene_id, t.im_id, t.obj_id);
            // A duplicated target line adds nothing.
            if let std::collections::hash_map::Entry::Vacant(slot) = rows.entry(key) {
                slot.insert(Vec::new());
                targets.push((t.scene_id, t.im_id, t.obj_id, t.inst_count));
            }
        }
        let (mut ignored, mut absent) = (0, 0);
        let mut images = HashSet::new();
        for (i, e) in results.estimates.iter().enumerate() {
            images.insert((e.scene_id, e.im_id));
            match rows.get_mut(&(e.scene_id, e.im_id, e.obj_id)) {
                Some(list) => list.push(i),
                None => {
                    ignored += 1;
                    let in_image = dataset
                        .scenes
                        .get(&e.scene_id)
                        .and_then(|s| s.images.get(&e.im_id))
                        .is_some_and(|im| im.gt.iter().any(|g| g.obj_id == e.obj_id));
                    absent += usize::from(!in_image);
                }
            }
        }
        Coverage {
            targets_without_estimate: rows.values().filter(|r| r.is_empty()).count(),
            targets,
            rows,
            estimates_ignored: ignored,
            estimates_for_absent_objects: absent,
            images_with_estimates: images.len(),
        }
    }

    /// The number of distinct test targets.
    pub fn targets(&self) -> usize {
        self.targets.len()
    }

    /// Estimates for targets beyond the `n_top` highest-scored ones each target considers.
    pub fn beyond_n_top(&self, n_top: NTop) -> usize {
        self.targets
            .iter()
            .map(|&(s, i, o, inst)| self.rows[&(s, i, o)].len().saturating_sub(n_top.keep(inst)))
            .sum()
    }
}

/// The estimates each target considers, grouped by image.
pub(crate) struct Selection {
    pub images: Vec<ImageWork>,
    /// Estimates evaluated (the first n_top of each target).
    pub evaluated: usize,
    /// Estimates for images or objects that are not test targets.
    pub ignored: usize,
    /// Targets with no estimate at all.
    pub targets_without_estimate: usize,
}

pub(crate) struct ImageWork {
    pub scene_id: u32,
    pub im_id: u32,
    /// (object, inst_count) of the image's targets, in the targets file's order.
    pub targets: Vec<(u32, u32)>,
    /// Per target object: (index into the results, est_id) in decreasing score order.
    pub estimates: Vec<(u32, Vec<(usize, u32)>)>,
}

/// Selects, per target, its `n_top` highest-scored estimates (ties keep file order, as Python's
/// `sorted(reverse=True)` does), grouped by image.
pub(crate) fn select_estimates(dataset: &Dataset, results: &Results, n_top: NTop) -> Selection {
    let coverage = Coverage::of(dataset, results);
    let mut images: BTreeMap<(u32, u32), ImageWork> = BTreeMap::new();
    let mut evaluated = 0;
    for &(scene_id, im_id, obj_id, inst_count) in &coverage.targets {
        let work = images
            .entry((scene_id, im_id))
            .or_insert_with(|| ImageWork {
                scene_id,
                im_id,
                targets: Vec::new(),
                estimates: Vec::new(),
            });
        work.targets.push((obj_id, inst_count));
        let idx = &coverage.rows[&(scene_id, im_id, obj_id)];
        if idx.is_empty() {
            continue;
        }
        let sorted = top(results, idx, n_top.keep(inst_count));
        evaluated += sorted.len();
        work.estimates.push((obj_id, sorted));
    }
    Selection {
        images: images.into_values().collect(),
        evaluated,
        ignored: coverage.estimates_ignored,
        targets_without_estimate: coverage.targets_without_estimate,
    }
}

/// The first `keep` of a target's rows `idx` (indices into the results, in file order) by
/// decreasing score, ties in file order, as Python's `sorted(reverse=True)` keeps them; each
/// with its est_id, the position among the target's rows.
fn top(results: &Results, idx: &[usize], keep: usize) -> Vec<(usize, u32)> {
    let mut sorted: Vec<(usize, u32)> = idx
        .iter()
        .enumerate()
        .map(|(est_id, &i)| (i, est_id as u32))
        .collect();
    sorted.sort_by(|a, b| {
        let (sa, sb) = (results.estimates[a.0].score, results.estimates[b.0].score);
        sb.partial_cmp(&sa).unwrap_or(std::cmp::Ordering::Equal)
    });
    sorted.truncate(keep);
    sorted
}

/// The estimates (indices into the results) the evaluation of `target` considers under
/// `n_top`, in decreasing score order.
pub fn target_estimates(results: &Results, target: &Target, n_top: NTop) -> Vec<usize> {
    let key = (target.scene_id, target.im_id, target.obj_id);
    let idx: Vec<usize> = results
        .estimates
        .iter()
        .enumerate()
        .filter(|(_, e)| (e.scene_id, e.im_id, e.obj_id) == key)
        .map(|(i, _)| i)
        .collect();
    top(results, &idx, n_top.keep(target.inst_count))
        .into_iter()
        .map(|(i, _)| i)
        .collect()
}
