//! Greedy matching of estimates to ground-truth instances (bop_toolkit's `pose_matching.py`):
//! in decreasing score order, each estimate takes the not yet matched valid instance with the
//! lowest error, if that error is strictly below the threshold of correctness.

use crate::dataset::Image;

/// Which estimates count per target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NTop {
    /// The `n` highest-scored estimates (the paper: 1).
    Top(u32),
    /// As many as the target has instances (bop_toolkit's `-1`).
    InstCount,
    /// Every estimate (bop_toolkit's `0`).
    All,
}

impl NTop {
    /// bop_toolkit's integer encoding, used in reports and flags.
    pub fn as_i64(self) -> i64 {
        match self {
            NTop::Top(n) => n as i64,
            NTop::InstCount => -1,
            NTop::All => 0,
        }
    }

    /// How many of a target's estimates count, for a target with `inst_count` instances.
    pub fn keep(self, inst_count: u32) -> usize {
        match self {
            NTop::Top(n) => n as usize,
            NTop::InstCount => inst_count as usize,
            NTop::All => usize::MAX,
        }
    }

    /// How many of an object's `instances` valid instances in one image are targets: at most
    /// n for `Top(n)`, all of them otherwise.
    pub fn targets(self, instances: usize) -> usize {
        match self {
            NTop::Top(n) => instances.min(n as usize),
            NTop::InstCount | NTop::All => instances,
        }
    }

    pub fn from_i64(n: i64) -> Result<Self, String> {
        match n {
            -1 => Ok(NTop::InstCount),
            0 => Ok(NTop::All),
            n if n > 0 && n <= u32::MAX as i64 => Ok(NTop::Top(n as u32)),
            n => Err(format!("n_top must be -1, 0 or positive, not {n}")),
        }
    }
}

/// The errors of one evaluated estimate against every ground-truth instance of its object in
/// its image (instances in increasing gt id order, also the invisible ones).
#[derive(Clone, Debug)]
pub struct EstimateErrors {
    pub scene_id: u32,
    pub im_id: u32,
    pub obj_id: u32,
    /// Index of the estimate among the rows of its (scene, image, object), in file order.
    pub est_id: u32,
    pub score: f64,
    pub gt_ids: Vec<u32>,
    /// `errors[column][i]`: the raw error of column `column` against `gt_ids[i]` (a column per
    /// VSD tau, then one per other error type).
    pub errors: Vec<Vec<f64>>,
}

/// Which ground-truth instances of an image are expected to be found.
///
/// With `visib_gt_min >= 0`, the instances of target objects visible at least that much; with
/// a negative value, the `inst_count` most visible instances of each target object (ties broken
/// by the lower gt id, as Python's stable sort does).
pub fn valid_gts(image: &Image, targets: &[(u32, u32)], visib_gt_min: f64) -> Vec<bool> {
    let inst_count = |obj: u32| targets.iter().find(|t| t.0 == obj).map(|t| t.1);
    if visib_gt_min >= 0.0 {
        return image
            .gt
            .iter()
            .map(|g| inst_count(g.obj_id).is_some() && g.visib_fract >= visib_gt_min)
            .collect();
    }
    let mut order: Vec<usize> = (0..image.gt.len()).collect();
    order.sort_by(|&a, &b| {
        image.gt[b]
            .visib_fract
            .partial_cmp(&image.gt[a].visib_fract)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut to_add: Vec<(u32, u32)> = targets.to_vec();
    let mut valid = vec![false; image.gt.len()];
    for gt_id in order {
        let obj = image.gt[gt_id].obj_id;
        if let Some(slot) = to_add.iter_mut().find(|t| t.0 == obj && t.1 > 0) {
            valid[gt_id] = true;
            slot.1 -= 1;
        }
    }
    valid
}

/// Matches the estimates of one (image, object), given in decreasing score order, and marks the
/// matched instances in `matched` (indexed by gt id). `error` gives the normalised error of an
/// estimate against the instance at position `i` of its `gt_ids`. Returns the matches as
/// (position of the estimate in `ests`, gt id), for those who need to know which estimate
/// found which instance (the outcomes of single targets), not only how many were found.
pub fn match_image_object<'a>(
    ests: impl IntoIterator<Item = &'a EstimateErrors>,
    n_top: NTop,
    threshold: f64,
    valid: &[bool],
    matched: &mut [bool],
    error: impl Fn(&EstimateErrors, usize) -> f64,
) -> Vec<(usize, usize)> {
    let limit = match n_top {
        NTop::Top(n) => n as usize,
        NTop::InstCount | NTop::All => usize::MAX,
    };
    let mut matches = Vec::new();
    for (position, est) in ests.into_iter().take(limit).enumerate() {
        let mut best: Option<usize> = None;
        let mut best_error = threshold;
        for (i, &gt_id) in est.gt_ids.iter().enumerate() {
            let g = gt_id as usize;
            if !valid[g] || matched[g] {
                continue;
            }
            let e = error(est, i);
            if e < best_error {
                best = Some(g);
                best_error = e;
            }
        }
        if let Some(g) = best {
            matched[g] = true;
            matches.push((position, g));
        }
    }
    matches
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::GtInstance;
    use crate::math::{Intrinsics, Pose};

    fn image(visib: &[(u32, f64)]) -> Image {
        Image {
            id: 0,
            camera: Intrinsics::from_row_major(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
            fisheye: None,
            depth_scale: 1.0,
            gt: visib
                .iter()
                .map(|&(obj_id, visib_fract)| GtInstance {
                    obj_id,
                    pose: Pose::identity(),
                    visib_fract,
                })
                .collect(),
        }
    }

    fn est(score: f64, errors: Vec<f64>) -> EstimateErrors {
        EstimateErrors {
            scene_id: 1,
            im_id: 0,
            obj_id: 5,
            est_id: 0,
            score,
            gt_ids: (0..errors.len() as u32).collect(),
            errors: vec![errors],
        }
    }

    #[test]
    fn validity_by_minimum_visibility_and_by_instance_count() {
        let im = image(&[(5, 0.05), (5, 0.6), (7, 0.9), (5, 0.6)]);
        assert_eq!(
            valid_gts(&im, &[(5, 2)], 0.1),
            vec![false, true, false, true]
        );
        // The inst_count most visible of each target object; ties go to the lower gt id.
        assert_eq!(
            valid_gts(&im, &[(5, 1)], -1.0),
            vec![false, true, false, false]
        );
        assert_eq!(
            valid_gts(&im, &[(5, 3), (7, 1)], -1.0),
            vec![true, true, true, true]
        );
    }

    #[test]
    fn greedy_matching_takes_the_lowest_error_strictly_below_the_threshold() {
        let ests = [est(0.9, vec![0.2, 0.1]), est(0.8, vec![0.25, 0.05])];
        let mut matched = vec![false; 2];
        let err = |e: &EstimateErrors, i: usize| e.errors[0][i];
        let matches = match_image_object(&ests, NTop::All, 0.3, &[true, true], &mut matched, err);
        // The first estimate takes gt 1 (0.1), the second gets gt 0 (0.25 < 0.3).
        assert_eq!(matched, vec![true, true]);
        assert_eq!(matches, vec![(0, 1), (1, 0)]);

        let mut matched = vec![false; 2];
        match_image_object(&ests, NTop::All, 0.25, &[true, true], &mut matched, err);
        assert_eq!(
            matched,
            vec![false, true],
            "0.25 is not strictly below 0.25"
        );

        let mut matched = vec![false; 2];
        match_image_object(&ests, NTop::Top(1), 0.3, &[true, true], &mut matched, err);
        assert_eq!(
            matched,
            vec![false, true],
            "only the top estimate is considered"
        );

        let mut matched = vec![false; 2];
        match_image_object(&ests, NTop::All, 0.3, &[true, false], &mut matched, err);
        assert_eq!(
            matched,
            vec![true, false],
            "invalid instances are never matched"
        );
    }
}
