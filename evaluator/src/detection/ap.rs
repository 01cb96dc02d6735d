//! Average precision as bop_toolkit's `score.calc_ap` computes it for 6D detection: COCO's
//! 101-point interpolation of the precision-recall curve of the score-sorted estimates.

use crate::stats;

/// The recall points precision is read at: 0, 0.01, ..., 1.
pub const RECALL_POINTS: usize = 101;

/// numpy's `linspace(0, 1, 101)`: `i * 0.01`, the last point exactly 1. The values decide
/// which recalls reach a point (7/100 vs 7 * 0.01), so they are computed as numpy does.
fn recall_point(i: usize) -> f64 {
    if i + 1 == RECALL_POINTS {
        1.0
    } else {
        i as f64 * 0.01
    }
}

/// The interpolated precision at each recall point: the highest precision reached at that
/// recall or above (0 where none is), for estimates in decreasing score order (`true`: a true
/// positive) against `instances` ground-truth instances, which must be at least one.
///
/// bop_toolkit pads the curve with (recall 0, precision 0) and (1, 0) and takes the maximum
/// over the points at or beyond each recall point; the order of points with equal recall does
/// not change a maximum, so the toolkit's unstable `argsort` of the recalls needs no copy.
pub fn interpolated_precision(outcomes: &[bool], instances: usize) -> [f64; RECALL_POINTS] {
    curve(outcomes.iter().copied(), outcomes.len(), instances)
}

/// [`interpolated_precision`] with image `i` counted `weights[i]` times (a bootstrap
/// replicate): each of `ranked`'s estimates, `(image, true positive)`, stands `weights[image]`
/// times in a row, against `instances` counted instances of the replicate. With every weight 1,
/// the same numbers to the last bit.
pub fn weighted_precision(
    ranked: &[(u32, bool)],
    weights: &[u32],
    instances: usize,
) -> [f64; RECALL_POINTS] {
    let copies =
        |&(image, hit): &(u32, bool)| std::iter::repeat_n(hit, weights[image as usize] as usize);
    let len = ranked.iter().map(|r| weights[r.0 as usize] as usize).sum();
    curve(ranked.iter().flat_map(copies), len, instances)
}

fn curve(
    outcomes: impl Iterator<Item = bool>,
    len: usize,
    instances: usize,
) -> [f64; RECALL_POINTS] {
    let n = instances as f64;
    // The padded curve (recall, precision); the recalls never decrease along it.
    let mut recalls = Vec::with_capacity(len + 2);
    let mut precisions = Vec::with_capacity(len + 2);
    recalls.push(0.0);
    precisions.push(0.0);
    let mut tp = 0usize;
    for (i, hit) in outcomes.enumerate() {
        tp += usize::from(hit);
        recalls.push(tp as f64 / n);
        precisions.push(tp as f64 / (i + 1) as f64);
    }
    recalls.push(1.0);
    precisions.push(0.0);
    // The highest precision from each point on.
    for i in (0..precisions.len() - 1).rev() {
        precisions[i] = precisions[i].max(precisions[i + 1]);
    }
    std::array::from_fn(|p| {
        let at = recall_point(p);
        let first = recalls.partition_point(|&r| r < at);
        precisions.get(first).copied().unwrap_or(0.0)
    })
}

/// The mean of the interpolated precisions, with numpy's summation.
pub fn average_precision(curve: &[f64; RECALL_POINTS]) -> f64 {
    stats::mean(curve)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recall_points_are_numpys() {
        assert_eq!(recall_point(0), 0.0);
        assert_eq!(recall_point(7), 0.07);
        assert_eq!(recall_point(29), 0.29);
        assert_eq!(recall_point(100), 1.0);
    }

    #[test]
    fn perfect_and_empty_rankings() {
        let all = interpolated_precision(&[true, true], 2);
        assert!(all.iter().all(|&p| p == 1.0));
        assert_eq!(average_precision(&all), 1.0);
        let none = interpolated_precision(&[], 3);
        assert_eq!(average_precision(&none), 0.0);
        let misses = interpolated_precision(&[false, false], 1);
        assert_eq!(average_precision(&misses), 0.0);
    }

    #[test]
    fn precision_is_the_best_at_or_beyond_each_recall() {
        // bop_toolkit's own example (score.py's __main__): F T T F T F over 6 instances.
        let curve = interpolated_precision(&[false, true, true, false, true, false], 6);
        // Recall 1/6 and 2/6 reach precision 2/3 (the second hit), 3/6 reaches 3/5.
        assert_eq!(curve[0], 2.0 / 3.0);
        assert_eq!(curve[33], 2.0 / 3.0);
        assert_eq!(curve[34], 0.6);
        assert_eq!(curve[50], 0.6);
        assert_eq!(curve[51], 0.0);
        let expected = (34.0 * (2.0 / 3.0) + 17.0 * 0.6) / 101.0;
        assert!((average_precision(&curve) - expected).abs() < 1e-15);
    }

    #[test]
    fn a_recall_equal_to_a_point_reaches_it() {
        // 7 of 100 found: recall 0.07 reaches the point 0.07.
        let mut outcomes = vec![true; 7];
        outcomes.push(false);
        let curve = interpolated_precision(&outcomes, 100);
        assert_eq!(curve[7], 1.0);
        assert_eq!(curve[8], 0.0);
    }
}
