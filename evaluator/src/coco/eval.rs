//! COCOeval for boxes (`bbox`) and masks (`segm`), following `pycocotools/cocoeval.py` of the
//! fork bop_toolkit runs (MartinSmeyer/cocoapi) step by step, so that every AP and AR agrees
//! with it to the last bit:
//!
//! - the fork keeps the ground truth's `ignore` flag (stock pycocotools overwrites it with
//!   `iscrowd`): a detection matched to an ignored instance is neither a true nor a false
//!   positive;
//! - per image and category, detections are sorted by score with a stable sort (numpy's
//!   mergesort: ties keep file order) and cut to the largest max-detections (100); ground
//!   truth is sorted ignored-last, also stably; IoUs come from maskApi ([`super::rle`]);
//! - greedy matching per IoU threshold: each detection takes the best remaining instance at
//!   least as good as the threshold (a later instance with an equal IoU wins), and stops at
//!   the first ignored instance once it holds a regular one;
//! - the area ranges use the ground truth's `area` field and the detection's area (its box's
//!   `w * h` when the results have boxes, else its mask's pixels, as `loadRes` sets it);
//!   unmatched detections outside a range are ignored in it;
//! - accumulation over images in the order of their (merged) ids, detections of all images
//!   sorted stably by score, cumulative sums in float, precision `tp / (tp + fp + eps)` with
//!   numpy's `spacing(1)`, the precision envelope, 101 recall points by a left
//!   `searchsorted`, and the means of `summarize` with numpy's pairwise summation.
//!
//! Thresholds are made as `np.linspace` makes them (`start + i * step`, the last one set to
//! `stop`), so that `iouThr == .75` finds its threshold exactly as numpy does.

use rayon::prelude::*;

use super::gt::CocoGt;
use super::rle::{Rle, bbox_iou, rle_iou};
use crate::stats::mean;

/// numpy's `spacing(1)`.
const EPS: f64 = f64::EPSILON;

/// The largest of COCO's max-detections (per image and category).
const MAX_DETS: [usize; 3] = [1, 10, 100];

/// COCO's area ranges: all, small (< 32²), medium (< 96²), large; bounds inclusive.
const AREA_RANGES: [[f64; 2]; 4] = [[0.0, 1e10], [0.0, 1024.0], [1024.0, 9216.0], [9216.0, 1e10]];

/// What is compared: boxes or masks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IouType {
    Bbox,
    Segm,
}

impl IouType {
    pub fn as_str(self) -> &'static str {
        match self {
            IouType::Bbox => "bbox",
            IouType::Segm => "segm",
        }
    }
}

/// One detection to score.
#[derive(Clone, Debug)]
pub struct Detection<'a> {
    /// Index into [`CocoGt::images`].
    pub image: usize,
    pub category_id: i64,
    pub score: f64,
    /// What `loadRes` sets as the area (see the module documentation).
    pub area: f64,
    pub bbox: [f64; 4],
    pub mask: Option<&'a Rle>,
}

/// numpy's `linspace(start, stop, num)` (endpoint included), value for value.
pub fn linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    let div = (num - 1) as f64;
    let step = (stop - start) / div;
    let mut v: Vec<f64> = (0..num).map(|i| i as f64 * step + start).collect();
    if num > 1 {
        v[num - 1] = stop;
    }
    v
}

/// COCOeval's IoU thresholds, 0.50:0.05:0.95.
pub fn iou_thresholds() -> Vec<f64> {
    linspace(0.5, 0.95, 10)
}

/// COCOeval's recall points, 0:0.01:1.
pub fn recall_thresholds() -> Vec<f64> {
    linspace(0.0, 1.0, 101)
}

/// The accumulated precision and recall (COCOeval's `eval`): -1 where a category has no
/// regular ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Accumulated {
    pub iou_thresholds: Vec<f64>,
    pub recall_thresholds: Vec<f64>,
    pub categories: Vec<i64>,
    /// `[T][R][K][A][M]`, C order.
    pub precision: Vec<f64>,
    /// `[T][K][A][M]`, C order.
    pub recall: Vec<f64>,
}

impl Accumulated {
    fn dims(&self) -> (usize, usize, usize, usize, usize) {
        (
            self.iou_thresholds.len(),
            self.recall_thresholds.len(),
            self.categories.len(),
            AREA_RANGES.len(),
            MAX_DETS.len(),
        )
    }

    pub fn precision_at(&self, t: usize, r: usize, k: usize, a: usize, m: usize) -> f64 {
        let (_, rn, kn, an, mn) = self.dims();
        self.precision[(((t * rn + r) * kn + k) * an + a) * mn + m]
    }

    pub fn recall_at(&self, t: usize, k: usize, a: usize, m: usize) -> f64 {
        let (_, _, kn, an, mn) = self.dims();
        self.recall[((t * kn + k) * an + a) * mn + m]
    }

    /// COCOeval's `summarize` for detection: AP, AP50, AP75, AP_small, AP_medium, AP_large,
    /// AR1, AR10, AR100, AR_small, AR_medium, AR_large.
    pub fn summarize(&self) -> [f64; 12] {
        [
            self.summary(true, None, 0, 2),
            self.summary(true, Some(0.5), 0, 2),
            self.summary(true, Some(0.75), 0, 2),
            self.summary(true, None, 1, 2),
            self.summary(true, None, 2, 2),
            self.summary(true, None, 3, 2),
            self.summary(false, None, 0, 0),
            self.summary(false, None, 0, 1),
            self.summary(false, None, 0, 2),
            self.summary(false, None, 1, 2),
            self.summary(false, None, 2, 2),
            self.summary(false, None, 3, 2),
        ]
    }

    /// One `_summarize`: the mean of the values above -1, or -1 when there is none.
    fn summary(&self, ap: bool, iou: Option<f64>, a: usize, m: usize) -> f64 {
        let (tn, rn, kn, _, _) = self.dims();
        let ts: Vec<usize> = (0..tn)
            .filter(|&t| iou.is_none_or(|v| self.iou_thresholds[t] == v))
            .collect();
        let mut values = Vec::new();
        for &t in &ts {
            if ap {
                for r in 0..rn {
                    for k in 0..kn {
                        values.push(self.precision_at(t, r, k, a, m));
                    }
                }
            } else {
                for k in 0..kn {
                    values.push(self.recall_at(t, k, a, m));
                }
            }
        }
        values.retain(|&v| v > -1.0);
        if values.is_empty() {
            -1.0
        } else {
            mean(&values)
        }
    }

    /// The precision at each recall point, area "all", 100 detections, averaged over the
    /// categories that have ground truth; at one IoU threshold, or averaged over all of them
    /// (`None`): the curves whose means are AP50, AP75 and AP. -1 where nothing is defined.
    pub fn precision_curve(&self, iou: Option<f64>) -> Vec<f64> {
        let (tn, rn, kn, _, _) = self.dims();
        (0..rn)
            .map(|r| {
                let mut values = Vec::new();
                for t in (0..tn).filter(|&t| iou.is_none_or(|v| self.iou_thresholds[t] == v)) {
                    for k in 0..kn {
                        values.push(self.precision_at(t, r, k, 0, 2));
                    }
                }
                values.retain(|&v| v > -1.0);
                if values.is_empty() {
                    -1.0
                } else {
                    mean(&values)
                }
            })
            .collect()
    }
}

/// The per-image, per-category, per-area-range result (COCOeval's `evaluateImg`).
struct ImageEval {
    /// Scores of the (at most 100) detections, best first.
    scores: Vec<f64>,
    /// `[T][D]`: the id of the matched ground truth, 0 for none (an id of 0 reads as none, as
    /// in COCOeval).
    matches: Vec<i64>,
    /// `[T][D]`.
    ignored: Vec<bool>,
    gt_ignored: Vec<bool>,
}

/// Runs COCOeval (`evaluate`, then `accumulate`) on the ground truth and the detections, the
/// detections in the toolkit's merged order (file order within an image).
pub fn evaluate(gt: &CocoGt, detections: &[Detection<'_>], iou_type: IouType) -> Accumulated {
    let iou_thrs = iou_thresholds();
    let rec_thrs = recall_thresholds();
    let categories = gt.categories.clone();
    let k_of = |c: i64| categories.binary_search(&c).ok();
    let (n_images, n_cats) = (gt.images.len(), categories.len());

    // Per (image, category): ground truth and detections in file order.
    let mut gts: Vec<Vec<usize>> = vec![Vec::new(); n_images * n_cats];
    for (i, a) in gt.annotations.iter().enumerate() {
        if let Some(k) = k_of(a.category_id) {
            gts[a.image * n_cats + k].push(i);
        }
    }
    let mut dts: Vec<Vec<usize>> = vec![Vec::new(); n_images * n_cats];
    for (i, d) in detections.iter().enumerate() {
        if let Some(k) = k_of(d.category_id) {
            dts[d.image * n_cats + k].push(i);
        }
    }

    // evalImgs[k][a][i], as COCOeval lays them out.
    let cells: Vec<[Option<ImageEval>; 4]> = (0..n_images * n_cats)
        .into_par_iter()
        .map(|cell| evaluate_cell(gt, detections, &gts[cell], &dts[cell], iou_type, &iou_thrs))
        .collect();

    let (tn, rn, an, mn) = (
        iou_thrs.len(),
        rec_thrs.len(),
        AREA_RANGES.len(),
        MAX_DETS.len(),
    );
    let blocks: Vec<(Vec<f64>, Vec<f64>)> = (0..n_cats * an)
        .into_par_iter()
        .map(|ka| {
            let (k, a) = (ka / an, ka % an);
            let evals: Vec<&ImageEval> = (0..n_images)
                .filter_map(|i| cells[i * n_cats + k][a].as_ref())
                .collect();
            // [M][T][R] precision and [M][T] recall of this category and area range.
            let mut precision = vec![-1.0; mn * tn * rn];
            let mut recall = vec![-1.0; mn * tn];
            for (m, &max_det) in MAX_DETS.iter().enumerate() {
                accumulate(&evals, max_det, tn, &rec_thrs, |t, r, v| {
                    precision[(m * tn + t) * rn + r] = v
                })
                .into_iter()
                .enumerate()
                .for_each(|(t, v)| {
                    if let Some(v) = v {
                        recall[m * tn + t] = v;
                    }
                });
            }
            (precision, recall)
        })
        .collect();

    let mut precision = vec![-1.0; tn * rn * n_cats * an * mn];
    let mut recall = vec![-1.0; tn * n_cats * an * mn];
    for (ka, (p, r)) in blocks.iter().enumerate() {
        let (k, a) = (ka / an, ka % an);
        for m in 0..mn {
            for t in 0..tn {
                recall[((t * n_cats + k) * an + a) * mn + m] = r[m * tn + t];
                for ri in 0..rn {
                    precision[(((t * rn + ri) * n_cats + k) * an + a) * mn + m] =
                        p[(m * tn + t) * rn + ri];
                }
            }
        }
    }
    Accumulated {
        iou_thresholds: iou_thrs,
        recall_thresholds: rec_thrs,
        categories,
        precision,
        recall,
    }
}

/// Stable sort of indices by descending score (numpy's `argsort(-scores, kind='mergesort')`).
fn by_score(indices: &mut [usize], score: impl Fn(usize) -> f64) {
    indices.sort_by(|&a, &b| score(b).total_cmp(&score(a)));
}

/// `computeIoU` and `evaluateImg` of one image and category, for the four area ranges.
fn evaluate_cell(
    gt: &CocoGt,
    detections: &[Detection<'_>],
    gt_ids: &[usize],
    dt_ids: &[usize],
    iou_type: IouType,
    iou_thrs: &[f64],
) -> [Option<ImageEval>; 4] {
    if gt_ids.is_empty() && dt_ids.is_empty() {
        return [None, None, None, None];
    }
    let mut dt: Vec<usize> = dt_ids.to_vec();
    by_score(&mut dt, |i| detections[i].score);
    dt.truncate(MAX_DETS[2]);
    let g: Vec<&super::gt::GtAnnotation> = gt_ids.iter().map(|&i| &gt.annotations[i]).collect();
    let d: Vec<&Detection<'_>> = dt.iter().map(|&i| &detections[i]).collect();
    let (nd, ng) = (d.len(), g.len());

    // ious[d][g], ground truth in file order.
    let mut ious = vec![0.0; nd * ng];
    for (di, det) in d.iter().enumerate() {
        for (gi, ann) in g.iter().enumerate() {
            ious[di * ng + gi] = match iou_type {
                IouType::Bbox => bbox_iou(&det.bbox, &ann.bbox, ann.iscrowd),
                IouType::Segm => match (det.mask, &ann.segmentation) {
                    (Some(dm), Some(gm)) => rle_iou(dm, gm, ann.iscrowd),
                    _ => 0.0,
                },
            };
        }
    }

    let tn = iou_thrs.len();
    std::array::from_fn(|a| {
        let [lo, hi] = AREA_RANGES[a];
        let ignore: Vec<bool> = g
            .iter()
            .map(|ann| ann.ignore || ann.area < lo || ann.area > hi)
            .collect();
        let mut order: Vec<usize> = (0..ng).collect();
        order.sort_by_key(|&i| ignore[i]);
        let gt_ignored: Vec<bool> = order.iter().map(|&i| ignore[i]).collect();
        let iscrowd: Vec<bool> = order.iter().map(|&i| g[i].iscrowd).collect();
        let mut gt_matched = vec![false; tn * ng];
        let mut matches = vec![0i64; tn * nd];
        let mut ignored = vec![false; tn * nd];
        if nd > 0 && ng > 0 {
            for (t, &thr) in iou_thrs.iter().enumerate() {
                for di in 0..nd {
                    let mut best = thr.min(1.0 - 1e-10);
                    let mut m: Option<usize> = None;
                    for (gi, &og) in order.iter().enumerate() {
                        if gt_matched[t * ng + gi] && !iscrowd[gi] {
                            continue;
                        }
                        if let Some(mm) = m
                            && !gt_ignored[mm]
                            && gt_ignored[gi]
                        {
                            break;
                        }
                        let v = ious[di * ng + og];
                        if v < best {
                            continue;
                        }
                        best = v;
                        m = Some(gi);
                    }
                    if let Some(mm) = m {
                        ignored[t * nd + di] = gt_ignored[mm];
                        matches[t * nd + di] = g[order[mm]].merged_id;
                        gt_matched[t * ng + mm] = true;
                    }
                }
            }
        }
        for (di, det) in d.iter().enumerate() {
            if det.area < lo || det.area > hi {
                for t in 0..tn {
                    if matches[t * nd + di] == 0 {
                        ignored[t * nd + di] = true;
                    }
                }
            }
        }
        Some(ImageEval {
            scores: d.iter().map(|det| det.score).collect(),
            matches,
            ignored,
            gt_ignored,
        })
    })
}

/// `accumulate` for one category, area range and max-detections: sets the precision at each
/// (threshold, recall point) through `set` and returns the recall per threshold (`None` when
/// the category has no regular ground truth: it stays -1).
fn accumulate(
    evals: &[&ImageEval],
    max_det: usize,
    tn: usize,
    rec_thrs: &[f64],
    mut set: impl FnMut(usize, usize, f64),
) -> Vec<Option<f64>> {
    if evals.is_empty() {
        return vec![None; tn];
    }
    let npig = evals
        .iter()
        .map(|e| e.gt_ignored.iter().filter(|&&i| !i).count())
        .sum::<usize>();
    if npig == 0 {
        return vec![None; tn];
    }
    // (image, detection) of every kept detection, concatenated in image order.
    let mut dets: Vec<(usize, usize)> = Vec::new();
    let mut scores: Vec<f64> = Vec::new();
    for (e, ev) in evals.iter().enumerate() {
        for d in 0..ev.scores.len().min(max_det) {
            dets.push((e, d));
            scores.push(ev.scores[d]);
        }
    }
    let mut order: Vec<usize> = (0..dets.len()).collect();
    by_score(&mut order, |i| scores[i]);
    let nd = order.len();
    let npig = npig as f64;
    let mut out = Vec::with_capacity(tn);
    let mut rc = vec![0.0; nd];
    let mut pr = vec![0.0; nd];
    for t in 0..tn {
        let (mut tp, mut fp) = (0u64, 0u64);
        for (j, &i) in order.iter().enumerate() {
            let (e, d) = dets[i];
            let ev = evals[e];
            let n = ev.scores.len();
            if !ev.ignored[t * n + d] {
                if ev.matches[t * n + d] != 0 {
                    tp += 1;
                } else {
                    fp += 1;
                }
            }
            let (tpf, fpf) = (tp as f64, fp as f64);
            rc[j] = tpf / npig;
            pr[j] = tpf / (fpf + tpf + EPS);
        }
        out.push(Some(if nd > 0 { rc[nd - 1] } else { 0.0 }));
        for i in (1..nd).rev() {
            if pr[i] > pr[i - 1] {
                pr[i - 1] = pr[i];
            }
        }
        for (r, &thr) in rec_thrs.iter().enumerate() {
            let pi = rc.partition_point(|&v| v < thr);
            // COCOeval stops at the first recall point beyond the last detection; the rest
            // keep 0.
            set(t, r, if pi < nd { pr[pi] } else { 0.0 });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_as_numpy_makes_them() {
        let t = iou_thresholds();
        assert_eq!(t.len(), 10);
        assert_eq!(t[0], 0.5);
        assert_eq!(t[5], 0.75);
        assert_eq!(t[9], 0.95);
        let r = recall_thresholds();
        assert_eq!(r.len(), 101);
        assert_eq!(r[100], 1.0);
    }
}
